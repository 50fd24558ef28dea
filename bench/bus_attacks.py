"""Bus attacks on live lockstep runs, with and without bus authentication: how each run ends.

    .venv/bin/python bench/bus_attacks.py                 # demo-pointing, 300 s simulated per run
    .venv/bin/python bench/bus_attacks.py --duration 120  # a quicker look

A local attacker joins the run's udp_multicast group on loopback (any local user finds it in
/proc/net/igmp and /proc/net/udp; here it is read from endpoints.json) and sends, until the run ends:

* ``random``: frames with the identifiers the flight software reads and random payloads (about 1 in 256
  passes the E2E CRC), 50 every 10 ms;
* ``replay``: every frame of an earlier run of the same mission (recorded by listening on its bus, SecOC
  authenticators included), 50 every 10 ms, over and over;
* ``none``: no attack (the reference, and the cost of authentication: flying time side by side).

Each attack flies the mission twice, as shipped and with ``bus_authentication: true``. A row: how the run
ended, its simulated time, the flight software's cycles, the counters that show the attack (E2E CRC
errors, frames refused by SecOC), healthy wheels isolated, and the requirements that failed. Prints a
table and writes bench/results/bus_attacks.json (with the host load).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import can

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from fsw.bus import Icd, open_bus  # noqa: E402

MISSION = ROOT / "config" / "missions" / "demo-pointing.yaml"
BATCH, PAUSE_S = 50, 0.01


def _fly(mission: Path, out: Path, duration_s: float, attack) -> dict:
    """Fly ``mission`` in lockstep over udp_multicast with ``attack(group, port, stop)`` in a thread."""
    cmd = [sys.executable, "-m", "hil_sim", "sil", "run", str(mission), "--bus", "udp_multicast",
           "--duration", str(duration_s), "--out", str(out), "--no-progress"]
    started = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stop, thread = threading.Event(), None
    try:
        while thread is None and proc.poll() is None:
            for ep in out.glob("*/endpoints.json"):
                try:
                    bus = json.loads(ep.read_text()).get("bus", "")
                except ValueError:
                    continue
                if bus.startswith("udp_multicast:"):
                    _, group, port = bus.split(":")
                    thread = threading.Thread(target=attack, args=(group, int(port), stop), daemon=True)
                    thread.start()
            time.sleep(0.01)
        proc.communicate(timeout=3600)
    finally:
        stop.set()
        if thread is not None:
            thread.join(timeout=10)
        if proc.poll() is None:
            proc.kill()
    wall_s = time.monotonic() - started
    run_dir = next(p for p in out.iterdir() if p.is_dir())
    summary = json.loads((run_dir / "summary.json").read_text())
    sim = json.loads((run_dir / "simulator.json").read_text())
    hk = _last_hk(run_dir)
    return {"status": summary["status"], "pass": summary.get("pass"), "sim_s": sim.get("sim_s"),
            "flying_wall_s": sim.get("wall_s"), "run_wall_s": wall_s, "cycles": hk.get("cycles"),
            "crc_errors": hk.get("bus_crc_errors"), "auth_refused": hk.get("bus_auth_failures"),
            "wheels_isolated": hk.get("wheels_isolated"),
            "failed": [r["name"] for r in summary.get("requirements", []) if r.get("pass") is False]}


def _last_hk(run_dir: Path) -> dict:
    last: dict = {}
    path = run_dir / "ground" / "tm_decoded.jsonl"
    if path.exists():
        for line in path.open():
            values = json.loads(line).get("values") or {}
            if "bus_crc_errors" in values:
                last = values
    return last


def _flood(frames_of) -> callable:
    def attack(group: str, port: int, stop: threading.Event) -> None:
        bus = open_bus(f"udp_multicast:{group}:{port}")  # sends on loopback, where the run's bus listens
        try:
            for batch in frames_of():
                if stop.is_set():
                    break
                for msg in batch:
                    bus.send(msg)
                time.sleep(PAUSE_S)
        except can.CanError:
            pass
        finally:
            bus.shutdown()
    return attack


def _random_batches():
    ids = sorted(Icd().ids_sent_by("SIM", "IMU", "STR", "RW1", "RW2", "RW3", "RW4"))
    rnd = random.Random(7)
    while True:
        yield [can.Message(arbitration_id=rnd.choice(ids), is_extended_id=False,
                           data=bytes(rnd.getrandbits(8) for _ in range(8))) for _ in range(BATCH)]


def _record(mission: Path, out: Path, duration_s: float) -> list[can.Message]:
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

    _fly(mission, out, duration_s, listen)
    return recorded


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--duration", type=float, default=300.0, help="simulated seconds per run")
    p.add_argument("--out", default=str(ROOT / "bench" / "results" / "bus_attacks.json"))
    args = p.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        authenticated = tmp_path / "mission" / MISSION.name
        authenticated.parent.mkdir()
        authenticated.write_text(MISSION.read_text() + "\nbus_authentication: true\n")
        missions = {"off": MISSION, "on": authenticated}
        recordings = {auth: _record(m, tmp_path / f"rec-{auth}", args.duration) for auth, m in missions.items()}
        for attack in ("none", "random", "replay"):
            for auth, mission in missions.items():
                if attack == "none":
                    flood = _flood(lambda: iter(()))
                elif attack == "random":
                    flood = _flood(_random_batches)
                else:
                    frames = recordings[auth]
                    flood = _flood(lambda f=frames: (f[i:i + BATCH] for _ in iter(int, 1)
                                                     for i in range(0, len(f), BATCH)))
                row = {"attack": attack, "authentication": auth,
                       **_fly(mission, tmp_path / f"{attack}-{auth}", args.duration, flood)}
                rows.append(row)
                print(f"{attack:7s} auth {auth:3s}  {row['status'][:60]:60s} sim {row['sim_s']:7.1f} s  "
                      f"cycles {row['cycles']}  crc {row['crc_errors']}  refused {row['auth_refused']}  "
                      f"isolated {row['wheels_isolated']}  failed {row['failed']}", flush=True)
        replayed = {auth: len(r) for auth, r in recordings.items()}
    result = {"bench": "bus_attacks", "mission": MISSION.name, "duration_s": args.duration,
              "frames_per_batch": BATCH, "pause_s": PAUSE_S, "replayed_frames": replayed,
              "load_avg": os.getloadavg(), "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
