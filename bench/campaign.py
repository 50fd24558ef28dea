"""Campaign throughput: the regression campaign in fast mode, local pool and Dask LocalCluster scaling.

    .venv/bin/python bench/campaign.py [--runs 4] [--duration 600] [--workers 1 2]

Reports, for the regression campaign (config/campaigns/regression.yaml) in ``fast`` mode:
  * local process pool with 2 workers: runs per minute and total simulated seconds per wall second;
  * a Dask ``distributed.LocalCluster`` with 1 and 2 worker processes (same code path): the scaling;
  * where one run's time goes per GNC tick (simulator frames out, flight software cycle, world step),
    from one in-process run with timers around the phases.
Goal (issue 7): >= 3,000 simulated seconds per wall second in total. Prints a table and writes
bench/results/campaign.json. Wall times include process start-up and each run's set-up.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hil_sim.campaign.runner import build_plan, prepare_out_dir, run_campaign  # noqa: E402
from hil_sim.campaign.spec import load_campaign  # noqa: E402

CAMPAIGN = ROOT / "config" / "campaigns" / "regression.yaml"
GOAL_SIM_S_PER_WALL_S = 3000.0


def _plan(runs: int, duration: float | None):
    campaign = load_campaign(CAMPAIGN)
    if duration is not None:
        campaign = campaign.model_copy(update={"duration_s": duration})
    plan, base = build_plan(CAMPAIGN, runs=runs, campaign=campaign)
    return plan, base


def _measure(label: str, runs: int, duration: float | None, **backend) -> dict:
    plan, base = _plan(runs, duration)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        prepare_out_dir(out, plan, CAMPAIGN, base)
        start = time.perf_counter()
        outcome = run_campaign(plan, out, **backend)
        wall = time.perf_counter() - start
    recs = outcome.records
    sim = sum(r.sim_time_s for r in recs)
    per_run = [r.sim_time_s / r.wall_s for r in recs if r.wall_s > 0]
    return {"backend": label, "runs": len(recs), "errors": sum(r.status == "error" for r in recs),
            "wall_s": wall, "sim_s": sim, "runs_per_min": 60.0 * len(recs) / wall,
            "sim_s_per_wall_s": sim / wall, "median_run_wall_s": statistics.median(r.wall_s for r in recs),
            "median_run_sim_s_per_wall_s": statistics.median(per_run)}


def _tick_breakdown(duration: float) -> dict:
    """One in-process run with timers around the tick phases (monkeypatched here, bench only)."""
    import hil_sim.lockstep as lockstep
    from fsw.app import FlightSoftware
    from fsw.bus.driver import FswBusDriver
    from hil_sim.campaign.fast import run_fast

    spent = {"simulator_frames_out": 0.0, "fsw_collect_inputs": 0.0, "fsw_cycle": 0.0,
             "world_step_and_commands_in": 0.0}
    originals = []

    def timed(cls, name, key):
        fn = getattr(cls, name)
        originals.append((cls, name, fn))

        def wrapper(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                spent[key] += time.perf_counter() - t0
        setattr(cls, name, wrapper)

    timed(lockstep.Simulator, "begin_tick", "simulator_frames_out")
    timed(FswBusDriver, "collect_tick", "fsw_collect_inputs")
    timed(FlightSoftware, "run_cycle", "fsw_cycle")
    timed(lockstep.Simulator, "end_tick", "world_step_and_commands_in")
    try:
        plan, _ = _plan(1, duration)
        _, mission = plan.mission(plan.draw(0), 0)
        t0 = time.perf_counter()
        result = run_fast(mission, 0, "fast", [])
        total = time.perf_counter() - t0
    finally:
        for cls, name, fn in originals:
            setattr(cls, name, fn)
    ticks = round(result.sim_time_s / mission.flight_software.gnc_period_s)
    out = {k: 1e3 * v / ticks for k, v in spent.items()}
    # the rest: the run's set-up (world and truth ephemeris for its epoch, flight software), truth
    # recording every tick, and judging at the end, spread over the ticks
    out["setup_recording_judging_ms"] = 1e3 * total / ticks - sum(out.values())
    out["total_ms_per_tick"] = 1e3 * total / ticks
    out["ticks"] = ticks
    out["sim_s_per_wall_s"] = result.sim_time_s / total
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=4, help="runs per measurement (default 4)")
    ap.add_argument("--duration", type=float, default=None, help="shorten runs (default: the mission's 600 s)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="LocalCluster sizes (default 1 2)")
    ap.add_argument("--no-dask", action="store_true")
    args = ap.parse_args(argv)

    rows = [_measure("local pool, 2 workers", args.runs, args.duration, workers=2)]
    if not args.no_dask:
        from distributed import Client, LocalCluster
        for n in args.workers:
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                    Client(cluster) as client:
                rows.append(_measure(f"Dask LocalCluster, {n} worker(s)", args.runs, args.duration, scheduler=client))
    breakdown = _tick_breakdown(min(args.duration or 120.0, 120.0))

    print(f"\nregression campaign, fast mode, {args.runs} runs per row, "
          f"{args.duration or 'full'} s per run, {os.cpu_count()} cores (load avg {os.getloadavg()[0]:.1f})")
    print(f"{'backend':32s} {'runs':>4s} {'wall s':>8s} {'runs/min':>9s} {'sim-s/wall-s':>13s} "
          f"{'median run s':>13s} {'per run x':>10s}")
    for r in rows:
        print(f"{r['backend']:32s} {r['runs']:4d} {r['wall_s']:8.1f} {r['runs_per_min']:9.2f} "
              f"{r['sim_s_per_wall_s']:13.1f} {r['median_run_wall_s']:13.1f} {r['median_run_sim_s_per_wall_s']:10.1f}")
    print(f"goal: >= {GOAL_SIM_S_PER_WALL_S:.0f} sim-s/wall-s in total")
    print("\none run in-process, per GNC tick [ms]:")
    for k, v in breakdown.items():
        if k not in ("ticks", "sim_s_per_wall_s"):
            print(f"  {k:30s} {v:8.3f}")
    print(f"  ({breakdown['ticks']} ticks, {breakdown['sim_s_per_wall_s']:.1f} sim-s/wall-s in this process)")

    result = {"bench": "campaign", "campaign": str(CAMPAIGN.relative_to(ROOT)), "runs_per_row": args.runs,
              "duration_s": args.duration, "cores": os.cpu_count(), "load_avg_1min": os.getloadavg()[0],
              "python": platform.python_version(), "rows": rows, "tick_breakdown_ms": breakdown,
              "goal_sim_s_per_wall_s": GOAL_SIM_S_PER_WALL_S,
              "best_sim_s_per_wall_s": max(r["sim_s_per_wall_s"] for r in rows)}
    dest = ROOT / "bench" / "results" / "campaign.json"
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nwrote {dest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
