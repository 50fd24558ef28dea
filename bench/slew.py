"""Large constrained slews: settling time against an unconstrained eigen-axis slew, and keep-out margins.

For each slew of the demo telescope (config/missions/demo-pointing.yaml: star-shaped Sun zone and Moon
cone, both enforced at once) the boresight starts on one sky target and is commanded to another whose
great circle crosses a zone. The closed loop runs in the campaign's fast mode (the real flight
software and truth models in one process over a virtual CAN bus, judged on truth).

  ratio = settling time / T_eigen,   T_eigen = theta / w_max + w_max / a_max   (theta >= w_max^2 / a_max)

The table also gives the boresight's path length from the command to settling ("path", deg) and its
ratio to the great-circle angle: the part of the time ratio that is the detour around a zone (geometry)
rather than speed. T_eigen is the time of an unconstrained eigen-axis slew through the same angle theta with the same rate
limit w_max (spacecraft.max_rate_deg_s) and command acceleration limit a_max
(control.max_command_accel_deg_s2): a trapezoidal rate profile. Goal: ratio <= 1.3 and the minimum
signed margin to every physical zone > 0.

    .venv/bin/python bench/slew.py [--quick]

Prints a table and writes bench/results/slew.json.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# (label, start [RA, Dec] deg, end [RA, Dec] deg): the geodesic start -> end crosses a zone
SLEWS = [
    ("A->B across the Sun", (330.0, -10.0), (95.0, 30.0)),
    ("B->C across the Moon", (95.0, 30.0), (200.0, 0.0)),
    ("C->A clear great circle (zones active)", (200.0, 0.0), (330.0, -10.0)),
    ("S1->S2 across the Sun (south)", (350.0, 40.0), (70.0, -25.0)),
    ("M1->M2 across the Moon (north-south)", (150.0, 60.0), (140.0, -30.0)),
]


def unit(ra_deg: float, dec_deg: float) -> np.ndarray:
    ra, dec = math.radians(ra_deg), math.radians(dec_deg)
    return np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])


def attitude_looking_at(direction_N: np.ndarray) -> list[float]:
    """q_NB with body +z on the direction and body x towards celestial north (scalar first)."""
    from scipy.spatial.transform import Rotation

    z = direction_N / np.linalg.norm(direction_N)
    north = np.array([0.0, 0.0, 1.0]) - z[2] * z
    x = north / np.linalg.norm(north)
    q = Rotation.from_matrix(np.column_stack([x, np.cross(z, x), z])).as_quat()
    return [float(q[3]), float(q[0]), float(q[1]), float(q[2])]


def eigen_axis_time_s(theta_deg: float, rate_deg_s: float, accel_deg_s2: float) -> float:
    if theta_deg >= rate_deg_s ** 2 / accel_deg_s2:
        return theta_deg / rate_deg_s + rate_deg_s / accel_deg_s2
    return 2.0 * math.sqrt(theta_deg / accel_deg_s2)


def slew_mission(base: dict, start, end) -> dict:
    data = json.loads(json.dumps(base, default=str))
    a, b = unit(*start), unit(*end)
    theta = math.degrees(math.acos(float(np.clip(a @ b, -1, 1))))
    fsw = data["flight_software"]
    t_eig = eigen_axis_time_s(theta, fsw["spacecraft"]["max_rate_deg_s"], fsw["control"]["max_command_accel_deg_s2"])
    data["initial_state"]["q_NB"] = attitude_looking_at(a)
    data["initial_state"]["omega_BN_B_rad_s"] = [0.0, 0.0, 0.0]
    fsw["pointing"]["target_N"] = a.tolist()
    data["timeline"] = [{"t_s": 5.0, "command": "SET_TARGET", "target_N": b.tolist()}]
    data["duration_s"] = 5.0 + 2.2 * t_eig + 60.0
    data["faults"] = []
    return data, theta, t_eig


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="only the first two slews")
    args = parser.parse_args(argv)
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission import Mission

    base = yaml.safe_load((ROOT / "config" / "missions" / "demo-pointing.yaml").read_text())
    slews = SLEWS[:2] if args.quick else SLEWS
    rows = []
    for label, start, end in slews:
        data, theta, t_eig = slew_mission(base, start, end)
        mission = Mission.model_validate(data)
        wall = time.perf_counter()
        result = run_fast(mission, seed=mission.seed)
        wall = time.perf_counter() - wall
        m = result.metrics
        settle = m["settling_time_s"]
        margins = {k[len("margin_"):-len("_deg")]: v for k, v in m.items() if k.startswith("margin_")}
        # how much of the ratio is the detour (geometry) and how much is speed: boresight path length
        # from the command to settling, against the great-circle angle
        tr = result.trajectory
        sel = (tr["t_s"] >= 5.0) & (tr["t_s"] <= 5.0 + settle) if math.isfinite(settle) else tr["t_s"] >= 5.0
        y = tr["boresight_N"][sel]
        path_deg = float(np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", y[:-1], y[1:]), -1, 1))).sum())
        rows.append({"slew": label, "angle_deg": theta, "eigen_axis_s": t_eig, "settling_s": settle,
                     "path_deg": path_deg, "path_ratio": path_deg / theta,
                     "ratio": settle / t_eig if math.isfinite(settle) else math.inf,
                     "margins_deg": margins, "final_error_deg": m["final_error_deg"], "wall_s": wall,
                     "sim_s": result.sim_time_s})
    print(f"{'slew':38s} {'angle':>6s} {'path':>6s} {'path/':>6s} {'T_eig':>6s} {'settle':>6s} {'ratio':>6s}"
          f"  margins [deg]")
    for r in rows:
        margins = " ".join(f"{k}={v:.2f}" for k, v in r["margins_deg"].items())
        print(f"{r['slew']:38s} {r['angle_deg']:6.1f} {r['path_deg']:6.1f} {r['path_ratio']:6.3f} "
              f"{r['eigen_axis_s']:6.1f} {r['settling_s']:6.1f} {r['ratio']:6.3f}  {margins}")
    ratios = [r["ratio"] for r in rows]
    min_margin = min(min(r["margins_deg"].values()) for r in rows)
    summary = {"median_ratio": statistics.median(ratios), "max_ratio": max(ratios), "min_margin_deg": min_margin,
               "goal_ratio_le": 1.3, "goal_margin_gt": 0.0,
               "ratio_goal_met": max(ratios) <= 1.3, "margin_goal_met": min_margin > 0.0}
    print(f"median ratio {summary['median_ratio']:.3f}, max {summary['max_ratio']:.3f} (goal <= 1.3); "
          f"smallest margin {min_margin:.2f} deg (goal > 0)")
    out = ROOT / "bench" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "slew.json").write_text(json.dumps({"rows": rows, "summary": summary}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
