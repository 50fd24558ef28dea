"""The processor-in-the-loop split: `keepout fsw` and `keepout sim` as two processes on one bus.

Over udp_multicast on the host and over SocketCAN vcan0 (in the vcan-vm guest, marker ``socketcan``), the
two commands fly demo-pointing (first slew) in lockstep: every tick answered, the timeline's telecommands
delivered, the truth requirements met, both processes ending by themselves with exit code 0.
"""
from __future__ import annotations

import json
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from comms.bus.transport import UDP_GROUP_PREFIX

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "config" / "missions" / "demo-pointing.yaml"
KEEPOUT = [sys.executable, "-m", "cli"]


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start_fsw(bus: str, tmp_path: Path, mission: Path = MISSION) -> tuple[subprocess.Popen, Path, int]:
    from comms.link_security import write_key_file

    tc_port = _free_port()
    log = tmp_path / "fsw.log"
    write_key_file(tmp_path / "bench.key")  # the bench's link key: both sides are given it
    proc = subprocess.Popen([*KEEPOUT, "fsw", str(mission), "--bus", bus, "--tc-port", str(tc_port),
                             "--tm-port", str(_free_port()), "--first-sync-timeout-s", "300",
                             "--key-file", str(tmp_path / "bench.key"), "--bus-file", str(tmp_path / "bus.txt")],
                            stdout=open(log, "w"), stderr=subprocess.STDOUT, cwd=ROOT)
    deadline = time.monotonic() + 600.0  # a fresh machine compiles the numba kernels on the first start
    while "fsw: ready" not in log.read_text():
        assert proc.poll() is None, log.read_text()
        assert time.monotonic() < deadline, "the flight software never said it was ready"
        time.sleep(0.2)
    return proc, log, tc_port


def _fly_split(bus: str, tmp_path: Path, duration_s: float, authenticated: bool = False) -> dict:
    mission = MISSION
    if authenticated:
        mission = tmp_path / "demo-pointing.yaml"
        mission.write_text(MISSION.read_text() + "\nbus_authentication: true\n")
    fsw, log, tc_port = _start_fsw(bus, tmp_path, mission)
    bus = (tmp_path / "bus.txt").read_text().strip()  # the bus the flight software opened, as docs/hil-bench.md
    assert f"fsw: ready: bus {bus}" in log.read_text()
    try:
        out = tmp_path / "sim"
        sim = subprocess.run([*KEEPOUT, "sim", str(mission), "--bus", bus, "--duration", str(duration_s),
                              "--tc", f"127.0.0.1:{tc_port}", "--out", str(out),
                              "--key-file", str(tmp_path / "bench.key")],
                             capture_output=True, text=True, cwd=ROOT, timeout=1200)
        assert sim.returncode == 0, sim.stdout + sim.stderr
        assert fsw.wait(timeout=120) == 0, log.read_text()  # ends by itself once SYNC stops
    finally:
        if fsw.poll() is None:
            fsw.kill()
    stats = json.loads((out / "simulator.json").read_text())
    ticks = int(round(duration_s * 10))
    assert stats["ticks"] == ticks and stats["cycle_done"] == ticks and stats["cycle_done_timeouts"] == 0
    assert stats["bus"] == bus and stats["telecommand_errors"] == []
    assert [c["command"] for c in stats["telecommands"]] == ["SEC_RESYNC", "SET_TARGET"]  # the first slew's target
    check = json.loads((out / "truth_check.json").read_text())
    names = {r["name"]: r for r in check["requirements"]}
    assert check["pass"], check
    assert names["keep-out margin sun"]["pass"] and names["keep-out margin moon"]["pass"]
    if duration_s >= 300.0:
        assert names["settling (timeline[0])"]["pass"]  # the slew happened: the flight software flew it
    if authenticated:  # every frame the simulator used was authenticated, none refused
        auth = stats["bus_authentication"]
        assert auth["frames_accepted"] >= 2 * ticks and auth["bad_mac"] == auth["unauthenticated"] == 0
        assert "(SecOC)" in log.read_text()
    return check


def test_split_flies_demo_pointing_over_udp_multicast(tmp_path: Path) -> None:
    """As docs/hil-bench.md walks through it on one host: the flight software picks a random group and port
    and writes them to --bus-file, the simulator is given them."""
    _fly_split("udp_multicast", tmp_path, duration_s=300.0)


@pytest.mark.socketcan
def test_split_flies_demo_pointing_over_socketcan(tmp_path: Path) -> None:
    _fly_split("socketcan:vcan0", tmp_path, duration_s=300.0)


@pytest.mark.socketcan
def test_split_flies_with_bus_authentication_over_socketcan(tmp_path: Path) -> None:
    _fly_split("socketcan:vcan0", tmp_path, duration_s=300.0, authenticated=True)


def test_split_flies_with_bus_authentication_over_udp_multicast(tmp_path: Path) -> None:
    _fly_split("udp_multicast", tmp_path, duration_s=300.0, authenticated=True)


def test_split_and_sil_judge_a_shortened_run_alike(tmp_path: Path) -> None:
    """--duration 120 ends the run before the first slew can settle: the split said FAIL (settling "not
    settled", final error 29.9 deg) where `keepout sil run` said "not reached" and PASS. One judge now:
    the same rows, values, limits and verdict."""
    (tmp_path / "split").mkdir()
    check = _fly_split("udp_multicast", tmp_path / "split", duration_s=120.0)
    sil = subprocess.run([*KEEPOUT, "sil", "run", str(MISSION), "--bus", "udp_multicast", "--duration", "120",
                          "--out", str(tmp_path / "sil"), "--no-progress"],
                         capture_output=True, text=True, cwd=ROOT, timeout=1200)
    assert sil.returncode == 0, sil.stdout + sil.stderr
    summary = json.loads(next((tmp_path / "sil").glob("*/summary.json")).read_text())
    sil_rows = {r["name"]: r for r in summary["requirements"]}
    split_rows = {r["name"]: r for r in check["requirements"]}
    assert split_rows and set(split_rows) <= set(sil_rows)
    for name, row in split_rows.items():
        assert (row["value"], row["limit"], row["pass"]) == (sil_rows[name]["value"], sil_rows[name]["limit"],
                                                            sil_rows[name]["pass"]), name
    assert split_rows["settling (timeline[0])"]["value"] == "not reached"
    assert check["pass"] and summary["pass"]


def test_sim_without_flight_software_says_what_to_start(tmp_path: Path) -> None:
    bus = f"udp_multicast:{UDP_GROUP_PREFIX}.250.{random.randint(1, 254)}:{random.randint(44000, 59000)}"
    sim = subprocess.run([*KEEPOUT, "sim", str(MISSION), "--bus", bus, "--duration", "5", "--wait-s", "1",
                          "--no-timeline", "--out", str(tmp_path / "sim")],
                         capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert sim.returncode == 3, sim.stdout + sim.stderr
    assert "start `keepout fsw MISSION --bus SPEC` first" in sim.stderr and "Traceback" not in sim.stderr


@pytest.mark.parametrize("option, value, message", [("--tm-port", "70000", "70000 is not a UDP port"),
                                                     ("--bitrate", "5", "not a CAN bit rate")])
def test_bad_fsw_options_are_one_line_errors(option: str, value: str, message: str) -> None:
    proc = subprocess.run([*KEEPOUT, "fsw", str(MISSION), option, value], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("command", ["fsw", "sim"])
def test_bad_bus_spec_is_a_one_line_error(command: str, tmp_path: Path) -> None:
    proc = subprocess.run([*KEEPOUT, command, str(MISSION), "--bus", "warpdrive:0"], capture_output=True,
                          text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "warpdrive:0" in proc.stderr and "pcan" in proc.stderr and "Traceback" not in proc.stderr
