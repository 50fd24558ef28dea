"""SAFE mode and the no-fix acquisition rotation.

SAFE: rate damping (omega_cmd = 0) until the rate stays below a threshold for 1 s, then the configured
body axis is turned to the Sun (the S^2 map of POINTING without zones). Without an attitude fix the
guidance damps the rate, then turns about the instrument boresight so the star tracker sweeps out of
its exclusion cones without moving the instrument.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.guidance.common import _BODY_CODES, GuidanceOutput, _norm, _saturate
from gnc.attitude import pointing_rate_command_nb, quat_to_dcm_nb


def _acquisition_rate_B(cfg, boresight_B: np.ndarray) -> np.ndarray:
    """Body rate [rad/s] that sweeps the star tracker out of any exclusion cone without moving the instrument.

    About the instrument boresight the tracker's boresight traces a circle; when the two are (nearly)
    parallel that circle degenerates, so rotate about the body axis most perpendicular to the tracker instead.
    """
    from gnc.attitude import quat_rotate

    st_B = quat_rotate(np.asarray(cfg.spacecraft.star_tracker_q_BS, dtype=float), np.array([0.0, 0.0, 1.0]))
    axis = np.asarray(boresight_B, dtype=float)
    if abs(float(axis @ st_B)) > math.cos(math.radians(60.0)):
        axis = np.eye(3)[int(np.argmin(np.abs(st_B)))]
        axis = axis - (axis @ st_B) * st_B
    return math.radians(cfg.estimator.acquisition_rate_deg_s) * axis / _norm(axis)


class SafeGuidance:
    """Mixin of `fsw.guidance.Guidance`: SAFE mode."""

    def _safe(self, t_s: float, dt_s: float, q: np.ndarray, omega: np.ndarray) -> GuidanceOutput:
        sc = self.cfg.safe
        rate = float(np.linalg.norm(omega))
        dirs = self.ephem.directions(t_s)
        self._dirs = dirs
        sun = dirs["sun"]
        R = quat_to_dcm_nb(q)
        out = GuidanceOutput(np.zeros(3), "SAFE", sun_N=sun, moon_N=dirs["moon"], boresight_N=R @ self.b_B)
        if self.slots:
            self._update_sky(t_s)
            out.margins_deg, out.margin_min_deg = self._sky_margins(out.boresight_N)
            out.zone_count = len(self.slots)
            out.zone_bodies = [_BODY_CODES[s.body] for s in self.slots]
        if self.safe_phase == "RATE_DAMPING":
            self._damped_s = self._damped_s + dt_s if rate < math.radians(sc.damping_exit_rate_deg_s) else 0.0
            if self._damped_s >= 1.0:
                self._set_safe_phase("SUN_ACQUISITION")
            out.safe_phase = self.safe_phase
            return out
        s_N = R @ self.sun_axis_B
        err = math.degrees(math.acos(max(-1.0, min(1.0, float(s_N @ sun)))))
        if self.safe_phase == "SUN_ACQUISITION" and err < 1.0:
            self._set_safe_phase("SUN_POINTING")
        elif self.safe_phase == "SUN_POINTING" and err > 5.0:
            self._set_safe_phase("SUN_ACQUISITION")
        u = sc.sun_gain_1_s * sun
        omega_cmd = np.asarray(pointing_rate_command_nb(q, self.sun_axis_B, np.ascontiguousarray(u)))
        out.omega_cmd_BN_B = _saturate(omega_cmd, math.radians(sc.max_rate_deg_s))
        out.safe_phase = self.safe_phase
        out.pointing_error_deg = err
        out.target_N = sun
        return out

    def _set_safe_phase(self, phase: str) -> None:
        self.safe_phase = phase
        self.events("SAFE_PHASE_CHANGED", phase=phase)
