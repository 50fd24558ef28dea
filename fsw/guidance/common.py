"""What every guidance mode shares: the per-cycle output record, the rate-command scaling, the law
constructors and small vector helpers.

Rate command scaling. ``omega_law`` is multiplied by ``min(1, omega_max / |omega_law|)``: a positive,
state-dependent time scaling. It changes the speed along the kinematic closed-loop path but not the path
itself, so the paper's safety and convergence results carry over to the scaled command.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

_BODY_CODES = {"sun": "SUN", "moon": "MOON", "earth": "EARTH", "inertial": "INERTIAL"}


def _norm(v: np.ndarray) -> float:
    # np.linalg.norm of a real 1-D array is sqrt(v.dot(v)): the same number, without its ~3 us of checks
    return math.sqrt(v.dot(v))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / _norm(v)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])))))


def d_s_to_deg(d_s: float) -> float:
    """Spherical separation d_s = 1 - cos(angle) -> angle in degrees, sign kept (negative inside)."""
    mag = math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - abs(d_s)))))
    return mag if d_s >= 0 else -mag


def signed_margin_deg(zone, x: np.ndarray) -> float:
    """Signed angular distance [deg] from the zone boundary (negative inside)."""
    return d_s_to_deg(float(zone.signed_separation(x)))



def _nan_constant(n: int) -> np.ndarray:
    a = np.full(n, np.nan)
    a.flags.writeable = False  # shared by every output that has no such vector: nobody may write into it
    return a


_NAN3, _NAN4 = _nan_constant(3), _nan_constant(4)


@dataclass
class GuidanceOutput:
    omega_cmd_BN_B: np.ndarray
    mode: str
    safe_phase: str = "NONE"
    active_zone: int = -1
    eps: float = float("nan")
    eps_max: float = float("nan")
    margins_deg: list[float] = field(default_factory=list)
    margin_min_deg: float = float("nan")
    pointing_error_deg: float = float("nan")
    att_error_deg: float = float("nan")
    roll_error_deg: float = float("nan")
    boresight_N: np.ndarray = field(default_factory=lambda: _NAN3)
    target_N: np.ndarray = field(default_factory=lambda: _NAN3)
    q_target_NB: np.ndarray = field(default_factory=lambda: _NAN4)
    zones_merged: bool = False
    assumptions_ok: bool = True
    sun_N: np.ndarray = field(default_factory=lambda: _NAN3)
    moon_N: np.ndarray = field(default_factory=lambda: _NAN3)
    zone_count: int = 0
    zone_bodies: list[str] = field(default_factory=list)


def _saturate(omega: np.ndarray, max_rate_rad_s: float) -> np.ndarray:
    n = _norm(np.asarray(omega, dtype=float))
    return omega * (max_rate_rad_s / n) if n > max_rate_rad_s else omega


def _make_star_law(target, zones, k1, kappa, eps):
    from gnc.laws import StarShapedLaw

    return StarShapedLaw(target, zones, k1=k1, kappa=kappa, eps=eps)


def _make_gradient_law(target, zones, k1, eps):
    from gnc.laws import GradientLaw

    return GradientLaw(target, zones, k1=k1, eps=eps)
