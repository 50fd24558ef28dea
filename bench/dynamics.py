"""Truth-model speed: simulated seconds per wall-clock second.

Model: hub + 4 pyramid reaction wheels (RK4 at 100 Hz, command held), IMU, star tracker, Sun/Moon truth
(spline of astropy, evaluated at every dynamics step) and Kepler orbit - the default ``WorldParams``.

Cases
- ``single 100Hz``: one World; every 10 ms step(0.01) + IMU sample, star tracker every 100 ms (lockstep SIL).
- ``single 10Hz-GNC``: one World; step(0.1) = 10 RK4 sub-steps at 100 Hz, IMU + star tracker every 100 ms.
- ``batch 100Hz`` / ``batch 10Hz-GNC``: WorldBatch of --runs runs (dispersed inertia, wheel speeds, rates),
  same patterns; the figure is the total over all runs.
Goals: single >= 1,000 sim-s/s, batch of 1,000 >= 50,000 sim-s/s in total.

Each case is repeated; the table quotes the median of the wall-clock rate and, because the machine is shared,
also the rate per CPU-second of this process (what one idle core would give) and the load average. Everything
runs on one core (numba threads lose on a loaded 2-core machine).

Run: ``.venv/bin/python bench/dynamics.py`` (``--quick`` for a short run). Writes bench/results/dynamics.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hil_sim.world.params import SpacecraftParams, WorldParams
from hil_sim.world.world import World, WorldBatch

RESULTS = Path(__file__).resolve().parent / "results" / "dynamics.json"
GOALS = {"single": 1_000.0, "batch": 50_000.0}


def _dispersed_params(count: int, rng: np.random.Generator) -> list[WorldParams]:
    base = WorldParams()
    out = []
    for _ in range(count):
        inertia = np.diag(rng.uniform([18, 22, 13], [22, 28, 17]))
        wheels = tuple(
            type(w)(**{**w.__dict__, "initial_speed_rad_s": float(rng.uniform(-200, 200))})
            for w in base.spacecraft.wheels)
        sc = SpacecraftParams(inertia_B_kgm2=tuple(map(tuple, inertia)), wheels=wheels,
                              omega_BN_B0_rad_s=tuple(rng.uniform(-0.01, 0.01, 3)))
        out.append(WorldParams(spacecraft=sc))
    return out


def _time_it(fn) -> tuple[float, float]:
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w0, time.process_time() - c0


def _timed_loop(step: Callable, imu_sample: Callable, star_tracker_sample: Callable, cmds: np.ndarray,
                dt: float, repeats: int) -> list[tuple[float, float]]:
    """(wall, CPU) seconds of ``repeats`` runs of the lockstep pattern: ``step(dt, cmds[k])`` and an IMU
    sample every step, a star-tracker sample every 100 ms. One untimed run first: compilation is cached,
    but the first call still loads it."""
    st_every = max(1, int(round(0.1 / dt)))

    def run() -> None:
        for k in range(len(cmds)):
            step(dt, cmds[k])
            imu_sample()
            if k % st_every == 0:
                star_tracker_sample()

    run()
    return [_time_it(run) for _ in range(repeats)]


def bench_single(sim_s: float, gnc_hz: float, repeats: int) -> dict:
    world = World(WorldParams(), seed=1)
    dt = 1.0 / gnc_hz
    cmds = np.random.default_rng(0).uniform(-0.02, 0.02, (int(round(sim_s / dt)), world.n_wheels))
    samples = _timed_loop(world.step, world.imu_sample, world.star_tracker_sample, cmds, dt, repeats)
    return _summary(samples, sim_s, runs=1)


def bench_batch(runs: int, sim_s: float, gnc_hz: float, repeats: int) -> dict:
    batch = WorldBatch(_dispersed_params(runs, np.random.default_rng(2)), seed=1)
    dt = 1.0 / gnc_hz
    cmds = np.random.default_rng(0).uniform(-0.02, 0.02, (int(round(sim_s / dt)), runs, batch.n_wheels))
    samples = _timed_loop(batch.step, batch.imu_sample_arrays, batch.star_tracker_sample_arrays, cmds, dt, repeats)
    return _summary(samples, sim_s, runs=runs)


def _summary(samples: list[tuple[float, float]], sim_s: float, runs: int) -> dict:
    wall = [runs * sim_s / w for w, _ in samples]
    cpu = [runs * sim_s / c for _, c in samples if c > 0]
    return {"runs": runs, "sim_s_per_repeat": sim_s, "repeats": len(samples),
            "sim_s_per_wall_s_median": statistics.median(wall), "sim_s_per_wall_s_all": wall,
            "sim_s_per_cpu_s_median": statistics.median(cpu) if cpu else None}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000, help="runs in the batch cases")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="shorter runs, 2 repeats (smoke check)")
    args = parser.parse_args(argv)
    repeats = 2 if args.quick else args.repeats
    load_before = os.getloadavg()
    cases = {
        "single 100Hz": ("single", lambda: bench_single(60.0 if args.quick else 300.0, 100.0, repeats)),
        "single 10Hz-GNC": ("single", lambda: bench_single(300.0 if args.quick else 1800.0, 10.0, repeats)),
        "batch 100Hz": ("batch", lambda: bench_batch(args.runs, 1.0 if args.quick else 5.0, 100.0, repeats)),
        "batch 10Hz-GNC": ("batch", lambda: bench_batch(args.runs, 2.0 if args.quick else 10.0, 10.0, repeats)),
    }
    results = {}
    for name, (kind, fn) in cases.items():
        res = fn()
        res["goal_sim_s_per_wall_s"] = GOALS[kind]
        res["meets_goal"] = res["sim_s_per_wall_s_median"] >= GOALS[kind]
        res["meets_goal_per_cpu_s"] = (res["sim_s_per_cpu_s_median"] or 0.0) >= GOALS[kind]
        results[name] = res

    header = (f"{'case':<18}{'runs':>6}{'sim-s/wall-s (median)':>24}{'sim-s/CPU-s':>14}{'goal':>10}"
              f"{'met (wall)':>12}{'met (CPU)':>11}")
    print(header)
    print("-" * len(header))
    for name, r in results.items():
        print(f"{name:<18}{r['runs']:>6}{r['sim_s_per_wall_s_median']:>24,.0f}"
              f"{(r['sim_s_per_cpu_s_median'] or 0):>14,.0f}{r['goal_sim_s_per_wall_s']:>10,.0f}"
              f"{'yes' if r['meets_goal'] else 'no':>12}{'yes' if r['meets_goal_per_cpu_s'] else 'no':>11}")
    load_after = os.getloadavg()
    print(f"load average before/after: {load_before[0]:.2f} / {load_after[0]:.2f} on {os.cpu_count()} CPUs")

    import numba

    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        "benchmark": "dynamics",
        "model": "hub + 4 pyramid wheels (RK4 100 Hz) + IMU + star tracker + Sun/Moon spline + Kepler orbit",
        "cases": results,
        "load_average_1min_before_after": [load_before[0], load_after[0]],
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "numba": numba.__version__,
        "numpy": np.__version__,
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }, indent=2))
    print(f"wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
