"""An example keepout plug-in package: two guidance laws and an estimator (see README.md).

Each entry point names a factory called with the flight software's configuration (`fsw.config.FswConfig`);
the classes below take it as their one constructor argument.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.plugins import AttitudeEstimate, EstimatorInput, GuidanceInput


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product, scalar first."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return np.array([a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
                     a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
                     a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
                     a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0])


def _conj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _dcm_NB(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of q_NB (body vectors into N)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _geodesic_rate_B(q_NB: np.ndarray, boresight_B: np.ndarray, aim_N: np.ndarray, gain: float) -> np.ndarray:
    """Body rate turning the boresight towards ``aim_N`` along their great circle at ``gain`` times the angle."""
    R = _dcm_NB(q_NB)
    y = R @ boresight_B
    axis = np.cross(y, aim_N)
    s = float(np.linalg.norm(axis))
    angle = math.atan2(s, float(y @ aim_N))
    if s < 1e-12:
        return np.zeros(3)
    return R.T @ (gain * angle * axis / s)


class GeodesicGuidance:
    """Proportional geodesic guidance: the rate is ``gain`` times the remaining angle, about the axis of the
    great circle (POINTING) or of the shortest rotation (QUATERNION) to the target. Not keepout's law: it
    knows nothing of the zones."""

    def __init__(self, cfg) -> None:
        self.gain = 0.5 * cfg.law.k1

    def command(self, state: GuidanceInput) -> np.ndarray:
        if state.mode == "POINTING":
            return _geodesic_rate_B(state.q_NB, state.boresight_B, state.target_N, self.gain)
        err = _qmul(_conj(state.q_NB), state.q_target_NB)  # body rotation from now to the target
        if err[0] < 0.0:
            err = -err
        return 2.0 * self.gain * err[1:]


class SunSeekingGuidance:
    """A deliberately unsafe law: it turns the instrument boresight to the Sun, whatever the target."""

    def __init__(self, cfg) -> None:
        self.gain = cfg.law.k1

    def command(self, state: GuidanceInput) -> np.ndarray:
        return _geodesic_rate_B(state.q_NB, state.boresight_B, state.sun_N, self.gain)


class StarGyroEstimator:
    """The star tracker's attitude when a fix arrives, the gyro integrated between fixes; no bias estimate."""

    def __init__(self, cfg) -> None:
        self.reset()

    def reset(self) -> None:
        self.q_NB: np.ndarray | None = None
        self.omega_B = np.zeros(3)

    def update(self, sample: EstimatorInput) -> AttitudeEstimate:
        gyro = sample.gyro_B
        if len(gyro):
            self.omega_B = gyro.mean(axis=0)
            if self.q_NB is not None:
                self.q_NB = self._propagate(self.q_NB, self.omega_B * sample.dt_s)
        if sample.q_NS is not None:
            q = _qmul(sample.q_NS, _conj(sample.q_BS))  # q_NB = q_NS (x) q_SB
            # the fix is star_tracker_latency_s old: carry it forward to now with the rate
            self.q_NB = self._propagate(q, self.omega_B * sample.star_tracker_latency_s)
        return AttitudeEstimate(None if self.q_NB is None else self.q_NB.copy(), self.omega_B.copy())

    @staticmethod
    def _propagate(q: np.ndarray, rotation_B: np.ndarray) -> np.ndarray:
        angle = float(np.linalg.norm(rotation_B))
        if angle == 0.0:
            return q
        dq = np.concatenate(([math.cos(angle / 2)], math.sin(angle / 2) * rotation_B / angle))
        q = _qmul(q, dq)
        return q / np.linalg.norm(q)
