"""Two wheels of four lost on demo-pointing, in fast mode: random pairs, kinds and times, the second often
during the slew to target C. Per run: the boresight's smallest margin, the time spent inside a zone and the
FDIR trips, on truth (the campaign judge). Every fault is a mission fault: physical ones (wheel_no_torque,
wheel_stuck) fail the wheel at their time, link ones (command frames lost, status lost) drop its frames.

    PYTHONPATH=$PWD python bench/double_wheel_failure.py --runs 30 --seed 1 --out /tmp/double.csv
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# bench/ holds fsw.py: run as a script, its folder must not shadow the fsw package
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(ROOT))

KINDS = ("no_torque", "stuck", "cmd_lost", "status_lost")
MISSION = ROOT / "config/missions/demo-pointing.yaml"


def _draw(rng: np.random.Generator, n_wheels: int) -> list[tuple[int, str, float]]:
    """Two distinct wheels, each with a kind and a time: the first anywhere before the second slew, the
    second within the slew to target C (300-450 s) two times in three, else anywhere."""
    a, b = (int(x) for x in rng.choice(n_wheels, size=2, replace=False))
    t1 = float(rng.uniform(5.0, 300.0))
    t2 = float(rng.uniform(300.0, 450.0)) if rng.random() < 2 / 3 else float(rng.uniform(t1 + 1.0, 550.0))
    return [(a, str(rng.choice(KINDS)), t1), (b, str(rng.choice(KINDS)), t2)]


def fly(mission, faults: list[tuple[int, str, float]], seed: int) -> dict:
    """One run with ``faults`` [(wheel index, kind, time)]; returns its row."""
    import hil_sim.campaign.fast as fast
    from hil_sim.sil import judge as summary
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import BusFault

    as_fault = {"no_torque": ("wheel_no_torque", "CMD"), "stuck": ("wheel_stuck", "CMD"),
                "cmd_lost": ("drop", "CMD"), "status_lost": ("drop", "STATUS")}
    added = [BusFault(kind=as_fault[k][0], message=f"RW{w + 1}_{as_fault[k][1]}", start_s=t, end_s=1e5)
             for w, k, t in faults]
    judge = fast.judge
    inside = {}

    def _judge(mission, truth, *args, **kwargs):  # the full margin series too: the time spent inside
        y_N = summary.boresight_N(truth["q_NB"], np.asarray(mission.spacecraft.instrument_boresight_B, dtype=float))
        zones = summary.sky_zone_series(mission, truth, y_N)
        worst = np.min(np.vstack([z.margin_deg for z in zones]), axis=0)
        below = np.nonzero(worst < 0.0)[0]
        inside["s"] = float(below.size * np.median(np.diff(truth["t_s"])))
        inside["from"] = float(truth["t_s"][below[0]]) if below.size else float("nan")
        return judge(mission, truth, *args, **kwargs)

    fast.judge = _judge  # (the judge keeps only each zone's minimum; the bench also wants the time inside)
    try:
        res = run_fast(mission.model_copy(update={"faults": list(mission.faults) + added}), seed)
    finally:
        fast.judge = judge
    m = res.metrics
    inside_s = inside["s"]
    return {"faults": " ".join(f"RW{w + 1}:{k}@{t:.0f}" for w, k, t in faults),
            "min_margin_deg": m.get("min_margin_deg"), "inside_s": inside_s, "inside_from_s": inside["from"],
            "final_error_deg": m.get("final_error_deg"), "trips": " ".join(sorted(set(
                e.split()[2] if len(e.split()) > 2 else e for e in res.events)))[:120],
            "events": ";".join(res.events)[:400]}


def main(argv: list[str] | None = None) -> int:
    from hil_sim.mission.model import load_mission

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=30)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default="double_wheel_failure.csv", help="one row per run (CSV)")
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "double_wheel_failure.json",
                   help="the summary and the rows (JSON, as every bench writes)")
    args = p.parse_args(argv)
    mission = load_mission(MISSION)
    rng = np.random.default_rng(args.seed)
    rows = []
    for run in range(args.runs):
        faults = _draw(rng, len(mission.spacecraft.wheels))
        t0 = time.time()
        row = {"run": run, **fly(mission, faults, seed=args.seed * 1000 + run)}
        rows.append(row)
        print(f"{run:3d} {row['faults']:48s} min margin {row['min_margin_deg']:8.2f} deg, inside "
              f"{row['inside_s']:6.1f} s ({time.time() - t0:.0f} s wall)", flush=True)
    with open(args.out, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    inside = [r for r in rows if r["min_margin_deg"] < 0]
    summary = {"runs": len(rows), "seed": args.seed, "entered_a_zone": len(inside),
               "worst_margin_deg": min(r["min_margin_deg"] for r in rows),
               "longest_inside_s": max(r["inside_s"] for r in rows), "host_loadavg_1min": os.getloadavg()[0]}
    print(f"{summary['runs']} runs, {summary['entered_a_zone']} entered a zone; worst margin "
          f"{summary['worst_margin_deg']:.2f} deg; longest inside {summary['longest_inside_s']:.0f} s")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
