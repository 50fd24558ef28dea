"""A local attacker on the bus of a live lockstep SIL run, shared by tests/sil/test_bus_injection.py and
bench/bus_attacks.py: start the run, find its udp_multicast group and port (as any local user would in
/proc/net/igmp and /proc/net/udp; here in endpoints.json), and run an attack in a thread until the run ends.

The attacker sends with keepout's loopback udp_multicast bus: python-can's own ``udp_multicast`` bus sends
on the default interface, where the run's loopback-only bus never hears it.
"""
from __future__ import annotations

import json
import random
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Iterable, Iterator

import can

ROOT = Path(__file__).resolve().parents[2]
Attack = Callable[[str, int, threading.Event], None]
BATCH = 50  # frames an attack sends between pauses


def fly_under_attack(out: Path, attack: Attack, mission: Path, duration_s: float,
                     timeout_s: float = 600.0) -> tuple[int, str, Path]:
    """Fly ``mission`` in lockstep over udp_multicast for ``duration_s``, with ``attack(group, port, stop)``
    in a thread from the moment its bus is known; (exit code, output, run folder) when it ends."""
    cmd = [sys.executable, "-m", "cli", "sil", "run", str(mission), "--bus", "udp_multicast",
           "--duration", str(duration_s), "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stop = threading.Event()
    thread = None
    try:
        deadline = time.monotonic() + 120.0
        while thread is None and time.monotonic() < deadline and proc.poll() is None:
            for found in out.glob("*/endpoints.json"):
                try:
                    bus = json.loads(found.read_text())["bus"]
                except (ValueError, KeyError):
                    continue
                if bus.startswith("udp_multicast:"):
                    _, group, port = bus.split(":")
                    thread = threading.Thread(target=attack, args=(group, int(port), stop), daemon=True)
                    thread.start()
            time.sleep(0.01)
        output, _ = proc.communicate(timeout=timeout_s)
    finally:
        stop.set()
        if thread is not None:
            thread.join(timeout=10)
        if proc.poll() is None:
            proc.kill()
    assert thread is not None, "the run's bus never appeared in endpoints.json"
    return proc.returncode, output, next(p for p in out.iterdir() if p.is_dir())


def attacker_bus(group: str, port: int) -> can.BusABC:
    """A python-can bus that sends into the run's group on loopback."""
    from comms.bus import open_bus

    return open_bus(f"udp_multicast:{group}:{port}")


def flood(batches: Callable[[], Iterable[list[can.Message]]], pause_s: float) -> Attack:
    """An attack that sends each batch of ``batches()`` then sleeps ``pause_s``, until told to stop."""
    def attack(group: str, port: int, stop: threading.Event) -> None:
        bus = attacker_bus(group, port)
        try:
            for batch in batches():
                if stop.is_set():
                    break
                for msg in batch:
                    bus.send(msg)
                time.sleep(pause_s)
        except can.CanError:
            pass
        finally:
            bus.shutdown()
    return attack


def random_frames(ids: list[int], seed: int = 7, size: int = BATCH) -> Iterator[list[can.Message]]:
    """Batches of frames with identifiers from ``ids`` and random 8-byte payloads, for ever."""
    rnd = random.Random(seed)
    while True:
        yield [can.Message(arbitration_id=rnd.choice(ids), is_extended_id=False,
                           data=bytes(rnd.getrandbits(8) for _ in range(8))) for _ in range(size)]


def replayed(frames: list[can.Message], size: int = BATCH) -> Iterator[list[can.Message]]:
    """``frames`` in batches, over and over."""
    while True:
        for i in range(0, len(frames), size):
            yield frames[i:i + size]


def flight_side_ids() -> list[int]:
    """The identifiers the flight software reads (the simulator's and its devices')."""
    from comms.bus import Icd

    return sorted(Icd().ids_sent_by("SIM", "IMU", "STR", "RW1", "RW2", "RW3", "RW4"))


def listener(recorded: list[can.Message]) -> Attack:
    """Not an attack: every frame on the bus appended to ``recorded`` (authenticators included)."""
    def listen(group: str, port: int, stop: threading.Event) -> None:
        bus = can.Bus(interface="udp_multicast", channel=group, port=port, receive_own_messages=False)
        try:
            while not stop.is_set():
                msg = bus.recv(0.05)
                if msg is not None:
                    recorded.append(msg)
        finally:
            bus.shutdown()
    return listen


def last_housekeeping(run_dir: Path) -> dict:
    """The last housekeeping values the run's ground archived ({} when none)."""
    last: dict = {}
    path = run_dir / "ground" / "tm_decoded.jsonl"
    if path.exists():
        with open(path) as f:
            for line in f:
                values = json.loads(line).get("values") or {}
                if "bus_crc_errors" in values:
                    last = values
    return last
