"""Reaction-wheel authority: what a set of wheels can give the body, about its worst axis.

Allocation is minimum norm (``tau_w = W^+ v``) scaled down as a whole until every wheel is within its limit
(`fsw.control.allocate_min_norm`), so along a unit direction d the reachable magnitude is
``min_i limit_i / |(W^+ d)_i|``. The same formula gives torque (limits = motor torques [N m]) and
momentum (limits = wheel momentum headroom [N m s]). Pure functions: the flight software recomputes its
slew limits with them when a wheel is isolated; the load-time checks use them on the mission.
"""
from __future__ import annotations

import numpy as np

from gnc._zone_radial import _fibonacci_sphere

_DIRECTIONS = 500  # ~5 deg apart: the worst axis to within a few per cent

def fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` nearly uniform unit vectors, shape (count, 3)."""
    return _fibonacci_sphere(count)

def wheel_authority(axes_B: np.ndarray, limits: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Largest magnitude along each unit direction (rows of ``directions``) that minimum-norm allocation
    on wheels with spin axes ``axes_B`` (n, 3) and per-wheel ``limits`` (n,) can produce."""
    W = np.asarray(axes_B, dtype=float).T  # 3 x n
    per_unit = np.abs(directions @ np.linalg.pinv(W).T)  # (m, n): |W^+ d| per wheel
    with np.errstate(divide="ignore"):
        return np.min(np.where(per_unit > 1e-12, np.asarray(limits, dtype=float)[None, :] / per_unit, np.inf), axis=1)

def worst_axis_authority(J_B_kgm2: np.ndarray, axes_B: np.ndarray, max_torque_Nm: np.ndarray,
                         momentum_Nms: np.ndarray, count: int = _DIRECTIONS) -> tuple[float, float]:
    """(angular acceleration [rad/s^2], body rate [rad/s]) the wheels can give about the worst body axis.

    A body acceleration ``alpha d`` needs the torque ``J d alpha``, a rate ``omega d`` the momentum
    ``J d omega`` (gyroscopic terms are small at slew rates). Wheels that do not span 3-D give (0, 0).
    """
    axes = np.asarray(axes_B, dtype=float)
    if axes.shape[0] < 3 or np.linalg.matrix_rank(axes, tol=1e-6) < 3:
        return 0.0, 0.0
    d = fibonacci_sphere(count)
    Jd = d @ np.asarray(J_B_kgm2, dtype=float).T
    size = np.linalg.norm(Jd, axis=1)
    accel = wheel_authority(axes, max_torque_Nm, Jd / size[:, None]) / size
    rate = wheel_authority(axes, momentum_Nms, Jd / size[:, None]) / size
    return float(np.min(accel)), float(np.min(rate))

__all__ = ["fibonacci_sphere", "wheel_authority", "worst_axis_authority"]
