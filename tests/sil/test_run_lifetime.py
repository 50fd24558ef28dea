"""Every run judged, many runs at once, children that die with their parent.

Real `keepout sil run` processes, started from an empty folder (not the checkout), killed the ways a user,
a scheduler or the kernel kills them; the process tree is read with psutil and checked by pid.
"""
from __future__ import annotations

import json
import os
import re
import resource
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from hil_sim.sil import orchestrator as sil
from hil_sim.sil.judge import telemetry_completeness

LONG_S = 3000.0  # a run that is still going when the test acts on it (lockstep flies ~x100: 30 s or more)
SHORT_S = 8.0  # the default mission holds its first target: every requirement passes


def _start(cwd: Path, duration: float, *extra: str, **popen) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "cli", "sil", "run", "--duration", str(duration), "--no-progress", *extra]
    return subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **popen)


def _run_dirs(out: Path) -> list[Path]:
    return sorted(out.glob("demo-pointing-*"))


def _wait_running(proc: subprocess.Popen, out: Path) -> Path:
    """Wait until the ground archives telemetry (the flight software is in its loop); returns the run dir."""
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        dirs = _run_dirs(out)
        raw = dirs[0] / "ground" / "tm_raw.bin" if dirs else None
        if raw is not None and raw.exists() and raw.stat().st_size > 20000:
            return dirs[0]
        assert proc.poll() is None, proc.communicate()[0]
        time.sleep(0.3)
    raise AssertionError("the run never got going")


def _running(cwd: Path) -> tuple[subprocess.Popen, Path]:
    """A long run started from ``cwd``, once its flight software flies: (process, run folder)."""
    proc = _start(cwd, LONG_S)
    return proc, _wait_running(proc, cwd / "runs")


def _assert_all_end(procs: list[psutil.Process]) -> None:
    """Every process in ``procs`` ends within a few seconds (checked by pid)."""
    _, alive = psutil.wait_procs(procs, timeout=15)
    assert not alive, f"left running: {[(p.pid, p.cmdline()) for p in alive]}"


def _fsw(parent: psutil.Process) -> psutil.Process:
    """The flight software: a direct child (its assumption-check worker is its own child)."""
    found = [p for p in parent.children() if p.cmdline()[1:3] == ["-m", "fsw"]]
    assert len(found) == 1, [p.cmdline() for p in parent.children()]
    return found[0]


def _summary(run_dir: Path) -> dict:
    return json.loads((run_dir / "summary.json").read_text())


def test_run_ids_are_unique_within_a_second():
    ids = {sil.run_id("demo") for _ in range(200)}
    assert len(ids) == 200
    assert all(re.fullmatch(r"demo-\d{8}-\d{6}-[0-9a-f]{6}", i) for i in ids)


def test_telemetry_completeness_counts_against_simulated_time():
    from fsw.config import RatesConfig

    rates = RatesConfig(gnc_rate_hz=10, housekeeping_rate_hz=1)
    full = {"missing_packets": 0, "per_apid": {"0x010": {"received": 600}, "0x011": {"received": 60}}}
    assert telemetry_completeness(full, 60.0, rates)[0]
    tail_lost = {"missing_packets": 0, "per_apid": {"0x010": {"received": 180}, "0x011": {"received": 18}}}
    ok, detail = telemetry_completeness(tail_lost, 60.0, rates)
    assert not ok and "GNC: 180 packets received of 600" in detail
    gaps = {**full, "missing_packets": 3}
    assert not telemetry_completeness(gaps, 60.0, rates)[0]
    assert not telemetry_completeness({}, 60.0, rates)[0]  # no ground summary: the ground died


@pytest.mark.slow
def test_four_runs_of_one_mission_at_once_all_pass_from_an_empty_folder(tmp_path):
    procs = [_start(tmp_path, SHORT_S) for _ in range(4)]  # default --out runs: relative to the empty folder
    outputs = [p.communicate(timeout=900)[0] for p in procs]
    failed = [f"exit code {p.returncode}:\n{out}" for p, out in zip(procs, outputs) if p.returncode != 0]
    assert not failed, "\n\n".join(failed)  # each failed run's whole output (a list's repr would be cut)
    dirs = _run_dirs(tmp_path / "runs")
    assert len(dirs) == 4
    buses = set()
    for run_dir in dirs:
        summary = _summary(run_dir)
        assert summary["status"] == "completed" and summary["pass"], summary
        assert summary["telemetry_complete"]["complete"], summary["telemetry_complete"]
        buses.add(summary["bus"])
    assert len(buses) == 4  # each run on its own bus


@pytest.mark.slow
def test_parent_killed_by_sigkill_leaves_no_child(tmp_path):
    proc, _ = _running(tmp_path)
    children = psutil.Process(proc.pid).children(recursive=True)
    fsw = _fsw(psutil.Process(proc.pid))
    assert len(children) >= 3 and fsw.children(), "ground, flight software and its assumption-check worker"
    proc.kill()
    proc.communicate()
    _assert_all_end(children)


@pytest.mark.slow
def test_sigterm_of_the_parent_is_judged_interrupted_and_stops_every_child(tmp_path):
    proc, run_dir = _running(tmp_path)
    children = psutil.Process(proc.pid).children(recursive=True)
    proc.terminate()
    text, _ = proc.communicate(timeout=120)
    assert proc.returncode == sil.EXIT_TERMINATED, text
    _assert_all_end(children)
    summary = _summary(run_dir)
    assert summary["status"] == "interrupted" and not summary["pass"]
    assert 0 < summary["simulated_s"] < LONG_S and (run_dir / "truth.npz").exists()


@pytest.mark.slow
def test_flight_software_killed_mid_run_is_judged_crashed_and_its_worker_dies(tmp_path):
    proc, run_dir = _running(tmp_path)
    fsw = _fsw(psutil.Process(proc.pid))
    workers = fsw.children(recursive=True)
    assert workers, "the assumption-check worker"
    fsw.kill()
    text, _ = proc.communicate(timeout=300)
    assert proc.returncode == sil.EXIT_CRASHED, text
    _assert_all_end(workers)
    summary = _summary(run_dir)
    assert re.match(r"crashed: fsw at t = \d+\.\d s", summary["status"]), summary["status"]
    assert not summary["pass"] and (run_dir / "truth.npz").exists()
    assert "CRASHED" in text and "status: crashed: fsw at t =" in text


@pytest.mark.slow
def test_ground_killed_mid_run_cannot_pass(tmp_path):
    proc, run_dir = _running(tmp_path)
    ground = [p for p in psutil.Process(proc.pid).children() if p.pid != _fsw(psutil.Process(proc.pid)).pid
              and "spawn_main" in " ".join(p.cmdline())]
    assert len(ground) == 1, [p.cmdline() for p in psutil.Process(proc.pid).children()]
    ground[0].kill()
    text, _ = proc.communicate(timeout=300)
    assert proc.returncode == sil.EXIT_CRASHED, text
    summary = _summary(run_dir)
    assert summary["status"].startswith("crashed: ground at t = ") and not summary["pass"], summary["status"]


def _udp_drops(port: int) -> int:
    """The kernel's count of datagrams dropped at the local UDP port (a full receive buffer)."""
    drops = 0
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        fields = line.split()
        if int(fields[1].split(":")[1], 16) == port:
            drops += int(fields[-1])
    return drops


@pytest.mark.slow
def test_ground_that_lost_telemetry_is_judged_incomplete(tmp_path):
    """The ground stopped (SIGSTOP) and its socket filled (junk datagrams: its buffer holds minutes of
    telemetry), so the kernel drops the flight software's packets for a few seconds: the run completes,
    but the judge sees the sequence gaps and the run cannot pass."""
    proc, run_dir = _running(tmp_path)
    ground = [p for p in psutil.Process(proc.pid).children() if "spawn_main" in " ".join(p.cmdline())][0]
    link = json.loads((run_dir / "endpoints.json").read_text())  # where the run's telemetry goes
    port = link["tm_port"]
    ground.suspend()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as junk:
        junk.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(link["tm_interface"]))
        junk.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        deadline = time.monotonic() + 120
        while _udp_drops(port) < 1000 and time.monotonic() < deadline:
            for _ in range(1000):
                junk.sendto(b"\0" * 1024, (link["tm_host"], port))
    time.sleep(5.0)  # telemetry sent now finds the socket full
    ground.resume()
    assert _udp_drops(port) > 0, "the kernel dropped nothing: the test did not make the ground lose telemetry"
    text, _ = proc.communicate(timeout=900)
    summary = _summary(run_dir)
    assert summary["status"] == "incomplete telemetry", (summary["telemetry_complete"], text)
    assert proc.returncode == sil.EXIT_INCOMPLETE_TELEMETRY and not summary["pass"]
    assert "missing in sequence-count gaps" in summary["telemetry_complete"]["detail"]


@pytest.mark.slow
def test_disk_full_mid_run_is_judged_crashed_with_a_summary(tmp_path):
    """Files may not grow past 1 MB (RLIMIT_FSIZE; SIGXFSZ ignored, so a write fails as on a full disk):
    the candump log hits it mid-run."""
    def limit_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, 1 << 20))

    proc = _start(tmp_path, LONG_S, preexec_fn=limit_files)
    text, _ = proc.communicate(timeout=900)
    assert proc.returncode == sil.EXIT_CRASHED, text
    assert "Traceback" not in text
    summary = _summary(_run_dirs(tmp_path / "runs")[0])
    # whichever hits the limit first: the ground's archive or the simulator's candump log
    assert summary["status"] in text and "File too large" in text, text
    assert re.match(r"crashed: (ground at t = .*: it could not write its telemetry archive|simulator at t = "
                    r".*File too large)", summary["status"]), summary["status"]
    assert not summary["pass"]


def test_unwritable_out_is_a_clear_error_before_anything_starts(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    result = subprocess.run([sys.executable, "-m", "cli", "sil", "run", "--out", str(blocker / "runs"),
                             "--no-progress"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == sil.EXIT_NOT_STARTED
    assert result.stderr.strip().splitlines() == [
        f"run could not start: --out {blocker / 'runs'}: cannot write the run folder there: Not a directory"]


# Root writes into read-only folders; without the capability that lets it (util-linux's setpriv, in every
# Debian), it is held to the folder's mode like any user.
AS_USER = (["setpriv", "--bounding-set=-dac_override,-dac_read_search",
            "--inh-caps=-dac_override,-dac_read_search", "--"] if os.geteuid() == 0 else [])


def test_read_only_out_is_a_clear_error(tmp_path):
    out = tmp_path / "ro"
    out.mkdir(mode=0o555)
    result = subprocess.run([*AS_USER, sys.executable, "-m", "cli", "sil", "run", "--out", str(out),
                             "--no-progress"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == sil.EXIT_NOT_STARTED and "Permission denied" in result.stderr
    assert "Traceback" not in result.stderr


def test_assumption_check_worker_dies_with_a_killed_flight_software():
    """The worker started by the checker ends when its parent is SIGKILLed (no `close` runs then)."""
    code = ("import time\nfrom fsw.assumption_check import AssumptionChecker\n"
            "c = AssumptionChecker('process'); c.start(); print(c.worker.pid, flush=True); time.sleep(600)")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    worker = psutil.Process(int(proc.stdout.readline()))
    assert worker.ppid() == proc.pid
    proc.kill()
    proc.wait()
    _assert_all_end([worker])
