"""`keepout bus log` (candump format read back by `cantools decode`) and `keepout bus monitor`."""
from __future__ import annotations

import io
import os
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from comms.bus import E2ESender, Icd, open_bus
from comms.bus.transport import random_udp_endpoint
from cli import bus as bus_cli
from cli.main import main as keepout_main

ROOT = Path(__file__).resolve().parents[2]
DBC = ROOT / "config" / "icd" / "keepout.dbc"
CANTOOLS = Path(sys.executable).with_name("cantools")


def _frames(icd: Icd) -> list[can.Message]:
    tx = E2ESender(icd)
    return [tx.frame("SYNC", dict(tick=7, frames_following=3, period_ms=100)),
            tx.frame("IMU_RATE", dict(omega_x=0.125, omega_y=-0.25, omega_z=0.0005, saturated=0)),
            tx.frame("ST_QUAT_A", dict(q_w=0.5, q_x=-0.5, valid=1, blind_source=1, sample_seq=3)),
            tx.frame("RW3_STATUS", dict(speed=-123.44, torque=0.0125, current=0.5, temp=31, fault=2))]


def _cantools_decode(log_text: str) -> str:
    result = subprocess.run([str(CANTOOLS), "decode", "--single-line", str(DBC)], input=log_text,
                            capture_output=True, text=True, check=True)
    return result.stdout


def _assert_decoded(decoded: str) -> None:
    lines = decoded.strip().splitlines()
    assert len(lines) == 4, decoded
    assert ":: SYNC(" in lines[0] and "tick: 7," in lines[0] and "period_ms: 100 ms" in lines[0]
    assert ":: IMU_RATE(" in lines[1] and "omega_x: 0.125 rad/s" in lines[1] and "omega_y: -0.25 rad/s" in lines[1]
    assert ":: ST_QUAT_A(" in lines[2] and "blind_source: sun" in lines[2]
    assert ":: RW3_STATUS(" in lines[3] and "speed: -123.44 rad/s" in lines[3] and "temp: 31 degC" in lines[3]


def test_log_frames_is_read_by_cantools_decode() -> None:
    icd = Icd()
    a, b = open_bus("virtual:clilog"), open_bus("virtual:clilog")
    try:
        for msg in _frames(icd):
            a.send(msg)
        out = io.StringIO()
        n = bus_cli.log_frames(b, out, "vcan0", lambda n: n < 4, lambda: 0.5)
    finally:
        a.shutdown()
        b.shutdown()
    assert n == 4
    assert all(line.split()[1] == "vcan0" for line in out.getvalue().splitlines())
    _assert_decoded(_cantools_decode(out.getvalue()))


def _log_via_cli(spec: str, tmp_path: Path) -> str:
    """Run `keepout bus log` as its own process on ``spec``, send frames, return the log text."""
    out = tmp_path / "bus.log"
    proc = subprocess.Popen([sys.executable, "-m", "cli", "bus", "log", "--bus", spec, "--count", "4",
                             "--duration", "60", "--out", str(out)], cwd=ROOT, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        first = proc.stderr.readline()
        assert "keepout bus:" in first, first + proc.stderr.read()
        time.sleep(0.3)
        bus = open_bus(spec)
        try:
            for msg in _frames(Icd()):
                bus.send(msg)
                time.sleep(0.01)
        finally:
            bus.shutdown()
        assert proc.wait(timeout=60) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    return out.read_text()


def test_keepout_bus_log_over_udp_multicast(tmp_path: Path) -> None:
    group, port = random_udp_endpoint()
    text = _log_via_cli(f"udp_multicast:{group}:{port}", tmp_path)
    _assert_decoded(_cantools_decode(text))


@pytest.mark.socketcan
def test_keepout_bus_log_over_socketcan(tmp_path: Path) -> None:
    text = _log_via_cli("socketcan:vcan1", tmp_path)
    assert text.split()[1] == "vcan1"
    _assert_decoded(_cantools_decode(text))


def test_monitor_lines_show_decoded_values_and_e2e_class() -> None:
    icd = Icd()
    frames = _frames(icd)
    damaged = bytearray(frames[1].data)
    damaged[5] ^= 0x10
    frames.append(can.Message(arbitration_id=frames[1].arbitration_id, data=bytes(damaged), is_extended_id=False))
    frames.append(can.Message(arbitration_id=0x7AB, data=b"\x01", is_extended_id=False))
    a, b = open_bus("virtual:climon"), open_bus("virtual:climon")
    try:
        for msg in frames:
            a.send(msg)
        out = io.StringIO()
        state = bus_cli.monitor(b, icd, out, lambda n: n < len(frames), lambda: 0.5, live=False)
    finally:
        a.shutdown()
        b.shutdown()
    lines = out.getvalue().splitlines()
    assert "SYNC" in lines[0] and "ok" in lines[0] and "tick=7" in lines[0]
    assert "IMU_RATE" in lines[4] and "crc_error" in lines[4] and "omega_x" not in lines[4]
    assert "0x7AB" in lines[5] and "unknown_id" in lines[5]
    assert state.receiver.counters["IMU_RATE"]["crc_error"] == 1
    table = state.table(time.monotonic())
    assert table.row_count == 5


def test_monitor_names_secoc_authenticators_and_does_not_call_them_unknown() -> None:
    from comms.bus.secoc import authenticator

    icd = Icd()
    sync = _frames(icd)[0]
    auth = authenticator(bytes(32), icd.authenticators["SIM"], 1, sync)
    stray = can.Message(arbitration_id=0x7AB, data=b"\x01", is_extended_id=False)
    state = bus_cli.MonitorState(icd)
    lines = [state.line(state.feed(msg, 1.0)) for msg in (sync, auth, stray)]
    assert "SECOC_SIM" in lines[1] and "0x7AB" in lines[2]
    assert state.table(2.0).caption == "unknown ids: 1"  # the stray frame, not the authenticator


def test_bad_bus_spec_is_a_clear_error(capsys: pytest.CaptureFixture) -> None:
    assert keepout_main(["bus", "log", "--bus", "canbus:9", "--count", "1"]) == 2
    assert "accepted: auto | socketcan" in capsys.readouterr().err
