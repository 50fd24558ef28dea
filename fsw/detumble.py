"""DETUMBLE: B-dot on the magnetometer after separation, until the body rate is low enough for the wheels.

`Detumbler(config, period_s)`, one ``step(mag_S_T, omega_BN_B, dt_s)`` per GNC cycle while the mode is DETUMBLE:

* the field in body axes from the magnetometer, ``b_B = R(q_BS) b_S``; its rate of change is the difference
  of two samples over the cycle, through a first-order low-pass filter of time constant ``tau``
  (``d <- d + a (raw - d)``, ``a = dt / (tau + dt)``): the magnetometer's noise differentiated at 10 Hz is
  larger than the field rate of a slow tumble, the filter is what a flight B-dot carries;
* the dipole ``m = -k dB/dt`` (`gnc.magnetic.bdot_dipole`), mapped onto the rods by least squares over their
  axes and scaled down as a whole until every rod is within its limit (the direction, and so the sign that
  removes rotational energy, is kept);
* the rate test on the gyro: ``|omega| < rate_threshold`` on every sample over ``dwell_s`` (from the first
  sample below to the latest); one sample at or above it restarts the count. ``complete`` is then true and
  stays so until `reset`.

No field this cycle (NaN): the rods get zero and the filter forgets the last sample (a difference across a
gap would be a step, not a rate). The wheels are not this stage's: the flight software holds them at zero
torque while the mode is DETUMBLE.
"""
from __future__ import annotations

import math

import numpy as np

from gnc.attitude import quat_to_dcm
from gnc.magnetic import bdot_dipole, saturate_dipole

_NO_BODY_LIMIT = np.full(3, np.inf)  # the rods' limits apply after the mapping onto them


class Detumbler:
    """The B-dot stage and its completion test. ``config``: `fsw.config.DetumbleConfig`."""

    def __init__(self, config, period_s: float) -> None:
        self.gain_Am2_s_T = float(config.gain_Am2_s_T)
        self.tau_s = float(config.filter_time_constant_s)
        self.threshold_rad_s = math.radians(config.rate_threshold_deg_s)
        self.dwell_s = float(config.dwell_s)
        self.max_Am2 = np.array(config.max_dipole_Am2, dtype=float)
        self.R_BS = quat_to_dcm(np.array(config.magnetometer_q_BS, dtype=float))
        self.rods_pinv = np.linalg.pinv(np.array(config.rod_axes_B, dtype=float).T)
        self.period_s = float(period_s)
        self.reset()

    def reset(self) -> None:
        """A new detumble: no field seen, no rate counted."""
        self.command_Am2 = np.zeros(3)
        self.b_dot_B_T_s = np.zeros(3)
        self._b_prev: np.ndarray | None = None
        self._filled = False
        self.below_s = 0.0
        self._below = False
        self.complete = False

    def field_rate(self, b_B_T: np.ndarray, dt_s: float) -> np.ndarray | None:
        """The filtered field rate [T/s] in body axes after this sample, None until two samples are known."""
        prev, self._b_prev = self._b_prev, b_B_T
        if prev is None or not dt_s > 0.0:
            return None
        raw = (b_B_T - prev) / dt_s
        if not self._filled:  # the first difference starts the filter (no pull from zero)
            self.b_dot_B_T_s, self._filled = raw, True
        else:
            self.b_dot_B_T_s = self.b_dot_B_T_s + dt_s / (self.tau_s + dt_s) * (raw - self.b_dot_B_T_s)
        return self.b_dot_B_T_s

    def step(self, mag_S_T: np.ndarray, omega_BN_B: np.ndarray, dt_s: float) -> np.ndarray:
        """This cycle's rod dipoles [A m^2] (rod order), also kept in ``command_Am2``; updates ``complete``."""
        dt = float(dt_s) if dt_s > 0.0 else self.period_s
        b_S = np.asarray(mag_S_T, dtype=float)
        if np.all(np.isfinite(b_S)):
            rate = self.field_rate(self.R_BS @ b_S, dt)
        else:
            self._b_prev, self._filled, rate = None, False, None
        if rate is None:
            self.command_Am2 = np.zeros(3)
        else:
            m_B = bdot_dipole(rate, self.gain_Am2_s_T, _NO_BODY_LIMIT)
            self.command_Am2 = saturate_dipole(self.rods_pinv @ m_B, self.max_Am2)
        w = np.asarray(omega_BN_B, dtype=float)
        below = bool(np.all(np.isfinite(w))) and float(np.linalg.norm(w)) < self.threshold_rad_s
        # the time since the first of an unbroken run of samples below the threshold
        self.below_s = (self.below_s + dt if self._below else 0.0) if below else 0.0
        self._below = below
        self.complete = self.complete or (below and self.below_s >= self.dwell_s - 1e-9)
        return self.command_Am2
