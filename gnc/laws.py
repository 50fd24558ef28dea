"""The paper's feedback laws for constrained stabilization on S^n (xdot = P(x) u).

* :class:`GradientLaw` (paper, Section "Constrained stabilization under conic constraints"):
  u = -grad W with the navigation function W = k1 d/(d + beta), d = d_s(x, x_d), and beta = h_i(d_s(x, g_i))
  in the eps-neighbourhood N_eps(U_i) of a cone (1 outside every neighbourhood). h_i is the cubic of the
  paper's footnote, h_i(p) = 1 + (p - Dhi)^3 / (Dhi - Dlo)^3 with Dlo = 1 - cos(xi_i) and
  Dhi = 1 - cos(xi_i + arccos(1 - eps)). Evaluated through the closed form (eq. conic_control_expression):
      u = k1 / (h + d)^2 (h x_d - h' d g_i)     in N_eps(U_i),
      u = k1 / (1 + d)^2 x_d                    outside.
* :class:`StarShapedLaw` (paper, eqs. n-sphere-control-law and individual_control_input_vector_design):
      u = k1 [ (d_i/eps) x_d - (1/kappa)(1 - d_i/eps) g_i ]   in N_eps(U_i), d_i = d_s(x, U_i),
      u = k1 x_d                                              outside every eps-layer.

Both laws are dimensionless maps S^n -> R^(n+1); with the attitude maps of :mod:`gnc.attitude` the
result becomes a body-rate command in rad/s (k1 then has units of 1/s).

Outside the paper's domain (x strictly inside a zone, which a correct closed loop never reaches but an
attitude *estimate* can) both laws keep pointing out of the zone: the gradient law clamps
d_s(x, g_i) to the boundary value Dlo (so u = -k1 h'(Dlo)/d g_i), the star law uses d_i = 0
(u = -k1/kappa g_i). Both are exactly the paper's boundary values.

The zones (``gnc.zones``) provide ``kernel``, ``separation``, ``separation_batch`` and ``bounding_cap``;
a zone whose bounding cap is farther than eps from x cannot be active, so it is skipped without
computing its (possibly expensive) separation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numba import njit

__all__ = ["GradientLaw", "StarShapedLaw", "LawDiagnosis", "cubic_h", "conic_layer_bounds"]

_UNIT_TOL = 1e-6  # how far |x| may be from 1 before a state is rejected as not on the sphere


@dataclass(frozen=True)
class LawDiagnosis:
    """What the law saw at one state.

    active_zone: index of the zone whose eps-layer contains x (the zone whose repulsion is active), or None.
    separation_to_unsafe: d_s(x, U) = min_i d_s(x, U_i) (0 inside a zone).
    separation_to_target: d_s(x, x_d).
    zone_separations: d_s(x, U_i) for every zone (signed: negative inside), same order as the zones.
    u: the control input; velocity: P(x) u.
    """

    active_zone: int | None
    separation_to_unsafe: float
    separation_to_target: float
    zone_separations: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    velocity: np.ndarray = field(repr=False)


# ----------------------------------------------------------------------------------------------
# helpers shared by both laws
# ----------------------------------------------------------------------------------------------


def _unit_vector(v, name: str) -> np.ndarray:
    arr = np.asarray(v, dtype=float)
    if arr.ndim != 1 or arr.shape[0] < 3:
        raise ValueError(f"{name} must be a vector in R^(n+1) with n >= 2, got shape {arr.shape}")
    # np.linalg.norm of a real 1-D array is sqrt(arr.dot(arr)): the same number without its ~3 us of
    # checks (a law is built on every aim advance of a slew)
    norm = math.sqrt(arr.dot(arr))
    if not math.isfinite(norm) or abs(norm - 1.0) > _UNIT_TOL:
        raise ValueError(f"{name} must be a unit vector (|{name}| = {norm:.9g})")
    return arr / norm


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def _check_state(x, dim: int) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (dim,):
        raise ValueError(f"state x must have shape ({dim},), got {arr.shape}")
    n2 = arr @ arr
    if not abs(n2 - 1.0) <= 2.0 * _UNIT_TOL:  # also rejects NaN
        raise ValueError(f"state x must be a unit vector on S^{dim - 1}, |x|^2 = {n2!r}")
    return arr


def _check_batch(X, dim: int) -> np.ndarray:
    arr = np.ascontiguousarray(X, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"states X must have shape (m, {dim}), got {arr.shape}")
    n2 = np.einsum("ij,ij->i", arr, arr)
    bad = ~(np.abs(n2 - 1.0) <= 2.0 * _UNIT_TOL)
    if np.any(bad):
        row = int(np.argmax(bad))
        raise ValueError(f"states X must be unit vectors; row {row} has |x|^2 = {n2[row]!r}")
    return arr


def _project(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return u - x * (x @ u) if u.ndim == 1 else u - x * np.einsum("ij,ij->i", x, u)[:, None]


def _cap_skip_cosines(zones: Sequence, eps: float, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Axes and cosine thresholds: zone i can only be within eps of x if x . axis_i >= threshold_i.

    d_s(x, U_i) >= d_s(x, cap_i) = 1 - cos(angle(x, axis_i) - rho_i), so d_s(x, U_i) <= eps needs
    angle(x, axis_i) <= rho_i + arccos(1 - eps). A small margin keeps rounding from skipping a zone
    that is exactly eps away.
    """
    theta_eps = float(np.arccos(1.0 - eps))
    axes = np.empty((len(zones), dim))
    thresholds = np.empty(len(zones))
    for i, zone in enumerate(zones):
        axis, half_angle = zone.bounding_cap
        axis = np.asarray(axis, dtype=float)
        axes[i] = axis / math.sqrt(axis.dot(axis))  # np.linalg.norm's number (see _unit_vector)
        reach = float(half_angle) + theta_eps + 1e-9
        thresholds[i] = np.cos(reach) if reach < np.pi else -2.0  # -2: never skip
    return axes, thresholds


def _zone_list(zones, dim: int) -> list:
    zones = list(zones)
    if not zones:
        raise ValueError("at least one zone is required")
    for i, zone in enumerate(zones):
        if int(zone.dim) != dim:
            raise ValueError(f"zone {i} lives in R^{zone.dim} but the target is in R^{dim}")
    return zones


# ----------------------------------------------------------------------------------------------
# Gradient law (conic zones)
# ----------------------------------------------------------------------------------------------


def conic_layer_bounds(half_angle: float, eps: float) -> tuple[float, float]:
    """(Dlo, Dhi): d_s(x, g_i) on the cone boundary and on the outer boundary of its eps-layer (paper footnote)."""
    reach = half_angle + float(np.arccos(1.0 - eps))
    if reach >= np.pi:
        raise ValueError(
            f"cone half-angle {np.degrees(half_angle):.3f} deg plus the eps-layer width "
            f"{np.degrees(np.arccos(1 - eps)):.3f} deg reaches past the antipode of its axis; reduce eps"
        )
    return 1.0 - float(np.cos(half_angle)), 1.0 - float(np.cos(reach))


def cubic_h(p, d_lo: float, d_hi: float):
    """The paper's footnote cubic h(p) = 1 + (p - Dhi)^3/(Dhi - Dlo)^3 and its derivative h'(p)."""
    span3 = (d_hi - d_lo) ** 3
    r = np.asarray(p, dtype=float) - d_hi
    return 1.0 + r**3 / span3, 3.0 * r**2 / span3


@njit(cache=True)
def _gradient_u_kernel(x, x_d, axes, d_lo, d_hi, k1, out):
    """u for one state into out; returns the active zone index or -1."""
    dim = x.shape[0]
    d = 0.0
    for k in range(dim):
        diff = x[k] - x_d[k]
        d += diff * diff
    d *= 0.5  # d_s(x, x_d) without cancellation near x_d
    best = -1
    best_s = 2.0
    best_p = 0.0
    for i in range(axes.shape[0]):
        c = 0.0
        for k in range(dim):
            c += x[k] * axes[i, k]
        p = 1.0 - c  # d_s(x, g_i)
        if p < d_hi[i]:
            # normalized depth in the layer; the layers are disjoint when eps < 1 - cos(delta), this only
            # breaks ties deterministically for configurations that violate it
            s = (p - d_lo[i]) / (d_hi[i] - d_lo[i])
            if s < best_s:
                best_s = s
                best = i
                best_p = p
    if best < 0:
        scale = k1 / ((1.0 + d) * (1.0 + d))
        for k in range(dim):
            out[k] = scale * x_d[k]
        return -1
    lo = d_lo[best]
    hi = d_hi[best]
    p = best_p if best_p > lo else lo
    span = hi - lo
    r = p - hi
    h = 1.0 + r * r * r / (span * span * span)
    hp = 3.0 * r * r / (span * span * span)
    scale = k1 / ((h + d) * (h + d))
    for k in range(dim):
        out[k] = scale * (h * x_d[k] - hp * d * axes[best, k])
    return best


@njit(cache=True)
def _gradient_u_batch_kernel(X, x_d, axes, d_lo, d_hi, k1, out, active):
    for j in range(X.shape[0]):
        active[j] = _gradient_u_kernel(X[j], x_d, axes, d_lo, d_hi, k1, out[j])


class _SphereLaw:
    """What both laws derive from u(x): the closed-loop velocity and the diagnosis.

    Subclasses provide ``dim``, ``target``, ``zones``, ``control``, ``control_batch`` and
    ``control_and_zone``."""

    def velocity(self, x) -> np.ndarray:
        """xdot = P(x) u(x)."""
        x = _check_state(x, self.dim)
        return _project(x, self.control(x))

    def velocity_batch(self, X) -> np.ndarray:
        X = _check_batch(X, self.dim)
        return _project(X, self.control_batch(X))

    def diagnose(self, x) -> LawDiagnosis:
        x = _check_state(x, self.dim)
        u, active = self.control_and_zone(x)
        seps = np.array([_signed(zone, x) for zone in self.zones])
        return LawDiagnosis(
            active_zone=active,
            separation_to_unsafe=float(max(seps.min(), 0.0)),
            separation_to_target=0.5 * float(np.sum((x - self.target) ** 2)),
            zone_separations=seps,
            u=u,
            velocity=_project(x, u),
        )


class GradientLaw(_SphereLaw):
    """u = -grad W, the paper's navigation-function law for conic zones (eq. negative_gradient_control_law).

    target: x_d (unit, R^(n+1)); zones: ``ConicZone`` objects (``kernel`` g_i and ``half_angle`` xi_i in rad);
    k1 > 0 [1/s when u drives an attitude]; eps: width of the eps-layer in d_s units.
    """

    def __init__(self, target, zones, k1: float = 1.0, eps: float = 0.1):
        self.target = _unit_vector(target, "target")
        self.dim = self.target.shape[0]
        self.zones = _zone_list(zones, self.dim)
        self.k1 = _positive(k1, "k1")
        self.eps = _positive(eps, "eps")
        if self.eps >= 2.0:
            raise ValueError(f"eps must be < 2 (the largest separation on the sphere), got {self.eps}")
        axes, lo, hi = [], [], []
        for i, zone in enumerate(self.zones):
            half_angle = getattr(zone, "half_angle", None)
            if half_angle is None:
                raise TypeError(
                    f"GradientLaw needs conic zones (with a half_angle); zone {i} is {type(zone).__name__}: "
                    "use StarShapedLaw for star-shaped zones"
                )
            d_lo, d_hi = conic_layer_bounds(float(half_angle), self.eps)
            axes.append(np.asarray(zone.kernel, dtype=float))
            lo.append(d_lo)
            hi.append(d_hi)
        self._axes = np.ascontiguousarray(axes)
        self._d_lo = np.asarray(lo)
        self._d_hi = np.asarray(hi)

    # -- the paper's scalar functions -------------------------------------------------------------
    def beta(self, x) -> float:
        """beta(x): h_i(d_s(x, g_i)) in the eps-layer of cone i, 1 outside (eq. obstacle-function-defnition)."""
        x = _check_state(x, self.dim)
        p = 1.0 - self._axes @ x
        inside = p < self._d_hi
        if not np.any(inside):
            return 1.0
        s = np.where(inside, (p - self._d_lo) / (self._d_hi - self._d_lo), np.inf)
        i = int(np.argmin(s))
        h, _ = cubic_h(max(p[i], self._d_lo[i]), self._d_lo[i], self._d_hi[i])
        return float(h)

    def potential(self, x) -> float:
        """W(x) = k1 d/(d + beta) (eq. navigation_function_on_sphere), in [0, k1] on M_0."""
        x = _check_state(x, self.dim)
        d = 0.5 * float(np.sum((x - self.target) ** 2))
        return self.k1 * d / (d + self.beta(x))

    # -- law evaluation ---------------------------------------------------------------------------
    def control(self, x) -> np.ndarray:
        """u(x), shape (n+1,)."""
        x = _check_state(x, self.dim)
        out = np.empty(self.dim)
        _gradient_u_kernel(x, self.target, self._axes, self._d_lo, self._d_hi, self.k1, out)
        return out

    def control_and_zone(self, x) -> tuple[np.ndarray, int | None]:
        x = _check_state(x, self.dim)
        out = np.empty(self.dim)
        i = _gradient_u_kernel(x, self.target, self._axes, self._d_lo, self._d_hi, self.k1, out)
        return out, (None if i < 0 else int(i))

    def control_batch(self, X) -> np.ndarray:
        """u for every row of X, shape (m, n+1) -> (m, n+1) (one compiled loop, no Python per row)."""
        X = _check_batch(X, self.dim)
        out = np.empty_like(X)
        active = np.empty(X.shape[0], dtype=np.int64)
        _gradient_u_batch_kernel(X, self.target, self._axes, self._d_lo, self._d_hi, self.k1, out, active)
        return out



def _signed(zone, x) -> float:
    fn = getattr(zone, "signed_separation", None)
    return float(fn(x)) if fn is not None else float(zone.separation(x))


# ----------------------------------------------------------------------------------------------
# Star-shaped law (any zones)
# ----------------------------------------------------------------------------------------------


@njit(cache=True)
def _star_screen(x, cap_axes, cap_cos, flags):
    """-1 if x is not a unit vector; else the number of zones whose bounding cap is within eps (flags set)."""
    n2 = 0.0
    for k in range(x.shape[0]):
        n2 += x[k] * x[k]
    if not abs(n2 - 1.0) <= 2.0 * _UNIT_TOL:
        return -1
    count = 0
    for i in range(cap_axes.shape[0]):
        c = 0.0
        for k in range(x.shape[0]):
            c += x[k] * cap_axes[i, k]
        if c >= cap_cos[i]:
            flags[i] = 1
            count += 1
        else:
            flags[i] = 0
    return count


# Compiled eagerly (explicit signature): it first runs when a state enters an eps-layer, which in flight
# is mid-slew; a lazy compile there cost one 0.1 s GNC cycle (a slip) on a machine without numba's cache.
@njit("float64[:](float64[:], float64[:], float64)", cache=True)
def _blend(p, q, a):
    """a p - (1 - a) q, one compiled call (cheaper than four numpy temporaries on 4-vectors)."""
    out = np.empty(p.shape[0])
    b = 1.0 - a
    for k in range(p.shape[0]):
        out[k] = a * p[k] - b * q[k]
    return out


class StarShapedLaw(_SphereLaw):
    """The paper's law for star-shaped zones (eq. n-sphere-control-law).

    target: x_d; zones: any gnc zones (``kernel`` g_i must be in sigma(U_i) and interior, g_i != -x_d:
    see :func:`gnc.checks.check_assumptions`); k1 > 0; kappa > 0 scales the repulsion down (kappa must
    exceed the paper's kappa_bar, else a stable undesired equilibrium can exist); eps in d_s units.
    """

    def __init__(self, target, zones, k1: float = 1.0, kappa: float = 1.0, eps: float = 0.1):
        self.target = _unit_vector(target, "target")
        self.dim = self.target.shape[0]
        self.zones = _zone_list(zones, self.dim)
        self.k1 = _positive(k1, "k1")
        self.kappa = _positive(kappa, "kappa")
        self.eps = _positive(eps, "eps")
        if self.eps >= 2.0:
            raise ValueError(f"eps must be < 2 (the largest separation on the sphere), got {self.eps}")
        self._kernels = np.ascontiguousarray([np.asarray(z.kernel, dtype=float) for z in self.zones])
        self._cap_axes, self._cap_cos = _cap_skip_cosines(self.zones, self.eps, self.dim)
        self._separations = [zone.separation for zone in self.zones]  # bound methods, looked up once
        self._flags = np.empty(len(self.zones), dtype=np.uint8)
        self._k1_target = self.k1 * self.target
        self._k1_kernels_over_kappa = [np.ascontiguousarray((self.k1 / self.kappa) * g) for g in self._kernels]

    def _nearest_layer(self, x: np.ndarray) -> tuple[int, float]:
        """(index, d_s(x, U_i)) of the nearest zone whose eps-layer holds x, or (-1, inf).

        x must already be a float64 array of the right shape; the unit-norm check happens here, fused
        with the bounding-cap screen in one compiled call (per-call overhead matters at ~10 us budgets).
        """
        flags = self._flags  # scratch, reused: a law instance is not meant to be shared between threads
        status = _star_screen(x, self._cap_axes, self._cap_cos, flags)
        if status < 0:
            raise ValueError(f"state x must be a unit vector on S^{self.dim - 1}, |x|^2 = {float(x @ x)!r}")
        best_i, best_d = -1, np.inf
        if status > 0:
            for i in range(len(self._separations)):
                if flags[i]:
                    d = self._separations[i](x)
                    if d < best_d:
                        best_i, best_d = i, d
        if best_d > self.eps:
            return -1, np.inf
        return best_i, float(best_d)

    def _u(self, i: int, d: float) -> np.ndarray:
        if i < 0:
            return self._k1_target.copy()
        # k1 [(d/eps) x_d - (1/kappa)(1 - d/eps) g_i] with k1 and k1/kappa folded into the vectors
        return _blend(self._k1_target, self._k1_kernels_over_kappa[i], d / self.eps)

    def control(self, x) -> np.ndarray:
        """u(x), shape (n+1,)."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.dim,):
            raise ValueError(f"state x must have shape ({self.dim},), got {x.shape}")
        return self._u(*self._nearest_layer(x))

    def control_and_zone(self, x) -> tuple[np.ndarray, int | None]:
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.dim,):
            raise ValueError(f"state x must have shape ({self.dim},), got {x.shape}")
        i, d = self._nearest_layer(x)  # checks |x| = 1 (as `_check_state` does) in its compiled screen
        return self._u(i, d), (None if i < 0 else i)

    def layer_separations(self, X) -> tuple[np.ndarray, np.ndarray]:
        """(active index per row, -1 outside every layer; d_s to that zone, inf outside) for a batch."""
        X = _check_batch(X, self.dim)
        m = X.shape[0]
        best_d = np.full(m, np.inf)
        best_i = np.full(m, -1, dtype=np.int64)
        near = X @ self._cap_axes.T >= self._cap_cos  # (m, zones): cap within eps
        for i, zone in enumerate(self.zones):
            rows = np.flatnonzero(near[:, i])
            if rows.size == 0:
                continue
            d = np.asarray(zone.separation_batch(X[rows]), dtype=float)
            better = d < best_d[rows]
            best_d[rows[better]] = d[better]
            best_i[rows[better]] = i
        outside = best_d > self.eps
        best_i[outside] = -1
        best_d[outside] = np.inf
        return best_i, best_d

    def control_batch(self, X) -> np.ndarray:
        """u for every row of X, shape (m, n+1); zones evaluated with their vectorised separation_batch."""
        X = _check_batch(X, self.dim)
        idx, d = self.layer_separations(X)
        active = idx >= 0
        a = np.where(active, d / self.eps, 1.0)
        g = self._kernels[np.where(active, idx, 0)]
        rep = np.where(active, (1.0 - a) / self.kappa, 0.0)
        return self.k1 * (a[:, None] * self.target[None, :] - rep[:, None] * g)

