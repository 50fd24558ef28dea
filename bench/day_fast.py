"""A day in orbit in fast mode: wall time of one closed-loop run of 24 h on one core, environment on.

The mission is the vs-Basilisk environment row's (bench/vs_basilisk.py: demo-pointing in a 550 km
Sun-synchronous orbit with the telescope's facets, gravity gradient, solar radiation pressure through the
Earth's shadow, drag and a residual dipole), flown for ``--hours`` by the campaigns' fast mode
(hil_sim.campaign.fast.run_fast: the real flight software and the simulator in one process, every frame
through the ICD). The goal: 24 h in under 120 s of wall time on one core. Without momentum management the
wheels take up what the environment gives them all day; the run is timed as it flies.

    python bench/day_fast.py [--hours 24] [--repeat 1] [--cpu 0]

Prints a table and writes bench/results/day_fast.json (with the host's load before and after).
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

from _results import write_result  # bench/_results.py: this script's folder is on sys.path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

GOAL_WALL_S_PER_DAY = 120.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0, help="simulated hours (default 24)")
    ap.add_argument("--repeat", type=int, default=1, help="runs to take the median of (default 1)")
    ap.add_argument("--cpu", type=int, default=0, help="the core to pin to (default 0; -1: no pinning)")
    args = ap.parse_args(argv)
    if args.cpu >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    from vs_basilisk import demo_mission, run_keepout

    duration_s = 3600.0 * args.hours
    run_keepout(demo_mission(60.0, "environment"))  # compile and load every kernel first: not timed
    load_before = os.getloadavg()[0]
    walls = [run_keepout(demo_mission(duration_s, "environment")) for _ in range(args.repeat)]
    load_after = os.getloadavg()[0]
    wall = statistics.median(walls)
    per_day = wall * 86400.0 / duration_s
    print(f"{'simulated':>12} {'wall (median)':>14} {'sim s / wall s':>15} {'wall per 24 h':>14} {'goal':>8}")
    print(f"{duration_s:>10.0f} s {wall:>12.1f} s {duration_s / wall:>15.0f} {per_day:>12.1f} s "
          f"{'<= ' + format(GOAL_WALL_S_PER_DAY, '.0f') + ' s':>8}  load {load_before:.2f} -> {load_after:.2f}")
    result = {"bench": "day_fast", "mission": "bench/vs_basilisk.py environment row (demo-pointing, 550 km SSO)",
              "duration_s": duration_s, "repeat": args.repeat, "cpu": args.cpu, "walls_s": walls,
              "median_wall_s": wall, "wall_s_per_24h": per_day, "goal_wall_s_per_24h": GOAL_WALL_S_PER_DAY,
              "meets_goal": per_day <= GOAL_WALL_S_PER_DAY, "load_avg_1min_before": load_before,
              "load_avg_1min_after": load_after, "python": platform.python_version()}
    dest = ROOT / "bench" / "results" / "day_fast.json"
    print(f"wrote {write_result(dest, result).relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
