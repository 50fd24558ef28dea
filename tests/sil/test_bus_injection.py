"""A local attacker on the udp_multicast bus of a live lockstep run (any local user finds the run's group and
port in /proc/net/igmp and /proc/net/udp, here in endpoints.json): datagrams that are not frames, an earlier
run's candump log replayed, and frames with valid identifiers and random data. Before the hardening the first
killed both the flight software and the simulator ("fatal: CanOperationError: could not unpack received
message", exit 4), the second stalled the loop and ended "crashed: fsw", the third moved onboard time to
4.75e9 s. Now each run flies to its end and passes: junk is counted, never obeyed."""
from __future__ import annotations

import json
import random
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import msgpack
import pytest

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "config" / "missions" / "demo-pointing.yaml"
DURATION_S = 300.0  # lockstep: a few seconds of wall time, long enough to be hit


def _fly_under_attack(out: Path, attack) -> tuple[int, str, Path]:
    """Start a lockstep SIL run, call ``attack(group, port, stop)`` in a thread once its bus is known, and
    return (exit code, output, run folder) when the run ends."""
    cmd = [sys.executable, "-m", "hil_sim", "sil", "run", str(MISSION), "--bus", "udp_multicast",
           "--duration", str(DURATION_S), "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stop = threading.Event()
    thread = None
    try:
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and proc.poll() is None:
            found = list(out.glob("*/endpoints.json"))
            if found:
                try:
                    bus = json.loads(found[0].read_text())["bus"]
                except (ValueError, KeyError):
                    bus = ""
                if bus.startswith("udp_multicast:"):
                    _, group, port = bus.split(":")
                    thread = threading.Thread(target=attack, args=(group, int(port), stop), daemon=True)
                    thread.start()
                    break
            time.sleep(0.01)
        output, _ = proc.communicate(timeout=600)
    finally:
        stop.set()
        if thread is not None:
            thread.join(timeout=10)
        if proc.poll() is None:
            proc.kill()
    assert thread is not None, "the run's bus never appeared in endpoints.json"
    return proc.returncode, output, next(out.glob("demo-pointing-*"))


def _sender() -> socket.socket:
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
    return tx


def _last_hk(run_dir: Path, channel: str) -> int:
    last = None
    with open(run_dir / "ground" / "tm_decoded.jsonl") as f:
        for line in f:
            rec = json.loads(line)
            values = rec.get("values") or {}
            if channel in values:
                last = values[channel]
    assert last is not None, f"no {channel} in the archive"
    return int(last)


@pytest.mark.slow
def test_datagrams_that_are_not_frames_never_stop_a_run(tmp_path: Path) -> None:
    junk = [b"0123456789", msgpack.packb({"arbitration_id": 1, "data": "x"}), msgpack.packb([1, 2, 3]),
            msgpack.packb({"unexpected": True}), b"\x00" * 300]

    def attack(group: str, port: int, stop: threading.Event) -> None:
        tx = _sender()
        while not stop.is_set():
            for d in junk:
                tx.sendto(d, (group, port))
            time.sleep(0.01)  # ~500 a second: a flood that fills the sockets' buffers drops real frames too

    code, output, run_dir = _fly_under_attack(tmp_path, attack)
    assert code == 0, output[-3000:]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed"
    sim = json.loads((run_dir / "simulator.json").read_text())
    assert sim["bus_decode_errors"] > 0
    assert _last_hk(run_dir, "bus_decode_errors") > 0


@pytest.mark.slow
def test_random_frames_with_valid_identifiers_cannot_move_onboard_time(tmp_path: Path) -> None:
    """Frames with the ICD's identifiers and random payloads: about 1 in 256 passes the CRC by chance, and a
    SYNC among those used to start its random tick."""
    from fsw.bus import Icd

    ids = sorted(Icd().ids_sent_by("SIM", "IMU", "STR", "RW1", "RW2", "RW3", "RW4"))  # what the flight side reads

    def attack(group: str, port: int, stop: threading.Event) -> None:
        rnd = random.Random(7)
        bus = can.Bus(interface="udp_multicast", channel=group, port=port, receive_own_messages=False)
        try:
            while not stop.is_set():
                for _ in range(50):
                    bus.send(can.Message(arbitration_id=rnd.choice(ids), is_extended_id=False,
                                         data=bytes(rnd.getrandbits(8) for _ in range(8))))
                time.sleep(0.001)
        except can.CanError:
            pass
        finally:
            bus.shutdown()

    code, output, run_dir = _fly_under_attack(tmp_path, attack)
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed", output[-3000:]
    truth = __import__("numpy").load(run_dir / "truth.npz")
    assert float(truth["t_s"][-1]) == pytest.approx(DURATION_S, abs=1.0)
    margins = [r for r in summary["requirements"] if r["name"].startswith("keep-out")]
    assert margins and all(r["pass"] for r in margins), margins
