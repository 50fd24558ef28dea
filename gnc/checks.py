"""The paper's assumptions as code: check a (target, zones, eps, kappa) set-up before flying it.

``check_assumptions(target, zones, eps, kappa=None)`` returns an :class:`AssumptionReport`:

* Assumption 1: for i != j, max_{a in U_i, b in U_j} a^T b <= cos(2 delta). delta is computed from the
  smallest separation between every pair of zones: closed form for two cones, otherwise the minimum of
  d_s over dense boundary samples of each zone against the other (``separation_batch``), refined by
  alternating nearest-point projections (``nearest``), which never increases the distance.
* eps interval: 0 < eps < min(eps_bar, 1 - cos delta) where eps_bar < d_s(x_d, U); so the upper end of
  the admissible interval is ``eps_max = min(d_s(x_d, U), 1 - cos delta)`` (open).
* x_d outside U; every kernel g_i strictly inside U_i and -g_i outside U_i; g_i != -x_d for the
  star-shaped law (the gradient law's cones may have g_i = -x_d, as in the paper's S^3 study).
* Assumption 2 (star-shaped law only): the sets R_i are pairwise disjoint, checked numerically on rays
  from x_d (every point of S^n lies on exactly one half great circle from x_d to -x_d).
* kappa_bar (star-shaped law only): on the geodesic G(x_d, -g_i) the closed-loop field is
  P(x)u = lambda(x) P(x) x_d with lambda = k1/(eps kappa) (kappa d - q^-(eps - d)), d = d_s(x, U_i),
  q^-(x) = x_d^T P(x) g_i / |P(x) x_d|^2 (paper, proof of the Fact for V_i). lambda > 0 on the whole
  layer part of the geodesic iff kappa > kappa_bar_i = max q^-(eps - d)/d there. At kappa <= kappa_bar
  the field vanishes on that geodesic: an undesired equilibrium, and it is *stable* where lambda
  turns from negative (nearer x_d) to positive (farther): the report lists them.

Every message names the zone indices and the numbers involved.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, Sequence

import numpy as np
from numba import njit

__all__ = ["AssumptionReport", "check_assumptions", "zone_pair_separation", "kappa_bar_for_zone", "r_sets_overlap"]


@dataclass
class AssumptionReport:
    ok: bool
    errors: list[str]
    warnings: list[str]
    delta: float | None  # rad; pi/2 for a single zone (the paper's upper end)
    eps_max: float  # upper end (open) of the admissible eps interval
    kappa_bar: float | None  # None unless the star-shaped law is checked
    law: str = "star"
    target_separation: float = float("nan")  # d_s(x_d, U)
    pair_separations: dict = field(default_factory=dict)  # (i, j) -> min d_s(U_i, U_j)
    kappa_bar_per_zone: list = field(default_factory=list)
    undesired_equilibria: list = field(default_factory=list)  # dicts: zone, x, stable
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        lines = [f"assumptions ({self.law} law): {'OK' if self.ok else 'VIOLATED'}"]
        if self.delta is not None:
            lines.append(f"  delta = {np.degrees(self.delta):.4f} deg, eps_max = {self.eps_max:.6g}")
        if self.kappa_bar is not None:
            lines.append(f"  kappa_bar = {self.kappa_bar:.6g}")
        lines += [f"  error: {e}" for e in self.errors]
        lines += [f"  warning: {w}" for w in self.warnings]
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


# ------------------------------------------------------------------------------------------------
# geometry helpers
# ------------------------------------------------------------------------------------------------


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(2.0 * np.arctan2(np.linalg.norm(a - b), np.linalg.norm(a + b)))


def _ds(a: np.ndarray, b: np.ndarray) -> float:
    return 0.5 * float(np.sum((a - b) ** 2))


def _is_cone(zone) -> bool:
    return getattr(zone, "half_angle", None) is not None


def _signed(zone, x) -> float:
    fn = getattr(zone, "signed_separation", None)
    if fn is not None:
        return float(fn(x))
    return float(zone.separation(x)) if not zone.contains(x) else -0.0


def _toward(g: np.ndarray, h: np.ndarray, angle: float) -> np.ndarray:
    """The point at `angle` from g on the great circle from g toward h (any direction if h = -g)."""
    w = h - g * (g @ h)
    nw = float(np.linalg.norm(w))
    if nw < 1e-12:
        w = _tangent_basis(g)[0]
    else:
        w = w / nw
    return np.cos(angle) * g + np.sin(angle) * w


def zone_pair_separation(zi, zj, samples: int | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """(min d_s between U_i and U_j, a in U_i, b in U_j). 0 if they touch or overlap.

    Cones: exact. Otherwise: if neither zone holds a point of the other (kernel, boundary samples), the
    closest pair lies on the two boundaries; the closest pair of dense boundary samples is refined by
    alternating nearest-point projections, each of which can only decrease the distance.
    """
    if _is_cone(zi) and _is_cone(zj):
        gi, gj = np.asarray(zi.kernel, float), np.asarray(zj.kernel, float)
        gap = _angle(gi, gj) - float(zi.half_angle) - float(zj.half_angle)
        if gap <= 0.0:
            return 0.0, gi, gj
        # nearest points lie on the great circle through the two axes
        a = _toward(gi, gj, float(zi.half_angle))
        b = _toward(gj, gi, float(zj.half_angle))
        return 1.0 - float(np.cos(gap)), a, b
    dim = int(zi.dim)
    num = samples if samples is not None else (4000 if dim == 3 else 12000)
    Bi = np.asarray(zi.boundary(num), dtype=float)
    Bj = np.asarray(zj.boundary(num), dtype=float)
    for za, zb, pts in ((zi, zj, Bj), (zj, zi, Bi)):
        for p in (np.asarray(zb.kernel, float), pts[0]):
            if za.contains(p):
                return 0.0, p, p
    # closest pair of samples (chunked: the full matrix can be large)
    best_dot, bi, bj = -2.0, 0, 0
    for start in range(0, Bi.shape[0], 2000):
        dots = Bi[start:start + 2000] @ Bj.T
        k = int(np.argmax(dots))
        r, c = divmod(k, dots.shape[1])
        if dots[r, c] > best_dot:
            best_dot, bi, bj = float(dots[r, c]), start + r, c
    a, b = Bi[bi], Bj[bj]
    dist = _ds(a, b)
    for _ in range(30):
        b2 = np.asarray(zj.nearest(a), dtype=float)
        a2 = np.asarray(zi.nearest(b2), dtype=float)
        d2 = _ds(a2, b2)
        if not d2 < dist - 1e-16:
            if _ds(a, b2) < dist:
                b, dist = b2, _ds(a, b2)
            break
        a, b, dist = a2, b2, d2
    if zj.contains(a) or zi.contains(b):
        return 0.0, a, b
    return dist, a, b


RAY_DIRECTION_GROUPS = 120  # ~30 rays of the 3,600 per group on S^2


def _tangent_basis(x_d: np.ndarray) -> np.ndarray:
    """Orthonormal basis (n, n+1) of the tangent space at x_d."""
    dim = x_d.shape[0]
    q, _ = np.linalg.qr(np.column_stack([x_d, np.eye(dim)]))
    return q[:, 1:dim].T


def _ray_directions(x_d: np.ndarray, count: int) -> np.ndarray:
    """Unit tangent directions at x_d, evenly spread (circle for S^2, Fibonacci sphere for S^3)."""
    basis = _tangent_basis(x_d)
    n = basis.shape[0]
    if n == 2:
        phi = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
        coords = np.column_stack([np.cos(phi), np.sin(phi)])
    elif n == 3:
        k = np.arange(count) + 0.5
        z = 1.0 - 2.0 * k / count
        r = np.sqrt(1.0 - z * z)
        phi = np.pi * (1.0 + 5.0**0.5) * k
        coords = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    else:
        rng = np.random.default_rng(0)
        coords = rng.standard_normal((count, n))
        coords /= np.linalg.norm(coords, axis=1, keepdims=True)
    return coords @ basis


# Margins of the exact culling in `_ray_windows` (see there): far above the rounding of a few products.
_CULL_MARGIN = 1e-9
_CULL_MARGIN_SQ = 1e-12


def _extremes_first(Bd: np.ndarray, x_d: np.ndarray) -> np.ndarray:
    """Sample indices alternating nearest to and farthest from x_d, inwards (see `_ray_windows`)."""
    by_distance = np.argsort(-(Bd @ x_d), kind="stable")
    out = np.empty_like(by_distance)
    out[0::2] = by_distance[: (len(by_distance) + 1) // 2]
    out[1::2] = by_distance[::-1][: len(by_distance) // 2]
    return out


def _direction_clusters(V: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Group the ray directions round ``count`` of themselves (evenly spread, so the groups are compact).

    Returns (centres (m, dim), radii (m,) with |v - centre| <= radius for every member v, order (members
    listed group by group, indices into V), starts (m + 1,): group j is order[starts[j]:starts[j + 1]]).
    """
    centres = np.ascontiguousarray(V[:: max(1, V.shape[0] // count)])
    label = np.argmax(V @ centres.T, axis=1)
    order = np.argsort(label, kind="stable")
    starts = np.searchsorted(label[order], np.arange(centres.shape[0] + 1))
    gap = np.linalg.norm(V - centres[label], axis=1)
    radii = np.zeros(centres.shape[0])
    np.maximum.at(radii, label, gap)
    return centres, radii * (1.0 + 1e-9) + 1e-12, order, starts


@njit(cache=True)
def _ray_windows(V, Bd, x_d, cos_eps, lo, hi, centres, radii, order, starts, sample_order):
    """For each ray direction V[k]: smallest and largest t in [0, pi] within theta_eps of a sample Bd[l],
    folded into lo[k] (min) and hi[k] (max).

    r_v(t)^T b = a_x cos t + a_v sin t = A cos(t - phi): within theta_eps for |t - phi| <= alpha,
    alpha = arccos(cos_eps / A) (`_fold_window`). A pair (v, b) with A < cos_eps adds nothing. Most do: the
    directions come in groups (`_direction_clusters`), and a group is skipped for b when a bound proves
    A < cos_eps for all its members (`_group_out_of_reach`). Of the pairs that do meet the layer, most
    cannot widen the window found so far (`_window_cannot_widen`). Both skips are exact, not heuristics:
    every pair left is computed exactly as before, and min/max do not depend on the order, so lo and hi are
    bit-identical to the full double loop. Visiting the samples nearest to and farthest from x_d first
    (sample_order) makes the windows nearly final early.
    """
    nv = V.shape[0]
    cos_eps_sq = cos_eps * cos_eps
    mu = 1e-7
    skips = cos_eps > 0.0
    cos_lo = np.full(nv, -2.0)  # cos(lo[k] + mu); -2: no skip yet
    cos_hi = np.full(nv, 2.0)  # cos(hi[k] - mu); 2: no skip yet
    for l in sample_order:
        a_x, norm_b_sq = _dot_and_norm_sq(Bd, l, x_d)
        need = cos_eps_sq - a_x * a_x - _CULL_MARGIN_SQ  # a pair can count only if a_v^2 >= about this
        norm_b = np.sqrt(norm_b_sq)
        for j in range(centres.shape[0]):
            if need > 0.0 and _group_out_of_reach(Bd, l, centres, radii, j, norm_b, need):
                continue
            for m in range(starts[j], starts[j + 1]):
                k = order[m]
                a_v = _row_dot(Bd, l, V, k)
                A = np.sqrt(a_x * a_x + a_v * a_v)
                if A < cos_eps or A == 0.0:
                    continue
                if skips and _window_cannot_widen(a_x, a_v, A, cos_eps, cos_eps_sq, cos_lo[k], cos_hi[k]):
                    continue
                lo_k, hi_k = lo[k], hi[k]
                _fold_window(lo, hi, k, a_x, a_v, A, cos_eps)
                if lo[k] != lo_k:
                    cos_lo[k] = np.cos(lo[k] + mu) if lo[k] + mu < np.pi else -2.0
                if hi[k] != hi_k:
                    cos_hi[k] = np.cos(hi[k] - mu) if hi[k] - mu > 0.0 else 2.0


@njit(cache=True, inline="always")
def _dot_and_norm_sq(Bd, l, x_d):
    """(Bd[l] . x_d, |Bd[l]|^2), summed in coordinate order."""
    a_x = 0.0
    norm_b_sq = 0.0
    for c in range(Bd.shape[1]):
        a_x += Bd[l, c] * x_d[c]
        norm_b_sq += Bd[l, c] * Bd[l, c]
    return a_x, norm_b_sq


@njit(cache=True, inline="always")
def _row_dot(P, i, Q, j):
    """P[i] . Q[j], summed in coordinate order (row views would cost an allocation per pair)."""
    s = 0.0
    for c in range(P.shape[1]):
        s += P[i, c] * Q[j, c]
    return s


@njit(cache=True, inline="always")
def _group_out_of_reach(Bd, l, centres, radii, j, norm_b, need):
    """True when no direction of group j can bring sample l within theta_eps: |a_v| = |b.v| <= |b.c| + |b| rho
    for centre c and radius rho >= |v - c| (Cauchy-Schwarz), and the group is skipped only when
    (bound + _CULL_MARGIN)^2 < cos_eps^2 - a_x^2 - _CULL_MARGIN_SQ (``need``), margins far above the
    rounding of these sums."""
    bound = abs(_row_dot(Bd, l, centres, j)) + norm_b * radii[j] + _CULL_MARGIN
    return bound * bound < need


@njit(cache=True, inline="always")
def _window_cannot_widen(a_x, a_v, A, cos_eps, cos_eps_sq, cos_lo_k, cos_hi_k):
    """True when the pair's window provably adds nothing to (lo, hi), whose ends are known through
    cos_lo_k = cos(lo + mu) and cos_hi_k = cos(hi - mu).

    With a_v > 0 (phi in (0, pi)) and cos_eps > 0 (alpha <= pi/2) only the unshifted window can meet
    [0, pi], and its ends need no arc function: with S = sqrt(A^2 - cos_eps^2),
    cos(phi -+ alpha) = (a_x cos_eps +- a_v S) / A^2 and sin(phi -+ alpha) = (a_v cos_eps -+ a_x S) / A^2.
    The pair is skipped when these prove 0 <= phi - alpha and lo + mu < phi - alpha (via cos, monotone on
    [0, pi]), and phi + alpha < hi - mu with phi + alpha <= pi, each with margins; mu = 1e-7 rad far exceeds
    the rounding of phi and alpha, which is below 1e-11 rad where S / A >= 1e-4 (pairs with smaller S are
    always computed). With a_v <= 0 (phi in [-pi, 0], the half circle through -v) the pair adds nothing
    when sin(phi + alpha) < 0 and sin(phi - alpha) < 0 (its window and the 2 pi-shifted one miss [0, pi]).
    """
    A_sq = A * A
    S = np.sqrt(max(A_sq - cos_eps_sq, 0.0))
    tol = _CULL_MARGIN
    if S < 1e-4 * A:
        return False  # alpha too ill-conditioned for the bounds: compute
    if a_v <= 0.0:
        # (the quotients by A^2 > 0 are compared as products: the margins cover the rounding)
        return a_v * cos_eps + a_x * S < -tol * A_sq and a_v * cos_eps - a_x * S < -tol * A_sq
    lo_ok = (a_v * cos_eps - a_x * S > tol * A_sq
             and a_x * cos_eps + a_v * S < (cos_lo_k - tol) * A_sq)
    # the window [phi - alpha, phi + alpha] lies inside (lo, hi)
    return lo_ok and (a_v * cos_eps + a_x * S > tol * A_sq
                      and a_x * cos_eps - a_v * S > (cos_hi_k + tol) * A_sq)


@njit(cache=True, inline="always")
def _fold_window(lo, hi, k, a_x, a_v, A, cos_eps):
    """Fold the pair's window [phi - alpha, phi + alpha], clipped to [0, pi], into (lo[k], hi[k]); it may
    wrap past t = +-pi, hence the three shifts."""
    two_pi = 2.0 * np.pi
    r = cos_eps / A
    alpha = np.arccos(r if r > -1.0 else -1.0)
    phi = np.arctan2(a_v, a_x)
    for shift in (-two_pi, 0.0, two_pi):
        t_lo = phi + shift - alpha
        t_hi = phi + shift + alpha
        if t_lo < 0.0:
            t_lo = 0.0
        if t_hi > np.pi:
            t_hi = np.pi
        if t_lo <= t_hi:
            if t_lo < lo[k]:
                lo[k] = t_lo
            if t_hi > hi[k]:
                hi[k] = t_hi


@njit(cache=True)
def _second_largest_per_row(M):
    """The second largest value of each row (a repeated maximum counts twice), as
    ``np.partition(M, -2, axis=1)[:, -2]`` gives it, in one pass instead of a partial sort."""
    out = np.empty(M.shape[0])
    for r in range(M.shape[0]):
        first = -np.inf
        second = -np.inf
        for x in M[r]:
            if x > first:
                second = first
                first = x
            elif x > second:
                second = x
        out[r] = second
    return out


@lru_cache(maxsize=8)
def _rays_and_groups(x_d_bytes: bytes, dim: int, directions: int) -> tuple[np.ndarray, tuple]:
    """The ray directions at x_d and their groups: a pure function of x_d, kept for the next time sample
    of the same target (the zones move, the target does not)."""
    V = np.ascontiguousarray(_ray_directions(np.frombuffer(x_d_bytes, dtype=float, count=dim).copy(), directions))
    return V, _direction_clusters(V, RAY_DIRECTION_GROUPS)


def r_sets_overlap(
    x_d: np.ndarray, zones: Sequence, eps: float, directions: int | None = None, boundary_samples: int | None = None
) -> tuple[list[tuple[int, int, np.ndarray]], dict]:
    """Numerical test of Assumption 2. Returns (overlaps [(i, j, witness point)], info).

    Every point of S^n other than +-x_d lies on one half great circle r_v(t) = cos t x_d + sin t v,
    t in (0, pi), v a unit tangent at x_d. On such a ray, R_i (i in I_a, i.e. -x_d not in D_eps(U_i))
    is the interval [t0_i, tmax_i(v)], t0_i the angle from x_d to D_eps(U_i) and tmax_i(v) the largest t
    with r_v(t) in D_eps(U_i); for i not in I_a it is [tmin_i(v), pi) (geodesics from -x_d). The zone
    interiors are not removed: R_j can only meet U_i after crossing the eps-layer in front of U_i, which
    is in R_i, so this changes no verdict.

    D_eps(U_i) along a ray: its far and near ends lie within theta_eps = arccos(1 - eps) of the zone
    boundary, so they are found in closed form from dense boundary samples b: the ray is within
    theta_eps of b for t in [phi - alpha, phi + alpha] with A cos(t - phi) = r_v(t)^T b. Resolution:
    the direction grid and the boundary sample spacing (both reported in info).
    """
    dim = x_d.shape[0]
    if directions is None:
        directions = 3600 if dim == 3 else 4000
    if boundary_samples is None:
        boundary_samples = 3000 if dim == 3 else 6000
    V, clusters = _rays_and_groups(np.ascontiguousarray(x_d, dtype=float).tobytes(), dim, directions)
    theta_eps = float(np.arccos(1.0 - eps))
    cos_eps = float(np.cos(theta_eps))
    m = len(zones)
    lo = np.full((m, V.shape[0]), np.inf)
    hi = np.full((m, V.shape[0]), -np.inf)
    spacing = 0.0
    for i, zone in enumerate(zones):
        Bd = np.asarray(zone.boundary(boundary_samples), dtype=float)
        if Bd.shape[0] > 1:
            nn = _second_largest_per_row(Bd[: min(400, len(Bd))] @ Bd.T)  # nearest other sample
            spacing = max(spacing, float(np.max(np.arccos(np.clip(nn, -1, 1)))))
        Bd = np.ascontiguousarray(Bd)
        _ray_windows(V, Bd, x_d, cos_eps, lo[i], hi[i], *clusters, _extremes_first(Bd, x_d))
    intervals = np.empty((m, V.shape[0], 2))
    for i, zone in enumerate(zones):
        hit = hi[i] >= lo[i]
        sep_target = float(zone.separation(x_d))
        t0 = max(float(np.arccos(np.clip(1.0 - sep_target, -1.0, 1.0))) - theta_eps, 0.0)
        if float(zone.separation(-x_d)) > eps:  # i in I_a
            intervals[i, :, 0] = np.where(hit, t0, np.inf)
            intervals[i, :, 1] = np.where(hit, hi[i], -np.inf)
        else:
            intervals[i, :, 0] = np.where(hit, lo[i], np.inf)
            intervals[i, :, 1] = np.where(hit, np.pi, -np.inf)
    overlaps = []
    for i in range(m):
        for j in range(i + 1, m):
            start = np.maximum(intervals[i, :, 0], intervals[j, :, 0])
            end = np.minimum(intervals[i, :, 1], intervals[j, :, 1])
            both = np.isfinite(start) & np.isfinite(end) & (end >= start)
            if both.any():
                k = int(np.argmax(np.where(both, end - start, -1.0)))
                t = 0.5 * (start[k] + end[k])
                overlaps.append((i, j, np.cos(t) * x_d + np.sin(t) * V[k]))
    info = {
        "directions": int(V.shape[0]),
        "direction_step_deg": float(np.degrees(2.0 * np.pi / V.shape[0])) if dim == 3 else float(np.degrees(np.sqrt(4 * np.pi / V.shape[0]))),
        "boundary_spacing_deg": float(np.degrees(spacing)),
    }
    return overlaps, info


def kappa_bar_for_zone(x_d: np.ndarray, zone, eps: float, samples: int = 4001) -> dict:
    """kappa_bar_i = max over x in N_eps(U_i) on G(x_d, -g_i) of q^-(x)(eps - d)/d, d = d_s(x, U_i).

    Returns a dict: kappa_bar (0 if the geodesic does not meet the layer, inf if it meets the zone),
    the maximiser x, and the arrays along the geodesic (lam, d, q) for locating equilibria.
    """
    from scipy.optimize import minimize_scalar

    from gnc.sphere import geodesic

    g = np.asarray(zone.kernel, float)
    out = {"kappa_bar": 0.0, "x": None, "lam": None, "d": None, "q": None, "hits_zone": False}
    if _angle(x_d, -g) < 1e-12:
        return out  # g = -x_d: the geodesic is the point x_d itself
    lam = np.linspace(0.0, 1.0, samples)
    X = geodesic(x_d, -g, lam)
    # only points whose bounding-cap distance is within eps can be in the layer; the rest get +inf
    axis, rho = zone.bounding_cap
    reach = float(rho) + float(np.arccos(np.clip(1.0 - eps, -1.0, 1.0)))
    near = X @ np.asarray(axis, float) >= (np.cos(reach) - 1e-12 if reach < np.pi else -2.0)
    d = np.full(samples, np.inf)
    if near.any():
        d[near] = np.asarray(zone.separation_batch(X[near]), dtype=float)

    def q_of(x):
        Pxd = x_d - x * (x @ x_d) if x.ndim == 1 else x_d[None, :] - x * (x @ x_d)[:, None]
        Pg = g - x * (x @ g) if x.ndim == 1 else g[None, :] - x * (x @ g)[:, None]
        num = Pxd @ g if x.ndim == 1 else np.einsum("ij,j->i", Pxd, g)
        den = Pxd @ Pxd if x.ndim == 1 else np.einsum("ij,ij->i", Pxd, Pxd)
        del Pg
        return num / np.maximum(den, 1e-300)

    q = q_of(X)
    out.update(lam=lam, d=d, q=q)
    layer = (d <= eps) & (lam > 0.0)
    if not layer.any():
        return out
    if (d[layer] <= 0.0).any():
        out.update(kappa_bar=np.inf, x=X[layer][np.argmin(d[layer])], hits_zone=True)
        return out
    f = np.full(samples, -np.inf)
    f[layer] = q[layer] * (eps - d[layer]) / d[layer]
    k = int(np.argmax(f))
    best, best_lam = float(f[k]), float(lam[k])
    step = lam[1] - lam[0]
    lo, hi = max(best_lam - step, 0.0), min(best_lam + step, 1.0)

    def neg_f(s):
        x = geodesic(x_d, -g, s)
        dd = float(zone.separation(x))
        if dd > eps or dd <= 0.0:
            return -0.0 if dd > eps else -np.inf
        return -float(q_of(x)) * (eps - dd) / dd

    res = minimize_scalar(neg_f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
    if res.success and -res.fun > best:
        best, best_lam = float(-res.fun), float(res.x)
    out.update(kappa_bar=best, x=geodesic(x_d, -g, best_lam))
    return out


def _equilibria_on_geodesic(info: dict, eps: float, kappa: float, x_d: np.ndarray, g: np.ndarray) -> list[dict]:
    """Sign changes of lambda = kappa d - q (eps - d) along G(x_d, -g_i) inside the layer."""
    from gnc.sphere import geodesic

    lam, d, q = info["lam"], info["d"], info["q"]
    if lam is None:
        return []
    in_layer = d <= eps
    lamb = np.ones_like(d)
    lamb[in_layer] = kappa * d[in_layer] - q[in_layer] * (eps - d[in_layer])
    found = []
    sign = np.sign(lamb)
    for k in np.flatnonzero(sign[:-1] * sign[1:] < 0):
        # linear interpolation of the root; stable when lambda goes - -> + moving away from x_d
        s = lam[k] + (lam[k + 1] - lam[k]) * lamb[k] / (lamb[k] - lamb[k + 1])
        found.append({"x": geodesic(x_d, -g, s), "stable": bool(lamb[k] < 0 < lamb[k + 1]), "lam": float(s)})
    return found


# ------------------------------------------------------------------------------------------------
# the report
# ------------------------------------------------------------------------------------------------


def _fmt(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{c:.4f}" for c in np.asarray(v, float)) + "]"


def check_assumptions(
    target,
    zones: Sequence,
    eps: float | Callable[[float], float],
    kappa: float | None = None,
    *,
    law: str | None = None,
    check_r_sets: bool = True,
) -> AssumptionReport:
    """Check the paper's assumptions for (x_d, zones, eps[, kappa]).

    law: "star" (StarShapedLaw) or "gradient" (GradientLaw, conic zones). Default: "gradient" when every
    zone is a cone and no kappa is given, else "star". Assumption 2 and kappa_bar belong to the star law.
    eps may be a function of eps_max (the eps the flight software would pick): the check then runs once
    instead of a probe for eps_max and a second full check (the pair separations are the costly part).
    """
    x_d = _unit_target(target)
    zones = _zones_around(x_d, zones)
    eps_of = eps if callable(eps) else None  # chosen from eps_max below
    eps = float("nan") if eps_of is not None else float(eps)
    law = _law_for(zones, law, kappa)
    errors: list[str] = []
    warnings: list[str] = []
    notes: list[str] = []

    if eps_of is None and not eps > 0.0:
        errors.append(f"eps = {eps} must be > 0")
    target_seps = _check_target_outside(x_d, zones, errors)
    target_sep = max(min(target_seps), 0.0)
    _check_kernels(x_d, zones, law, errors, notes)
    pair_seps, delta, worst_pair = _check_assumption_1(zones, errors, notes)
    one_minus_cos_delta = 1.0 - float(np.cos(delta))
    eps_max = min(target_sep, one_minus_cos_delta)
    if eps_of is not None:
        eps = float(eps_of(eps_max))
        if not eps > 0.0:
            errors.insert(0, f"eps = {eps} must be > 0")  # where the check on a given eps puts it
    _check_eps_interval(zones, eps, target_seps, one_minus_cos_delta, worst_pair, law, errors)

    report = AssumptionReport(
        ok=False,
        errors=errors,
        warnings=warnings,
        delta=delta,
        eps_max=eps_max,
        kappa_bar=None,
        law=law,
        target_separation=target_sep,
        pair_separations=pair_seps,
        notes=notes,
    )
    if law == "gradient":
        notes.append("gradient law: Assumption 2 and kappa are not needed (Theorem for conic constraints)")
        report.ok = not errors
        return report
    if check_r_sets and len(zones) > 1 and eps > 0 and delta > 0:
        _check_assumption_2(x_d, zones, eps, errors, notes)
    kbars = _kappa_bars(report, x_d, zones, eps, kappa)
    _check_kappa(report, kbars, x_d, kappa, eps, target_seps)
    report.ok = not errors
    return report


def _unit_target(target) -> np.ndarray:
    x_d = np.asarray(target, dtype=float)
    if x_d.ndim != 1 or abs(np.linalg.norm(x_d) - 1.0) > 1e-6:
        raise ValueError(f"target must be a unit vector, got {target!r}")
    return x_d / np.linalg.norm(x_d)


def _zones_around(x_d: np.ndarray, zones: Sequence) -> list:
    """The zones as a list, at least one, all in the target's space."""
    zones = list(zones)
    if not zones:
        raise ValueError("at least one zone is required")
    for i, z in enumerate(zones):
        if int(z.dim) != x_d.shape[0]:
            raise ValueError(f"zone {i} lives in R^{z.dim}, the target in R^{x_d.shape[0]}")
    return zones


def _law_for(zones: list, law: str | None, kappa: float | None) -> str:
    """The law checked: the one asked for, else the gradient law for cones without kappa (see check_assumptions)."""
    if law is None:
        law = "gradient" if (kappa is None and all(_is_cone(z) for z in zones)) else "star"
    if law not in ("star", "gradient"):
        raise ValueError(f"law must be 'star' or 'gradient', got {law!r}")
    if law == "gradient" and not all(_is_cone(z) for z in zones):
        bad = [i for i, z in enumerate(zones) if not _is_cone(z)]
        raise ValueError(f"the gradient law needs conic zones; zones {bad} are not cones")
    return law


def _check_target_outside(x_d: np.ndarray, zones: list, errors: list[str]) -> list[float]:
    """x_d outside U: the signed separation of x_d from each zone (eps_bar is below their minimum)."""
    target_seps = [_signed(z, x_d) for z in zones]
    for i, s in enumerate(target_seps):
        if s <= 0.0:
            errors.append(f"target x_d = {_fmt(x_d)} is inside zone {i} (signed separation {s:.6g})")
    return target_seps


def _check_kernels(x_d: np.ndarray, zones: list, law: str, errors: list[str], notes: list[str]) -> None:
    """Every g_i strictly inside U_i, -g_i outside it, and g_i != -x_d for the star-shaped law."""
    for i, z in enumerate(zones):
        g = np.asarray(z.kernel, float)
        sg = _signed(z, g)
        if not sg < 0.0:
            errors.append(f"zone {i}: kernel g_{i} = {_fmt(g)} is not strictly inside the zone (signed separation {sg:.6g})")
        if z.contains(-g):
            errors.append(f"zone {i}: -g_{i} = {_fmt(-g)} lies in the zone, so g_{i} cannot be a kernel point (sigma(U_{i}))")
        if _angle(g, -x_d) < 1e-9:
            if law == "star":
                errors.append(f"zone {i}: g_{i} = -x_d; the star-shaped law needs g_i != -x_d (geodesics G(x_d, g_i) undefined)")
            else:
                notes.append(f"zone {i}: g_{i} = -x_d (allowed for the gradient law's cones)")


def _check_assumption_1(zones: list, errors: list[str], notes: list[str]) -> tuple[dict, float, tuple | None]:
    """Assumption 1: (pair separations, delta, the closest pair); delta is 0 when some pair touches."""
    pair_seps = {}
    delta = np.pi / 2.0
    worst_pair = None
    for i in range(len(zones)):
        for j in range(i + 1, len(zones)):
            dmin, a, b = zone_pair_separation(zones[i], zones[j])
            pair_seps[(i, j)] = dmin
            if dmin <= 0.0:
                errors.append(f"Assumption 1: zones {i} and {j} touch or overlap (separation {dmin:.3g}, near {_fmt(a)})")
                continue
            d_ij = 0.5 * float(np.arccos(np.clip(1.0 - dmin, -1.0, 1.0)))
            if d_ij < delta:
                delta, worst_pair = d_ij, (i, j)
    if any(v <= 0.0 for v in pair_seps.values()):
        delta = 0.0
    if len(zones) > 1 and worst_pair is not None:
        notes.append(
            f"Assumption 1: delta = {np.degrees(delta):.4f} deg (closest pair: zones {worst_pair[0]} and {worst_pair[1]}, "
            f"min separation {pair_seps[worst_pair]:.6g}), 1 - cos(delta) = {1.0 - float(np.cos(delta)):.6g}"
        )
    return pair_seps, delta, worst_pair


def _check_eps_interval(zones: list, eps: float, target_seps: list[float], one_minus_cos_delta: float,
                        worst_pair: tuple | None, law: str, errors: list[str]) -> None:
    """eps below eps_bar and 1 - cos(delta); for the gradient law, each cone and its layer short of 180 deg."""
    target_sep = max(min(target_seps), 0.0)
    if eps >= target_sep and target_sep > 0.0:
        errors.append(
            f"eps = {eps:.6g} is not below eps_bar < d_s(x_d, U) = {target_sep:.6g} (zone {int(np.argmin(target_seps))} is "
            f"{np.degrees(np.arccos(1 - target_sep)):.3f} deg from x_d): x_d lies in the eps-layer, so the law "
            "is not k1 x_d at the target and a spurious equilibrium appears near x_d"
        )
    if len(zones) > 1 and eps >= one_minus_cos_delta:
        i, j = worst_pair if worst_pair is not None else (0, 1)
        errors.append(
            f"eps = {eps:.6g} is not below 1 - cos(delta) = {one_minus_cos_delta:.6g} (zones {i} and {j}): "
            "their eps-dilations are not guaranteed disjoint"
        )
    if law == "gradient":
        for i, z in enumerate(zones):
            reach = float(z.half_angle) + float(np.arccos(np.clip(1.0 - eps, -1.0, 1.0)))
            if reach >= np.pi:
                errors.append(f"zone {i}: half-angle + eps-layer width = {np.degrees(reach):.3f} deg >= 180 deg")


def _check_assumption_2(x_d: np.ndarray, zones: list, eps: float, errors: list[str], notes: list[str]) -> None:
    """Assumption 2: the R_i pairwise disjoint, on rays from x_d (r_sets_overlap)."""
    overlaps, info = r_sets_overlap(x_d, zones, eps)
    for i, j, w in overlaps:
        errors.append(
            f"Assumption 2: R_{i} and R_{j} overlap (e.g. at x = {_fmt(w)}); zones {i} and {j} shadow each other "
            "as seen from x_d, so a trajectory can cycle between their layers"
        )
    notes.append(
        f"Assumption 2 checked on {info['directions']} rays from x_d (about {info['direction_step_deg']:.2f} deg apart), "
        f"boundary samples {info['boundary_spacing_deg']:.3f} deg apart"
        + ("" if overlaps else ": R_i pairwise disjoint")
    )


def _kappa_bars(report: AssumptionReport, x_d: np.ndarray, zones: list, eps: float, kappa: float | None) -> list:
    """kappa_bar_i per zone; geodesics to -g_i through a zone are errors, and with kappa given the undesired
    equilibria on them go into the report."""
    kbars = []
    for i, z in enumerate(zones):
        info = kappa_bar_for_zone(x_d, z, eps)
        kbars.append(info["kappa_bar"])
        if info["hits_zone"]:
            report.errors.append(
                f"zone {i}: the geodesic from x_d to -g_{i} passes through the zone (at {_fmt(info['x'])}); "
                "no kappa removes the undesired equilibria there"
            )
        if kappa is not None and info["lam"] is not None:
            g = np.asarray(z.kernel, float)
            for eq in _equilibria_on_geodesic(info, eps, float(kappa), x_d, g):
                eq["zone"] = i
                report.undesired_equilibria.append(eq)
    return kbars


def _check_kappa(report: AssumptionReport, kbars: list, x_d: np.ndarray, kappa: float | None, eps: float,
                 target_seps: list[float]) -> None:
    """kappa_bar (the largest of the zones') into the report, and kappa judged against it."""
    target_sep = max(min(target_seps), 0.0)
    target_in_layer = eps >= target_sep
    if target_in_layer:
        # q^- grows without bound as x -> x_d along the geodesic, so no kappa is sufficient
        kbars = [np.inf if target_seps[i] <= eps else k for i, k in enumerate(kbars)]
    report.kappa_bar_per_zone = kbars
    report.kappa_bar = float(max(kbars)) if kbars else 0.0
    where = _stable_equilibrium_clause(report, x_d)
    if kappa is not None and target_in_layer:
        report.errors.append(
            f"x_d is inside the eps-layer of zone {int(np.argmin(target_seps))} (d_s(x_d, U) = {target_sep:.6g} <= eps = {eps:.6g}): "
            f"no kappa is sufficient (kappa_bar = inf){where}"
        )
    elif kappa is not None and np.isfinite(report.kappa_bar):
        if float(kappa) <= report.kappa_bar:
            i = int(np.argmax(kbars))
            report.errors.append(
                f"kappa = {float(kappa):.6g} <= kappa_bar = {report.kappa_bar:.6g} (zone {i}, on the geodesic from x_d "
                f"to -g_{i}): the field can vanish there and create a STABLE undesired equilibrium{where}; "
                f"choose kappa > {report.kappa_bar:.6g}"
            )
    elif kappa is None and report.kappa_bar > 0:
        report.warnings.append(f"kappa not given; it must exceed kappa_bar = {report.kappa_bar:.6g}")


def _stable_equilibrium_clause(report: AssumptionReport, x_d: np.ndarray) -> str:
    """'; stable undesired equilibrium at ...' for the first stable one in the report, else ''."""
    stable = [e for e in report.undesired_equilibria if e["stable"]]
    if not stable:
        return ""
    e = stable[0]
    return (
        f"; stable undesired equilibrium at x = {_fmt(e['x'])} (zone {e['zone']}), "
        f"{np.degrees(_angle(e['x'], x_d)):.3f} deg from x_d"
    )

