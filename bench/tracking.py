"""POINTING guidance step cost: a fixed target against a moving one (nadir, a ground point).

    .venv/bin/python bench/tracking.py                 # 500 s of the example mission per case
    .venv/bin/python bench/tracking.py --duration-s 200

The example mission config/missions/earth-observation.yaml (Sun and Moon cones, a 600 km orbit) without its
timeline, run in fast mode (`hil_sim.campaign.fast.run_fast`: the real flight software, lockstep) with the
initial target as

* fixed:  the direction of Bengaluru at t = 0, fixed in N (target_kind inertial);
* ground: Bengaluru on the rotating Earth (target_kind ground, as the mission has it);
* nadir:  the Earth's centre (target_kind nadir).

None of them enters a zone's eps-layer: there the law is rebuilt every cycle for a moving target (its
substitute target moves with it; tests/fsw/test_tracking_steady.py flies one through a layer).

Wall-clock time of each POINTING guidance step (`PointingGuidance._pointing`, the per-cycle law) after a
warm-up; median, p99 and max in microseconds. Prints a table and writes bench/results/tracking.json.
"""
from __future__ import annotations

import argparse
import json
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
MISSION = ROOT / "config" / "missions" / "earth-observation.yaml"
WARMUP_CYCLES = 50

# the initial target lines of the example mission, replaced per case
_TARGET_LINES = re.compile(r"^    target_kind: ground\n    target_ground: .*\n", re.M)
_CASES = {
    "fixed": "    target_kind: inertial\n    target_N: {target_N}\n",
    "ground": "    target_kind: ground\n"
              "    target_ground: {{latitude_deg: 12.97, longitude_deg: 77.59, altitude_m: 920.0, min_elevation_deg: 10.0}}\n",
    "nadir": "    target_kind: nadir\n",
}


def _mission_text(case: str, duration_s: float) -> str:
    text = MISSION.read_text()
    text = re.sub(r"^timeline:\n(  - .*\n)+", "", text, flags=re.M)
    text = re.sub(r"^duration_s: .*$", f"duration_s: {duration_s}", text, flags=re.M)
    ra, dec = np.radians([246.164, 15.085])
    target_N = [float(np.cos(dec) * np.cos(ra)), float(np.cos(dec) * np.sin(ra)), float(np.sin(dec))]
    line = _CASES[case].format(target_N=target_N)
    new, n = _TARGET_LINES.subn(line, text)
    if n != 1:
        raise SystemExit(f"{MISSION}: the initial target lines were not found; update bench/tracking.py")
    return new


def run_case(case: str, duration_s: float) -> dict:
    from fsw.guidance.pointing import PointingGuidance
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import load_mission

    mission = load_mission(MISSION, text=_mission_text(case, duration_s))
    times: list[float] = []
    orig = PointingGuidance._pointing

    def timed(self, t_s, q, omega):
        t0 = time.perf_counter_ns()
        out = orig(self, t_s, q, omega)
        times.append((time.perf_counter_ns() - t0) * 1e-3)
        return out

    PointingGuidance._pointing = timed
    try:
        result = run_fast(mission, 621)
    finally:
        PointingGuidance._pointing = orig
    us = np.asarray(times[WARMUP_CYCLES:])
    m = result.metrics
    return {"case": case, "steps": int(us.size), "median_us": float(np.median(us)),
            "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max()),
            "min_margin_deg": m.get("min_margin_deg"), "final_error_deg": m.get("final_error_deg")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration-s", type=float, default=500.0)
    ap.add_argument("--cases", nargs="*", default=list(_CASES), choices=list(_CASES))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "tracking.json"))
    args = ap.parse_args()
    rows = [run_case(c, args.duration_s) for c in args.cases]
    print(f"{'case':<14}{'steps':>7}{'median us':>11}{'p99 us':>10}{'max us':>10}{'min margin':>12}{'final err':>11}")
    for r in rows:
        print(f"{r['case']:<14}{r['steps']:>7}{r['median_us']:>11.1f}{r['p99_us']:>10.1f}{r['max_us']:>10.1f}"
              f"{r['min_margin_deg'] if r['min_margin_deg'] is not None else float('nan'):>12.3f}"
              f"{r['final_error_deg'] if r['final_error_deg'] is not None else float('nan'):>11.3f}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"mission": str(MISSION.relative_to(ROOT)), "duration_s": args.duration_s,
                               "python": platform.python_version(), "machine": platform.machine(),
                               "rows": rows}, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
