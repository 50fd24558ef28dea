"""Reproduce the paper's three simulation studies: ``keepout paper`` / ``python -m gnc.paper``.

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
stay > 0), final d_s(x, x_d), time to d_s(x, x_d) < 1e-4. Outputs in ``--out`` (default docs/paper):
``table.md``, ``results.json`` and PNG figures.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CONVERGED_DS = 1e-4  # d_s(x, x_d) threshold for "time to converge"

__all__ = ["Study", "RunResult", "build_studies", "simulate", "run_studies", "add_cli", "main"]


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


def simulate(study: Study, rng_seed: int = 0) -> RunResult:
    """Fixed-step RK4 on q_NB for every run at once (the law is evaluated with control_batch)."""
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
    t0 = time.perf_counter()
    for k in range(steps):
        k1 = rhs(q)
        k2 = rhs(q + 0.5 * dt * k1)
        k3 = rhs(q + 0.5 * dt * k2)
        k4 = rhs(q + dt * k3)
        q = q + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        xs[k + 1] = state(q)
    wall = time.perf_counter() - t0
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


# ------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------


def _contour_on_sphere(zone, level: float, half_width: float, n: int = 220) -> list[np.ndarray]:
    """Curves {d_s(x, U) = level} around an S^2 zone (for plots), on a gnomonic grid about the kernel.

    d_s outside the zone is the distance to its boundary, taken here over 3000 boundary samples (plot
    accuracy, and independent of the zone's exact search, which is far too slow for a 48,000-point grid
    on radial zones). Inside/outside: the zone is star-shaped about the kernel, so in the gnomonic
    plane a point is inside iff its radius is below the boundary radius in its direction.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gnc.zones import default_tangent_basis

    g = np.asarray(zone.kernel, float)
    B = default_tangent_basis(g)
    bnd = np.asarray(zone.boundary(3000), float)
    plane = bnd[:, None, :] @ B[None, :, :]
    plane = plane[:, 0, :] / (bnd @ g)[:, None]
    b_ang = np.arctan2(plane[:, 1], plane[:, 0])
    order = np.argsort(b_ang)
    b_ang, b_rad = b_ang[order], np.hypot(plane[order, 0], plane[order, 1])
    b_ang = np.concatenate([b_ang[-1:] - 2 * np.pi, b_ang, b_ang[:1] + 2 * np.pi])
    b_rad = np.concatenate([b_rad[-1:], b_rad, b_rad[:1]])
    s = np.linspace(-half_width, half_width, n)
    S1, S2 = np.meshgrid(s, s)
    P = g[None, :] + S1.reshape(-1, 1) * B[:, 0] + S2.reshape(-1, 1) * B[:, 1]
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    D = np.empty(P.shape[0])
    for start in range(0, P.shape[0], 4000):
        D[start:start + 4000] = 1.0 - np.max(P[start:start + 4000] @ bnd.T, axis=1)
    inside = np.hypot(S1.ravel(), S2.ravel()) <= np.interp(np.arctan2(S2.ravel(), S1.ravel()), b_ang, b_rad)
    D[inside] = 0.0
    fig = plt.figure()
    cs = plt.contour(S1, S2, D.reshape(S1.shape), levels=[level])
    curves = []
    for seg in cs.allsegs[0]:
        Y = g[None, :] + seg[:, :1] * B[:, 0] + seg[:, 1:2] * B[:, 1]
        curves.append(Y / np.linalg.norm(Y, axis=1, keepdims=True))
    plt.close(fig)
    return curves


def _azimuthal(points: np.ndarray, center: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Azimuthal equidistant map about `center`: radius = angle from center (deg)."""
    ang = np.degrees(np.arccos(np.clip(points @ center, -1.0, 1.0)))
    az = np.arctan2(points @ basis[1], points @ basis[0])
    return np.column_stack([ang * np.cos(az), ang * np.sin(az)])


def plot_s2(study: Study, res: RunResult, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    eps = study.params["eps"]
    colors = plt.cm.tab10(np.arange(10))
    layers = []
    for z in study.zones:
        _, rho = z.bounding_cap
        layers.append(_contour_on_sphere(z, eps, np.tan(min(rho + 0.2, 1.3))))
    boundaries = [np.vstack([b, b[:1]]) for b in (np.asarray(z.boundary(1500), float) for z in study.zones)]

    fig = plt.figure(figsize=(15, 5.6))
    # two 3-D views of the sphere
    for panel, (elev, azim) in enumerate(((20, -60), (-35, 130))):
        ax = fig.add_subplot(1, 3, panel + 1, projection="3d")
        _draw_s2_view(ax, study, res, boundaries, layers, colors, elev, azim)
    _draw_s2_map(fig.add_subplot(1, 3, 3), study, res, boundaries, layers, colors)
    fig.suptitle(f"{study.title}: zones (red), eps-layers (dashed, eps={eps}), kernels (yellow), x_d (star)")
    fig.tight_layout()
    name = "s2_star_sphere.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    return [name, _plot_s2_separation(study, res, out, colors)]


_S2_ZONE_COLOR = "#c0392b"


def _draw_s2_view(ax, study: Study, res: RunResult, boundaries: list[np.ndarray], layers: list,
                  colors: np.ndarray, elev: float, azim: float) -> None:
    """The sphere seen from (elev, azim): zones, their eps-layers, kernels, runs and x_d on the near side."""
    x_d = study.target
    u, v = np.mgrid[0 : 2 * np.pi : 60j, 0 : np.pi : 30j]
    ax.plot_surface(np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v), color="#dfe6ee", alpha=0.25, linewidth=0)
    view = np.array([np.cos(np.radians(elev)) * np.cos(np.radians(azim)), np.cos(np.radians(elev)) * np.sin(np.radians(azim)), np.sin(np.radians(elev))])

    def draw(P, **kw):
        P = np.asarray(P)
        vis = P @ view > -0.05
        Q = np.where(vis[:, None], P * 1.003, np.nan)
        ax.plot(Q[:, 0], Q[:, 1], Q[:, 2], **kw)

    for i, z in enumerate(study.zones):
        draw(boundaries[i], color=_S2_ZONE_COLOR, lw=1.6)
        for c in layers[i]:
            draw(c, color=_S2_ZONE_COLOR, lw=0.7, ls="--")
        g = z.kernel
        if g @ view > 0:
            ax.scatter(*g, color="gold", edgecolor="k", s=30, zorder=5)
    for r in range(res.x.shape[1]):
        draw(res.x[:, r], color=colors[r % 10], lw=1.2)
        if res.x[0, r] @ view > 0:
            ax.scatter(*res.x[0, r], color=colors[r % 10], marker="o", s=18)
    if x_d @ view > 0:
        ax.scatter(*x_d, color="k", marker="*", s=120)
    ax.view_init(elev=elev, azim=azim)
    ax.set_box_aspect((1, 1, 1), zoom=1.35)
    ax.set_axis_off()
    ax.set_title(f"view elev {elev}, azim {azim}")


def _draw_s2_map(ax, study: Study, res: RunResult, boundaries: list[np.ndarray], layers: list,
                 colors: np.ndarray) -> None:
    """Azimuthal equidistant map about x_d (the whole sphere; -x_d on the outer circle)."""
    x_d = study.target
    basis = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) if abs(x_d[2]) > 0.9 else np.linalg.qr(np.column_stack([x_d, np.eye(3)]))[0][:, 1:3].T
    for i, z in enumerate(study.zones):
        P = _azimuthal(boundaries[i], x_d, basis)
        ax.fill(P[:, 0], P[:, 1], color=_S2_ZONE_COLOR, alpha=0.35, lw=0)
        ax.plot(P[:, 0], P[:, 1], color=_S2_ZONE_COLOR, lw=1.2)
        for c in layers[i]:
            C = _azimuthal(c, x_d, basis)
            ax.plot(C[:, 0], C[:, 1], color=_S2_ZONE_COLOR, lw=0.6, ls="--")
        G = _azimuthal(z.kernel[None, :], x_d, basis)
        ax.scatter(G[:, 0], G[:, 1], color="gold", edgecolor="k", s=30, zorder=5)
        ax.annotate(f"U{i + 1}", G[0] + 6, fontsize=8)
    for r in range(res.x.shape[1]):
        P = _azimuthal(res.x[:, r], x_d, basis)
        ax.plot(P[:, 0], P[:, 1], color=colors[r % 10], lw=1.1, label=f"run {r + 1}")
        ax.scatter(P[0, 0], P[0, 1], color=colors[r % 10], s=16)
    ax.scatter([0], [0], color="k", marker="*", s=120, zorder=6)
    circle = np.linspace(0, 2 * np.pi, 200)
    for rad in (45, 90, 135, 180):
        ax.plot(rad * np.cos(circle), rad * np.sin(circle), color="0.8", lw=0.5)
    ax.set_aspect("equal")
    ax.set_title("azimuthal equidistant map about x_d (deg)")
    ax.legend(fontsize=6, loc="lower left", ncol=2)


def _plot_s2_separation(study: Study, res: RunResult, out: Path, colors: np.ndarray) -> str:
    """Separation from the unsafe set and convergence to x_d over time, per run; returns the file name."""
    import matplotlib.pyplot as plt

    eps = study.params["eps"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    for r in range(res.x.shape[1]):
        ax[0].plot(res.t, res.signed_sep[:, r], color=colors[r % 10], lw=1, label=f"run {r + 1}")
        ax[1].semilogy(res.t, np.maximum(res.ds_target[:, r], 1e-16), color=colors[r % 10], lw=1)
    ax[0].axhline(eps, color="0.5", ls="--", lw=0.8)
    ax[0].set_ylim(bottom=0.0)
    ax[0].set_xlabel("t [s]")
    ax[0].set_ylabel("d_s(x, U)")
    ax[0].set_title("separation from the unsafe set (dashed: eps)")
    ax[1].axhline(CONVERGED_DS, color="0.5", ls="--", lw=0.8)
    ax[1].set_xlabel("t [s]")
    ax[1].set_ylabel("d_s(x, x_d)")
    ax[1].set_title("convergence")
    ax[0].legend(fontsize=6, ncol=3)
    fig.tight_layout()
    name = "s2_star_separation.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    return name


def plot_s3(study: Study, res: RunResult, out: Path, extra: tuple[Study, RunResult] | None = None) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = plt.cm.tab10(np.arange(10))
    star = study.key.startswith("s3_star")
    ncols = 4 if star else 3
    fig = plt.figure(figsize=(4.2 * ncols, 7.6))
    panels = []
    if star:
        ax = fig.add_subplot(2, ncols, 1, projection="3d")
        z = study.zones[0]
        rng = np.random.default_rng(0)
        w = rng.normal(size=(6000, 3))
        w /= np.linalg.norm(w, axis=1, keepdims=True)
        qexp = z.exponent
        a = z.semi_axes
        p = np.sign(w) * np.abs(w) ** (2.0 / qexp) * a
        ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=0.3, color="#c0392b", alpha=0.5)
        ax.set_title("O_0: |p1|^0.4+|p2|^0.4+|p3|^0.4 <= 1.5")
        ax.set_xlabel("p1")
        ax.set_ylabel("p2")
        ax.set_zlabel("p3")
        slots = [2, 3, 4, 5, 6, 7, 8]
    else:
        slots = [1, 2, 3, 4, 5, 6]
    labels = ["eta (x1)", "q1 (x2)", "q2 (x3)", "q3 (x4)"]
    for k in range(4):
        ax = fig.add_subplot(2, ncols, slots[k])
        for r in range(res.x.shape[1]):
            ax.plot(res.t, res.x[:, r, k], color=colors[r % 10], lw=1)
        ax.set_xlabel("t [s]")
        ax.set_title(labels[k])
        panels.append(ax)
    ax = fig.add_subplot(2, ncols, slots[4])
    for r in range(res.x.shape[1]):
        ax.semilogy(res.t, np.maximum(res.ds_target[:, r], 1e-16), color=colors[r % 10], lw=1)
    ax.axhline(CONVERGED_DS, color="0.5", ls="--", lw=0.8)
    ax.set_xlabel("t [s]")
    ax.set_title("d_s(x, x_d)")
    ax = fig.add_subplot(2, ncols, slots[5])
    for r in range(res.x.shape[1]):
        ax.plot(res.t, res.signed_sep[:, r], color=colors[r % 10], lw=1, label=f"run {r + 1}")
    ax.axhline(study.params["eps"], color="0.5", ls="--", lw=0.8)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("t [s]")
    ax.set_title("d_s(x, U) (dashed: eps)")
    ax.legend(fontsize=6, ncol=2)
    if star and extra is not None:
        lit, lres = extra
        ax = fig.add_subplot(2, ncols, slots[6])
        for r in range(lres.x.shape[1]):
            ang = np.degrees(2 * np.arcsin(np.minimum(1.0, np.sqrt(lres.ds_target[:, r] / 2))))
            ax.plot(lres.t, ang, color=colors[r % 10], lw=1)
        ax.set_yscale("log")
        final = np.degrees(2 * np.arcsin(np.minimum(1.0, np.sqrt(lres.ds_target[-1] / 2))))
        ax.axhline(float(np.median(final)), color="0.4", ls=":", lw=0.8)
        ax.annotate(f"stalls at {np.median(final):.2f} deg", (lres.t[-1] * 0.45, float(np.median(final)) * 1.4), fontsize=8)
        ax.set_xlabel("t [s]")
        ax.set_title("literal p4=0 reading: angle to x_d [deg]\n(stalls: eps > d_s(x_d, U))", fontsize=9)
    fig.suptitle(f"{study.title} (x_d = e1)")
    fig.tight_layout()
    name = f"{study.key}.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    return [name]


# ------------------------------------------------------------------------------------------------
# the whole reproduction
# ------------------------------------------------------------------------------------------------


def run_studies(out: Path | None, quick: bool = False, figures: bool = True, only: list[str] | None = None) -> dict:
    studies = build_studies(quick=quick, only=only)
    results: dict = {"converged_threshold_ds": CONVERGED_DS, "studies": {}}
    sims = {}
    for st in studies:
        res = simulate(st)
        sims[st.key] = (st, res)
        rows = run_metrics(st, res)
        rep = st.report
        results["studies"][st.key] = {
            "title": st.title,
            "params": st.params,
            "dt_s": st.dt,
            "t_final_s": st.t_final,
            "mapping": st.mapping,
            "expect_convergence": st.expect_convergence,
            "assumptions_ok": bool(rep.ok) if rep is not None else None,
            "assumptions": rep.summary() if rep is not None else "",
            "delta_deg": float(np.degrees(rep.delta)) if rep is not None and rep.delta is not None else None,
            "eps_max": float(rep.eps_max) if rep is not None else None,
            "kappa_bar": rep.kappa_bar if rep is not None else None,
            "wall_time_s": res.wall_s,
            "runs": rows,
        }
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        figs = []
        if figures:
            for key, (st, res) in sims.items():
                if key == "s2_star":
                    figs += plot_s2(st, res, out)
                elif key == "s3_cones":
                    figs += plot_s3(st, res, out)
                elif key == "s3_star":
                    figs += plot_s3(st, res, out, extra=sims.get("s3_star_literal"))
        results["figures"] = figs
        (out / "results.json").write_text(json.dumps(_jsonable(results), indent=2) + "\n")
        (out / "table.md").write_text(markdown_table(results))
    return results


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if np.isfinite(v) else str(v)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def markdown_table(results: dict) -> str:
    lines = [
        "# Reproduction of the paper's simulation studies",
        "",
        "Generated by `keepout paper` (`python -m gnc.paper`). Every run integrates the attitude q_NB with",
        "fixed-step RK4 (renormalised); x is the quaternion (S^3) or the boresight R b (S^2).",
        f"Columns: min over time of the signed separation d_s(x, U) (negative would mean inside a zone), final",
        f"d_s(x, x_d), and the first time d_s(x, x_d) < {CONVERGED_DS:g}.",
        "",
    ]
    for key, st in results["studies"].items():
        lines.append(f"## {key}: {st['title']}")
        lines.append("")
        p = ", ".join(f"{k} = {v}" for k, v in st["params"].items())
        lines.append(f"{p}; dt = {st['dt_s']} s, t_final = {st['t_final_s']} s, {st['mapping']} map")
        lines.append("")
        lines.append("```")
        lines.append(st["assumptions"])
        lines.append("```")
        lines.append("")
        lines.append("| run | x(0) | min signed d_s(x,U) | final d_s(x,x_d) | final angle to x_d [deg] | t(d_s<1e-4) [s] |")
        lines.append("|---|---|---|---|---|---|")
        for r in st["runs"]:
            t_conv = "never" if r["time_to_ds_below_1e-4_s"] is None else f"{r['time_to_ds_below_1e-4_s']:.2f}"
            x0 = "[" + ", ".join(f"{v:.3f}" for v in r["x0"]) + "]"
            lines.append(
                f"| {r['run']} | {x0} | {r['min_signed_separation']:.5f} | {r['final_ds_target']:.3e} | "
                f"{r['final_angle_to_target_deg']:.3g} | {t_conv} |"
            )
        lines.append("")
    for fig in results.get("figures", []):
        lines.append(f"![{fig}]({fig})")
        lines.append("")
    return "\n".join(lines)


def _handler(args: argparse.Namespace) -> int:
    out = Path(args.out)
    t0 = time.perf_counter()
    results = run_studies(out, quick=args.quick, figures=not args.no_figures, only=args.study or None)
    failed = []
    for key, st in results["studies"].items():
        mins = [r["min_signed_separation"] for r in st["runs"]]
        conv = [r["time_to_ds_below_1e-4_s"] is not None for r in st["runs"]]
        status = "ok"
        if min(mins) <= 0.0:
            status = "UNSAFE"
            failed.append(key)
        elif st["expect_convergence"] and not all(conv):
            status = "NOT CONVERGED"
            failed.append(key)
        elif not st["expect_convergence"]:
            status = f"rejected by check_assumptions as expected ({sum(conv)}/{len(conv)} runs converged)"
        print(f"{key:18s} runs={len(mins):2d} min signed d_s={min(mins):.5f}  converged={sum(conv)}/{len(conv)}  {status}")
    print(f"wrote {out / 'table.md'}, {out / 'results.json'} and figures in {time.perf_counter() - t0:.1f} s")
    return 1 if failed else 0


def add_cli(subparsers) -> None:
    p = subparsers.add_parser("paper", help="reproduce the paper's simulation studies (table + figures)")
    p.add_argument("--out", default="docs/paper", help="output folder (default: docs/paper)")
    p.add_argument("--quick", action="store_true", help="shorter horizons (for tests)")
    p.add_argument("--no-figures", action="store_true", help="only the table and JSON")
    p.add_argument("--study", action="append", choices=["s3_cones", "s3_star", "s3_star_literal", "s2_star"],
                   help="run only this study (repeatable)")
    p.set_defaults(func=_handler)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m gnc.paper", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command")
    add_cli(sub)
    args = parser.parse_args(["paper", *(argv if argv is not None else sys.argv[1:])])
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
