"""The attitude held on the coarse sun sensors while the star tracker is lost.

Without star-tracker fixes the MEKF propagates on the gyro alone, and its attitude walks off with the
gyro's bias drift: about 4 deg (1 sigma) in 3 h at a 1e-7 rad/s/sqrt(s) bias random walk, enough to carry
the instrument into a zone the estimate says it is clear of. With ``flight_software.sun_sensor_fix`` the
estimator fuses the Sun direction the cells measure (`gnc.magnetic.css_sun_fix`) once the star tracker has
given no fused fix for ``after_s``: a vector measurement ``b = A(q)^T s_N`` with the onboard Sun, which
holds the two axes across the Sun line (and the gyro bias about them) to the cells' accuracy. The rotation
about the Sun line stays on the gyro, and in the Earth's shadow every cell is dark and the whole attitude
coasts on it; the first sample out of the shadow brings the two axes back. The guidance keeps using the
estimate as it is, so SAFE's Sun acquisition and its keep-out guard go on through the loss; the star
tracker's first accepted fix takes over again.

The update is the textbook MEKF vector update (Markley and Crassidis, Fundamentals of Spacecraft Attitude
Determination and Control, 2014, sec. 6.2.4) with the body-frame error of the estimator's own updates
(``q_true = q (x) dq(dtheta)``): ``H = [[b_pred x], 0]``, Joseph form, the variance across the line of
sight floored at the measurement's (`_floor_across`). Innovations larger than ``gate_deg`` or four
predicted sigmas are not fused and counted.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from fsw.estimation import _rotvec_quat
from gnc.attitude import quat_multiply_nb, quat_to_dcm_nb
from gnc.magnetic import css_sun_fix


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def sun_vector_update(q: np.ndarray, bias: np.ndarray, P: np.ndarray, sun_meas_B: np.ndarray, sun_N: np.ndarray,
                      sigma_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """One MEKF update with a measured unit Sun direction in body axes. Returns the new (q, bias, P), the
    innovation angle [deg] and the predicted 1-sigma of the innovation [deg] (for the gate)."""
    b_pred = quat_to_dcm_nb(np.ascontiguousarray(q)).T @ sun_N
    H = np.zeros((3, 6))
    H[:, 0:3] = _skew(b_pred)
    R = sigma_rad * sigma_rad * np.eye(3)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    y = sun_meas_B - b_pred
    dx = K @ y
    ikh = np.eye(6) - K @ H
    P_new = ikh @ P @ ikh.T + K @ R @ K.T
    P_new = 0.5 * (P_new + P_new.T)
    _floor_across(P_new, b_pred, sigma_rad)
    q_new = quat_multiply_nb(np.ascontiguousarray(q), _rotvec_quat(np.ascontiguousarray(dx[0:3])))
    q_new = q_new / np.linalg.norm(q_new)
    innov_deg = math.degrees(math.acos(max(-1.0, min(1.0, float(sun_meas_B @ b_pred)))))
    sigma_deg = math.degrees(math.sqrt(max(0.0, float(np.trace(S)) / 2.0)))  # two axes across the line of sight
    return q_new, bias + dx[3:6], P_new, innov_deg, sigma_deg


def _floor_across(P: np.ndarray, b: np.ndarray, sigma_rad: float) -> None:
    """Hold the attitude variance across the line of sight ``b`` at least ``sigma_rad**2`` (in place).

    The cells' error is mostly not white: the dark cells' bound and the cells' mounting give the same error
    for as long as the Sun stays where it is on the body, which in SAFE is hours. Fused at 10 Hz as if
    independent, the filter's variance fell to a hundredth of the true error (NEES mean 21 over a
    3 h loss). The floor keeps the filter's claim at the measurement's own accuracy (Schmidt's consider
    idea in its simplest form); the variance added is positive semi-definite, so P stays a covariance."""
    e1 = np.cross(b, np.eye(3)[int(np.argmin(np.abs(b)))])
    e1 /= np.linalg.norm(e1)
    for e in (e1, np.cross(b, e1)):
        short = sigma_rad * sigma_rad - float(e @ P[0:3, 0:3] @ e)
        if short > 0.0:
            P[0:3, 0:3] += short * np.outer(e, e)


class SunSensorFix:
    """The estimator's Sun fix from the coarse sun sensors while the star tracker is lost (see module doc).
    `cycle` once per GNC cycle after the estimator's own update; events on entering and leaving."""

    def __init__(self, cfg: Any, event: Any) -> None:
        self.cfg = cfg
        self.event = event
        self.normals_B = np.asarray(cfg.normals_B, dtype=float)
        self.active = False
        self.fused = 0  # Sun directions fused since the star tracker was lost
        self.rejected = 0  # ... gated out
        self.dark = 0  # cycles with the fix on and no Sun direction (the Earth's shadow, or too few cells)

    def cycle(self, estimator: Any, css_mA: np.ndarray, sun_N_of: Any) -> bool:
        """Fuse this cycle's Sun direction when the star tracker has been lost for ``after_s``.
        ``sun_N_of``: a callable giving the onboard Sun direction (only called when a fix is fused).
        Returns whether the estimate was changed."""
        lost = estimator.initialized and not estimator.star_tracker_used and estimator.coasting_s >= self.cfg.after_s
        if lost != self.active:
            self._switch(lost, estimator.coasting_s)
        if not lost:
            return False
        sun_B = css_sun_fix(self.normals_B, css_mA, self.cfg.full_scale_mA, self.cfg.lit_fraction) \
            if len(css_mA) == len(self.normals_B) else None
        if sun_B is None:
            self.dark += 1
            return False
        q, bias, P, innov, sigma = sun_vector_update(estimator.q_NB, estimator.bias_B, estimator.P, sun_B,
                                                     np.asarray(sun_N_of(), dtype=float),
                                                     math.radians(self.cfg.sigma_deg))
        if innov > max(self.cfg.gate_deg, 4.0 * sigma):
            self.rejected += 1
            return False
        estimator.q_NB = q
        estimator.bias_B[:] = bias
        estimator.P[:, :] = P
        self.fused += 1
        return True

    def _switch(self, lost: bool, coasting_s: float) -> None:
        self.active = lost
        if lost:
            self.fused = self.rejected = self.dark = 0
            self.event("SUN_SENSOR_FIX_ON", coasting_s=coasting_s)
        else:
            self.event("SUN_SENSOR_FIX_OFF", fused=self.fused, rejected=self.rejected)
