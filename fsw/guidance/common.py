"""What every guidance mode shares: the per-cycle output record (`fsw.records.GuidanceOutput`), the
rate-command scaling, the law constructors and small vector helpers.

Rate command scaling. ``omega_law`` is multiplied by ``min(1, omega_max / |omega_law|)``: a positive,
state-dependent time scaling. It changes the speed along the kinematic closed-loop path but not the path
itself, so the paper's safety and convergence results carry over to the scaled command.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.records import NAN3 as _NAN3, NAN4 as _NAN4, GuidanceOutput  # noqa: F401 - the guidance modes import them from here

_BODY_CODES = {"sun": "SUN", "moon": "MOON", "earth": "EARTH", "inertial": "INERTIAL"}


def _norm(v: np.ndarray) -> float:
    # np.linalg.norm of a real 1-D array is sqrt(v.dot(v)): the same number, without its ~3 us of checks
    return math.sqrt(v.dot(v))


def unit_vector(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to length one (a 3-vector of the guidance: never zero there)."""
    return v / _norm(v)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle [deg] between unit 3-vectors ``a`` and ``b``."""
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])))))


def d_s_to_deg(d_s: float) -> float:
    """Spherical separation d_s = 1 - cos(angle) -> angle in degrees, sign kept (negative inside)."""
    mag = math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - abs(d_s)))))
    return mag if d_s >= 0 else -mag


def signed_margin_deg(zone, x: np.ndarray) -> float:
    """Signed angular distance [deg] from the zone boundary (negative inside)."""
    return d_s_to_deg(float(zone.signed_separation(x)))


def _saturate(omega: np.ndarray, max_rate_rad_s: float) -> np.ndarray:
    n = _norm(np.asarray(omega, dtype=float))
    return omega * (max_rate_rad_s / n) if n > max_rate_rad_s else omega


def _make_star_law(target, zones, k1, kappa, eps):
    from gnc.laws import StarShapedLaw

    return StarShapedLaw(target, zones, k1=k1, kappa=kappa, eps=eps)


def _make_gradient_law(target, zones, k1, eps):
    from gnc.laws import GradientLaw

    return GradientLaw(target, zones, k1=k1, eps=eps)
