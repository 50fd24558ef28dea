"""Full `keepout sil run` of every mission in config/missions/ (three processes on one bus).

The five runs start together (each its own bus group/port and its own telemetry ports, so they cannot
hear each other) with shortened durations, over udp_multicast on the host; the SocketCAN variant runs
in the vcan VM. Each summary's requirements are checked, and the run folder's contents are checked
against independent readers: hashlib for the config hash, cantools for the candump log, scipy's
Rotation and plain geometry for the Moon-cone margin.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = ROOT / "config" / "missions"
# (mission, simulated seconds): long enough for what each test judges
RUNS = {
    "demo-pointing": 200.0,        # first slew (125 deg past the Sun zone) settles by ~190 s
    "fault-imu-dropout": 110.0,    # IMU dropped 60..62 s, FDIR trip and SAFE entry
    "demo-quaternion": 90.0,       # reorientation under way past the forbidden-attitude cone
    "paper-s3-cones": 90.0,
    "paper-s3-star": 90.0,
}
RUN_TIMEOUT_S = 1500


def _start(mission: str, duration: float, out: Path, bus: str = "udp_multicast", **popen) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "cli", "sil", "run", str(MISSIONS / f"{mission}.yaml"), "--bus", bus,
           "--duration", str(duration), "--out", str(out), "--no-progress"]
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **popen)


def _run_dir(out: Path, mission: str) -> Path:
    dirs = sorted(out.glob(f"{mission}-*"))
    assert len(dirs) == 1, f"expected one run folder for {mission} in {out}: {dirs}"
    return dirs[0]


def _requirement(summary: dict, name: str) -> dict:
    found = [r for r in summary["requirements"] if r["name"] == name]
    assert found, f"no requirement {name!r} in {[r['name'] for r in summary['requirements']]}"
    return found[0]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    procs = {m: _start(m, d, out) for m, d in RUNS.items()}
    results = {}
    for mission, proc in procs.items():
        try:
            text, _ = proc.communicate(timeout=RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            text, _ = proc.communicate()
        results[mission] = {"code": proc.returncode, "output": text, "out": out}
    return results


def _summary(runs, mission: str) -> tuple[dict, Path]:
    result = runs[mission]
    run_dir = _run_dir(result["out"], mission)
    assert (run_dir / "summary.json").exists(), result["output"]
    return json.loads((run_dir / "summary.json").read_text()), run_dir


@pytest.mark.slow
@pytest.mark.parametrize("mission", list(RUNS))
def test_every_mission_keeps_out_and_never_slips(runs, mission):
    summary, run_dir = _summary(runs, mission)
    assert summary["simulated_s"] == pytest.approx(RUNS[mission], abs=0.2), runs[mission]["output"]
    keepout = [r for r in summary["requirements"] if r["name"].startswith("keep-out margin")]
    assert keepout, "every mission has zones"
    for r in keepout:
        assert r["pass"], f"{mission}: {r}"
    assert _requirement(summary, "cycle slips")["pass"], runs[mission]["output"]
    assert _requirement(summary, "unexpected FDIR events")["pass"], summary["fdir_trips"]
    assert summary["simulator"]["cycle_done_timeouts"] == 0
    for name in ("mission.yaml", "mission.yaml.sha256", "truth.npz", "bus.candump.log", "summary.json",
                 "margins.png", "wheels.png", "estimation.png", "ground/tm_raw.bin", "ground/events.jsonl"):
        assert (run_dir / name).exists(), f"{mission}: {name} missing"


@pytest.mark.slow
def test_demo_pointing_passes_every_requirement(runs):
    summary, run_dir = _summary(runs, "demo-pointing")
    failed = [r for r in summary["requirements"] if not r["pass"]]
    assert runs["demo-pointing"]["code"] == 0 and not failed, (failed, runs["demo-pointing"]["output"])
    settle = [s for s in summary["settling"] if s["target_from"] == "timeline[0]"][0]
    assert settle["settled_at_s"] is not None and settle["settling_time_s"] > 125.0  # >= a 125 deg slew at 1 deg/s
    assert (run_dir / "sky.png").exists()


@pytest.mark.slow
def test_demo_run_folder_is_consistent_with_independent_readers(runs):
    import cantools
    from scipy.spatial.transform import Rotation

    summary, run_dir = _summary(runs, "demo-pointing")
    # the config hash is the sha256 of the config file as written
    digest = hashlib.sha256((run_dir / "mission.yaml").read_bytes()).hexdigest()
    assert (run_dir / "mission.yaml.sha256").read_text().split()[0] == digest == summary["config_sha256"]
    # the flight software read its own file: the config used's flight_software section, number for number,
    # and the run's bus, with none of the truth's keys
    used, flown = (yaml.safe_load((run_dir / name).read_text()) for name in ("mission.yaml", "fsw.yaml"))
    assert set(flown) == {"bus", "flight_software"} and flown["flight_software"] == used["flight_software"]
    assert flown["bus"] == {"spec": used["bus"], "bitrate_bps": used["bus_bitrate_bps"],
                            "authentication": used["bus_authentication"]}
    # the candump log decodes with cantools and our DBC: one SYNC per tick, ticks in order
    db = cantools.database.load_file(ROOT / "config" / "icd" / "keepout.dbc")
    parser = cantools.logreader.Parser(open(run_dir / "bus.candump.log"))
    sync_id = db.get_message_by_name("SYNC").frame_id
    ticks = [db.decode_message(f.frame_id, f.data)["tick"] for f in parser if f.frame_id == sync_id]
    assert ticks == list(range(len(ticks))) and len(ticks) == summary["simulator"]["ticks"]
    # the Moon cone (15 deg) margin from truth with scipy's rotation and plain geometry
    truth = np.load(run_dir / "truth.npz")
    q = truth["q_NB"]
    y = Rotation.from_quat(np.c_[q[:, 1:], q[:, :1]]).apply([0.0, 0.0, 1.0])
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", y, truth["moon_N"]), -1, 1)))
    assert summary["zones"]["moon"]["min_margin_deg"] == pytest.approx(float((angle - 15.0).min()), abs=1e-6)


@pytest.mark.slow
def test_fault_run_trips_fdir_and_keeps_out(runs):
    summary, run_dir = _summary(runs, "fault-imu-dropout")
    assert _requirement(summary, "expected FDIR events")["pass"], summary["fdir_trips"]
    assert "IMU_STALE" in summary["fdir_trips"]
    events = [json.loads(line) for line in (run_dir / "ground" / "events.jsonl").read_text().splitlines()]
    to_safe = [e for e in events if e.get("event") == "MODE_CHANGED" and e["args"].get("to_mode") == "SAFE"]
    assert to_safe and 60.0 <= to_safe[0]["time_s"] <= 65.0
    injected = json.loads((run_dir / "simulator.json").read_text())["faults_injected"]
    assert injected, "the simulator logs every injected fault"


@pytest.mark.slow
def test_interrupt_stops_all_three_processes_and_still_writes_the_summary(tmp_path):
    import psutil

    proc = _start("demo-pointing", 3000.0, tmp_path, start_new_session=True)  # long enough to be interrupted on a busy host
    deadline = time.monotonic() + 600
    raw = None
    while time.monotonic() < deadline:
        dirs = list(tmp_path.glob("demo-pointing-*"))
        raw = dirs[0] / "ground" / "tm_raw.bin" if dirs else None
        if raw is not None and raw.exists() and raw.stat().st_size > 20000:
            break
        assert proc.poll() is None, proc.communicate()[0]
        time.sleep(0.5)
    children = psutil.Process(proc.pid).children(recursive=True)
    assert len(children) >= 2  # the ground and the flight software
    os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does to the foreground group
    text, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, text
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, f"left running: {alive}"
    run_dir = _run_dir(tmp_path, "demo-pointing")
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["interrupted"] and not summary["pass"]
    assert 0 < summary["simulated_s"] < 600
    assert (run_dir / "truth.npz").exists() and (run_dir / "bus.candump.log").stat().st_size > 0


def test_rejected_mission_starts_nothing(tmp_path):
    text = (MISSIONS / "demo-pointing.yaml").read_text().replace("half_angle_deg: 15.0", "half_angle_deg: 150.0")
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    result = subprocess.run([sys.executable, "-m", "cli", "sil", "run", str(bad), "--out", str(tmp_path / "runs"),
                             "--no-progress"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    assert f"{bad}:" in result.stderr and "half_angle_deg" in result.stderr
    assert not (tmp_path / "runs").exists()


@pytest.mark.socketcan
@pytest.mark.slow
def test_demo_over_socketcan(tmp_path):
    proc = _start("demo-pointing", 60.0, tmp_path, bus="socketcan:vcan0")
    text, _ = proc.communicate(timeout=RUN_TIMEOUT_S)
    summary = json.loads((_run_dir(tmp_path, "demo-pointing") / "summary.json").read_text())
    assert summary["bus"] == "socketcan:vcan0", text
    for r in summary["requirements"]:
        if r["name"].startswith("keep-out") or r["name"] == "cycle slips":
            assert r["pass"], (r, text)
    assert summary["simulator"]["cycle_done_timeouts"] == 0
