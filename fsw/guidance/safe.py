"""SAFE mode and the no-fix acquisition rotation.

SAFE: rate damping (omega_cmd = 0) until the rate stays below a threshold for 1 s, then the configured
body axis is turned to the Sun. SAFE keeps the instrument out of the zones like every other mode: with
zones configured, the Sun-safe attitude is reached by the POINTING machinery itself (the paper's law on
the inflated zones, path planning, the rate governor), aimed at the boresight direction of a Sun-safe
attitude, with the roll law turning the Sun axis onto the Sun. That direction lies on the cone of
boresights for which ``sun_axis_B`` can face the Sun (half-angle = angle between the two body axes), the
point of it nearest the boresight and clear of every zone by the retreat standoff; if the whole cone is
blocked, the nearest clear direction (`ZoneGeometry.retreat_target`), and the Sun axis gets as near the
Sun as that allows. With forbidden-attitude zones instead (a QUATERNION mission), the Sun-safe attitude is
reached by the QUATERNION machinery (the paper's law on S^3 with the zones, the attitude path planner, the
governor) at SAFE's rate: the attitude that puts ``sun_axis_B`` on the Sun, turned about the Sun line to
the one nearest the attitude that is clear of every zone by the retreat standoff; if every such attitude is
blocked, the nearest clear attitude (`_nearest_clear_attitude`). Without zones, the Sun axis is turned
straight to the Sun (S^2 map, no law).

Without an attitude fix the guidance damps the rate, then turns about the instrument boresight so the
star tracker sweeps out of its exclusion cones without moving the instrument.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.guidance.common import GuidanceOutput, angle_deg, _norm, _saturate
from fsw.guidance.zone_merging import ZoneGeometry
from gnc.attitude import pointing_rate_command_nb, quat_from_axis_angle, quat_multiply, quat_to_dcm_nb
from gnc.zones import _fibonacci_directions, default_tangent_basis


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


def _nearest_clear_attitude(center: np.ndarray, zones: list, d_free: float, near: np.ndarray) -> np.ndarray:
    """The attitude nearest ``center`` whose separation from every zone exceeds ``d_free``: shells of 1 deg
    around it on S^3, on the first with a clear point the one nearest ``near``; ``center`` if none is."""
    basis = default_tangent_basis(center)
    dirs = _fibonacci_directions(SHELL_DIRECTIONS, 3) @ basis.T
    for r in np.radians(np.arange(1.0, 180.0, 1.0)):
        shell = math.cos(r) * center + math.sin(r) * dirs
        free = np.min([z.separation_batch(shell) for z in zones], axis=0) > d_free
        if free.any():
            cand = shell[free]
            return cand[int(np.argmax(cand @ near))]
    return center


SHELL_DIRECTIONS = 64


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
            out.zone_bodies = self._slot_body_codes()
        elif self.s3_law_zones:
            self._attitude_margins(out, self._lift(q))
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
        if self.slots:
            out = self._sun_safe_keepout(t_s, q, omega, sun, out.boresight_N)
        elif self.s3_law_zones:
            out = self._sun_safe_attitude_keepout(t_s, q, sun)
        else:
            u = sc.sun_gain_1_s * sun
            omega_cmd = np.asarray(pointing_rate_command_nb(q, self.sun_axis_B, np.ascontiguousarray(u)))
            out.omega_cmd_BN_B = _saturate(omega_cmd, math.radians(sc.max_rate_deg_s))
        out.safe_phase = self.safe_phase
        out.pointing_error_deg = err
        out.target_N = sun
        return out

    SAFE_AIM_REFRESH_DEG = 1.0  # the Sun moves 1 deg in a day: a new aim (and plan) then, not every cycle

    def _sun_safe_keepout(self, t_s: float, q: np.ndarray, omega: np.ndarray, sun_N: np.ndarray,
                          y_N: np.ndarray) -> GuidanceOutput:
        """Sun acquisition through POINTING: the law, the plan and the governor on the zones, aimed at the
        boresight of a Sun-safe attitude, the roll law turning ``sun_axis_B`` to the Sun, at SAFE's rate."""
        if (self._safe_sun is None or angle_deg(sun_N, self._safe_sun) > self.SAFE_AIM_REFRESH_DEG
                or self._safe_aim_covered()):
            self._safe_sun = sun_N
            self.target_N = self._sun_safe_boresight(sun_N, y_N)
            self._drop_path()
            self._sky_law_key = None
        kept = self.roll_axis_B, self.roll_ref_N, self.max_rate_rad_s
        self.roll_axis_B, self.roll_ref_N = self.sun_axis_B, sun_N
        self.max_rate_rad_s = min(self.max_rate_rad_s, math.radians(self.cfg.safe.max_rate_deg_s))
        try:
            out = self._pointing(t_s, q, omega)
        finally:
            self.roll_axis_B, self.roll_ref_N, self.max_rate_rad_s = kept
        out.mode = "SAFE"
        out.target_N = sun_N
        return out

    def _safe_aim_covered(self) -> bool:
        """Whether a zone (as the law sees it) has moved over the Sun-safe aim: in low orbit the Earth's zone
        sweeps round the sky once an orbit, and an aim it covers would leave the boresight pressed against
        the moving zone's edge; a new aim is then chosen on the ring, clear of it."""
        return any(s.law is not None and float(s.law.signed_separation(self.target_N)) <= 0.0 for s in self.slots)

    def _sun_safe_boresight(self, sun_N: np.ndarray, y_N: np.ndarray) -> np.ndarray:
        """Boresight direction [N] of the Sun-safe attitude nearest ``y_N`` that is clear of every zone."""
        alpha = math.acos(max(-1.0, min(1.0, float(self.b_B @ self.sun_axis_B))))
        p = y_N - float(y_N @ sun_N) * sun_N
        if _norm(p) < 1e-6:  # boresight on the Sun line: any side
            p = np.cross(sun_N, np.eye(3)[int(np.argmin(np.abs(sun_N)))])
        p = p / _norm(p)
        az = np.radians(np.arange(0.0, 360.0, 5.0))
        ring = (math.cos(alpha) * sun_N + math.sin(alpha) * (np.cos(az)[:, None] * p
                                                             + np.sin(az)[:, None] * np.cross(sun_N, p)))
        zones = [s.law for s in self.slots]
        eps = getattr(self, "_current_eps", float("nan"))
        eps = eps if math.isfinite(eps) else self.cfg.law.eps_max_used
        standoff = self.cfg.law.retreat_standoff_deg
        d_free = ZoneGeometry.clear_separation(standoff, eps)
        free = np.ones(len(ring), dtype=bool)
        for z in zones:
            free &= z.separation_batch(ring) > d_free
        if free.any():
            cand = ring[free]
            return cand[int(np.argmax(cand @ y_N))]
        aim, _ = ZoneGeometry.retreat_target(ring[0], zones, eps, standoff, near=y_N, force=True)
        return aim

    def _sun_safe_attitude_keepout(self, t_s: float, q: np.ndarray, sun_N: np.ndarray) -> GuidanceOutput:
        """Sun acquisition through QUATERNION: the paper's law on S^3 with the attitude zones, the plan and
        the governor, aimed at a Sun-safe attitude, at SAFE's rate; the QUATERNION target is kept."""
        kept = self.q_target, self.max_rate_rad_s
        if self._safe_sun is None or angle_deg(sun_N, self._safe_sun) > self.SAFE_AIM_REFRESH_DEG:
            self._safe_sun = sun_N
            self._safe_q = self._sun_safe_attitude(sun_N, self._lift(q))
            self.q_target = self._safe_q
            self._drop_s3_path()
        self.q_target = self._safe_q
        self.max_rate_rad_s = min(self.max_rate_rad_s, math.radians(self.cfg.safe.max_rate_deg_s))
        try:
            out = self._quaternion(t_s, q)
        finally:
            self.q_target, self.max_rate_rad_s = kept
        out.mode = "SAFE"
        out.sun_N, out.moon_N = sun_N, self._dirs["moon"]
        out.target_N = sun_N
        return out

    SAFE_ROLL_STEP_DEG = 5.0  # spacing of the Sun-safe attitudes searched about the Sun line

    def _sun_safe_attitude(self, sun_N: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Attitude q_NB (on the sheet of the lifted ``x``) with ``sun_axis_B`` on the Sun, the rotation about
        the Sun line chosen nearest ``x`` among those clear of every attitude zone by the retreat standoff;
        when none is, the clear attitude nearest the least blocked of them (`_nearest_clear_attitude`)."""
        s_N = quat_to_dcm_nb(x) @ self.sun_axis_B
        axis = np.cross(s_N, sun_N)
        if _norm(axis) < 1e-9:  # on the Sun (any axis) or opposite it (any perpendicular axis)
            axis = np.cross(s_N, np.eye(3)[int(np.argmin(np.abs(s_N)))])
        angle = math.acos(max(-1.0, min(1.0, float(s_N @ sun_N))))
        q0 = quat_multiply(quat_from_axis_angle(axis / _norm(axis), angle), x)  # shortest turn: nearest x
        about_sun = quat_multiply(np.concatenate(([0.0], sun_N)), q0)
        half = np.radians(np.arange(0.0, 360.0, self.SAFE_ROLL_STEP_DEG)) / 2.0
        ring = np.cos(half)[:, None] * q0 + np.sin(half)[:, None] * about_sun
        ring *= np.where(ring @ x < 0.0, -1.0, 1.0)[:, None]  # same attitude, on x's sheet
        # the standoff alone: the law's eps is chosen for the aim it is built on (`law_eps`), so an aim clear of
        # the zones is outside its eps-layer whatever the standoff
        d_free = 1.0 - math.cos(math.radians(self.cfg.law.retreat_standoff_deg))
        seps = np.min([z.separation_batch(ring) for z in self.s3_law_zones], axis=0)
        free = seps > d_free
        if free.any():
            cand = ring[free]
            return cand[int(np.argmax(cand @ x))]
        return _nearest_clear_attitude(ring[int(np.argmax(seps))], self.s3_law_zones, d_free, x)

    def _set_safe_phase(self, phase: str) -> None:
        self.safe_phase = phase
        self.events("SAFE_PHASE_CHANGED", phase=phase)
