"""Magnetic momentum management on a 550 km Sun-synchronous orbit: the wheels' stored momentum with and without
the flight software's unloading (fsw.momentum), every environment torque on.

    .venv/bin/python bench/momentum.py [--duration 10800] [--gain 0.01] [--max-dipole 15]

The spacecraft and orbit are bench/vs_basilisk.py's ``environment`` row (demo-pointing's telescope and its
slews, gravity gradient, SRP and drag on eight facets, a residual dipole of [0.5, -0.3, 0.8] A m^2), with a
magnetometer and three body-axis rods fitted. Two fast-mode runs (hil_sim.campaign.fast.run_fast, seed 1),
identical but for ``flight_software.momentum_management.enabled``; per run: the peak and final |h_w| (the
wheels' spin momentum in body axes, from the truth's wheel speeds), the final |h_excess| (h_w less the bias,
here zero), the keep-out margins of the run's judge. Writes bench/results/momentum.json.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from _results import write_result  # bench/_results.py: this script's folder is on sys.path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the fsw package before bench/fsw.py


SLEWS_END_S = 600.0  # demo-pointing's second slew (at 300 s) has settled by then


def momentum_mission(duration_s: float, managed: bool, gain_1_s: float = 0.01, max_dipole_Am2: float = 15.0,
                     wheel_speeds_rad_s: list[float] | None = None):
    """The environment row's mission with a magnetometer and rods; the flight software unloads when ``managed``;
    ``wheel_speeds_rad_s``: the wheels' speeds at the start in place of demo-pointing's (none stored)."""
    import yaml
    from gnc.ephemeris import EARTH_RADIUS_KM
    from hil_sim.mission.model import load_mission
    from vs_basilisk import ENV_ALTITUDE_KM, ENV_DISTURBANCE, ENV_FACETS, ENV_INCLINATION_DEG, MISSION

    data = yaml.safe_load(MISSION.read_text())
    data["orbit"] = {"semi_major_axis_km": EARTH_RADIUS_KM + ENV_ALTITUDE_KM, "inclination_deg": ENV_INCLINATION_DEG,
                     "raan_deg": 40.0}
    del data["flight_software"]["orbit"]  # taken from the truth orbit, as the environment row does
    data["spacecraft"]["facets"] = ENV_FACETS
    data["spacecraft"]["disturbance"].update(ENV_DISTURBANCE)
    if wheel_speeds_rad_s is not None:
        data["initial_state"]["wheel_speeds_rad_s"] = list(wheel_speeds_rad_s)
    data["spacecraft"]["magnetometer"] = {"noise_std_T": 5e-8}
    data["spacecraft"]["magnetorquers"] = {"max_dipole_Am2": [max_dipole_Am2] * 3}
    # the rods' axes and limits and the magnetometer's mounting: the flight software's knowledge is the truth's
    data["flight_software"]["momentum_management"] = {"enabled": managed, "gain_1_s": gain_1_s}
    return load_mission(MISSION, text=yaml.safe_dump(data)).model_copy(update={"duration_s": duration_s})


def fly(mission, seed: int = 1) -> dict:
    """One fast-mode run: its judge's metrics and the wheels' momentum [N m s] from the truth's wheel speeds."""
    from hil_sim.campaign import fast

    kept: dict = {}
    judge = fast.judge

    def keeping(m, truth, *args):  # the truth's wheel speeds, which the run's result does not carry
        kept["t_s"], kept["speed"] = truth["t_s"].copy(), truth["wheel_speed_rad_s"].copy()
        return judge(m, truth, *args)

    fast.judge = keeping
    try:
        result = fast.run_fast(mission, seed)
    finally:
        fast.judge = judge
    wheels = mission.spacecraft.wheels
    G = np.array([w.axis_B for w in wheels]).T
    Js = np.array([w.spin_inertia_kgm2 for w in wheels])
    h = np.linalg.norm((G @ (Js[:, None] * kept["speed"].T)).T, axis=1)
    margins = {k: v for k, v in result.metrics.items() if k.startswith("margin_") or k == "min_margin_deg"}
    return {"sim_time_s": result.sim_time_s, "t_s": kept["t_s"], "h_Nms": h, "margins_deg": margins,
            "unexpected_fdir_events": result.metrics.get("unexpected_fdir_events")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10800.0, help="simulated seconds per run")
    ap.add_argument("--gain", type=float, default=0.01, help="momentum_management.gain_1_s [1/s]")
    ap.add_argument("--max-dipole", type=float, default=15.0, help="each rod's saturation [A m^2]")
    args = ap.parse_args()
    out = {"duration_s": args.duration, "gain_1_s": args.gain, "max_dipole_Am2": args.max_dipole, "runs": {}}
    print(f"{'run':>10} {'peak |h_w|':>12} {'after slews':>13} {'final |h_excess|':>17} {'min margin':>11} "
          f"{'wall':>7}")
    for managed in (False, True):
        t0 = time.perf_counter()
        run = fly(momentum_mission(args.duration, managed, args.gain, args.max_dipole))
        wall = time.perf_counter() - t0
        tick = float(run["t_s"][1] - run["t_s"][0])
        name = "managed" if managed else "unmanaged"
        after = run["t_s"] >= SLEWS_END_S
        row = {"peak_h_Nms": float(run["h_Nms"].max()), "final_h_excess_Nms": float(run["h_Nms"][-1]),
               "peak_h_after_slews_Nms": float(run["h_Nms"][after].max()) if after.any() else None,
               "h_every_1000_s_Nms": [round(float(x), 4) for x in run["h_Nms"][::int(round(1000.0 / tick))]],
               "margins_deg": run["margins_deg"], "sim_time_s": run["sim_time_s"], "wall_s": wall,
               "unexpected_fdir_events": run["unexpected_fdir_events"]}
        out["runs"][name] = row
        print(f"{name:>10} {row['peak_h_Nms']:>8.4f} Nms {row['peak_h_after_slews_Nms']:>9.4f} Nms "
              f"{row['final_h_excess_Nms']:>13.4f} Nms "
              f"{run['margins_deg']['min_margin_deg']:>7.2f} deg {wall:>5.0f} s")
    print("wrote", write_result(ROOT / "bench" / "results" / "momentum.json", out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
