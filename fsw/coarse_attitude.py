"""The coarse attitude: the Sun sensors and the magnetometer hold the estimate while the star tracker is
lost, and find it when the star tracker has never given one.

Without star-tracker fixes the MEKF propagates on the gyro alone, and its attitude walks off with the
gyro's bias drift: 11 deg in 3.3 h with `config/missions/star-tracker-lost.yaml`'s gyro, enough to carry
the instrument into a zone the estimate says it is clear of. With ``flight_software.coarse_attitude`` the
estimator fuses, once the star tracker has given no fused fix for ``after_s``:

* the Sun direction the cells measure (`gnc.magnetic.css_sun_fix`) against the onboard Sun, which holds
  the two axes across the Sun line; in the Earth's shadow every cell is dark;
* with ``field_sigma_deg`` set, the magnetometer's field direction against the onboard IGRF model
  (`gnc.field_model`, to the truth's degree unless told otherwise), which holds the two axes across the field line, the rotation about the Sun line
  among them, in the shadow too. Samples taken while the rods drive are left out (the rods' own field
  on the magnetometer).

Each is the textbook MEKF vector update (Markley and Crassidis, Fundamentals of Spacecraft Attitude
Determination and Control, 2014, sec. 6.2.4) with the body-frame error of the estimator's own updates
(``q_true = q (x) dq(dtheta)``): ``H = [[b_pred x], 0]``, Joseph form, the variance across the line of
sight floored at the measurement's (`_floor_across`). Innovations larger than ``gate_deg`` or four
predicted sigmas are not fused and counted.

A flight software that has never had a star-tracker fix (blind from separation) has no attitude to hold:
after ``after_s`` with both a Sun direction and a field it takes the TRIAD attitude of the two (the more
accurate first), and the guidance's SAFE turns the Sun axis to the Sun through the keep-out law
as it does on the star tracker. The star tracker's first accepted fix takes over again.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from fsw.estimation import _rotvec_quat
from gnc.attitude import dcm_to_quat, quat_multiply_nb, quat_to_dcm, quat_to_dcm_nb, skew
from fsw.guidance.common import angle_deg, unit_vector
from gnc.field_model import FieldModel
from gnc.magnetic import css_sun_fix

_SECONDS_PER_DAY = 86400.0
MIN_TRIAD_ANGLE_DEG = 10.0  # the Sun and the field closer than this do not fix the rotation about them


def vector_update(q: np.ndarray, P: np.ndarray, meas_B: np.ndarray, ref_N: np.ndarray,
                  sigma_rad: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """One MEKF update with a measured unit direction in body axes and its unit reference in N. Returns the
    new (q, P), the innovation angle [deg] and the predicted 1-sigma of the innovation [deg].

    The gyro bias is a consider state (Schmidt): the update corrects the attitude and carries the bias's
    covariance (P's bias rows), but never moves the bias, which is why it is neither taken nor returned. A coarse direction's error is degrees and not white (the dark
    cells' bound as the body turns about the Sun line); fused at 10 Hz the filter read its changes as a
    bias and walked it to 370 deg/h (true 2 deg/h), which then turned the attitude 22 deg off about the
    field line in the next eclipse. The bias the star tracker last estimated (or zero, blind) is the better
    figure for as long as the coarse sensors fly."""
    b_pred = quat_to_dcm_nb(np.ascontiguousarray(q)).T @ ref_N
    H = np.zeros((3, 6))
    H[:, 0:3] = skew(b_pred)
    R = sigma_rad * sigma_rad * np.eye(3)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    K[3:6, :] = 0.0  # the bias considered, not estimated (Joseph's form below holds for any gain)
    dx = K @ (meas_B - b_pred)
    ikh = np.eye(6) - K @ H
    P_new = ikh @ P @ ikh.T + K @ R @ K.T
    P_new = 0.5 * (P_new + P_new.T)
    _floor_across(P_new, P, b_pred, sigma_rad)
    q_new = quat_multiply_nb(np.ascontiguousarray(q), _rotvec_quat(np.ascontiguousarray(dx[0:3])))
    q_new = q_new / np.linalg.norm(q_new)
    innov_deg = math.degrees(math.acos(max(-1.0, min(1.0, float(meas_B @ b_pred)))))
    sigma_deg = math.degrees(math.sqrt(max(0.0, float(np.trace(S)) / 2.0)))  # two axes across the line of sight
    return q_new, P_new, innov_deg, sigma_deg


def _floor_across(P: np.ndarray, P_prior: np.ndarray, b: np.ndarray, sigma_rad: float) -> None:
    """Hold the attitude variance across the line of sight ``b`` at least at ``sigma_rad**2``, or at the
    prior's where that was smaller (in place).

    The cells' error is mostly not white: the dark cells' bound and the cells' mounting give the same error
    for as long as the Sun stays where it is on the body, which in SAFE is hours; the field model's error in the
    field's direction changes only along the orbit. Fused at 10 Hz as if independent, the filter's variance
    fell to a hundredth of the true error (NEES mean 21 over a 3 h loss). The floor keeps the filter's
    claim at the measurement's own accuracy (Schmidt's consider idea in its simplest form): a coarse
    direction can bring a drifted estimate down to its own accuracy, never below, and an estimate already
    better than it (the star tracker's, just lost) keeps its variance, so it is barely moved. The variance
    added is positive semi-definite, so P stays a covariance."""
    e1 = np.cross(b, np.eye(3)[int(np.argmin(np.abs(b)))])
    e1 /= np.linalg.norm(e1)
    for e in (e1, np.cross(b, e1)):
        floor = min(sigma_rad * sigma_rad, float(e @ P_prior[0:3, 0:3] @ e))
        short = floor - float(e @ P[0:3, 0:3] @ e)
        if short > 0.0:
            P[0:3, 0:3] += short * np.outer(e, e)


def triad_q_NB(first_B: np.ndarray, first_N: np.ndarray, second_B: np.ndarray, second_N: np.ndarray) -> np.ndarray:
    """The attitude q_NB that puts ``first_B`` exactly on ``first_N`` and ``second_B`` in the plane of the two
    references (TRIAD; every vector a unit vector, the two pairs not parallel)."""
    def frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        t2 = unit_vector(np.cross(a, b))
        return np.column_stack((a, t2, np.cross(a, t2)))

    return dcm_to_quat(frame(first_N, second_N) @ frame(first_B, second_B).T)


class CoarseAttitude:
    """The coarse attitude of the Sun sensors and the magnetometer (see the module doc): `cycle` once per
    GNC cycle after the estimator's own update; events on entering and leaving."""

    def __init__(self, cfg: Any, event: Any, epoch_jd_utc: float) -> None:
        self.cfg = cfg
        self.event = event
        self.jd0 = epoch_jd_utc
        self.normals_B = np.asarray(cfg.normals_B, dtype=float)
        self.uses_field = cfg.field_sigma_deg is not None
        self.R_BS = quat_to_dcm(np.asarray(cfg.magnetometer_q_BS, dtype=float))
        self.field = FieldModel(cfg.geomagnetic_gauss_T) if self.uses_field else None
        self.active = False
        self.fused = 0  # directions fused since the star tracker was lost
        self.rejected = 0  # ... gated out

    def cycle(self, estimator: Any, css_mA: np.ndarray, mag_S_T: np.ndarray, rods_quiet: bool, t_s: float,
              ephem: Any) -> bool:
        """Fuse (or, never initialised, find) the attitude this cycle when the star tracker has been lost for
        ``after_s``. ``ephem``: the onboard `gnc.sky_ephemeris.SkyEphemeris` (asked only when a direction
        is fused). Returns whether the estimate was changed."""
        lost = not estimator.star_tracker_used and estimator.coasting_s >= self.cfg.after_s
        if lost != self.active:
            self._switch(lost, estimator.coasting_s)
        if not lost:
            return False
        pairs = self._directions(css_mA, mag_S_T, rods_quiet, t_s, ephem)
        if not estimator.initialized:
            return self._initialise(estimator, pairs)
        changed = False
        for meas_B, ref_N, sigma_deg in pairs:
            q, P, innov, sigma = vector_update(estimator.q_NB, estimator.P, meas_B, ref_N, math.radians(sigma_deg))
            if innov > max(self.cfg.gate_deg, 4.0 * sigma):
                self.rejected += 1
                continue
            estimator.q_NB = q
            estimator.P[:, :] = P
            self.fused += 1
            changed = True
        return changed

    def _directions(self, css_mA: np.ndarray, mag_S_T: np.ndarray, rods_quiet: bool, t_s: float,
                    ephem: Any) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """This cycle's (measured in B, reference in N, sigma [deg]): the Sun first, then the field."""
        out = []
        cfg = self.cfg
        sun_B = (css_sun_fix(self.normals_B, css_mA, cfg.full_scale_mA, cfg.lit_fraction)
                 if len(css_mA) == len(self.normals_B) else None)
        if sun_B is not None:
            out.append((sun_B, np.asarray(ephem.directions(t_s)["sun"], dtype=float), cfg.sun_sigma_deg))
        if self.uses_field and rods_quiet and np.all(np.isfinite(mag_S_T)) and np.any(mag_S_T):
            ref = self.field.field_N(ephem.position_N_km(t_s), self.jd0 + t_s / _SECONDS_PER_DAY)
            out.append((unit_vector(self.R_BS @ mag_S_T), unit_vector(ref), cfg.field_sigma_deg))
        return out

    def _initialise(self, estimator: Any, pairs: list[tuple[np.ndarray, np.ndarray, float]]) -> bool:
        """Never a star-tracker fix: the TRIAD attitude of the Sun and the field (the more accurate of the two
        exact, the other in its plane), when both are seen and far enough apart, with a covariance of their
        accuracy."""
        if len(pairs) < 2:
            return False
        (s_B, s_N, s_sig), (b_B, b_N, b_sig) = sorted(pairs, key=lambda p: p[2])  # the more accurate first
        if min(angle_deg(s_B, b_B), angle_deg(s_N, b_N)) < MIN_TRIAD_ANGLE_DEG:
            return False
        estimator.q_NB = triad_q_NB(s_B, s_N, b_B, b_N)
        att = math.radians(max(s_sig, b_sig)) * 2.0  # the rotation about the Sun line rests on the field alone
        bias = math.radians(estimator.cfg.initial_bias_sigma_deg_s)
        estimator.P[:, :] = np.diag([att * att] * 3 + [bias * bias] * 3)
        estimator.bias_B[:] = 0.0
        estimator.initialized = True
        self.event("COARSE_ATTITUDE_FOUND", sun_field_angle_deg=angle_deg(pairs[0][0], pairs[1][0]))
        return True

    def _switch(self, lost: bool, coasting_s: float) -> None:
        self.active = lost
        if lost:
            self.fused = self.rejected = 0
            self.event("COARSE_ATTITUDE_ON", coasting_s=coasting_s)
        else:
            self.event("COARSE_ATTITUDE_OFF", fused=self.fused, rejected=self.rejected)
