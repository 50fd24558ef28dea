"""A day in orbit in fast mode: wall time of one closed-loop run of 24 h on one core, environment on.

The mission is the vs-Basilisk environment row's (bench/vs_basilisk.py: demo-pointing in a 550 km
Sun-synchronous orbit with the telescope's facets, gravity gradient, solar radiation pressure through the
Earth's shadow, drag and a residual dipole), flown for ``--hours`` by the campaigns' fast mode
(hil_sim.campaign.fast.run_fast: the real flight software and the simulator in one process, every frame
through the ICD). The goal: 24 h in under 120 s of wall time on one core. Without momentum management the
wheels take up what the environment gives them all day; the run is timed as it flies.

``--mission PATH`` flies a mission file instead (e.g. config/missions/leo-day.yaml: the magnetometer and the
rods unloading the wheels, ground targets), for ``--hours`` from its start, its timeline as written.

    python bench/day_fast.py [--mission PATH] [--hours 24] [--repeat 1] [--cpu 0]

Prints a table and writes bench/results/day_fast.json (day_fast_<mission file's stem>.json with --mission),
with the wall and CPU seconds of each run and the host's load before and after.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable

from _results import write_result  # bench/_results.py: this script's folder is on sys.path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

GOAL_WALL_S_PER_DAY = 120.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0, help="simulated hours (default 24)")
    ap.add_argument("--repeat", type=int, default=1, help="runs to take the median of (default 1)")
    ap.add_argument("--cpu", type=int, default=0, help="the core to pin to (default 0; -1: no pinning)")
    ap.add_argument("--mission", type=Path, default=None,
                    help="a mission file to fly (default: bench/vs_basilisk.py's environment row)")
    args = ap.parse_args(argv)
    if args.cpu >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    from vs_basilisk import run_keepout

    duration_s = 3600.0 * args.hours
    mission_of, name = _mission(args.mission)
    run_keepout(mission_of(60.0))  # compile and load every kernel first: not timed
    load_before = os.getloadavg()[0]
    walls, cpus = [], []
    for _ in range(args.repeat):
        cpu0 = time.process_time()
        walls.append(run_keepout(mission_of(duration_s)))
        cpus.append(time.process_time() - cpu0)
    load_after = os.getloadavg()[0]
    wall = statistics.median(walls)
    per_day = wall * 86400.0 / duration_s
    cpu_per_day = statistics.median(cpus) * 86400.0 / duration_s
    print(name)
    print(f"{'simulated':>12} {'wall (median)':>14} {'sim s / wall s':>15} {'wall per 24 h':>14} {'CPU per 24 h':>13} "
          f"{'goal':>8}")
    print(f"{duration_s:>10.0f} s {wall:>12.1f} s {duration_s / wall:>15.0f} {per_day:>12.1f} s {cpu_per_day:>11.1f} s "
          f"{'<= ' + format(GOAL_WALL_S_PER_DAY, '.0f') + ' s':>8}  load {load_before:.2f} -> {load_after:.2f}")
    result = {"bench": "day_fast", "mission": name,
              "duration_s": duration_s, "repeat": args.repeat, "cpu": args.cpu, "walls_s": walls,
              "median_wall_s": wall, "wall_s_per_24h": per_day, "cpus_s": cpus,
              "cpu_s_per_24h": cpu_per_day, "goal_wall_s_per_24h": GOAL_WALL_S_PER_DAY,
              "meets_goal": per_day <= GOAL_WALL_S_PER_DAY, "load_avg_1min_before": load_before,
              "load_avg_1min_after": load_after, "python": platform.python_version()}
    stem = "day_fast" if args.mission is None else f"day_fast_{args.mission.stem}"
    dest = ROOT / "bench" / "results" / f"{stem}.json"
    print(f"wrote {write_result(dest, result).relative_to(ROOT)}")
    return 0


def _mission(path: Path | None) -> tuple[Callable[[float], Any], str]:
    """(the mission flown for a duration [s], its name for the JSON): the environment row's, or ``path``'s
    (validated as written, then its duration set, so a short warm-up ends before its timeline's end)."""
    from vs_basilisk import demo_mission
    if path is None:
        return (lambda duration_s: demo_mission(duration_s, "environment"),
                "bench/vs_basilisk.py environment row (demo-pointing, 550 km SSO)")
    from hil_sim.mission.model import load_mission
    mission = load_mission(path)
    try:
        name = str(path.resolve().relative_to(ROOT))
    except ValueError:
        name = str(path)
    return lambda duration_s: mission.model_copy(update={"duration_s": duration_s}), name


if __name__ == "__main__":
    sys.exit(main())
