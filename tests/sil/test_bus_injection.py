"""A local attacker on the udp_multicast bus of a live lockstep run (any local user finds the run's group and
port in /proc/net/igmp and /proc/net/udp, here in endpoints.json): datagrams that are not frames, frames with
valid identifiers and random data, and an earlier run's traffic replayed. Before the hardening the first
killed both the flight software and the simulator ("fatal: CanOperationError: could not unpack received
message", exit 4) and the second moved onboard time to 4.75e9 s. Now junk is counted, never obeyed; forged
frames never move onboard time; with bus_authentication no forged or replayed frame is used at all and the
runs fly to their end. (The attacker sends on loopback, where the run's bus listens: frames sent with
python-can's own udp_multicast bus leave on the default interface and never arrived, which an earlier
version of these tests did not notice.)"""
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


def _fly_under_attack(out: Path, attack, mission: Path = MISSION) -> tuple[int, str, Path]:
    """Start a lockstep SIL run, call ``attack(group, port, stop)`` in a thread once its bus is known, and
    return (exit code, output, run folder) when the run ends."""
    cmd = [sys.executable, "-m", "hil_sim", "sil", "run", str(mission), "--bus", "udp_multicast",
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


def _attacker_bus(group: str, port: int) -> can.BusABC:
    """A python-can bus that sends into the run's group on loopback (python-can's own udp_multicast bus
    sends on the default interface, where the run's loopback-only bus never hears it)."""
    from fsw.bus import open_bus

    return open_bus(f"udp_multicast:{group}:{port}")


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


def _random_frames(ids: list[int], seed: int = 7, pause_s: float = 0.001):
    """An attack: frames with the ICD's identifiers and random payloads, 50 every ``pause_s`` (at most)."""
    def attack(group: str, port: int, stop: threading.Event) -> None:
        rnd = random.Random(seed)
        bus = _attacker_bus(group, port)
        try:
            while not stop.is_set():
                for _ in range(50):
                    bus.send(can.Message(arbitration_id=rnd.choice(ids), is_extended_id=False,
                                         data=bytes(rnd.getrandbits(8) for _ in range(8))))
                time.sleep(pause_s)
        except can.CanError:
            pass
        finally:
            bus.shutdown()
    return attack


def _flight_side_ids() -> list[int]:
    from fsw.bus import Icd

    return sorted(Icd().ids_sent_by("SIM", "IMU", "STR", "RW1", "RW2", "RW3", "RW4"))  # what the flight side reads


@pytest.mark.slow
def test_random_frames_with_valid_identifiers_cannot_move_onboard_time(tmp_path: Path) -> None:
    """Without authentication: about 1 in 256 random frames passes the CRC by chance. A SYNC among those
    used to start its random tick; now no forged tick is ever followed and no healthy wheel is isolated.
    The flood is still a denial of service on an unauthenticated bus: the forged frames that pass the CRC
    move the alive counters, so genuine frames of the next ticks fail their sequence check and the
    lockstep loop stalls (docs/security.md); the run ends with its status recorded."""
    code, output, run_dir = _fly_under_attack(tmp_path, _random_frames(_flight_side_ids()))
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] in ("completed",) or summary["status"].startswith("crashed: fsw"), summary["status"]
    truth = __import__("numpy").load(run_dir / "truth.npz")
    sim_s = float(truth["t_s"][-1])
    assert _last_hk(run_dir, "bus_crc_errors") > 1000  # the frames did reach the flight software
    assert _last_hk(run_dir, "wheels_isolated") == 0
    cycles = _last_hk(run_dir, "cycles")
    assert cycles <= round(sim_s * 10) + 1  # onboard time never ran ahead of the simulator's


@pytest.mark.slow
def test_random_frames_with_valid_identifiers_cannot_touch_an_authenticated_run(tmp_path: Path) -> None:
    """Forged frames (~1,000 a second) against a run with bus_authentication: none is used, the run flies to
    its end and meets its requirements. (A faster flood still fills the sockets' buffers: the kernel drops a
    genuine frame now and then, a lost CYCLE_DONE costs a lockstep timeout, cycles slip and telemetry is
    lost, a denial of service no authentication prevents; bench/bus_attacks.py, docs/security.md.)"""
    code, output, run_dir = _fly_under_attack(tmp_path / "run", _random_frames(_flight_side_ids(), pause_s=0.05),
                                              _authenticated_mission(tmp_path))
    _flew_safely(run_dir, output)
    truth = __import__("numpy").load(run_dir / "truth.npz")
    assert float(truth["t_s"][-1]) == pytest.approx(DURATION_S, abs=1.0)
    assert _last_hk(run_dir, "bus_auth_failures") > 500 and _last_hk(run_dir, "bus_crc_errors") == 0
    assert _last_hk(run_dir, "wheels_isolated") == 0


def _flew_safely(run_dir: Path, output: str) -> None:
    """The run flew to its end and met every requirement but, perhaps, cycle slips: a flood that takes the
    host's CPUs can make a tick late or a datagram dropped by the kernel, whatever the bus's protection."""
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed", output[-3000:]
    truth = __import__("numpy").load(run_dir / "truth.npz")
    assert float(truth["t_s"][-1]) == pytest.approx(DURATION_S, abs=1.0)
    failed = [r["name"] for r in summary["requirements"] if r["pass"] is False and r["name"] != "cycle slips"]
    assert not failed, (failed, output[-3000:])


def _authenticated_mission(tmp_path: Path) -> Path:
    (tmp_path / "mission").mkdir()
    path = tmp_path / "mission" / "demo-pointing.yaml"
    path.write_text(MISSION.read_text() + "\nbus_authentication: true\n")
    return path


@pytest.mark.slow
def test_an_earlier_runs_traffic_replayed_into_an_authenticated_run_is_refused(tmp_path: Path) -> None:
    """The replay that still broke a run without authentication: every frame of an earlier run (SYNCs that
    run ahead of the simulator's included) played into a live lockstep run. Without authentication nothing
    tells the two SYNC streams apart (the replayed ones took the onboard clock and the run ended "crashed:
    fsw"); with bus_authentication each run has its own key, so every replayed frame fails the MAC."""
    mission = _authenticated_mission(tmp_path)
    recorded: list[can.Message] = []

    def listen(group: str, port: int, stop: threading.Event) -> None:
        bus = can.Bus(interface="udp_multicast", channel=group, port=port, receive_own_messages=False)
        try:
            while not stop.is_set():
                msg = bus.recv(0.05)
                if msg is not None:
                    recorded.append(msg)
        finally:
            bus.shutdown()

    code, output, _ = _fly_under_attack(tmp_path / "earlier", listen, mission)
    assert code == 0, output[-3000:]
    auth_ids = {1008, 1009}
    assert len(recorded) > 10_000 and {m.arbitration_id for m in recorded} & auth_ids == auth_ids

    def replay(group: str, port: int, stop: threading.Event) -> None:
        bus = _attacker_bus(group, port)
        try:
            while not stop.is_set():
                for i in range(0, len(recorded), 50):
                    if stop.is_set():
                        break
                    for msg in recorded[i:i + 50]:
                        bus.send(msg)
                    time.sleep(0.02)  # ~2,500 frames a second: an attack, not a flood that starves the CPUs
        except can.CanError:
            pass
        finally:
            bus.shutdown()

    code, output, run_dir = _fly_under_attack(tmp_path / "attacked", replay, mission)
    _flew_safely(run_dir, output)
    refused = json.loads((run_dir / "simulator.json").read_text())["bus_authentication"]
    assert refused["bad_mac"] > 0 and refused["frames_accepted"] >= DURATION_S * 10
    assert _last_hk(run_dir, "bus_auth_failures") > 0
    assert _last_hk(run_dir, "bus_stale_syncs") == 0  # no replayed SYNC ever reached the flight software
    assert _last_hk(run_dir, "wheels_isolated") == 0
