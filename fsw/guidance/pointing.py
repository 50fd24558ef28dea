"""POINTING mode: the instrument boresight on S^2 kept out of the Sun, Moon and Earth zones.

The zones are rebuilt from the onboard ephemeris as they move (physical ones for the margins, inflated ones
for the law), merged when close (`zone_merging`), and the `gnc.laws.StarShapedLaw` steers the boresight
to the target, or to a substitute when the target lies in a zone's eps-layer, or out of the closing gap
between two zones that cannot merge; `gnc.attitude.pointing_rate_command_nb` maps the law's ``u`` to a
body rate with no component about the boresight. A separate proportional roll law turns about the
boresight (it cannot move the boresight, so it cannot affect keep-out).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fsw.guidance._kernels import boresight_nb, pointing_command_nb
from fsw.guidance.common import _BODY_CODES, GuidanceOutput, _angle_deg, _make_star_law, signed_margin_deg
from fsw.guidance.zone_merging import ZoneGeometry
from gnc import sky_zones

ZONE_REBUILD_TOL_DEG = 0.1  # extra inflation of the law's zones covering their motion between rebuilds
LAW_REBUILD_TRIGGER_DEG = 0.08
PHYS_REBUILD_TOL_DEG = 0.5


def _warm_batch_kernels(builders: list) -> None:
    """Run each zone shape's batch separation once: the substitute-target search is their first caller,
    possibly hours into a run, and loading their compiled code there took 0.3-0.7 s (a cycle slip in the
    soak). One zone per builder, any centre."""
    probe = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    for builder in builders:
        builder.build(np.array([1.0, 0.0, 0.0])).separation_batch(probe)


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


class PointingGuidance:
    """Mixin of `fsw.guidance.Guidance`: POINTING mode and the sky zones every mode reports margins on."""

    def _update_sky(self, t_s: float) -> bool:
        """Recompute zone centres; rebuild zones that moved too far. True if a law zone was rebuilt.

        Law zones (inflated by the extra ZONE_REBUILD_TOL_DEG) are rebuilt when their centre has moved
        by LAW_REBUILD_TRIGGER_DEG; physical zones (margin telemetry, FDIR) after PHYS_REBUILD_TOL_DEG,
        their margins corrected by the drift meanwhile. At most one zone is rebuilt per cycle (the
        largest drift first), which keeps the cycle time flat; the slack between trigger and inflation
        covers the cycles a pending rebuild may wait.
        """
        dirs = self.ephem.directions(t_s) if self.slots else {}
        self._dirs = dirs
        worst, worst_kind, worst_slot = 0.0, None, None
        first = False
        for s in self.slots:
            c = s.fixed_center if s.fixed_center is not None else dirs[s.body]
            s.center_N = c
            if s.built_center is None:
                s.phys, s.law = s.builder_phys.build(c), s.builder_law.build(c)
                s.built_center, s.built_center_law = c.copy(), c.copy()
                s.phys_drift_deg = _angle_deg(c, s.built_center)
                first = True
                continue
            s.phys_drift_deg = _angle_deg(c, s.built_center)
            law_drift = _angle_deg(c, s.built_center_law) / LAW_REBUILD_TRIGGER_DEG
            phys_drift = s.phys_drift_deg / PHYS_REBUILD_TOL_DEG
            for drift, kind in ((law_drift, "law"), (phys_drift, "phys")):
                if drift >= 1.0 and drift > worst:
                    worst, worst_kind, worst_slot = drift, kind, s
        if worst_slot is not None:
            c = worst_slot.center_N
            if worst_kind == "law":
                worst_slot.law = worst_slot.builder_law.build(c)
                worst_slot.built_center_law = c.copy()
            else:
                worst_slot.phys = worst_slot.builder_phys.build(c)
                worst_slot.built_center = c.copy()
                worst_slot.phys_drift_deg = _angle_deg(c, worst_slot.built_center)
        return first or worst_kind == "law"


    def _sky_margins(self, y_N: np.ndarray) -> tuple[list[float], float]:
        """Signed physical margins [deg], conservative: minus the zone's drift since it was built (as
        `_update_sky` found it this cycle)."""
        margins = [signed_margin_deg(s.phys, y_N) - s.phys_drift_deg for s in self.slots]
        return margins, (min(margins) if margins else float("nan"))


    def _pointing(self, t_s: float, q: np.ndarray, omega: np.ndarray) -> GuidanceOutput:
        rebuilt = self._update_sky(t_s)
        y = boresight_nb(q, self.b_B)
        out = GuidanceOutput(None, "POINTING", boresight_N=y, target_N=self.target_N.copy())
        out.sun_N, out.moon_N = self._dirs.get("sun", out.sun_N), self._dirs.get("moon", out.moon_N)
        u_law = self.target_N
        governor_rate = -1.0
        if self.slots:
            # escape from the gap of an unmergeable pair: start inside the standoff of both zones, end
            # once 1.5 standoffs clear of one of them (the hysteresis keeps it from flickering)
            escaping = self._squeezed(y, 1.5) if self._escaping else self._squeezed(y, 1.0)
            if escaping != self._escaping:
                self._escaping, self._sky_law_key = escaping, None
                if escaping and t_s - self._escape_event_t >= 60.0:
                    self._escape_event_t = t_s
                    self.events("ASSUMPTION_VIOLATED", reason="boresight between two close zones that cannot merge: steering out of the gap")
            if rebuilt or self._sky_law_key is None or self._aim_moved(t_s, y):
                zones = [s.law for s in self.slots]
                geometry = self.sky_geometry
                merged, groups = geometry.merge(zones, keep_outside=[y], keep_merged=self._sky_groups)
                if groups != self._sky_groups:
                    self._report_merge(self._sky_groups, groups)
                    self._checks_dirty = True
                self._sky_groups = groups
                self._sky_law_zones = merged
                if self._plan_due or self._path_blocked(t_s, merged + geometry.pending):
                    self._plan(t_s, y, merged + geometry.pending)
                aim = self._aim
                eps_max = ZoneGeometry.fast_eps_max(aim, merged, geometry.unmerged)
                eps = self._eps_for(max(eps_max, 1e-5))
                target, occ = self._substitute_target(t_s, merged, eps, geometry.pending, y, aim)
                if occ != self._occulted:
                    if occ >= len(merged) and not self._escaping:
                        self.events("ASSUMPTION_VIOLATED", reason="target between two zones closing around the boresight: steering out of the gap")
                    elif 0 <= occ < len(merged):
                        self.events("ASSUMPTION_VIOLATED", reason=f"target in the eps-layer of zone {occ}: steering to the nearest safe direction")
                    self._occulted = occ
                    self._checks_dirty = True
                if occ >= 0:
                    eps_max = ZoneGeometry.fast_eps_max(target, merged, geometry.unmerged)
                    eps = self._eps_for(max(eps_max, 1e-5))
                self._sky_target = target
                self._sky_eps, self._sky_eps_max = eps, eps_max
                self._current_eps = eps
                self._sky_law = _make_star_law(target, merged, 1.0, self.kappa, eps)
                self._sky_law_key = True
            u_law, zone = self._sky_law.control_and_zone(y)
            out.eps, out.eps_max = self._sky_eps, self._sky_eps_max
            out.active_zone = -1 if zone is None else self._sky_groups[zone][0]
            out.margins_deg, out.margin_min_deg = self._sky_margins(y)
            out.zones_merged = any(len(g) > 1 for g in self._sky_groups)
            out.zone_count = len(self.slots)
            out.zone_bodies = self._slot_body_codes()
            governor_rate = self._governor_rate(out.margins_deg)
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


    def _slot_body_codes(self) -> list[str]:
        """Telemetry code of each slot's body (the slots are fixed at start-up): one list, read-only by use."""
        codes = getattr(self, "_body_codes", None)
        if codes is None:
            codes = self._body_codes = [_BODY_CODES[s.body] for s in self.slots]
        return codes

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
                           aim: np.ndarray) -> tuple[np.ndarray, int]:
        """`ZoneGeometry.retreat_target` for the law's aim (the commanded target, or the point ahead on
        the planned path), reusing the last substitute while it is
        still clear of every zone by the standoff (a search costs milliseconds; zones rebuild every ~1 s
        in low orbit). It is searched again when it stops being clear, and at least every
        SUBSTITUTE_REFRESH_S, so it comes back towards the target as the zones move on.

        While the boresight is squeezed between two close zones that could not merge (`_squeezed`), or
        inside the would-be merged shape of such a pair, it first gets out: the law target is then the
        nearest direction clear of every zone by the standoff, on the commanded target's side. Such a pair
        leaves the law no admissible eps between its zones, so that is the one place it must not stay."""
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
            occ = ZoneGeometry.occulting(aim, zones, eps, pending)
            if occ >= 0 and occ_then >= 0 and clear(x):
                return x, occ
            if occ < 0:  # what retreat_target answers for a usable target, without looking again
                self._substitute = (aim, aim, t_s, -1)
                return aim, -1
        x, occ = ZoneGeometry.retreat_target(aim, zones, eps, standoff, avoid=pending, near=y)
        self._substitute = (aim, x, t_s, occ)
        return x, occ

    def _report_merge(self, old: list[list[int]], new: list[list[int]]) -> None:
        old_pairs = {(g[0], j) for g in old for j in g[1:]}
        new_pairs = {(g[0], j) for g in new for j in g[1:]}
        for a, b in sorted(new_pairs - old_pairs):
            ca, cb = self.slots[a].center_N, self.slots[b].center_N
            sep = math.degrees(math.acos(max(-1.0, min(1.0, float(ca @ cb)))))
            self.events("ZONES_MERGED", zone_a=a, zone_b=b, separation_deg=sep)
        for a, b in sorted(old_pairs - new_pairs):
            self.events("ZONES_SPLIT", zone_a=a, zone_b=b)

