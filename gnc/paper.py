"""The paper's three simulation studies as pure computation: ``keepout paper`` (cli/paper.py) runs them,
hil_sim/paper_figures.py draws them and writes the table.

1. ``s3_cones``: S^3, seven cones (axes +-e2, +-e3, +-e4, -e1, half-angle pi/12), x_d = e1, GradientLaw,
   k1 = 1, eps = 0.125, quaternion kinematics, 10 initial conditions in M_0 (several behind the cones).
2. ``s3_star``: S^3, the superellipsoid |p1|^0.4 + |p2|^0.4 + |p3|^0.4 <= 1.5 in the plane tangent at
   g1 = -[.5, .5, .5, .5], x_d = e1, StarShapedLaw, k1 = kappa = 1, eps = 0.1, 10 initial conditions.
   The literal reading of the paper (p4 = 0) is checked too: ``check_assumptions`` rejects it (its spike
   reaches d_s = 0.066 of x_d < eps) and its simulation stalls at a spurious equilibrium near x_d.
3. ``s2_star``: S^2, four non-convex star zones of our design (a five-pointed star polygon, a concave
   superellipse, a lobed radial shape, an irregular eight-pointed star polygon) satisfying Assumptions 1
   and 2, x_d = +z, StarShapedLaw, k1 = kappa = 1, eps = 0.01, 9 initial conditions, integrated on SO(3):
   the attitude quaternion is propagated with the body rate omega = b^x R^T u of the pointing map.

Every run integrates the *attitude* (q_NB) with fixed-step RK4 and renormalisation; x is the quaternion
itself (S^3) or the boresight R b (S^2). Per run: min over time of the signed separation d_s(x, U) (must
stay > 0), final d_s(x, x_d), time to d_s(x, x_d) < 1e-4. No clock is read here: the integration is
timed with the clock a caller passes.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

CONVERGED_DS = 1e-4  # d_s(x, x_d) threshold for "time to converge"

__all__ = ["Study", "RunResult", "build_studies", "simulate", "run_metrics", "study_summary", "run_studies"]


@dataclass
class Study:
    key: str
    title: str
    target: np.ndarray
    zones: list
    law: object
    initial: np.ndarray  # (runs, n+1) initial x in M_0
    mapping: str  # "quaternion" (x = q_NB) or "pointing" (x = R_NB b_B)
    dt: float  # s
    t_final: float  # s
    params: dict
    report: object = None  # gnc.checks.AssumptionReport
    expect_convergence: bool = True
    boresight_B: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))


@dataclass
class RunResult:
    t: np.ndarray  # (steps,)
    x: np.ndarray  # (steps, runs, n+1)
    signed_sep: np.ndarray  # (steps, runs) min_i signed d_s(x, U_i)
    ds_target: np.ndarray  # (steps, runs)
    wall_s: float


# ------------------------------------------------------------------------------------------------
# study definitions
# ------------------------------------------------------------------------------------------------


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _sph(polar_deg: float, az_deg: float) -> np.ndarray:
    p, a = np.radians(polar_deg), np.radians(az_deg)
    return np.array([np.sin(p) * np.cos(a), np.sin(p) * np.sin(a), np.cos(p)])


def s3_cones_setup() -> tuple[np.ndarray, list, dict]:
    from gnc.zones import ConicZone

    E = np.eye(4)
    axes = [E[1], E[2], E[3], -E[1], -E[2], -E[3], -E[0]]
    return E[0], [ConicZone(a, np.pi / 12) for a in axes], {"k1": 1.0, "eps": 0.125}


def s3_cones_initial() -> np.ndarray:
    # 1-4 sit behind a cone as seen from x_d (on the great circle from e1 through the cone axis, beyond
    # the cone), slightly off that circle (the circle itself carries the undesired saddle).
    return _unit([
        [-0.50, 0.85, 0.04, 0.03],   # behind +e2
        [-0.45, 0.04, -0.88, 0.06],  # behind -e3
        [-0.60, -0.05, 0.07, 0.80],  # behind +e4
        [-0.55, -0.83, -0.03, 0.05],  # behind -e2
        [-0.80, 0.35, 0.35, 0.30],   # near -x_d, between the cones
        [-0.20, -0.60, 0.60, -0.50],
        [0.10, 0.50, -0.50, 0.70],
        [0.30, -0.70, -0.40, 0.50],
        [-0.70, 0.10, -0.50, -0.50],
        [-0.30, -0.30, 0.60, -0.68],
    ])


def s3_star_setup(literal: bool = False) -> tuple[np.ndarray, list, dict]:
    from gnc.zones import paper_s3_star_zone

    return np.eye(4)[0], [paper_s3_star_zone(literal=literal)], {"k1": 1.0, "kappa": 1.0, "eps": 0.1}


def s3_star_initial() -> np.ndarray:
    # 1-4 behind the zone: their geodesic to x_d = e1 crosses the zone (its spikes shadow the region
    # around -e1); 5 near -x_d; the rest spread over M_0.
    return _unit([
        [-0.95, -0.27, -0.14, -0.10],
        [-0.95, -0.17, -0.20, -0.15],
        [-0.97, -0.09, -0.11, -0.19],
        [-0.93, -0.20, -0.29, -0.12],
        [-0.95, 0.20, 0.15, -0.20],
        [0.00, 0.70, 0.70, 0.10],
        [-0.30, 0.60, -0.60, 0.40],
        [0.20, -0.20, 0.80, 0.50],
        [-0.60, 0.50, 0.40, 0.45],
        [0.10, -0.90, 0.40, 0.10],
    ])


def s2_star_setup() -> tuple[np.ndarray, list, dict]:
    """Four non-convex star zones around the equator, x_d = +z (north pole)."""
    from gnc.zones import StarZone, default_tangent_basis

    def rotated_basis(center, angle_deg):
        B = default_tangent_basis(center)
        a = np.radians(angle_deg)
        return np.column_stack([np.cos(a) * B[:, 0] + np.sin(a) * B[:, 1], -np.sin(a) * B[:, 0] + np.cos(a) * B[:, 1]])

    # five-pointed star polygon (outline: 10 vertices, tangent-plane lengths, tan(angle))
    k = np.arange(10)
    ang = np.pi / 2 + np.pi * k / 5
    r = np.where(k % 2 == 0, 0.55, 0.2)
    star5 = StarZone.polygon(_sph(75, 0), None, np.column_stack([r * np.cos(ang), r * np.sin(ang)]))
    # concave superellipse |p1/0.6|^0.6 + |p2/0.42|^0.6 <= 1: four cusped spikes, turned by 25 deg
    c1 = _sph(95, 90)
    spiky = StarZone.superellipsoid(c1, rotated_basis(c1, 25), [0.6, 0.42], 0.6)

    # lobed radial shape: three rounded lobes with deep notches between them
    def lobes(u: np.ndarray) -> np.ndarray:
        return 0.33 * (1.0 + 0.5 * np.cos(3.0 * np.arctan2(u[:, 1], u[:, 0]))) + 0.05

    lobed = StarZone.radial(_sph(80, 180), None, lobes)
    # irregular eight-pointed star polygon (arms of different lengths)
    arms = np.array([0.6, 0.18, 0.35, 0.18, 0.5, 0.18, 0.42, 0.18])
    a8 = np.arange(8) * np.pi / 4 + 0.2
    star8 = StarZone.polygon(_sph(100, 270), None, np.column_stack([arms * np.cos(a8), arms * np.sin(a8)]))
    return np.array([0.0, 0.0, 1.0]), [star5, spiky, lobed, star8], {"k1": 1.0, "kappa": 1.0, "eps": 0.01}


def s2_star_initial() -> np.ndarray:
    # 1-4 behind a zone (beyond it, seen from x_d = +z), 5 near -x_d, others in between.
    return np.array([
        _sph(128, 3),
        _sph(140, 88),
        _sph(130, 183),
        _sph(145, 268),
        _sph(172, 40),
        _sph(100, 45),
        _sph(110, 225),
        _sph(60, 120),
        _sph(118, 312),
    ])


def build_studies(quick: bool = False, only: list[str] | None = None) -> list[Study]:
    """The three studies plus the literal (rejected) reading of study 2. quick: shorter horizons.

    only: keys to build (default all); each study runs check_assumptions, which takes a few seconds.
    """
    from gnc.checks import check_assumptions
    from gnc.laws import GradientLaw, StarShapedLaw

    def wanted(key: str) -> bool:
        return not only or key in only

    studies = []
    if wanted("s3_cones"):
        x_d, zones, p = s3_cones_setup()
        studies.append(Study(
            "s3_cones", "S^3, seven cones, gradient law", x_d, zones, GradientLaw(x_d, zones, p["k1"], p["eps"]),
            s3_cones_initial(), "quaternion", 0.01, 20.0 if quick else 30.0, {**p, "law": "GradientLaw"},
            report=check_assumptions(x_d, zones, p["eps"], law="gradient"),
        ))
    if wanted("s3_star"):
        x_d, zones, p = s3_star_setup()
        studies.append(Study(
            "s3_star", "S^3, superellipsoid star zone (tangent plane at g1), star-shaped law", x_d, zones,
            StarShapedLaw(x_d, zones, p["k1"], p["kappa"], p["eps"]), s3_star_initial(), "quaternion", 0.01,
            14.0 if quick else 25.0, {**p, "law": "StarShapedLaw"},
            report=check_assumptions(x_d, zones, p["eps"], p["kappa"]),
        ))
    if wanted("s3_star_literal"):
        x_d, zones, p = s3_star_setup(literal=True)
        studies.append(Study(
            "s3_star_literal", "S^3, superellipsoid read literally (p4 = 0): rejected by check_assumptions", x_d,
            zones, StarShapedLaw(x_d, zones, p["k1"], p["kappa"], p["eps"]), s3_star_initial()[:4], "quaternion",
            0.01, 10.0 if quick else 25.0, {**p, "law": "StarShapedLaw"},
            report=check_assumptions(x_d, zones, p["eps"], p["kappa"]), expect_convergence=False,
        ))
    if wanted("s2_star"):
        x_d, zones, p = s2_star_setup()
        studies.append(Study(
            "s2_star", "S^2, four non-convex star zones, star-shaped law, pointing map on SO(3)", x_d, zones,
            StarShapedLaw(x_d, zones, p["k1"], p["kappa"], p["eps"]), s2_star_initial(), "pointing",
            0.01 if quick else 0.005, 12.0 if quick else 20.0, {**p, "law": "StarShapedLaw", "boresight_B": [0.0, 0.0, 1.0]},
            report=check_assumptions(x_d, zones, p["eps"], p["kappa"]),
        ))
    return studies


# ------------------------------------------------------------------------------------------------
# simulation on the attitude
# ------------------------------------------------------------------------------------------------


def initial_attitudes(x0: np.ndarray, mapping: str, b_B: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """q_NB for each initial x: x itself (quaternion), or a rotation taking b_B to x times a random turn about b_B."""
    from gnc import attitude as att

    if mapping == "quaternion":
        return _unit(x0)
    out = []
    for y in _unit(x0):
        axis = np.cross(b_B, y)
        s = np.linalg.norm(axis)
        angle = np.arctan2(s, b_B @ y)
        if s < 1e-12:
            axis = np.cross(b_B, [1.0, 0.0, 0.0]) if abs(b_B[0]) < 0.9 else np.cross(b_B, [0.0, 1.0, 0.0])
        q_arc = att.quat_from_axis_angle(axis, angle)
        q_spin = att.quat_from_axis_angle(b_B, rng.uniform(-np.pi, np.pi))  # leaves the boresight unchanged
        out.append(att.quat_multiply(q_arc, q_spin))
    return np.array(out)


def simulate(study: Study, rng_seed: int = 0, clock: Callable[[], float] | None = None) -> RunResult:
    """Fixed-step RK4 on q_NB for every run at once (the law is evaluated with control_batch).

    clock: seconds (e.g. time.perf_counter) that time the integration loop; without one, wall_s is 0.
    """
    from gnc import attitude as att

    b_B = np.asarray(study.boresight_B, float)
    rng = np.random.default_rng(rng_seed)
    q = initial_attitudes(study.initial, study.mapping, b_B, rng)
    law = study.law

    def state(qn: np.ndarray) -> np.ndarray:
        return qn if study.mapping == "quaternion" else att.quat_rotate(qn, b_B)

    def rhs(qq: np.ndarray) -> np.ndarray:
        qn = qq / np.linalg.norm(qq, axis=1, keepdims=True)
        x = state(qn)
        u = law.control_batch(x)
        if study.mapping == "quaternion":
            omega_BN_B = att.quaternion_rate_command(qn, u)
        else:
            omega_BN_B = att.pointing_rate_command(qn, b_B, u)
        return att.quat_derivative(qn, omega_BN_B)

    steps = int(round(study.t_final / study.dt))
    dt = study.dt
    xs = np.empty((steps + 1, q.shape[0], study.target.shape[0]))
    xs[0] = state(q)
    t0 = clock() if clock is not None else 0.0
    for k in range(steps):
        k1 = rhs(q)
        k2 = rhs(q + 0.5 * dt * k1)
        k3 = rhs(q + 0.5 * dt * k2)
        k4 = rhs(q + dt * k3)
        q = q + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        xs[k + 1] = state(q)
    wall = clock() - t0 if clock is not None else 0.0
    t = np.arange(steps + 1) * dt
    signed = signed_separation_history(study.zones, xs)
    ds_target = 0.5 * np.sum((xs - study.target) ** 2, axis=2)
    return RunResult(t, xs, signed, ds_target, wall)


def signed_separation_history(zones: list, xs: np.ndarray) -> np.ndarray:
    """min_i signed d_s(x, U_i) for every recorded state, exactly, with few exact evaluations.

    Branch and bound: outside a zone's bounding cap, 1 - cos(angle to the cap) is a lower bound of
    d_s(x, U_i). Zones are visited per state in order of that bound, and a zone's exact (possibly
    expensive) separation is computed only while its bound is below the best exact value so far.
    """
    steps, runs, dim = xs.shape
    X = xs.reshape(-1, dim)
    m = len(zones)
    lower = np.empty((X.shape[0], m))
    for i, zone in enumerate(zones):
        axis, rho = zone.bounding_cap
        ang = np.arccos(np.clip(X @ np.asarray(axis, float), -1.0, 1.0))
        lower[:, i] = np.where(ang > rho, 1.0 - np.cos(ang - rho), -np.inf)  # inside the cap: no bound
    order = np.argsort(lower, axis=1)
    best = np.full(X.shape[0], np.inf)
    for rank in range(m):
        zi = order[:, rank]
        need = lower[np.arange(X.shape[0]), zi] < best
        for i, zone in enumerate(zones):
            rows = np.flatnonzero(need & (zi == i))
            if rows.size == 0:
                continue
            batch = getattr(zone, "signed_separation_batch", None)
            vals = batch(X[rows]) if batch is not None else np.array([zone.signed_separation(x) for x in X[rows]])
            best[rows] = np.minimum(best[rows], vals)
    return best.reshape(steps, runs)


def run_metrics(study: Study, res: RunResult) -> list[dict]:
    rows = []
    for r in range(res.x.shape[1]):
        ds = res.ds_target[:, r]
        below = np.flatnonzero(ds < CONVERGED_DS)
        rows.append({
            "run": r + 1,
            "x0": [round(float(v), 6) for v in res.x[0, r]],
            "min_signed_separation": float(res.signed_sep[:, r].min()),
            "final_ds_target": float(ds[-1]),
            "final_angle_to_target_deg": float(np.degrees(2 * np.arcsin(min(1.0, np.sqrt(ds[-1] / 2.0))))),
            "time_to_ds_below_1e-4_s": float(res.t[below[0]]) if below.size else None,
        })
    return rows


def study_summary(study: Study, res: RunResult) -> dict:
    """The study's parameters, its assumption report in numbers and its per-run metrics."""
    rep = study.report
    return {
        "title": study.title,
        "params": study.params,
        "dt_s": study.dt,
        "t_final_s": study.t_final,
        "mapping": study.mapping,
        "expect_convergence": study.expect_convergence,
        "assumptions_ok": bool(rep.ok) if rep is not None else None,
        "assumptions": rep.summary() if rep is not None else "",
        "delta_deg": float(np.degrees(rep.delta)) if rep is not None and rep.delta is not None else None,
        "eps_max": float(rep.eps_max) if rep is not None else None,
        "kappa_bar": rep.kappa_bar if rep is not None else None,
        "wall_time_s": res.wall_s,
        "runs": run_metrics(study, res),
    }


def run_studies(quick: bool = False, only: list[str] | None = None, clock: Callable[[], float] | None = None
                ) -> tuple[dict, dict[str, tuple[Study, RunResult]]]:
    """Build and simulate the studies (``build_studies``'s quick and only). Returns the results, a summary
    per study, and each study's key -> (study, its simulation) for the figures."""
    results: dict = {"converged_threshold_ds": CONVERGED_DS, "studies": {}}
    sims: dict[str, tuple[Study, RunResult]] = {}
    for st in build_studies(quick=quick, only=only):
        res = simulate(st, clock=clock)
        sims[st.key] = (st, res)
        results["studies"][st.key] = study_summary(st, res)
    return results, sims
