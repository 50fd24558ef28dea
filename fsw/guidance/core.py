"""The guidance object the flight software holds: mode switching, telecommanded targets and gains, the
assumption-check hand-over, and `Guidance.step`, which runs the active mode once per GNC cycle.

The modes themselves are mixins, one module each: `pointing`, `path_following`, `quaternion`, `safe`.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.assumption_check import CheckResult
from fsw.guidance._kernels import FP_WIDTH
from fsw.guidance.common import _BODY_CODES, GuidanceOutput, _saturate, unit_vector, signed_margin_deg
from fsw.guidance.edge_rule import law_eps
from gnc.sky_ephemeris import SkyEphemeris
from fsw.guidance.path_following import PathFollowing
from fsw.guidance.path_planning import PathFollower
from fsw.guidance.pointing import ZONE_REBUILD_TOL_DEG, PointingGuidance, _SkySlot, _warm_batch_kernels
from fsw.guidance.quaternion import QuaternionGuidance
from fsw.guidance.slew_limits import (
    BRAKING_RESERVE_DEG, GainsRefused, allowed_braking_deg, rate_for_distance_deg_s, rate_limit_problem, rule_eps,
)
from fsw.guidance.safe import SafeGuidance, _acquisition_rate_B
from fsw.guidance.watchdog import ProgressWatchdog, StallRecovery
from fsw.guidance.zone_merging import ZoneGeometry
from gnc import sky_zones
from gnc.attitude import quat_to_dcm_nb


class Guidance(PointingGuidance, PathFollowing, StallRecovery, QuaternionGuidance, SafeGuidance):
    """Mode logic and guidance laws; `step` runs once per GNC cycle."""

    MODES = ("SAFE", "POINTING", "QUATERNION", "DETUMBLE")

    def __init__(self, cfg, events=None) -> None:
        self.cfg = cfg
        self.events = events or (lambda name, **args: None)
        self.mode = cfg.initial_mode
        self._init_law_and_limits(cfg)
        self._init_targets(cfg)
        self._init_sky_slots(cfg)
        self._init_pointing_cycle_state()
        self._init_safe_and_checks()
        self._init_path_guidance(cfg)
        self.last_t_s = 0.0

    def _init_law_and_limits(self, cfg) -> None:
        """The law's gains and what the rate loop can follow."""
        self.k1 = cfg.law.k1
        self.kappa = cfg.law.kappa
        self.eps_cfg = cfg.law.eps
        self.max_rate_rad_s = math.radians(cfg.spacecraft.max_rate_deg_s)
        # what the rate loop can follow: the braking rule and the governor (slew_limits) use them
        self.accel_deg_s2 = cfg.control.max_command_accel_deg_s2
        self.bandwidth_rad_s = cfg.control.rate_bandwidth_rad_s
        self._governor_margins: list[float] | None = None
        self.rate_cap_deg_s = math.inf  # lowered when a wheel is lost (reduce_slew_authority)

    def _init_targets(self, cfg) -> None:
        """The ephemeris, the boresight and the targets of each mode."""
        self.ephem = SkyEphemeris(cfg)
        p = cfg.pointing
        self.b_B = np.asarray(p.boresight_B, dtype=float)
        self.target_N = np.asarray(p.target_N, dtype=float)
        self.roll_axis_B = np.asarray(p.roll_axis_B, dtype=float)
        self.roll_ref_N = np.asarray(p.roll_reference_N, dtype=float)
        self.q_target = np.asarray(cfg.quaternion.target_q_NB, dtype=float)
        self.sun_axis_B = np.asarray(cfg.safe.sun_axis_B, dtype=float)
        self.no_fix_s = 0.0
        # the commanded POINTING target is a fixed direction: what arms the zones kept for inertial targets
        # only (`PointingGuidance._update_arming`)
        self._target_fixed = p.target_kind == "inertial"
        self.acquisition_omega_B = _acquisition_rate_B(cfg, self.b_B)

    def _init_sky_slots(self, cfg) -> None:
        """One slot per configured sky zone, with its zone builders (the margins', fast, and the law's; with a
        coarse attitude the law's for each margin, `PointingGuidance.use_coarse_margin`)."""
        p = cfg.pointing
        margin = cfg.law.margin_deg
        coarse_margin = cfg.coarse_margin_deg()
        self.slots: list[_SkySlot] = []
        for i, z in enumerate(p.zones):
            extra = self.ephem.earth_angular_radius_deg if (z.body == "earth" and z.add_body_angular_radius) else 0.0
            fixed = np.asarray(z.direction_N, dtype=float) if z.body == "inertial" else None
            law = sky_zones.SkyZoneBuilder(z.geometry, margin + ZONE_REBUILD_TOL_DEG, extra)
            slot = _SkySlot(i, z.name, z.body, sky_zones.SkyZoneBuilder(z.geometry, 0.0, extra, fast=True), law, fixed)
            if coarse_margin is not None:
                slot.law_builders = (law, sky_zones.SkyZoneBuilder(z.geometry, coarse_margin + ZONE_REBUILD_TOL_DEG, extra))
            slot.inertial_only = slot.disarmed = z.armed == "inertial_targets"  # armed once the boresight is clear
            self.slots.append(slot)
        self._inertial_only = [s for s in self.slots if s.inertial_only]
        self._armed = tuple(s.index for s in self.slots if not s.disarmed)
        self._body_codes = [_BODY_CODES[s.body] for s in self.slots]  # telemetry codes, fixed with the slots
        self.sky_geometry = ZoneGeometry(3, cfg.law.merge_gap_deg)
        if self.slots:
            _warm_batch_kernels([s.builder_law for s in self.slots])

    def _init_pointing_cycle_state(self) -> None:
        """What the POINTING and S^3 cycles keep between cycles: nothing kept yet, no path planned."""
        self._sky_law = None
        self._sky_law_key = None
        # the compiled POINTING cycle's packed state (`PointingGuidance._pointing`): the slots and their
        # zones, the law's zones and law, what is kept while the zones stay the same objects
        self._sky_pack = None
        self._law_pack = None
        self._sky_res = None  # a compiled cycle's sky not applied to the slots yet (`_settle_sky`)
        self._target_out = (None, None)  # (target_N, its read-only copy the POINTING outputs share)
        self._merge_kept = None
        self._merge_close_kept = None  # (zones, previous groups, merged, groups, pending, unmerged): `_merge_close`
        self._law_zones_kept = None
        self._governor_kept = None
        self._sky_group_first: list[int] = []
        self._sky_zones_merged = False
        self._fp = np.zeros(FP_WIDTH + 2 * len(self.slots))
        self._write_arming()
        self._eph_k = None
        self._fp_key = None
        self._fp_law = None
        self._fp_vecs = None
        self._zone_facts_kept: dict[int, tuple] = {}
        self._sky_groups: list[list[int]] = []
        self._sky_law_zones: list = []
        self._build_s3_zones()
        self._q_lift: np.ndarray | None = None
        self._drop_s3_path()  # no S^3 path yet: the law heads for the target until one is planned

    def _init_safe_and_checks(self) -> None:
        """SAFE mode's state, the assumption-check cache, occultation and escape."""
        self.safe_phase = "RATE_DAMPING"
        self._damped_s = 0.0
        self._safe_sun: np.ndarray | None = None  # the Sun direction the Sun-safe aim was chosen for
        self._safe_q = self.q_target  # the Sun-safe attitude SAFE aims at in a mission with attitude zones
        self._held_target_N = self.target_N  # the POINTING target while SAFE aims elsewhere
        # assumption-check cache (refreshed by the housekeeping task and on changes)
        self.eps_max_checked = float("inf")
        self.assumptions_ok = True
        self.check_errors: list[str] = []
        self._checks_dirty = True
        self._occulted = -1
        self._substitute: tuple | None = None  # (commanded target, substitute, time found, occulting index)
        self._escaping = False
        self._escape_point: np.ndarray | None = None
        self._escape_event_t = -math.inf

    def _init_path_guidance(self, cfg) -> None:
        """The follower of the planned slew path, the law's aim on it, when it was planned, the watchdog."""
        self._follower: PathFollower | None = None
        self._aim: np.ndarray = self.target_N
        self._aim_k = -1
        self._plan_due = True
        self._planned_t = -math.inf
        self._watchdog = ProgressWatchdog(cfg.law.stall_watchdog_s)

    # ------------------------------------------------------------------------------ configuration
    def set_mode(self, mode: str) -> None:
        if mode not in self.MODES:
            raise ValueError(f"unknown mode {mode!r}; allowed: {self.MODES}")
        if mode == "SAFE" and self.mode != "SAFE":
            self._held_target_N = self.target_N  # SAFE aims the boresight elsewhere; POINTING resumes this
        elif mode != "SAFE" and self.mode == "SAFE":
            self.target_N, self._sky_law_key = self._held_target_N, None
        self._safe_sun = None
        self.mode = mode
        self._drop_path()
        self._watchdog.reset()
        self._governor_margins = None
        if mode == "SAFE":
            self.safe_phase = "RATE_DAMPING"
            self._damped_s = 0.0
        if mode == "QUATERNION":
            self._q_lift = None
            self._drop_s3_path()
        self._checks_dirty = True

    def set_gains(self, k1: float, kappa: float, eps: float | str, rate_limit_deg_s: float) -> None:
        """Adopt new law gains and rate limit, or raise `GainsRefused` with the reason code (nothing changes)."""
        if not (k1 > 0 and kappa > 0 and rate_limit_deg_s > 0):
            raise GainsRefused("GAINS_INADMISSIBLE", "k1, kappa and rate limit must be positive")
        if eps != "auto" and not (0.0 < float(eps) < 1.0):
            raise GainsRefused("GAINS_INADMISSIBLE", "eps must be in (0, 1) or 'auto'")
        refused = rate_limit_problem(rate_limit_deg_s, eps, self.cfg, self.accel_deg_s2)
        if refused is not None:
            raise GainsRefused(*refused)
        if rate_limit_deg_s > self.rate_cap_deg_s:
            raise GainsRefused("WHEEL_AUTHORITY", f"the wheels left allow at most {self.rate_cap_deg_s:.3g} deg/s")
        self.k1, self.kappa, self.eps_cfg = float(k1), float(kappa), eps
        self.max_rate_rad_s = math.radians(rate_limit_deg_s)
        self._sky_law_key = None
        self._s3_law = None
        self._checks_dirty = True

    def reduce_slew_authority(self, accel_deg_s2: float, rate_cap_deg_s: float) -> tuple[float, float]:
        """The wheels left give only ``accel_deg_s2`` and ``rate_cap_deg_s`` (momentum) about the worst axis:
        shrink the acceleration the governor assumes, the rate limit (to the cap and to what the braking
        rule allows at the new acceleration) and k1 in proportion (k1 = 2 a / w lands a slew without
        overshoot). Returns the new (rate limit [deg/s], acceleration [deg/s^2])."""
        if accel_deg_s2 < self.accel_deg_s2:
            self.k1 *= accel_deg_s2 / self.accel_deg_s2
            self.accel_deg_s2 = accel_deg_s2
        allowed = allowed_braking_deg(self.cfg.law.margin_deg, rule_eps(self.eps_cfg, self.cfg.law.eps_max_used))
        self.rate_cap_deg_s = min(self.rate_cap_deg_s, rate_cap_deg_s,
                                  rate_for_distance_deg_s(allowed, self.accel_deg_s2, self.bandwidth_rad_s))
        rate = min(math.degrees(self.max_rate_rad_s), self.rate_cap_deg_s)
        self.max_rate_rad_s = math.radians(rate)
        self._sky_law_key = None
        self._s3_law = None
        return rate, self.accel_deg_s2

    def _govern(self, omega_BN_B: np.ndarray, margins_deg: list[float], angle_per_margin: float = 1.0) -> np.ndarray:
        """The rate governor (`slew_limits`): scale ``omega_BN_B`` down to the largest rate that can still
        stop before the nearest zone the boresight (or attitude) is approaching, i.e. whose margin fell
        since the last cycle; a zone being left is not a reason to slow down (the law pushes out of it).
        ``angle_per_margin``: body rotation per degree of margin (2 on S^3, where the quaternion's angle is
        half the rotation's)."""
        rate = self._governor_rate(margins_deg, angle_per_margin)
        return omega_BN_B if rate < 0.0 else _saturate(omega_BN_B, rate)

    def _governor_rate(self, margins_deg: list[float], angle_per_margin: float = 1.0) -> float:
        """`_govern`'s rate limit [rad/s] for this cycle's margins, -1 when no zone is being approached."""
        prev, self._governor_margins = self._governor_margins, list(margins_deg)
        if prev is None or len(prev) != len(margins_deg):
            return -1.0
        closing = [m for m, p in zip(margins_deg, prev) if m < p]
        if not closing:
            return -1.0
        room = angle_per_margin * min(closing) - BRAKING_RESERVE_DEG
        return math.radians(rate_for_distance_deg_s(room, self.accel_deg_s2, self.bandwidth_rad_s))

    def target_violation(self, kind: str, value: np.ndarray, on_earth: bool = False) -> tuple[int, float] | None:
        """(zone index, margin deg) when a candidate target lies inside an (inflated) zone, else None.
        ``on_earth``: the direction is a nadir or ground target's, which the zones kept for inertial targets
        only do not guard."""
        if kind == "DIRECTION":
            self._update_sky(self.last_t_s)
            x = unit_vector(np.asarray(value, dtype=float))
            for s in self.slots:
                if on_earth and s.inertial_only:
                    continue
                m = signed_margin_deg(s.law, x)
                if m <= 0.0:
                    return s.index, m
            return None
        q = unit_vector(np.asarray(value, dtype=float))
        for i, z in enumerate(self.s3_law_zones):
            m = signed_margin_deg(z, q)
            if m <= 0.0:
                return i, m
        return None

    def set_target_direction(self, target_N: np.ndarray) -> None:
        self._target_fixed = True
        if self.mode == "SAFE":  # kept for POINTING; SAFE keeps aiming at its Sun-safe attitude
            self._held_target_N = unit_vector(np.asarray(target_N, dtype=float))
            return
        self.target_N = unit_vector(np.asarray(target_N, dtype=float))
        self._drop_path()
        self._sky_law_key = None
        self._checks_dirty = True


    def assumption_snapshot(self):
        """(target, zones, eps, kappa, law) the full check should look at now, or None (no zones)."""
        eps = getattr(self, "_current_eps", float("nan"))
        eps = eps if math.isfinite(eps) else 0.01
        if self.mode == "POINTING" and self._sky_law_zones:
            return (np.array(self._sky_target), list(self._sky_law_zones), eps, self.kappa, "star")
        if self.mode == "QUATERNION" and self.s3_law_zones:
            law = "gradient" if self.s3_use_gradient else "star"
            return (self.q_target.copy(), list(self.s3_law_zones), eps, None if law == "gradient" else self.kappa, law)
        return None

    def apply_check_result(self, result: CheckResult | None) -> None:
        """Take a finished check: telemetry flag, events on a new violation. Never changes the law:
        the per-cycle eps bound (`ZoneGeometry.fast_eps_max`) is already conservative."""
        if result is None:
            self.assumptions_ok, self.check_errors, self.eps_max_checked = True, [], float("inf")
            return
        was_ok = self.assumptions_ok
        self.assumptions_ok = result.ok
        self.check_errors = result.errors
        self.eps_max_checked = result.eps_max
        if not result.ok and was_ok:  # on the transition only: the flag stays in telemetry meanwhile
            self.events("ASSUMPTION_VIOLATED", reason=("; ".join(result.errors) or "check failed")[:110])

    def forget_law_state(self) -> None:
        """Drop what the law learnt from past cycles (groups, substitute and escape targets), so the next
        cycle rebuilds it from scratch (after the start-up warm-up ran every mode once)."""
        self._sky_law_key = None
        self._sky_groups = []
        self._occulted = -1
        self._substitute = None
        self._escaping = False
        self._escape_point = None
        self._drop_path()

    def mark_checked(self) -> None:
        self._checks_dirty = False

    @property
    def checks_dirty(self) -> bool:
        return self._checks_dirty

    def _eps_for(self, eps_max: float) -> float:
        return law_eps(self.cfg.law, eps_max, self.eps_cfg)


    # ------------------------------------------------------------------------------------- modes
    def step(self, t_s: float, dt_s: float, q_NB: np.ndarray | None, omega_BN_B: np.ndarray) -> GuidanceOutput:
        self.last_t_s = t_s
        if self.mode == "DETUMBLE":
            return self._detumble(q_NB)
        if q_NB is None:
            # No attitude knowledge: rate damping, then (if the star tracker stays silent or blind) the
            # acquisition rotation, which never moves the instrument boresight.
            self.no_fix_s += dt_s
            acquiring = self.no_fix_s >= self.cfg.estimator.acquisition_delay_s
            out = GuidanceOutput(self.acquisition_omega_B.copy() if acquiring else np.zeros(3), self.mode,
                                 safe_phase="RATE_DAMPING" if self.mode == "SAFE" else "NONE")
            if self.slots:
                self._update_sky(t_s)
            return out
        self.no_fix_s = 0.0
        q = np.ascontiguousarray(q_NB, dtype=float)
        if self.mode == "POINTING":
            return self._pointing(t_s, q, omega_BN_B)
        if self.mode == "QUATERNION":
            return self._quaternion(t_s, q)
        return self._safe(t_s, dt_s, q, omega_BN_B)

    def _detumble(self, q_NB: np.ndarray | None) -> GuidanceOutput:
        """DETUMBLE: no rate command (the rods' B-dot and the wheels' zero torque are the flight software's,
        `fsw.detumble`) and no margins: a tumbling body cannot steer its boresight, the door is what keeps
        the instrument out of the zones, so the keep-out monitor has nothing it could act on. The boresight
        when the attitude is known (telemetry, the door's own margins)."""
        out = GuidanceOutput(np.zeros(3), "DETUMBLE")
        if q_NB is not None:
            out.boresight_N = quat_to_dcm_nb(np.ascontiguousarray(q_NB, dtype=float)) @ self.b_B
        return out
