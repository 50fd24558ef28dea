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
import sys
import tempfile
from pathlib import Path

import can

ROOT = Path(__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "sil"))  # bus_attack_kit: the attacker, shared with the tests
from bus_attack_kit import (BATCH, flight_side_ids, flood, fly_under_attack, last_housekeeping,  # noqa: E402
                            listener, random_frames, replayed)

MISSION = ROOT / "config" / "missions" / "demo-pointing.yaml"
PAUSE_S = 0.01  # between batches of BATCH frames


def _fly(mission: Path, out: Path, duration_s: float, attack) -> dict:
    code, _, run_dir = fly_under_attack(out, attack, mission, duration_s, timeout_s=3600.0)
    summary = json.loads((run_dir / "summary.json").read_text())
    sim = json.loads((run_dir / "simulator.json").read_text())
    hk = last_housekeeping(run_dir)
    return {"status": summary["status"], "exit_code": code, "pass": summary.get("pass"), "sim_s": sim.get("sim_s"),
            "flying_wall_s": sim.get("wall_s"), "cycles": hk.get("cycles"), "crc_errors": hk.get("bus_crc_errors"),
            "auth_refused": hk.get("bus_auth_failures"), "wheels_isolated": hk.get("wheels_isolated"),
            "failed": [r["name"] for r in summary.get("requirements", []) if r.get("pass") is False]}


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
        recordings: dict[str, list[can.Message]] = {}
        for auth, mission in missions.items():  # an earlier run of each, recorded off its bus
            recordings[auth] = []
            _fly(mission, tmp_path / f"rec-{auth}", args.duration, listener(recordings[auth]))
        attacks = {"none": lambda auth: iter(()), "random": lambda auth: random_frames(flight_side_ids()),
                   "replay": lambda auth: replayed(recordings[auth])}
        print(f"{'attack':7s} {'auth':4s} {'status':40s} {'sim_s':>6s} {'flying_s':>8s} {'cycles':>6s} "
              f"{'crc':>6s} {'refused':>8s} {'isolated':>8s}  failed")
        for attack, batches in attacks.items():
            for auth, mission in missions.items():
                row = {"attack": attack, "authentication": auth,
                       **_fly(mission, tmp_path / f"{attack}-{auth}", args.duration,
                              flood(lambda b=batches, a=auth: b(a), PAUSE_S))}
                rows.append(row)
                print(f"{attack:7s} {auth:4s} {row['status'][:40]:40s} {row['sim_s']:6.1f} {row['flying_wall_s']:8.2f} "
                      f"{row['cycles']!s:>6s} {row['crc_errors']!s:>6s} {row['auth_refused']!s:>8s} "
                      f"{row['wheels_isolated']!s:>8s}  {', '.join(row['failed'])}", flush=True)
        replayed_frames = {auth: len(r) for auth, r in recordings.items()}
    result = {"bench": "bus_attacks", "mission": MISSION.name, "duration_s": args.duration,
              "frames_per_batch": BATCH, "pause_s": PAUSE_S, "replayed_frames": replayed_frames,
              "load_avg": os.getloadavg(), "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
