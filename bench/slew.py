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

What geometry allows: "short" is the shortest boresight path that keeps law.margin_deg from every zone
(the zones as the law sees them, onboard ephemeris at the command time; a visibility graph on the
sphere), "short/" its ratio to the great circle, and "lb" = eigen-axis time over that path / T_eigen, the
best ratio any law could reach at these limits. ratio - lb is what the law and the loop cost.
The paper's assumptions are checked at each slew's target with the eps the configuration gives
(gnc.checks, as `keepout config check` does for a mission's own targets): "ok", eps and kappa_bar.

    .venv/bin/python bench/slew.py [--quick] [--law-only] [--jerk-off]

"TV" is the total variation of the wheel torque commands over the slew (sum over cycles and wheels of
|tau_k - tau_(k-1)|, N m): a smooth slew is a few times the torque limits, a chattering one many times
that (--jerk-off flies every slew again without the rate command's jerk limit, for comparison).

The flight software plans slews round the zones (pointing.path, fsw.guidance.path_planning). --law-only also runs
every slew with path planning off, side by side: the paper's law heading straight for the target.

QUATERNION mode: demo-quaternion's two reorientations, each past a forbidden-attitude zone on S^3, with
slew planning on S^3 (quaternion.path, fsw.guidance.attitude_planning) and with the law alone: ratio to
the eigen-axis slew of the same rotation angle, and the margins to the physical S^3 zones.

Prints a table and writes bench/results/slew.json.
"""
from __future__ import annotations

import argparse
import json
import math
import os
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


def _polygon(zone, margin_deg: float, vertices: int = 240) -> tuple[np.ndarray, np.ndarray]:
    """Vertices at signed margin margin_deg on rays from the kernel, and inward edge normals.

    The zones here are convex (a cone, a superellipse with exponent >= 1) and so is their margin_deg
    neighbourhood; the vertices lie on its boundary, so the polygon is inscribed in it and a path around
    the polygon is never longer than one around the zone: the length below is a lower bound.
    """
    g = np.asarray(zone.kernel, dtype=float)
    e1 = np.cross(g, [0.0, 0.0, 1.0] if abs(g[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(g, e1)
    want = 1.0 - math.cos(math.radians(margin_deg))
    pts = []
    for phi in 2.0 * math.pi * np.arange(vertices) / vertices:
        t = math.cos(phi) * e1 + math.sin(phi) * e2
        lo, hi = 0.0, math.pi - 1e-6
        for _ in range(40):  # bisection on the ray: the zone is star-shaped about its kernel
            mid = 0.5 * (lo + hi)
            if zone.signed_separation(math.cos(mid) * g + math.sin(mid) * t) >= want:
                hi = mid
            else:
                lo = mid
        pts.append(math.cos(lo) * g + math.sin(lo) * t)
    P = np.array(pts)
    N = np.cross(P, np.roll(P, -1, axis=0))
    N /= np.linalg.norm(N, axis=1)[:, None]
    return P, (N if float((N @ g).mean()) > 0 else -N)


def _arc(a: np.ndarray, b: np.ndarray, step_deg: float = 0.25) -> np.ndarray:
    ang = math.acos(max(-1.0, min(1.0, float(a @ b))))
    s = np.linspace(0.0, 1.0, max(3, int(math.degrees(ang) / step_deg) + 2))[1:-1]
    return (np.sin((1 - s) * ang)[:, None] * a + np.sin(s * ang)[:, None] * b) / math.sin(ang)


def shortest_safe_path(start: np.ndarray, end: np.ndarray, zones: list, margin_deg: float) -> tuple[float, np.ndarray]:
    """(length [deg], vertices) of the shortest path from start to end keeping margin_deg from every
    (convex) zone; (inf, start) when there is none.

    Visibility graph: start, end and the polygon vertices; besides the polygon sides, only tangent
    segments can be on a shortest path (a vertex whose two neighbours lie on the same side of the
    segment's great circle), so only those are tested for crossing a polygon.
    """
    from fsw.guidance.path_planning import path_length_deg, shortest_route

    polys = [_polygon(z, margin_deg) for z in zones]
    nodes = [start, end] + [v for P, _ in polys for v in P]
    first = np.cumsum([2] + [len(P) for P, _ in polys])
    owner = {}
    for k, (P, _) in enumerate(polys):
        for i in range(len(P)):
            owner[first[k] + i] = (k, i)

    def tangent(node: int, normal: np.ndarray) -> bool:
        if node not in owner:
            return True
        k, i = owner[node]
        P = polys[k][0]
        return (P[i - 1] @ normal) * (P[(i + 1) % len(P)] @ normal) >= 0.0

    def free(a: np.ndarray, b: np.ndarray) -> bool:
        X = _arc(a, b)
        return not any(np.any(np.all(X @ N.T > 1e-12, axis=1)) for _, N in polys)

    edges: list[tuple[int, int]] = []

    def link(i: int, j: int, check: bool = True) -> None:
        n = np.cross(nodes[i], nodes[j])
        if not check or (tangent(i, n) and tangent(j, n) and free(nodes[i], nodes[j])):
            edges.append((i, j))

    link(0, 1)
    for j in range(2, len(nodes)):
        link(0, j)
        link(1, j)
    for k, (P, _) in enumerate(polys):
        for i in range(len(P)):
            link(first[k] + i, first[k] + (i + 1) % len(P), check=False)
        for k2 in range(k + 1, len(polys)):
            for i in range(len(P)):
                for j in range(len(polys[k2][0])):
                    link(first[k] + i, first[k2] + j)
    route = shortest_route(np.array(nodes), edges)  # the flight planner's graph search; the graph is this one
    if route is None:
        return math.inf, start[None, :]
    return path_length_deg(route), route


def what_geometry_allows(mission, t_s: float) -> dict:
    """Shortest safe path and the paper's assumptions at the slew's target (zones at time t_s)."""
    from gnc.checks import check_assumptions
    from hil_sim.mission.physics_checks import SkyZones

    fsw = mission.flight_software
    sky = SkyZones(mission)
    start = np.asarray(fsw.pointing.target_N, dtype=float)
    target = np.asarray(mission.timeline[0].target_N, dtype=float)
    short, _ = shortest_safe_path(start, target, sky.physical(t_s), fsw.law.margin_deg)
    zones = sky.law(t_s)
    eps_max = float(check_assumptions(target, zones, 1e-9, kappa=None, law="star", check_r_sets=False).eps_max)
    law = fsw.law
    eps = min(law.eps_fraction * eps_max, law.eps_max_used) if law.eps == "auto" else float(law.eps)
    rep = check_assumptions(target, zones, eps, kappa=law.kappa, law="star")
    return {"shortest_path_deg": short, "eps": eps, "eps_max": eps_max, "kappa": law.kappa,
            "kappa_bar": float(rep.kappa_bar), "assumptions_ok": bool(rep.ok), "assumption_errors": list(rep.errors)}


def slew_mission(base: dict, start, end, path_planning: bool = True, jerk_limit: bool = True) -> dict:
    data = json.loads(json.dumps(base, default=str))
    data["flight_software"].setdefault("pointing", {}).setdefault("path", {})["enabled"] = path_planning
    if not jerk_limit:
        data["flight_software"]["control"]["max_command_jerk_deg_s3"] = 0.0
    a, b = unit(*start), unit(*end)
    theta = math.degrees(math.acos(float(np.clip(a @ b, -1, 1))))
    data["flight_software"]["pointing"]["target_N"] = a.tolist()
    return _one_slew(data, attitude_looking_at(a), {"target_N": b.tolist()}, theta), theta, \
        eigen_axis_time_s(theta, *_limits(data))


def _limits(data: dict) -> tuple[float, float]:
    fsw = data["flight_software"]
    return fsw["spacecraft"]["max_rate_deg_s"], fsw["control"]["max_command_accel_deg_s2"]


def _one_slew(data: dict, q0: list[float], target: dict, theta_deg: float) -> dict:
    """``data`` cut to one slew: at rest on ``q0``, SET_TARGET ``target`` at 5 s, no faults, and time to
    settle (2.2 x the eigen-axis slew of ``theta_deg`` and a minute)."""
    data["initial_state"]["q_NB"] = q0
    data["initial_state"]["omega_BN_B_rad_s"] = [0.0, 0.0, 0.0]
    data["timeline"] = [{"t_s": 5.0, "command": "SET_TARGET", **target}]
    data["duration_s"] = 5.0 + 2.2 * eigen_axis_time_s(theta_deg, *_limits(data)) + 60.0
    data["faults"] = []
    return data


def run_slews(base: dict, slews: list, geometry: bool = True, path_planning: bool = True,
              jerk_limit: bool = True) -> list[dict]:
    from fsw.guidance.path_planning import path_length_deg
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import Mission

    rows = []
    for label, start, end in slews:
        data, theta, t_eig = slew_mission(base, start, end, path_planning, jerk_limit)
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
        path_deg = path_length_deg(y)
        row = {"slew": label, "angle_deg": theta, "eigen_axis_s": t_eig, "settling_s": settle,
               "path_deg": path_deg, "path_ratio": path_deg / theta,
               "ratio": settle / t_eig if math.isfinite(settle) else math.inf,
               "margins_deg": margins, "final_error_deg": m["final_error_deg"], "wall_s": wall,
               "torque_variation_Nm": m.get("torque_variation_Nm", math.nan),
               "sim_s": result.sim_time_s}
        if geometry:
            geo = what_geometry_allows(mission, 5.0)
            fsw = mission.flight_software
            t_short = eigen_axis_time_s(geo["shortest_path_deg"], fsw.spacecraft.max_rate_deg_s,
                                        fsw.control.max_command_accel_deg_s2)
            row.update({"shortest_path_deg": geo["shortest_path_deg"],
                        "shortest_path_ratio": geo["shortest_path_deg"] / theta, "ratio_lower_bound": t_short / t_eig,
                        "eps": geo["eps"], "eps_max": geo["eps_max"], "kappa": geo["kappa"],
                        "kappa_bar": geo["kappa_bar"], "assumptions_ok": geo["assumptions_ok"],
                        "assumption_errors": geo["assumption_errors"]})
        rows.append(row)
    return rows


# QUATERNION mode (config/missions/demo-quaternion.yaml): its two reorientations, each past a forbidden-
# attitude zone on S^3 (label, start q_NB, end q_NB, scalar first)
QUATERNION_SLEWS = [
    ("Q1 past the radiator-Sun cone", (0.994465, -0.039614, 0.04721, 0.085095), (0.444925, -0.00554, -0.374227, 0.813612)),
    ("Q2 past the antenna-lock star", (0.444925, -0.00554, -0.374227, 0.813612), (-0.214345, 0.788442, -0.477302, 0.323416)),
]


def quaternion_slew_mission(base: dict, start, end, path_planning: bool = True) -> tuple[dict, float, float]:
    """The demo-quaternion mission cut to one slew: at rest on ``start``, ``end`` commanded at 5 s.
    Returns (mission data, rotation angle [deg], T_eigen [s])."""
    data = json.loads(json.dumps(base, default=str))
    fsw = data["flight_software"]
    fsw["quaternion"].setdefault("path", {})["enabled"] = path_planning
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    theta = 2.0 * math.degrees(math.acos(min(1.0, abs(float(a @ b)))))  # rotation angle
    fsw["quaternion"]["target_q_NB"] = a.tolist()
    return _one_slew(data, a.tolist(), {"q_target_NB": b.tolist()}, theta), theta, eigen_axis_time_s(theta, *_limits(data))


def run_quaternion_slews(base: dict, path_planning: bool) -> list[dict]:
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import Mission

    rows = []
    for label, start, end in QUATERNION_SLEWS:
        data, theta, t_eig = quaternion_slew_mission(base, start, end, path_planning)
        mission = Mission.model_validate(data)
        m = run_fast(mission, seed=mission.seed).metrics
        settle = m["settling_time_s"]
        rows.append({"slew": label, "rotation_deg": theta, "eigen_axis_s": t_eig, "settling_s": settle,
                     "ratio": settle / t_eig if math.isfinite(settle) else math.inf,
                     "margins_deg": {k[len("margin_"):-len("_deg")]: v for k, v in m.items() if k.startswith("margin_")},
                     "torque_variation_Nm": m.get("torque_variation_Nm", math.nan),
                     "final_error_deg": m["final_error_deg"]})
    return rows


def _print_short(rows: list[dict]) -> None:
    """The comparison rows: angle, path, its ratio, T_eigen, settling, ratio, TV, margins."""
    for r in rows:
        margins = " ".join(f"{k}={v:.2f}" for k, v in r["margins_deg"].items())
        print(f"{r['slew']:38s} {r['angle_deg']:6.1f} {r['path_deg']:6.1f} {r['path_ratio']:6.3f} "
              f"{r['eigen_axis_s']:6.1f} {r['settling_s']:6.1f} {r['ratio']:6.3f} TV {r['torque_variation_Nm']:6.2f} Nm  {margins}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="only the first two slews")
    parser.add_argument("--jerk-off", action="store_true",
                        help="also fly every slew without the rate command's jerk limit (control.max_command_jerk_deg_s3: 0) "
                             "and record it under 'jerk_off': the torque chatter it removes")
    parser.add_argument("--law-only", action="store_true",
                        help="also fly every slew with path planning off (the law alone) and record it under 'law_only'")
    args = parser.parse_args(argv)

    base = yaml.safe_load((ROOT / "config" / "missions" / "demo-pointing.yaml").read_text())
    slews = SLEWS[:2] if args.quick else SLEWS
    rows = run_slews(base, slews)
    print(f"{'slew':38s} {'angle':>6s} {'path':>6s} {'path/':>6s} {'short/':>6s} {'T_eig':>6s} {'settle':>6s} "
          f"{'ratio':>6s} {'lb':>6s} {'eps':>6s} {'ok':>3s} {'TV Nm':>6s}  margins [deg]")
    for r in rows:
        margins = " ".join(f"{k}={v:.2f}" for k, v in r["margins_deg"].items())
        print(f"{r['slew']:38s} {r['angle_deg']:6.1f} {r['path_deg']:6.1f} {r['path_ratio']:6.3f} "
              f"{r['shortest_path_ratio']:6.3f} {r['eigen_axis_s']:6.1f} {r['settling_s']:6.1f} {r['ratio']:6.3f} "
              f"{r['ratio_lower_bound']:6.3f} {r['eps']:6.4f} {'yes' if r['assumptions_ok'] else 'NO':>3s} "
              f"{r['torque_variation_Nm']:6.2f}  {margins}")
    ratios = [r["ratio"] for r in rows]
    min_margin = min(min(r["margins_deg"].values()) for r in rows)
    yaml_law = base["flight_software"]["law"]
    summary = {"median_ratio": statistics.median(ratios), "max_ratio": max(ratios), "min_margin_deg": min_margin,
               "max_ratio_lower_bound": max(r["ratio_lower_bound"] for r in rows),
               "max_torque_variation_Nm": max(r["torque_variation_Nm"] for r in rows),
               "assumptions_ok": all(r["assumptions_ok"] for r in rows),
               "law": yaml_law, "control": base["flight_software"]["control"],
               "max_rate_deg_s": base["flight_software"]["spacecraft"]["max_rate_deg_s"],
               "load_average": list(os.getloadavg()),
               "goal_ratio_le": 1.3, "goal_margin_gt": 0.0,
               "ratio_goal_met": max(ratios) <= 1.3, "margin_goal_met": min_margin > 0.0}
    print(f"median ratio {summary['median_ratio']:.3f}, max {summary['max_ratio']:.3f} (goal <= 1.3); "
          f"smallest margin {min_margin:.2f} deg (goal > 0)")
    report = {"rows": rows, "summary": summary}
    if args.law_only:
        alone = run_slews(base, slews, geometry=False, path_planning=False)
        print("\nthe law alone (pointing.path.enabled: false):")
        _print_short(alone)
        report["law_only"] = {"rows": alone, "max_ratio": max(r["ratio"] for r in alone),
                              "min_margin_deg": min(min(r["margins_deg"].values()) for r in alone)}
    qbase = yaml.safe_load((ROOT / "config" / "missions" / "demo-quaternion.yaml").read_text())
    qrows = {"planned": run_quaternion_slews(qbase, True), "law_only": run_quaternion_slews(qbase, False)}
    print(f"\nQUATERNION mode (demo-quaternion; ratio = settling / eigen-axis slew of the same rotation):")
    print(f"{'slew':38s} {'rot':>6s} {'T_eig':>6s} {'planned':>8s} {'ratio':>6s} {'law':>7s} {'ratio':>6s}  margins planned [deg]")
    for p, law in zip(qrows["planned"], qrows["law_only"]):
        margins = " ".join(f"{k}={v:.2f}" for k, v in p["margins_deg"].items())
        print(f"{p['slew']:38s} {p['rotation_deg']:6.1f} {p['eigen_axis_s']:6.1f} {p['settling_s']:8.1f} "
              f"{p['ratio']:6.3f} {law['settling_s']:7.1f} {law['ratio']:6.3f}  {margins}")
    report["quaternion"] = qrows
    summary["quaternion_max_ratio"] = max(r["ratio"] for r in qrows["planned"])
    summary["quaternion_min_margin_deg"] = min(min(r["margins_deg"].values()) for r in qrows["planned"])
    if args.jerk_off:
        rough = run_slews(base, slews, geometry=False, jerk_limit=False)
        print("\nwithout the jerk limit (control.max_command_jerk_deg_s3: 0):")
        _print_short(rough)
        report["jerk_off"] = {"rows": rough, "max_torque_variation_Nm": max(r["torque_variation_Nm"] for r in rough)}
    out = ROOT / "bench" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "slew.json").write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
