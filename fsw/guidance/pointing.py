"""POINTING mode: the instrument boresight on S^2 kept out of the Sun, Moon and Earth zones.

The target is a fixed direction in N, or a target on the rotating Earth (nadir, a ground point) whose
direction is computed again every cycle from the onboard orbit (`SkyEphemeris.target_direction_N`): the
same law and guard steer to it, the target simply moves (`PointingGuidance._track_target`).

The zones are rebuilt from the onboard ephemeris as they move (physical ones for the margins, inflated ones
for the law), merged when close (`zone_merging`), and the `gnc.laws.StarShapedLaw` steers the boresight
to the target, or to a substitute when the target lies in a zone's eps-layer, or out of the closing gap
between two zones that cannot merge; `gnc.attitude.pointing_rate_command_nb` maps the law's ``u`` to a
body rate with no component about the boresight. A separate proportional roll law turns about the
boresight (it cannot move the boresight, so it cannot affect keep-out). Its reference is fixed in N, or
chosen by a rule (`pointing.roll_reference`: the Sun, the orbit's velocity or normal; `_follow_roll_rule`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fsw.guidance._kernels import (
    ARC_WIDTH, FP_AIM_K, FP_B, FP_COS_AHEAD, FP_EPH, FP_EPS, FP_F, FP_FOLLOW, FP_LAW_TARGET, FP_NPREV, FP_PREV, FP_ROLL_AXIS,
    FP_ROLL_REF, FP_START, FP_STEADY, FP_T, FP_TARGET, FP_U0, R_AIM, R_AIM_DONE, R_DRIFT, R_ERROR, R_LAW_ERROR,
    R_LAW_RATE, R_MARGIN_MIN,
    R_NEAREST, R_OMEGA, R_ROLL, R_WORST, R_WORST_KIND, R_Y, R_ZONE, SG_BODY, SG_BUILT, SG_BUILT_LAW, SG_FIXED,
    ZT_CAP_AXIS, ZT_CAP_COS, ZT_COUNT, ZT_KERNEL, ZT_KIND, ZT_START, ZT_WIDTH, boresight_nb, pack_zones,
    pointing_command_nb, pointing_law_nb, pointing_step_nb, zone_separations_nb,
)
from fsw.guidance.common import (
    _BODY_CODES, _NAN3, _NAN4, GuidanceOutput, angle_deg, _make_star_law, signed_margin_deg,
)
from fsw.guidance.edge_rule import TARGET_IN_LAYER
from fsw.guidance.slew_limits import armable
from gnc.sky_ephemeris import EPHEMERIS_NODE_S
from fsw.guidance.watchdog import MIN_ERROR_DEG, RATE_FRACTION
from fsw.guidance.zone_merging import ZoneGeometry
from gnc import sky_zones
from gnc.laws import _positive, _unit_vector, _zone_list

ZONE_REBUILD_TOL_DEG = 0.1  # extra inflation of the law's zones covering their motion between rebuilds
LAW_REBUILD_TRIGGER_DEG = 0.08
PHYS_REBUILD_TOL_DEG = 0.5
# a roll rule's reference within this of the target's line (either way) is not taken: the last one is held
ROLL_RULE_HOLD_DEG = 25.0
_ROLL_RULE_HOLD_COS = math.cos(math.radians(ROLL_RULE_HOLD_DEG))
_BODY_INDEX = {"sun": 0, "moon": 1, "earth": 2, "inertial": 3}  # rows of `sky_directions_nb`; 3: a fixed centre
_NO_PATH = np.zeros((1, 3))
_NO_LAW = (np.zeros((0, ZT_WIDTH)), np.zeros((0, ARC_WIDTH)))


def _warm_batch_kernels(builders: list) -> None:
    """Run each zone shape's batch separation once: the substitute-target search is their first caller,
    possibly hours into a run, and loading their compiled code there took 0.3-0.7 s (a cycle slip in the
    soak). One zone per builder, any centre."""
    probe = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    for builder in builders:
        builder.build(np.array([1.0, 0.0, 0.0])).separation_batch(probe)


def _same_objects(kept, now) -> bool:
    """Whether two sequences hold the very same objects, in order (zones are immutable: the same object is
    the same zone, and any rebuilt zone is a new one)."""
    return len(kept) == len(now) and all(a is b for a, b in zip(kept, now))


@dataclass
class _SkySlot:
    index: int
    name: str
    body: str
    builder_phys: sky_zones.SkyZoneBuilder
    builder_law: sky_zones.SkyZoneBuilder
    fixed_center: np.ndarray | None
    center_N: np.ndarray | None = None
    built_center: np.ndarray | None = None
    built_center_law: np.ndarray | None = None
    phys: object | None = None
    law: object | None = None
    phys_drift_deg: float = 0.0  # angle between center_N and built_center, this cycle
    law_builders: tuple = ()  # (law.margin_deg's, the coarse attitude's margin's) with a coarse attitude
    # armed: 'inertial_targets' (`fsw.config.SkyZoneConfig.armed`): kept out only while the target is a fixed
    # direction and the boresight has left it; disarmed, neither the law nor the margins see it
    inertial_only: bool = False
    disarmed: bool = False
    arming_seen: tuple[float, float] | None = None  # (time, margin from the law's zone) while waiting to arm
    # center_N and phys_drift_deg (and the guidance's `_dirs`) as the last cycle left them once
    # `PointingGuidance._settle_sky` has run: a compiled cycle leaves them to it (nothing in a steady
    # cycle reads them; every reader settles first)


class PointingGuidance:
    """Mixin of `fsw.guidance.Guidance`: POINTING mode and the sky zones every mode reports margins on."""

    # a target on the Earth: (kind, its Earth-fixed point [km] or None for nadir), or None for a fixed
    # target; the target_N it last set; whether the configured initial target was taken up (the first
    # POINTING cycle does it: the start-up warm-up runs one before any telecommand)
    _track: tuple[str, np.ndarray | None] | None = None
    _tracked_N: np.ndarray | None = None
    _track_started = False
    # the roll rule's reference (`_follow_roll_rule`) and what it was computed for (an ephemeris node, or 0)
    _roll_rule_ref: np.ndarray | None = None
    _roll_rule_key: int | None = None

    def set_target_on_earth(self, kind: str, ground=None) -> None:
        """Make the POINTING target nadir (``kind`` 'nadir') or the `fsw.config.GroundTargetConfig`
        ``ground`` ('ground'), followed every cycle from now on; a later `set_target_direction` (a fixed
        target) ends it. The caller checks the target against the zones first, as for a fixed target."""
        if kind not in ("nadir", "ground"):
            raise ValueError(f"unknown target kind {kind!r}; allowed: 'nadir', 'ground'")
        point = self.ephem.ground_point_E_km(ground) if kind == "ground" else None
        self._track_started = True
        self.set_target_direction(self.ephem.target_direction_N(self.last_t_s, point))
        self._track = (kind, point)
        self._tracked_N = self._held_target_N if self.mode == "SAFE" else self.target_N
        self._target_fixed = False
        self._update_arming(None, self.last_t_s)

    def target_on_earth_N(self, kind: str, ground=None, t_s: float | None = None) -> np.ndarray:
        """The direction of a nadir or ground target at ``t_s`` (default: the last cycle's time), e.g. to
        check it against the zones before `set_target_on_earth`."""
        point = self.ephem.ground_point_E_km(ground) if kind == "ground" else None
        return self.ephem.target_direction_N(self.last_t_s if t_s is None else t_s, point)

    def _track_target(self, t_s: float) -> None:
        """A target on the Earth moves: its direction now, as a new target_N (replaced, never written into:
        `_cycle_inputs` and the outputs tell a new target by identity), the law's aim unless a planned
        path leads it, and the law given it as its target (`_retarget_law`) or rebuilt for it. A target_N
        this did not set came from a telecommand (`set_target_direction`): a fixed target, followed no more."""
        if not self._track_started:
            self._track_started = True
            p = self.cfg.pointing
            if p.target_kind != "inertial":
                point = self.ephem.ground_point_E_km(p.target_ground) if p.target_kind == "ground" else None
                self._track, self._tracked_N = (p.target_kind, point), self.target_N
        track = self._track
        if track is None:
            return
        if self.target_N is not self._tracked_N:
            self._track = None
            return
        direction = self.ephem.target_direction_N(t_s, track[1])
        self.target_N = self._tracked_N = direction
        if self._follower is None:
            self._aim = direction
        if not self._retarget_law(self._aim):
            self._sky_law_key = None

    def _retarget_law(self, aim: np.ndarray) -> bool:
        """Give the current law the moved ``aim`` as its target, as `_rebuild_sky_law` would, without the
        rest of the rebuild when nothing else changed: the law's zones the same objects and none close to
        another (the merge would return them as they are), no plan due, no substitute or escape in force.
        Then the steady compiled cycle goes on (`pointing_step_nb` takes the law's target and eps from
        ``fp``). The eps comes again from the aim's separations (near a zone they bound eps_max), and the
        zone table with it only when it changed. False when the law must be rebuilt: the aim inside an
        eps-layer needs a substitute target, found round where the aim is, so it is searched again each
        cycle while the aim moves there, as for any new target."""
        law = self._law_pack
        kept = self._law_zones_kept
        if (self._sky_law_key is None or law is None or kept is None or kept[1] is None or kept[1][1] is not law[1]
                or self._merge_kept is None or self._escaping or self._occulted != -1 or self._plan_due):
            return False
        geometry = self.sky_geometry
        if geometry.pending or geometry.unmerged:
            return False
        # `_fast_eps_max` and `ZoneGeometry.occulting_from` with no pair set aside and nothing pending: the
        # pairwise bound and the aim's nearest zone (a minimum is exact, in any order)
        nearest = min(zone_separations_nb(aim, *kept[1]).tolist(), default=math.inf)  # (numpy's min: 1.7 us more)
        bound = kept[2].get(())
        if bound is None:
            bound = kept[2][()] = ZoneGeometry.pair_bound(self._sky_law_zones, [])
        eps_max = min(bound, nearest)
        eps = self._eps_for(eps_max)
        if nearest <= eps:
            return False
        self._sky_target = aim
        self._sky_eps, self._sky_eps_max = eps, eps_max
        self._current_eps = eps
        if eps == law[3]:
            self._sky_law = None  # the law object, when a cycle needs it, is made again from _sky_target
            self._law_pack = (law[0], law[1], _unit_vector(aim, "target"), eps)
        else:
            self._set_sky_law(aim, self._sky_law_zones, eps, kept[1])
        return True

    def _update_sky(self, t_s: float) -> bool:
        """Recompute zone centres; rebuild zones that moved too far. True if a law zone was rebuilt.

        Law zones (inflated by the extra ZONE_REBUILD_TOL_DEG) are rebuilt when their centre has moved
        by LAW_REBUILD_TRIGGER_DEG; physical zones (margin telemetry, FDIR) after PHYS_REBUILD_TOL_DEG,
        their margins corrected by the drift meanwhile. At most one zone is rebuilt per cycle (the
        largest drift first), which keeps the cycle time flat; the slack between trigger and inflation
        covers the cycles a pending rebuild may wait.
        """
        dirs = self.ephem.directions(t_s) if self.slots else {}
        self._sky_res = None  # every slot's state is set below
        self._dirs = dirs
        worst, worst_kind, worst_slot = 0.0, None, None
        first = False
        for s in self.slots:
            c = s.fixed_center if s.fixed_center is not None else dirs[s.body]
            s.center_N = c
            if s.built_center is None:
                self._sky_pack = None
                s.phys, s.law = s.builder_phys.build(c), s.builder_law.build(c)
                s.built_center, s.built_center_law = c.copy(), c.copy()
                s.phys_drift_deg = angle_deg(c, s.built_center)
                first = True
                continue
            s.phys_drift_deg = angle_deg(c, s.built_center)
            law_drift = angle_deg(c, s.built_center_law) / LAW_REBUILD_TRIGGER_DEG
            phys_drift = s.phys_drift_deg / PHYS_REBUILD_TOL_DEG
            for drift, kind in ((law_drift, "law"), (phys_drift, "phys")):
                if drift >= 1.0 and drift > worst:
                    worst, worst_kind, worst_slot = drift, kind, s
        if worst_slot is not None:
            self._sky_pack = None
            c = worst_slot.center_N
            if worst_kind == "law":
                worst_slot.law = worst_slot.builder_law.build(c)
                worst_slot.built_center_law = c.copy()
            else:
                worst_slot.phys = worst_slot.builder_phys.build(c)
                worst_slot.built_center = c.copy()
                worst_slot.phys_drift_deg = angle_deg(c, worst_slot.built_center)
        rebuilt_law = first or worst_kind == "law"
        if rebuilt_law:
            # whoever asked (SAFE, the door's margins, a telecommand's check), the law must fly the new zone:
            # the pointing cycle's own sky check then sees no drift left and would keep the old one. Before
            # (found 2026-11-29 by the star-tracker-lost campaign), SAFE's call took the rebuilds and its law
            # flew a frozen Earth zone while the real one swept over the parked boresight, 35 deg deep.
            self._sky_law_key = None
        return rebuilt_law

    def use_coarse_margin(self, coarse: bool) -> None:
        """The law's zones inflated by the coarse attitude's margin (``coarse``: the estimate rests on the
        Sun sensors and the magnetometer, degrees off where the star tracker's is arcseconds) or by
        law.margin_deg again: each built law zone rebuilt now where it was built, and the law made anew."""
        self._settle_sky()
        for s in self.slots:
            s.builder_law = s.law_builders[1 if coarse else 0]
            if s.built_center_law is not None:
                s.law = s.builder_law.build(s.built_center_law)
        self._sky_pack = None
        self._sky_law_key = None

    def _update_arming(self, y_N: np.ndarray | None, t_s: float) -> None:
        """Arm or disarm the zones kept for inertial targets only: disarmed at once when the target is on the
        Earth (its direction lies inside an Earth zone); armed when the target is a fixed direction and the
        boresight ``y_N`` is outside the law's (inflated) zone, so the law starts from its safe set, and can
        stop short of the physical zone from the rate it closes on it (`armable`). Either change makes the
        law anew on the armed zones (ZONE_ARMED, ZONE_DISARMED) and plans the slew again."""
        changed = False
        for s in self._inertial_only:
            if not s.disarmed and not self._target_fixed:
                s.disarmed, changed = True, True
                self.events("ZONE_DISARMED", zone=s.index, body=_BODY_CODES[s.body])
            elif s.disarmed and self._target_fixed and y_N is not None and s.law is not None:
                m = signed_margin_deg(s.law, y_N)
                seen = s.arming_seen
                if seen is not None and t_s <= seen[0]:
                    continue  # this cycle's margin was seen already (SAFE and the door ask again)
                s.arming_seen = (t_s, m)
                if seen is not None and self.armable(m, (seen[1] - m) / (t_s - seen[0])):
                    s.disarmed, s.arming_seen, changed = False, None, True
                    self.events("ZONE_ARMED", zone=s.index, body=_BODY_CODES[s.body])
        if changed:
            self._armed = tuple(s.index for s in self.slots if not s.disarmed)
            self._write_arming()
            self._sky_law_key = None
            self._plan_due = True
            self._checks_dirty = True

    def armable(self, law_margin_deg: float, closing_deg_s: float) -> bool:
        """Whether a zone may be armed with the boresight ``law_margin_deg`` outside it as the law sees it,
        closing on it at ``closing_deg_s``: outside it, and able to stop (`slew_limits.braking_distance_deg`)
        within the inflation margin less the braking reserve. A zone sweeping onto a parked boresight (the
        Earth's, 0.06 deg/s) arms as soon as it is outside; a slew heading into it at 1 deg/s (4 deg to stop
        at 0.2 deg/s^2) waits until it has turned away."""
        return bool(armable(law_margin_deg, closing_deg_s, self.cfg.law.margin_deg, self.accel_deg_s2,
                            self.bandwidth_rad_s))

    def _write_arming(self) -> None:
        """The disarmed slots' flags where the compiled law reads them (`pointing_law_nb`: a NaN margin)."""
        n = len(self.slots)
        self._fp[FP_PREV + n:FP_PREV + 2 * n] = [1.0 if s.disarmed else 0.0 for s in self.slots]

    def _local_groups(self, groups: list[list[int]]) -> list[list[int]]:
        """Slot-index ``groups`` as indices into the armed slots' zones (what the merge sees)."""
        if len(self._armed) == len(self.slots):
            return [list(g) for g in groups]
        where = {k: j for j, k in enumerate(self._armed)}
        local = [[where[k] for k in g if k in where] for g in groups]
        return [g for g in local if g]

    def _sky_margins(self, y_N: np.ndarray) -> tuple[list[float], float]:
        """Signed physical margins [deg], conservative: minus the zone's drift since it was built (as
        `_update_sky` found it this cycle); NaN for a disarmed zone, which the smallest leaves out."""
        self._settle_sky()
        if self._inertial_only:
            self._update_arming(y_N, self.last_t_s)
        margins = [math.nan if s.disarmed else signed_margin_deg(s.phys, y_N) - s.phys_drift_deg for s in self.slots]
        kept = [m for m in margins if m == m] if self._inertial_only else margins
        return margins, (min(kept) if kept else float("nan"))

    def sky_margins_at(self, t_s: float, y_N: np.ndarray) -> tuple[list[float], list[str]]:
        """The boresight ``y_N``'s signed physical margins [deg] from the sky zones at onboard time ``t_s``
        (conservative, as `_sky_margins`) and each zone's body code: what the aperture door judges in every
        mode, whatever zones the mode's law steers round."""
        self._update_sky(t_s)
        return self._sky_margins(y_N)[0], self._slot_body_codes()


    def _follow_roll_rule(self, t_s: float, rule: str) -> None:
        """The roll reference of the rule ``rule`` (`pointing.roll_reference`) at ``t_s`` as ``roll_ref_N``.

        'sun': the Sun seen from the spacecraft, once per ephemeris node (it moves ~0.0004 deg in one);
        'velocity': the onboard orbit's velocity direction, every cycle (0.06 deg/s in low orbit);
        'orbit_normal': the orbit's normal, fixed. The roll law turns about the boresight only (its rate is
        along b: the boresight's own rate R (omega x b) gets nothing from it), so no rule can move the
        boresight or touch the keep-out guarantee. A reference within ROLL_RULE_HOLD_DEG of the target's line
        (the Sun near nadir or zenith for a nadir target) fixes no roll well and flips it as it passes: the
        last reference is held instead (the configured roll_reference_N until one was taken)."""
        e = self.ephem
        if rule == "velocity":
            ref = e.velocity_direction_N(t_s)
        else:
            key = math.floor(t_s / EPHEMERIS_NODE_S) if rule == "sun" else 0
            if key != self._roll_rule_key:
                self._roll_rule_key = key
                self._roll_rule_ref = (e.directions(key * EPHEMERIS_NODE_S)["sun"] if rule == "sun"
                                       else e.orbit_normal_N())
            ref = self._roll_rule_ref
        target = self.target_N
        if abs(ref[0] * target[0] + ref[1] * target[1] + ref[2] * target[2]) < _ROLL_RULE_HOLD_COS:
            self.roll_ref_N = ref

    def _pointing(self, t_s: float, q: np.ndarray, omega: np.ndarray) -> GuidanceOutput:
        rule = self.cfg.pointing.roll_reference
        if rule != "inertial" and self.mode == "POINTING":  # SAFE steers the roll to its own reference
            self._follow_roll_rule(t_s, rule)
        if self.mode != "SAFE" and (self._track_started is False or self._track is not None):
            self._track_target(t_s)  # SAFE flies its own aim, the target on the Earth held for POINTING
        if self._inertial_only:
            self._update_arming(boresight_nb(q, self.b_B), t_s)
        pack = self._sky_pack
        if pack is None or "directions" in vars(self.ephem):
            pack = self._sky_pack_now()
        if pack is None:
            rebuilt = self._update_sky(t_s)
            y = boresight_nb(q, self.b_B)
        else:
            # steady state in one compiled call (design note 15); when a zone must be rebuilt, the law is
            # stale or the aim moves on, the kernel stops after the sky and the boresight and the cycle
            # goes on below, in the order of the Python it replaces
            follower = self._follower
            steady = (self._sky_law_key is not None and self._law_pack is not None and not self._escaping
                      and not self.sky_geometry.unmerged
                      and not (follower is not None
                               and t_s - self._planned_t >= self.cfg.pointing.path.replan_period_s))
            fp = self._cycle_inputs(t_s, 1.0 if steady else 0.0)
            law = self._law_pack or _NO_LAW
            res = np.empty(R_DRIFT + 2 * len(pack[0]))
            if pointing_step_nb(q, fp, pack[0], follower.path if follower is not None else _NO_PATH, law[0], law[1],
                                pack[1], pack[2], res) != 0.0:
                return self._pointing_output(t_s, res, res[R_Y:R_Y + 3], True)
            rebuilt = self._apply_sky(res)
            y = res[R_Y:R_Y + 3]
        u_law = self.target_N
        governor_rate = -1.0
        out = None
        if self.slots:
            # escape from the gap of an unmergeable pair: start inside the standoff of both zones, end
            # once 1.5 standoffs clear of one of them (the hysteresis keeps it from flickering)
            escaping = self._squeezed(y, 1.5) if self._escaping else self._squeezed(y, 1.0)
            if escaping != self._escaping:
                self._escaping, self._sky_law_key = escaping, None
                if escaping and t_s - self._escape_event_t >= 60.0:
                    self._escape_event_t = t_s
                    self.events("ASSUMPTION_VIOLATED", reason="boresight between two close zones that cannot merge: steering out of the gap")
            if rebuilt or self._sky_law_key is None or (
                    self._aim_from(res) if pack is not None and res[R_AIM_DONE] != 0.0 else self._aim_moved(t_s, y)):
                self._rebuild_sky_law(t_s, y)
            pack = self._sky_pack_now()
            if pack is not None and self._law_pack is not None:
                n = len(self.slots)
                res = np.empty(R_DRIFT + 2 * n)
                drift = np.array([s.phys_drift_deg for s in self.slots])
                fp = self._cycle_inputs(t_s, 0.0)
                law = self._law_pack
                pointing_law_nb(q, y, fp, law[0], law[1], pack[1], pack[2], drift, res)
                return self._pointing_output(t_s, res, y, False)
            out = GuidanceOutput(None, "POINTING", boresight_N=y, target_N=self.target_N.copy())
            out.sun_N, out.moon_N = self._dirs.get("sun", out.sun_N), self._dirs.get("moon", out.moon_N)
            if not self._sky_law_zones:  # every zone disarmed: straight for the target
                u_law, zone = self._sky_target, None
            else:
                if self._sky_law is None:  # the law as arrays only so far (`_set_sky_law`): the same law as an object
                    self._sky_law = _make_star_law(self._sky_target, self._sky_law_zones, 1.0, self.kappa, self._sky_eps)
                u_law, zone = self._sky_law.control_and_zone(y)
            out.eps, out.eps_max = self._sky_eps, self._sky_eps_max
            out.active_zone = -1 if zone is None else self._sky_groups[zone][0]
            out.margins_deg, out.margin_min_deg = self._sky_margins(y)
            out.zones_merged = any(len(g) > 1 for g in self._sky_groups)
            out.zone_count = len(self.slots)
            out.zone_bodies = self._slot_body_codes()
            governor_rate = self._governor_rate(out.margins_deg)
        else:
            out = GuidanceOutput(None, "POINTING", boresight_N=y, target_N=self.target_N.copy())
            out.sun_N, out.moon_N = self._dirs.get("sun", out.sun_N), self._dirs.get("moon", out.moon_N)
        out.assumptions_ok = self.assumptions_ok
        # the law's rate b^x R^T k1 u within the rate limit and the governor's rate; the roll rate is about
        # the boresight, the law's rate normal to it: the roll gets what the rate limit leaves, so the body
        # rate as a whole stays within the limit (at most half of it). One compiled call (`_kernels`).
        c = pointing_command_nb(q, y, self.b_B, np.ascontiguousarray(u_law, dtype=float), self.k1,
                                self.max_rate_rad_s, governor_rate, self.target_N, self.roll_axis_B,
                                self.roll_ref_N, self.cfg.pointing.roll_gain_1_s)
        out.pointing_error_deg = float(c[4])
        self._watch_progress(t_s, y, out.pointing_error_deg, float(c[3]), out.active_zone)
        out.omega_cmd_BN_B = c[:3]
        out.roll_error_deg = math.degrees(c[5])
        return out

    def _rebuild_sky_law(self, t_s: float, y: np.ndarray) -> None:
        """The law for the zones as they are now, the boresight ``y`` and the aim: merging, the path check,
        eps, the substitute target. What only depends on the zones is kept while they stay the same objects
        (merge without a close pair, the pairwise eps bound, the law's zone arrays)."""
        armed = self._armed
        zones = [self.slots[k].law for k in armed]
        geometry = self.sky_geometry
        merged, groups = self._merge_law_zones(zones, y)
        if len(armed) != len(self.slots):  # the merge's groups index the armed zones: as slot indices
            groups = [[armed[j] for j in g] for g in groups]
        if groups != self._sky_groups:
            self._report_merge(self._sky_groups, groups)
            self._checks_dirty = True
        self._sky_groups = groups
        self._sky_group_first = [g[0] for g in groups]
        self._sky_zones_merged = any(len(g) > 1 for g in groups)
        self._sky_law_zones = merged
        if self._plan_due or self._path_blocked(t_s, merged + geometry.pending):
            self._plan(t_s, y, merged + geometry.pending)
        aim = self._aim
        zpack = self._law_zones_pack(merged)
        seps = None if zpack is None else zone_separations_nb(aim, *zpack).tolist()
        eps_max = self._fast_eps_max(aim, merged, geometry.unmerged, seps)
        eps = self._eps_for(eps_max)
        target, occ = self._substitute_target(t_s, merged, eps, geometry.pending, y, aim, seps)
        if occ != self._occulted:
            if occ >= len(merged) and not self._escaping:
                self.events("ASSUMPTION_VIOLATED", reason="target between two zones closing around the boresight: steering out of the gap")
            elif 0 <= occ < len(merged):
                self.events("ASSUMPTION_VIOLATED", reason=TARGET_IN_LAYER.format(zone=self._sky_group_first[occ]))
            self._occulted = occ
            self._checks_dirty = True
        if occ >= 0:
            eps_max = ZoneGeometry.fast_eps_max(target, merged, geometry.unmerged)
            eps = self._eps_for(eps_max)
        self._sky_target = target
        self._sky_eps, self._sky_eps_max = eps, eps_max
        self._current_eps = eps
        self._set_sky_law(target, merged, eps, zpack)
        self._sky_law_key = True

    def _zone_facts(self, zone) -> tuple:
        """What the guidance derives from one zone object (immutable), kept while it is in use: (its
        bounding cap as `sky_zones.cap_of` gives it, its `pack_zones` row and arcs or None, the law's cap
        axis and half-angle and kernel as `gnc.laws.StarShapedLaw` computes them)."""
        facts = self._zone_facts_kept.get(id(zone))
        if facts is not None and facts[0] is zone:
            return facts[1]
        if len(self._zone_facts_kept) > 64:
            self._zone_facts_kept.clear()
        cap = sky_zones.cap_of(zone)
        pack = pack_zones([zone])
        axis, half_angle = zone.bounding_cap
        axis = np.asarray(axis, dtype=float)
        law = (axis / math.sqrt(axis.dot(axis)), float(half_angle), np.asarray(zone.kernel, dtype=float))
        facts = (cap, pack, law)
        self._zone_facts_kept[id(zone)] = (zone, facts)
        return facts

    def _merge_law_zones(self, zones: list, y: np.ndarray) -> tuple[list, list[list[int]]]:
        """`ZoneGeometry.merge` of the law's zones. When no two of them come within the merge gap (its
        first test, on the same caps), the merge returns them as they are, whatever the boresight: then
        without calling it (and at once while they stay the same objects)."""
        geometry = self.sky_geometry
        kept = self._merge_kept
        if not (kept is not None and _same_objects(kept, zones)):
            caps = [self._zone_facts(z)[0] for z in zones]
            gap = geometry.merge_gap_rad
            for gi in range(len(zones)):
                for gj in range(gi + 1, len(zones)):
                    (ai, ri), (aj, rj) = caps[gi], caps[gj]
                    d = math.acos(max(-1.0, min(1.0, float(ai @ aj))))
                    if not d - ri - rj >= gap:  # a close pair: the merge decides
                        self._merge_kept = None
                        return self._merge_close(zones, y)
            self._merge_kept = tuple(zones)
        geometry.pending, geometry.unmerged = [], []
        return list(zones), [[i] for i in range(len(zones))]

    def _merge_close(self, zones: list, y: np.ndarray) -> tuple[list, list[list[int]]]:
        """`ZoneGeometry.merge` of zones with a close pair. Its result depends on the boresight only where it
        judged a pair that was not merged before against it; otherwise the same zone objects with the same
        previous grouping give the same shapes, which are kept (a ground target moves the aim every cycle
        and with it the law, not the merged Sun and Moon)."""
        geometry = self.sky_geometry
        previous = self._local_groups(self._sky_groups)
        kept = self._merge_close_kept
        if kept is not None and _same_objects(kept[0], zones) and kept[1] == previous:
            geometry.pending, geometry.unmerged = list(kept[4]), list(kept[5])
            return list(kept[2]), [list(g) for g in kept[3]]
        merged, groups = geometry.merge(zones, keep_outside=[y], keep_merged=previous)
        self._merge_close_kept = None if geometry.saw_keep_outside else (
            tuple(zones), previous, tuple(merged), [list(g) for g in groups], list(geometry.pending),
            list(geometry.unmerged))
        return merged, groups

    def _law_zones_pack(self, merged: list):
        """`pack_zones` of the law's zones (from each zone's packed row), kept while they are the same
        objects."""
        kept = self._law_zones_kept
        if kept is not None and _same_objects(kept[0], merged):
            return kept[1]
        packs = [self._zone_facts(z)[1] for z in merged]
        if not packs:  # every zone disarmed: a law with no zone to keep out (the kernels take no rows)
            pack = _NO_LAW
        elif any(p is None for p in packs):
            pack = None
        else:
            tab = np.concatenate([p[0] for p in packs])
            start = 0
            for i in range(len(packs)):
                if tab[i, ZT_KIND] != 0.0:
                    tab[i, ZT_START] = start
                    start += int(tab[i, ZT_COUNT])
            pack = (tab, np.ascontiguousarray(np.concatenate([p[1] for p in packs])))
        self._law_zones_kept = (tuple(merged), pack, {}, {})
        return pack

    def _fast_eps_max(self, aim: np.ndarray, merged: list, unmerged: list, seps: list[float] | None) -> float:
        """`ZoneGeometry.fast_eps_max` with the pairwise bound kept for the same zones (it only depends on
        them) and the aim's separations ``seps`` already computed."""
        kept = self._law_zones_kept
        if seps is None or kept is None or kept[1] is None:
            return ZoneGeometry.fast_eps_max(aim, merged, unmerged)
        key = tuple(sorted(tuple(sorted(p)) for p in unmerged))
        bound = kept[2].get(key)
        if bound is None:
            bound = kept[2][key] = ZoneGeometry.pair_bound(merged, unmerged)
        for d in seps:
            bound = min(bound, d)
        return bound

    def _set_sky_law(self, target: np.ndarray, merged: list, eps: float, zpack) -> None:
        """The star-shaped law on ``merged`` towards ``target`` (`gnc.laws.StarShapedLaw` with k1 = 1: its
        checks and its arrays, computed as its constructor does): as arrays for `pointing_step_nb`, the
        zones' part kept for the same zones and kappa; or the law object itself for zones the kernels do
        not know."""
        if zpack is None:
            self._sky_law = _make_star_law(target, merged, 1.0, self.kappa, eps)
            self._law_pack = None
            return
        law_target = _unit_vector(target, "target")
        eps = _positive(eps, "eps")
        if eps >= 2.0:
            raise ValueError(f"eps must be < 2 (the largest separation on the sphere), got {eps}")
        if not merged:
            self._sky_law = None
            self._law_pack = (zpack[0], zpack[1], law_target, eps)
            return
        laws = self._law_zones_kept[3]
        tab = laws.get((self.kappa, eps))
        if tab is None:
            base = laws.get(self.kappa)
            if base is None:
                _zone_list(merged, 3)
                k1, kappa = _positive(1.0, "k1"), _positive(self.kappa, "kappa")
                tab = zpack[0].copy()
                halves = []
                # `gnc.laws._cap_skip_cosines`: the axes here, the cosines (they depend on eps) below
                for i, zone in enumerate(merged):
                    axis, half_angle, g = self._zone_facts(zone)[2]
                    tab[i, ZT_CAP_AXIS:ZT_CAP_AXIS + 3] = axis
                    halves.append(half_angle)
                    tab[i, ZT_KERNEL:ZT_KERNEL + 3] = np.ascontiguousarray((k1 / kappa) * g)
                base = laws[self.kappa] = (tab, halves)
            tab, halves = base[0].copy(), base[1]
            theta_eps = float(np.arccos(1.0 - eps))
            for i, half_angle in enumerate(halves):
                reach = half_angle + theta_eps + 1e-9
                tab[i, ZT_CAP_COS] = np.cos(reach) if reach < np.pi else -2.0  # -2: never skip
            if len(laws) > 32:
                laws.clear()
            laws[(self.kappa, eps)] = tab
        self._sky_law = None
        self._law_pack = (tab, zpack[1], law_target, eps)

    def _sky_pack_now(self):
        """(slot bodies, slot centres, packed physical zones) for the compiled cycle, or None: the Python
        path (no zones, a zone not built yet, an ephemeris replaced by a test, zones the kernels do not know)."""
        pack = self._sky_pack
        if pack is not None:
            return pack if "directions" not in vars(self.ephem) else None
        if not self.slots or "directions" in vars(self.ephem) or any(s.built_center is None for s in self.slots):
            return None
        phys = pack_zones([s.phys for s in self.slots])
        if phys is None:
            return None
        geo = np.zeros((len(self.slots), 4, 3))
        for i, s in enumerate(self.slots):
            if s.fixed_center is not None:
                geo[i, SG_FIXED] = s.fixed_center
            geo[i, SG_BUILT] = s.built_center
            geo[i, SG_BUILT_LAW] = s.built_center_law
            geo[i, SG_BODY, 0] = _BODY_INDEX[s.body]
        self._sky_pack = pack = (geo, *phys)
        return pack

    def _cycle_inputs(self, t_s: float, steady: float) -> np.ndarray:
        """The inputs of `pointing_step_nb` / `pointing_law_nb` (layout FP_*), with last cycle's margins for
        the governor (`_governor_rate`): the cycle's values, and the rest again when one of the values they
        come from was replaced (the target and the roll axes are replaced, never written into: SAFE swaps
        them for its own every cycle)."""
        fp = self._fp
        e = self.ephem
        k = math.floor(t_s / EPHEMERIS_NODE_S)
        f = t_s / EPHEMERIS_NODE_S - k  # as `SkyEphemeris.directions`
        if k != self._eph_k:
            s0, m0 = e._geocentric(k)
            s1, m1 = e._geocentric(k + 1)
            fp[FP_EPH:FP_EPH + 18].reshape(6, 3)[:] = (e.p_hat, e.q_hat, s0, s1, m0, m1)
            self._eph_k = k
        follower = self._follower
        key = self._fp_key
        if (key is None or key[0] is not self.k1 or key[1] is not self.max_rate_rad_s or key[2] is not follower
                or key[3] is not self.accel_deg_s2 or key[4] is not self.bandwidth_rad_s):
            self._fp_key = (self.k1, self.max_rate_rad_s, follower, self.accel_deg_s2, self.bandwidth_rad_s)
            fp[FP_U0:FP_EPS] = (e.u0, e.n_rad_s, e.radius_km, self.k1, self.max_rate_rad_s,
                                self.cfg.pointing.roll_gain_1_s, self.accel_deg_s2, self.bandwidth_rad_s)
            fp[FP_COS_AHEAD] = follower.cos_ahead if follower is not None else 0.0
            fp[FP_FOLLOW] = 1.0 if follower is not None else 0.0
            fp[FP_B:FP_B + 3] = self.b_B
        vecs = self._fp_vecs
        if (vecs is None or vecs[0] is not self.target_N or vecs[1] is not self.roll_axis_B
                or vecs[2] is not self.roll_ref_N):
            self._fp_vecs = (self.target_N, self.roll_axis_B, self.roll_ref_N)
            fp[FP_TARGET:FP_TARGET + 3] = self.target_N
            fp[FP_ROLL_AXIS:FP_ROLL_AXIS + 3] = self.roll_axis_B
            fp[FP_ROLL_REF:FP_ROLL_REF + 3] = self.roll_ref_N
        law = self._law_pack
        if law is not self._fp_law:  # a new law: its eps and target
            self._fp_law = law
            if law is not None:
                fp[FP_EPS] = law[3]
                fp[FP_LAW_TARGET:FP_LAW_TARGET + 3] = law[2]
        fp[FP_T] = t_s
        fp[FP_F] = f
        fp[FP_STEADY] = steady
        if follower is not None:
            fp[FP_START] = follower.index
            fp[FP_AIM_K] = self._aim_k
        prev = self._governor_margins
        if prev is None:
            fp[FP_NPREV] = -1.0
            return fp
        fp[FP_NPREV] = len(prev)
        # the margins the law kernel left in fp last cycle (`_pointing_output` keeps their list), or others
        if prev is not self._governor_kept and len(prev) == len(self.slots):  # the only count the kernels use
            fp[FP_PREV:FP_PREV + len(prev)] = prev
        return fp

    def _aim_from(self, res: np.ndarray) -> bool:
        """`_aim_moved` (`advance_aim`) with the path index the kernel found this cycle."""
        f = self._follower
        f.index = int(res[R_NEAREST])
        k = int(res[R_AIM])
        if k == self._aim_k:
            return False
        if k == len(f.path) - 1:  # the path is done: the last leg is the paper's law to the real target
            self._follower, self._aim, self._aim_k = None, self.target_N, -1
        else:
            self._aim, self._aim_k = f.path[k], k
        return True

    def _apply_sky(self, res: np.ndarray) -> bool:
        """`_update_sky` from the kernel's sky: the slots' centres and drifts, and the one rebuild it asks
        for. True if a law zone was rebuilt."""
        self._sky_res = res
        self._settle_sky()
        w = int(res[R_WORST])
        if w < 0:
            return False
        slot = self.slots[w]
        c = slot.center_N
        self._sky_pack = None
        if res[R_WORST_KIND] == 0.0:
            slot.law = slot.builder_law.build(c)
            slot.built_center_law = c.copy()
            return True
        slot.phys = slot.builder_phys.build(c)
        slot.built_center = c.copy()
        slot.phys_drift_deg = angle_deg(c, slot.built_center)
        return False

    def _settle_sky(self) -> None:
        """The sky of the last compiled cycle (`pointing_step_nb`'s ``res``), if not applied yet, as
        `_update_sky` leaves it: the directions (`_dirs`), the slots' centres and drifts."""
        res = self._sky_res
        if res is None:
            return
        self._sky_res = None
        dirs = self._dirs = {"sun": res[0:3], "moon": res[3:6], "earth": res[6:9]}
        for s, drift in zip(self.slots, res[R_DRIFT:R_DRIFT + len(self.slots)].tolist()):
            s.center_N = s.fixed_center if s.fixed_center is not None else dirs[s.body]
            s.phys_drift_deg = drift

    def _pointing_output(self, t_s: float, res: np.ndarray, y: np.ndarray, compiled_sky: bool) -> GuidanceOutput:
        """The cycle's output from `pointing_law_nb`'s results; the governor's and the watchdog's state, and
        with ``compiled_sky`` (the whole cycle was one call) the sky as `_update_sky` leaves it (applied to
        the slots when read, `_settle_sky`)."""
        vals = res.tolist()  # the scalars as Python floats in one call (not an array slice or scalar each)
        if vals[R_LAW_ERROR] != 0.0:
            raise ValueError(f"state x must be a unit vector on S^2, |x|^2 = {float(y @ y)!r}")
        slots = self.slots
        n = len(slots)
        if compiled_sky:
            self._sky_res = res  # the slots' sky, applied when read (`_settle_sky`)
            sun, moon = res[0:3], res[3:6]
            follower = self._follower
            if follower is not None:
                follower.index = int(vals[R_NEAREST])
        else:
            dirs = self._dirs
            sun, moon = dirs.get("sun", _NAN3), dirs.get("moon", _NAN3)
        zone = int(vals[R_ZONE])
        active = -1 if zone < 0 else self._sky_group_first[zone]
        error = vals[R_ERROR]
        target = self._target_out
        if target[0] is not self.target_N:  # a new target: its copy for the outputs, read-only as they share it
            copy = self.target_N.copy()
            copy.flags.writeable = False
            target = self._target_out = (self.target_N, copy)
        # the record's dict in one step (the dataclass constructor, with its keyword handling and default
        # factories, cost ~3 us a cycle)
        out = object.__new__(GuidanceOutput)
        out.__dict__ = {
            "omega_cmd_BN_B": res[R_OMEGA:R_OMEGA + 3], "mode": "POINTING", "safe_phase": "NONE",
            "active_zone": active, "eps": self._sky_eps, "eps_max": self._sky_eps_max,
            "margins_deg": vals[R_DRIFT + n:R_DRIFT + 2 * n], "margin_min_deg": vals[R_MARGIN_MIN],
            "pointing_error_deg": error, "att_error_deg": math.nan, "roll_error_deg": math.degrees(vals[R_ROLL]),
            "boresight_N": y, "target_N": target[1], "q_target_NB": _NAN4,
            "zones_merged": self._sky_zones_merged, "assumptions_ok": self.assumptions_ok, "sun_N": sun,
            "moon_N": moon, "zone_count": n, "zone_bodies": self._body_codes,
        }
        # the margins as the law kernel left them in fp[FP_PREV:] for the next cycle's governor
        self._governor_margins = self._governor_kept = vals[R_DRIFT + n:R_DRIFT + 2 * n]
        # the progress watchdog (`_watch_progress`): a cycle that is not idle (its test in
        # `ProgressWatchdog.update`) only restarts the watch
        law_rate = vals[R_LAW_RATE]
        watchdog = self._watchdog
        if (watchdog.window_s > 0.0 and active < 0 and self._occulted < 0 and not self._escaping
                and error >= MIN_ERROR_DEG and law_rate < RATE_FRACTION * self.max_rate_rad_s):
            self._watch_progress(t_s, y, error, law_rate, active)
        else:
            watchdog.reset()
        return out


    def _slot_body_codes(self) -> list[str]:
        """Telemetry code of each slot's body (the slots are fixed at start-up, `Guidance.__init__`): one
        list, read-only by use."""
        return self._body_codes

    def _squeezed(self, y: np.ndarray, factor: float) -> bool:
        """True if the boresight is within factor x the standoff of both zones of a close pair that could
        not merge (checked every cycle: two separations per pair)."""
        if not self.sky_geometry.unmerged:
            return False
        d = 1.0 - math.cos(math.radians(factor * self.cfg.law.retreat_standoff_deg))
        zones = self._sky_law_zones
        return any(float(zones[i].separation(y)) < d and float(zones[j].separation(y)) < d
                   for i, j in self.sky_geometry.unmerged)

    SUBSTITUTE_REFRESH_S = 60.0


    def _substitute_target(self, t_s: float, zones: list, eps: float, pending: list, y: np.ndarray,
                           aim: np.ndarray, seps: list[float] | None = None) -> tuple[np.ndarray, int]:
        """`ZoneGeometry.retreat_target` for the law's aim (the commanded target, or the point ahead on
        the planned path), reusing the last substitute while it is
        still clear of every zone by the standoff (a search costs milliseconds; zones rebuild every ~1 s
        in low orbit). It is searched again when it stops being clear, and at least every
        SUBSTITUTE_REFRESH_S, so it comes back towards the target as the zones move on.

        While the boresight is squeezed between two close zones that could not merge (`_squeezed`), or
        inside the would-be merged shape of such a pair, it first gets out: the law target is then the
        nearest direction clear of every zone by the standoff, on the commanded target's side. Such a pair
        leaves the law no admissible eps between its zones, so that is the one place it must not stay.
        ``seps``: the zones' separations from ``aim`` when already computed."""
        standoff = self.cfg.law.retreat_standoff_deg
        d_free = ZoneGeometry.clear_separation(standoff, eps)
        clear = lambda x: all(float(z.separation(x)) > d_free for z in list(zones) + list(pending))  # noqa: E731
        if self._escaping or any(p.contains(y) for p in pending):
            escape = self._escape_point
            if escape is None or not clear(escape):
                escape, _ = ZoneGeometry.retreat_target(y, zones, eps, standoff, avoid=pending, near=aim, force=True)
                self._escape_point = escape
            return escape, len(zones) + len(pending)
        self._escape_point = None
        kept = self._substitute
        if kept is not None and kept[0] is aim and t_s - kept[2] < self.SUBSTITUTE_REFRESH_S:
            _, x, _, occ_then = kept
            occ = (ZoneGeometry.occulting(aim, zones, eps, pending) if seps is None
                   else ZoneGeometry.occulting_from(seps, aim, eps, pending))
            if occ >= 0 and occ_then >= 0 and clear(x):
                return x, occ
            if occ < 0:  # what retreat_target answers for a usable target, without looking again
                self._substitute = (aim, aim, t_s, -1)
                return aim, -1
        if seps is not None and ZoneGeometry.occulting_from(seps, aim, eps, pending) < 0:
            x, occ = aim, -1  # what retreat_target answers for a usable target
        else:
            x, occ = ZoneGeometry.retreat_target(aim, zones, eps, standoff, avoid=pending, near=y)
        self._substitute = (aim, x, t_s, occ)
        return x, occ

    def _report_merge(self, old: list[list[int]], new: list[list[int]]) -> None:
        self._settle_sky()
        old_pairs = {(g[0], j) for g in old for j in g[1:]}
        new_pairs = {(g[0], j) for g in new for j in g[1:]}
        for a, b in sorted(new_pairs - old_pairs):
            ca, cb = self.slots[a].center_N, self.slots[b].center_N
            sep = math.degrees(math.acos(max(-1.0, min(1.0, float(ca @ cb)))))
            self.events("ZONES_MERGED", zone_a=a, zone_b=b, separation_deg=sep)
        for a, b in sorted(old_pairs - new_pairs):
            self.events("ZONES_SPLIT", zone_a=a, zone_b=b)
