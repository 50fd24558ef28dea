"""Campaign throughput: the regression campaign in fast mode, local pool and Dask LocalCluster scaling.

    .venv/bin/python bench/campaign.py [--runs 4] [--duration 600] [--workers 1 2]

Reports, for the regression campaign (config/campaigns/regression.yaml) in ``fast`` mode:
  * local process pool with 2 workers: runs per minute and total simulated seconds per wall second;
  * a Dask ``distributed.LocalCluster`` with 1 and 2 worker processes (same code path): the scaling;
  * where one run's time goes per GNC tick (simulator frames out, flight software cycle, world step),
    from one in-process run with timers around the phases.
Goal: >= 3,000 simulated seconds per wall second in total. Prints a table and writes
bench/results/campaign.json. Wall times include process start-up and each run's set-up.

What a fast-mode tick costs, and why (see docs/campaign/README.md, "Speed of fast mode"): every GNC tick
still moves ~22 ICD frames (SYNC, 10 IMU, 2 star-tracker, 4 wheel statuses, 4 wheel commands,
CYCLE_DONE) through the E2E-protected codec and a python-can bus, and runs the flight software's own
Python cycle; the world (RK4 at 100 Hz) and the sensors take one compiled call per tick.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

from _results import write_result  # bench/_results.py: this script's folder is on sys.path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hil_sim.campaign.runner import build_plan, prepare_out_dir, run_campaign  # noqa: E402
from hil_sim.campaign.spec import load_campaign  # noqa: E402

CAMPAIGN = ROOT / "config" / "campaigns" / "regression.yaml"
GOAL_SIM_S_PER_WALL_S = 3000.0


def _base_mission():
    from hil_sim.mission.model import load_mission
    return load_mission(_plan(1, None)[1])


def _budget_ms_per_tick(mission) -> float:
    """The goal's time per GNC tick on each core: every core stepping ticks of the mission's period."""
    return 1e3 * mission.flight_software.gnc_period_s * os.cpu_count() / GOAL_SIM_S_PER_WALL_S


def _tick_frames(mission) -> list[str]:
    """The ICD messages one GNC tick of ``mission`` carries in lockstep, in their order: SYNC, the IMU and
    whole star-tracker samples of the period, a status per wheel; back, a command per wheel and CYCLE_DONE."""
    period, sc = mission.flight_software.gnc_period_s, mission.spacecraft
    wheels = range(1, len(sc.wheels) + 1)
    return (["SYNC"] + ["IMU_RATE"] * round(sc.imu.rate_hz * period)
            + ["ST_QUAT_A", "ST_QUAT_B"] * int(sc.star_tracker.rate_hz * period + 1e-9)
            + [f"RW{i}_STATUS" for i in wheels] + [f"RW{i}_CMD" for i in wheels] + ["CYCLE_DONE"])


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


def _dask_efficiency(rows: list[dict]) -> float | None:
    """Parallel efficiency of the Dask LocalCluster from 1 to 2 workers: S2 / (2 S1), S in sim-s per wall-s."""
    by_n = {r["backend"]: r["sim_s_per_wall_s"] for r in rows}
    one, two = by_n.get("Dask LocalCluster, 1 worker(s)"), by_n.get("Dask LocalCluster, 2 worker(s)")
    return two / (2.0 * one) if one and two else None


def _tick_breakdown(duration: float) -> dict:
    """One in-process run with timers around the tick phases (monkeypatched here, bench only).

    Wall-clock times per tick (what a run costs on this host now) and the thread's CPU time (less
    sensitive to the other processes on a shared host); the timers' own cost (~1 us per timed call)
    is included in the phases."""
    import hil_sim.devices.nodes as devices
    import hil_sim.sil.lockstep as lockstep
    from fsw import control, estimation, fdir, guidance
    from fsw.app import FlightSoftware
    from fsw.bus.driver import FswBusDriver
    from hil_sim.campaign.fast import run_fast

    spent: dict[str, list[float]] = {}
    originals = []

    def timed(cls, name, key):
        fn = getattr(cls, name)
        originals.append((cls, name, fn))
        spent[key] = [0.0, 0.0]

        def wrapper(*a, **k):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                acc = spent[key]
                acc[0] += time.perf_counter() - t0
                acc[1] += time.thread_time() - c0
        setattr(cls, name, wrapper)

    timed(lockstep.Simulator, "begin_tick", "simulator_frames_out")
    timed(FswBusDriver, "collect_tick", "fsw_collect_inputs")
    timed(FlightSoftware, "run_cycle", "fsw_cycle")
    timed(lockstep.Simulator, "end_tick", "world_step_and_commands_in")
    # parts of the phases above
    timed(estimation.AttitudeEstimator, "_tick", "fsw_cycle.estimation")  # what the GNC cycle calls
    timed(guidance.Guidance, "step", "fsw_cycle.guidance")
    timed(control.RateController, "step", "fsw_cycle.control")
    timed(fdir.Fdir, "evaluate_cycle", "fsw_cycle.fdir")  # residual, wheel values and every monitor
    timed(FswBusDriver, "send_wheel_torques", "fsw_cycle.wheel_commands_out")
    timed(FlightSoftware, "_send_gnc_tm", "fsw_cycle.telemetry")
    timed(devices.Devices, "step_period", "world_step_and_commands_in.world_and_sensors")  # what end_tick calls
    try:
        plan, _ = _plan(2, duration)
        # a first run loads the worker's caches (numba, ICD, ephemeris), as a campaign worker's first run does
        for i in range(2):
            for acc in spent.values():
                acc[0] = acc[1] = 0.0
            _, mission = plan.mission(plan.draw(i), i)
            t0, c0 = time.perf_counter(), time.thread_time()
            result = run_fast(mission, i, "fast", [])
            total, total_cpu = time.perf_counter() - t0, time.thread_time() - c0
    finally:
        for cls, name, fn in originals:
            setattr(cls, name, fn)
    ticks = round(result.sim_time_s / mission.flight_software.gnc_period_s)
    phases = [k for k in spent if "." not in k]
    out = {k: 1e3 * spent[k][0] / ticks for k in phases}
    # the rest: the run's set-up (world, flight software), truth recording every tick, and judging at
    # the end, spread over the ticks
    out["setup_recording_judging_ms"] = 1e3 * total / ticks - sum(out.values())
    out["total_ms_per_tick"] = 1e3 * total / ticks
    out["ticks"] = ticks
    out["sim_s_per_wall_s"] = result.sim_time_s / total
    cpu = {k: 1e3 * v[1] / ticks for k, v in spent.items()}
    cpu["setup_recording_judging_ms"] = 1e3 * total_cpu / ticks - sum(cpu[k] for k in phases)
    cpu["total_ms_per_tick"] = 1e3 * total_cpu / ticks
    cpu["sim_s_per_cpu_s"] = result.sim_time_s / total_cpu
    out["cpu_ms_per_tick"] = cpu
    return out


def _frame_path_floor(names: list[str], repeats: int = 7, ticks: int = 2000) -> dict:
    """The least a fast-mode tick can cost with the frames on a python-can bus, whatever the flight
    software and the world cost: one tick's frames ``names`` (``_tick_frames``), with constant signals,
    through the steps every frame takes:

    * ``message_objects``: only a ``can.Message`` built per frame and passed through a deque;
    * ``virtual_bus``: the same messages sent and received on the ``LightVirtualBus`` of fast mode;
    * ``icd_e2e_bus``: the generated ICD codec (encode with range checks and CRC) on the sending side and
      the E2E receiver (CRC, decode, range and counter checks) on the receiving side, over that bus,
      frame by frame;
    * ``icd_e2e_burst``: the same work as fast mode does it: the tick's frames encoded in one compiled
      call, carried as one burst, classified in one compiled call (comms/bus/kernels.py).

    Medians of ``repeats`` runs of ``ticks`` ticks, in microseconds per tick."""
    import collections

    import numpy as np

    from comms.bus import E2EReceiver, E2ESender, Icd, open_bus
    from comms.bus.icd import _data_frame
    from comms.bus.transport import recv_burst, send_burst

    icd = Icd()
    # mid-range values: every frame passes the codec's and the receiver's range checks
    signals = {n: {s: (0.0 if lo <= 0.0 <= hi else lo) for s, (lo, hi) in icd.spec(n).ranges.items()
                   if not s.startswith("E2E_")} for n in set(names)}
    ids = [icd.spec(n).frame_id for n in names]
    payload = bytearray(8)
    channel = f"virtual:floor{os.getpid()}"
    tx, rx = open_bus(channel, light=True), open_bus(channel, light=True)
    sender, receiver = E2ESender(icd), E2EReceiver(icd)
    burst_sender, burst_receiver = E2ESender(icd), E2EReceiver(icd)
    idx = np.array([icd.message_index[n] for n in names], dtype=np.int64)
    rows = np.zeros((len(names), icd.table.start.shape[1]))
    for i, n in enumerate(names):
        for s, v in signals[n].items():
            rows[i, icd.column(n, s)] = v
    queue: collections.deque = collections.deque()

    def message_objects() -> None:
        for frame_id in ids:
            queue.append(_data_frame(frame_id, payload))
        while queue:
            queue.popleft()

    def virtual_bus() -> None:
        for frame_id in ids:
            tx.send(_data_frame(frame_id, payload))
        while rx.recv(0.0) is not None:
            pass

    def icd_e2e_bus() -> None:
        for name in names:
            tx.send(sender.frame(name, signals[name]))
        while True:
            msg = rx.recv(0.0)
            if msg is None:
                break
            frame = receiver.classify(msg, 0.0)
            if not frame.delivered:
                raise RuntimeError(f"floor: frame {frame.name} classified {frame.status}")

    def icd_e2e_burst() -> None:
        send_burst(tx, burst_sender.burst(idx, rows))
        while (burst := recv_burst(rx, 0.0)) is not None:
            checked = burst_receiver.check(burst)
            burst_receiver.classify_until(checked, 0.0)
            if any(code > 1 for code in checked.codes):
                raise RuntimeError("floor: a frame of the burst was not delivered")

    out = {}
    try:
        for step in (message_objects, virtual_bus, icd_e2e_bus, icd_e2e_burst):
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                for _ in range(ticks):
                    step()
                times.append(1e6 * (time.perf_counter() - t0) / ticks)
            out[step.__name__] = statistics.median(times)
    finally:
        tx.shutdown()
        rx.shutdown()
    out["frames_per_tick"] = len(names)
    return out


def _print_floor(floor: dict, budget_ms: float) -> None:
    budget_us = 1e3 * budget_ms
    print(f"\nthe frame path's floor, {floor['frames_per_tick']} frames per tick, no flight software, no world "
          f"[us per tick; the goal's whole budget is {budget_us:.0f} us]:")
    for k in ("message_objects", "virtual_bus", "icd_e2e_bus", "icd_e2e_burst"):
        print(f"  {k:44s} {floor[k]:8.1f}  ({100.0 * floor[k] / budget_us:5.1f} % of the budget)")


def _print_breakdown(breakdown: dict, budget_ms: float) -> None:
    cpu = breakdown["cpu_ms_per_tick"]
    print("\none run in-process (the second, caches warm), per GNC tick [ms]:")
    print(f"  {'phase':44s} {'wall':>8s} {'cpu':>8s}")
    for k, v in cpu.items():
        if k in ("sim_s_per_cpu_s",):
            continue
        wall = breakdown.get(k)
        name = ("    " + k.split(".", 1)[1]) if "." in k else k
        print(f"  {name:44s} {'' if wall is None else f'{wall:8.3f}':>8s} {v:8.3f}")
    print(f"  ({breakdown['ticks']} ticks, {breakdown['sim_s_per_wall_s']:.1f} sim-s/wall-s, "
          f"{cpu['sim_s_per_cpu_s']:.1f} sim-s per CPU-s in this process; the goal needs <= {budget_ms:.3f} ms "
          f"per GNC tick on each of {os.cpu_count()} cores)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=4, help="runs per measurement (default 4; keep it even, so 2 "
                    "workers share the runs evenly and the efficiency measures the backend, not the split)")
    ap.add_argument("--duration", type=float, default=None, help="shorten runs (default: the mission's 600 s)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="LocalCluster sizes (default 1 2)")
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--breakdown-only", action="store_true",
                    help="only the per-tick breakdown of one in-process run (prints, writes no JSON)")
    ap.add_argument("--floor-only", action="store_true",
                    help="only the frame path's floor per tick (prints, writes no JSON)")
    args = ap.parse_args(argv)
    mission = _base_mission()
    budget_ms = _budget_ms_per_tick(mission)
    if args.floor_only:
        _print_floor(_frame_path_floor(_tick_frames(mission)), budget_ms)
        return 0
    if args.breakdown_only:
        _print_breakdown(_tick_breakdown(min(args.duration or 120.0, 120.0)), budget_ms)
        return 0

    rows = [_measure("local pool, 2 workers", args.runs, args.duration, workers=2)]
    if not args.no_dask:
        from distributed import Client, LocalCluster
        for n in args.workers:
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                    Client(cluster) as client:
                rows.append(_measure(f"Dask LocalCluster, {n} worker(s)", args.runs, args.duration, scheduler=client))
    breakdown = _tick_breakdown(min(args.duration or 120.0, 120.0))
    floor = _frame_path_floor(_tick_frames(mission))

    print(f"\nregression campaign, fast mode, {args.runs} runs per row, "
          f"{args.duration or 'full'} s per run, {os.cpu_count()} cores (load avg {os.getloadavg()[0]:.1f})")
    print(f"{'backend':32s} {'runs':>4s} {'wall s':>8s} {'runs/min':>9s} {'sim-s/wall-s':>13s} "
          f"{'median run s':>13s} {'per run x':>10s}")
    for r in rows:
        print(f"{r['backend']:32s} {r['runs']:4d} {r['wall_s']:8.1f} {r['runs_per_min']:9.2f} "
              f"{r['sim_s_per_wall_s']:13.1f} {r['median_run_wall_s']:13.1f} {r['median_run_sim_s_per_wall_s']:10.1f}")
    print(f"goal: >= {GOAL_SIM_S_PER_WALL_S:.0f} sim-s/wall-s in total")
    efficiency = _dask_efficiency(rows)
    if efficiency is not None:
        print(f"Dask LocalCluster efficiency from 1 to 2 workers: {100 * efficiency:.1f} % "
              f"(throughput with 2 / (2 x throughput with 1); goal >= 90 %)")
    _print_breakdown(breakdown, budget_ms)
    _print_floor(floor, budget_ms)

    result = {"bench": "campaign", "campaign": str(CAMPAIGN.relative_to(ROOT)), "runs_per_row": args.runs,
              "duration_s": args.duration, "cores": os.cpu_count(), "load_avg_1min": os.getloadavg()[0],
              "python": platform.python_version(), "rows": rows, "tick_breakdown_ms": breakdown,
              "frame_path_floor_us_per_tick": floor,
              "goal_sim_s_per_wall_s": GOAL_SIM_S_PER_WALL_S,
              "goal_ms_per_tick_per_core": budget_ms,
              "best_sim_s_per_wall_s": max(r["sim_s_per_wall_s"] for r in rows),
              "dask_efficiency_1_to_2_workers": efficiency, "goal_dask_efficiency": 0.9}
    dest = ROOT / "bench" / "results" / "campaign.json"
    print(f"\nwrote {write_result(dest, result)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
