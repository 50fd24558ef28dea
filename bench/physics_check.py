"""CPU time of the load-time physics check (`hil_sim.mission.physics_checks.check_mission`) per shipped mission.

What a first `keepout sil run` of a mission never seen before spends before flying (the verdict is
kept afterwards, see docs/first-run.md). Each mission is checked once untimed (imports, kernel caches
loaded), then ``--repeat`` times; the table gives the smallest CPU time (the host is shared, CPU time is
steadier than wall time) and the wall time of that run.

Run: ``.venv/bin/python bench/physics_check.py [--repeat N]``. Writes bench/results/physics_check.json
with the host load.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# bench/fsw.py would shadow the fsw package: drop this folder from the path
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
RESULTS = ROOT / "bench" / "results" / "physics_check.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2, help="timed checks per mission (default 2)")
    args = parser.parse_args()

    from hil_sim.mission.model import load_mission
    from hil_sim.mission.physics_checks import check_mission

    load_before = os.getloadavg()
    rows = []
    print(f"{'mission':24s} {'cpu s':>7s} {'wall s':>7s} {'samples':>8s}  verdict")
    for path in sorted((ROOT / "config" / "missions").glob("*.yaml")):
        mission = load_mission(path)
        report = check_mission(mission)
        best = None
        for _ in range(max(1, args.repeat)):
            cpu0, wall0 = time.process_time(), time.perf_counter()
            check_mission(mission)
            cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
            if best is None or cpu < best[0]:
                best = (cpu, wall)
        rows.append({"mission": path.stem, "cpu_s": round(best[0], 3), "wall_s": round(best[1], 3),
                     "samples": report.samples, "ok": report.ok})
        print(f"{path.stem:24s} {best[0]:7.2f} {best[1]:7.2f} {report.samples:8d}  {'PASS' if report.ok else 'FAIL'}")
    result = {"missions": rows, "repeat": args.repeat,
              "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                          "loadavg_before": load_before, "loadavg_after": os.getloadavg()}}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1) + "\n")
    print(f"load average {load_before[0]:.2f} -> {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; wrote {RESULTS}")


if __name__ == "__main__":
    main()
