"""Magnetic momentum management: the wheels' stored momentum dumped through the magnetorquer rods.

`MomentumManager(config, G, Js)`, one ``step(mag_S_T, wheel_speed_rad_s)`` per GNC cycle after the rate loop:

* ``h_w = G (Js * Omega)``: the wheels' spin momentum in body axes [N m s] from the last known wheel speeds
  (the rate loop's, which keep a wheel's last report when it misses one);
* ``h_excess = h_w - bias``; the field in body axes from the magnetometer, ``b_B = R(q_BS) b_S``;
* the body dipole of the cross-product law (`gnc.magnetic.unloading_dipole`), mapped onto the rods by least
  squares over their axes and scaled down as a whole until every rod is within its limit (one compiled
  kernel, fsw._momentum_nb: numpy's per-call overhead on 3-vectors cost more than the law).

The attitude loop is left alone: it keeps pointing, so the field's torque ``m x B`` shows in the body as a
disturbance the rate loop rejects, and the wheels' momentum drains. No feed-forward of ``m x B`` to the wheels
(the rods' torque is micro-newton-metres, well inside what the rate loop absorbs, and a feed-forward built
on a measured field would be one more path into the wheel commands that the keep-out guard does not see).

No field this cycle (NaN): the last command is held for one cycle (a single lost MAG_FIELD does not chop
the dipole), then zero until the field is back.
"""
from __future__ import annotations

import numpy as np

from fsw._momentum_nb import unloading_step_nb
from gnc.attitude import quat_to_dcm


class MomentumManager:
    """The unloading stage. ``config``: `fsw.config.MomentumManagementConfig`; ``G`` (3 x n) the wheel axes
    in body axes as columns, ``Js`` (n) their spin inertias [kg m^2]."""

    HOLD_CYCLES = 1  # cycles the last command outlives a missing field

    def __init__(self, config, G: np.ndarray, Js: np.ndarray) -> None:
        self.gain_1_s = float(config.gain_1_s)
        self.bias_B_Nms = np.array(config.wheel_momentum_bias_Nms, dtype=float)
        self.max_Am2 = np.array(config.max_dipole_Am2, dtype=float)
        self.R_BS = quat_to_dcm(np.array(config.magnetometer_q_BS, dtype=float))
        # body dipole = A d for rod dipoles d; the least-squares inverse maps a body dipole onto the rods
        self.rods_pinv = np.linalg.pinv(np.array(config.rod_axes_B, dtype=float).T)
        self.G = np.array(G, dtype=float)
        self.Js = np.array(Js, dtype=float)
        self.command_Am2 = np.zeros(3)
        self.h_excess_norm_Nms = 0.0
        self._missed = 0

    def wheel_momentum_B(self, wheel_speed_rad_s: np.ndarray) -> np.ndarray:
        """The wheels' spin momentum in body axes [N m s]."""
        return self.G @ (self.Js * np.asarray(wheel_speed_rad_s, dtype=float))

    def step(self, mag_S_T: np.ndarray, wheel_speed_rad_s: np.ndarray) -> np.ndarray:
        """This cycle's rod dipoles [A m^2] (rod order), also kept in ``command_Am2``.

        `gnc.magnetic.unloading_dipole` (no body limit) then `saturate_dipole` of its least-squares mapping
        onto the rods, compiled as one kernel (fsw._momentum_nb)."""
        command = np.empty(self.rods_pinv.shape[0])
        norm, finite = unloading_step_nb(self.G, self.Js, np.asarray(wheel_speed_rad_s, dtype=float),
                                         self.bias_B_Nms, self.R_BS, np.asarray(mag_S_T, dtype=float),
                                         self.gain_1_s, self.rods_pinv, self.max_Am2, command)
        self.h_excess_norm_Nms = norm
        if not finite:
            self._missed += 1
            if self._missed > self.HOLD_CYCLES:
                self.command_Am2 = np.zeros(3)
            return self.command_Am2
        self._missed = 0
        self.command_Am2 = command
        return command
