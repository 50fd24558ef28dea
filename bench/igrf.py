"""What the Earth's field model costs the truth: config/missions/leo-day.yaml (every environment torque, a residual
dipole, a magnetometer and three rods) with ``spacecraft.disturbance.magnetic_field`` the centred dipole (its
default), IGRF-14 to degree 6 and to degree 13.

    .venv/bin/python bench/igrf.py [--span 600] [--repeats 5]      # pin it: taskset -c 1 ...

Per model: the world stepped by GNC periods (0.1 s) with the wheels commanding zero, the median over the
repeats of the wall time per dynamics step (RK4 at the mission's 100 Hz: four field evaluations a step), and
the magnetometer's field per call (`MagneticNodes.field_B_T`, once per GNC tick). Writes
bench/results/igrf.json.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from _results import write_result  # bench/_results.py: this script's folder is on sys.path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the fsw package before bench/fsw.py
MODELS = {"dipole": None, "igrf degree 6": {"model": "igrf", "degree": 6}, "igrf degree 13": {"model": "igrf"}}


def _mission(field: dict | None):
    import yaml
    from hil_sim.mission.model import load_mission

    path = ROOT / "config" / "missions" / "leo-day.yaml"
    data = yaml.safe_load(path.read_text())
    if field is not None:
        data["spacecraft"]["disturbance"]["magnetic_field"] = field
    return load_mission(path, text=yaml.safe_dump(data, sort_keys=False))


def main() -> None:
    from comms.bus import Icd
    from hil_sim.devices.magnetic import MagneticNodes
    from hil_sim.mission.model import magnetic_device_params, world_params
    from hil_sim.world.world import World

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--span", type=float, default=600.0, help="simulated seconds per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    missions = {name: _mission(field) for name, field in MODELS.items()}
    worlds = {name: World(world_params(m), seed=1) for name, m in missions.items()}
    zero = np.zeros(len(missions["dipole"].spacecraft.wheels))
    for world in worlds.values():
        world.step(1.0, zero)  # the kernels load (or compile) outside the timing
    times: dict[str, list[float]] = {name: [] for name in worlds}
    for _ in range(args.repeats):  # the models interleaved: the machine's load falls on each alike
        for name, world in worlds.items():
            t0 = time.perf_counter()
            for _ in range(int(round(args.span / 0.1))):
                world.step(0.1, zero)
            times[name].append(time.perf_counter() - t0)
    steps = args.span * missions["dipole"].simulation.dynamics_rate_hz
    rows = {}
    for name, world in worlds.items():
        nodes = MagneticNodes(Icd(), magnetic_device_params(missions[name]))
        nodes.field_B_T(world)
        t0 = time.perf_counter()
        for _ in range(20_000):
            nodes.field_B_T(world)
        rows[name] = {"us_per_dynamics_step": 1e6 * statistics.median(times[name]) / steps,
                      "magnetometer_field_us_per_call": 1e6 * (time.perf_counter() - t0) / 20_000}
    base = rows["dipole"]["us_per_dynamics_step"]
    print(f"{'field model':<16}{'us / dynamics step':>20}{'over the dipole':>18}{'CPU s / simulated day':>24}"
          f"{'magnetometer us / call':>24}")
    for name, row in rows.items():
        extra = row["us_per_dynamics_step"] - base
        row["extra_cpu_s_per_simulated_day"] = extra * 1e-6 * 86_400 * steps / args.span
        print(f"{name:<16}{row['us_per_dynamics_step']:>20.2f}{extra:>+18.2f}"
              f"{row['extra_cpu_s_per_simulated_day']:>+24.1f}{row['magnetometer_field_us_per_call']:>24.2f}")
    dest = write_result(ROOT / "bench" / "results" / "igrf.json",
                        {"mission": "config/missions/leo-day.yaml", "span_s": args.span, "repeats": args.repeats,
                         "rows": rows})
    print(f"wrote {dest}")


if __name__ == "__main__":
    main()
