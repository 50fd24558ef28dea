"""Zone merging and the law's view of a set of zones: close zones grouped into one shape (an enclosing
cone or a bridge), the admissible eps (Assumption 1 from bounding caps), and the substitute target when
the commanded one lies in a zone's eps-layer.

`merge_zones` is the public entry (also used by the configuration's load-time checks); `ZoneGeometry`
keeps what a merge left over (pairs that could not merge, their would-be shapes) for the guidance.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.guidance.common import signed_margin_deg
from gnc import sky_zones


class ZoneGeometry:
    """The law's view of a set of zones for one target: merging, admissible eps, retreat target."""

    def __init__(self, dim: int, merge_gap_deg: float):
        self.dim = dim
        self.merge_gap_rad = math.radians(merge_gap_deg)
        self.groups: list[list[int]] = []
        self.pending: list = []  # would-be shapes of close pairs that could not merge around the boresight
        self.unmerged: list[tuple[int, int]] = []  # every close pair left separate, as indices into merge()'s output
        self.saw_keep_outside = False  # the last merge() judged a new pair against keep_outside

    MAX_MERGED_RADIUS_RAD = math.radians(80.0)

    def merge(self, zones: list, keep_outside: list[np.ndarray] = (),
              keep_merged: list[list[int]] = ()) -> tuple[list, list[list[int]]]:
        """Group zones whose bounding caps are closer than the merge gap; a group becomes one cone.

        When the enclosing cone would exceed 80 deg or would swallow a point of ``keep_outside`` (the
        current boresight: a cone grown around the spacecraft's own pointing would leave the law nowhere
        to go), the two sides are bridged instead: one star polygon containing both caps and little else
        (`gnc.sky_zones.bridge_zone`), which leaves the notch between them free. A group already merged
        takes part through its enclosing cone (Sun and Moon merged near new moon, then the Earth zone
        sweeping by). A pair that belonged to one group of ``keep_merged`` (the previous grouping) stays
        merged even when its shape has grown over the boresight: splitting it would leave two zones too
        close for Assumption 1 around the spacecraft, while inside the merged zone the law pushes the
        boresight straight out of it. A new pair whose shapes would both swallow the boresight stays
        separate and its would-be shape is kept in ``self.pending``: the spacecraft sits in the closing
        gap between the two zones and has to leave it (`retreat_target` avoids pending shapes) before the
        pair can merge. The 24 h soak found that case as a keep-out violation when the Earth zone swept
        towards the Moon zone with the boresight parked between them.
        """
        # groups of zone indices, each with its shape and bounding cap; pairs of groups closer than the
        # gap merge until none is left (judged on the merged shapes: a cone grown around Sun and Moon can
        # reach the Earth zone although neither of them does)
        zone_caps = [sky_zones.cap_of(z) for z in zones]
        groups, shapes, caps = [[i] for i in range(len(zones))], list(zones), list(zone_caps)
        refused: set[tuple[tuple[int, ...], tuple[int, ...]]] = set()
        self.pending = []
        self.saw_keep_outside = False
        previous = [set(g) for g in keep_merged]
        while (found := self._first_merge(groups, caps, zone_caps, keep_outside, refused, previous)) is not None:
            gi, gj, shape = found
            members = sorted(groups[gi] + groups[gj])
            for k in (gj, gi):
                del groups[k], shapes[k], caps[k]
            groups.append(members)
            shapes.append(shape)
            caps.append(sky_zones.cap_of(shape))
        order = sorted(range(len(groups)), key=lambda k: groups[k][0])
        position = {tuple(groups[k]): n for n, k in enumerate(order)}
        self.unmerged = [(position[a], position[b]) for a, b in refused if a in position and b in position]
        return [shapes[k] for k in order], [groups[k] for k in order]

    def _first_merge(self, groups, caps, zone_caps, keep_outside, refused, previous):
        """(gi, gj, merged shape) for the first pair of groups to merge, or None. A pair that can be
        neither coned nor bridged is remembered in ``refused`` (and its shape in ``self.pending`` when a
        keep-out point was what stopped it)."""
        for gi in range(len(groups)):
            for gj in range(gi + 1, len(groups)):
                pair = (tuple(groups[gi]), tuple(groups[gj]))
                (ai, ri), (aj, rj) = caps[gi], caps[gj]
                d = math.acos(max(-1.0, min(1.0, float(ai @ aj))))
                if pair in refused or d - ri - rj >= self.merge_gap_rad:
                    continue
                sticky = any(set(pair[0] + pair[1]) <= g for g in previous)
                avoid = () if sticky else keep_outside
                self.saw_keep_outside = self.saw_keep_outside or bool(len(avoid))
                shape = sky_zones.enclosing_cone([zone_caps[k] for k in groups[gi] + groups[gj]])
                if shape.bounding_cap[1] > self.MAX_MERGED_RADIUS_RAD or any(shape.contains(p) for p in avoid):
                    cone = shape if shape.bounding_cap[1] <= self.MAX_MERGED_RADIUS_RAD else None
                    shape = sky_zones.bridge_zone(caps[gi], caps[gj]) if self.dim == 3 else None
                    if shape is None or any(shape.contains(p) for p in avoid):
                        refused.add(pair)
                        if shape is not None or cone is not None:
                            self.pending.append(shape if shape is not None else cone)
                        continue
                return gi, gj, shape
        return None

    @staticmethod
    def fast_eps_max(target: np.ndarray, zones: list, ignore: list[tuple[int, int]] = ()) -> float:
        """min(1 - cos(delta), d_s(x_d, U)) with delta from bounding caps (a conservative lower bound).

        Pairs in ``ignore`` (close pairs that could not merge: `merge` sets them aside) do not count:
        they have no admissible eps at all, and letting them drive eps to zero would take the law's
        repulsion away everywhere, not just at their neck, which the substitute target keeps the
        spacecraft out of. The full assumption check still reports them."""
        bound = ZoneGeometry.pair_bound(zones, ignore)
        for z in zones:
            bound = min(bound, float(z.separation(target)))
        return bound

    @staticmethod
    def pair_bound(zones: list, ignore: list[tuple[int, int]] = ()) -> float:
        """The part of `fast_eps_max` that depends on the zones alone: min(1, 1 - cos(delta)) over the
        pairs not in ``ignore`` (the guidance keeps it while the zones stay the same)."""
        bound = 1.0
        caps = [sky_zones.cap_of(z) for z in zones]
        skip = {tuple(sorted(p)) for p in ignore}
        for i in range(len(zones)):
            for j in range(i + 1, len(zones)):
                if (i, j) in skip:
                    continue
                gap = math.acos(max(-1.0, min(1.0, float(caps[i][0] @ caps[j][0])))) - caps[i][1] - caps[j][1]
                delta = max(gap, 0.0) / 2.0
                bound = min(bound, 1.0 - math.cos(delta))
        return bound

    RETREAT_RING_STEP_DEG = 1.0
    RETREAT_AZIMUTHS = 36
    RETREAT_RINGS_PER_BATCH = 8  # ~300 directions: one separation_batch call per zone, ~2 ms with the Earth polygon

    @staticmethod
    def clear_separation(standoff_deg: float, eps: float) -> float:
        """d_s a direction must exceed to be clear of a zone: the standoff, and never inside the eps-layer."""
        return max(1.0 - math.cos(math.radians(standoff_deg)), 1.5 * eps)

    @staticmethod
    def occulting(target: np.ndarray, zones: list, eps: float, avoid: list = ()) -> int:
        """Index of the zone whose eps-layer holds the target, len(zones) + k if the k-th avoid shape
        contains it, -1 if the target is usable."""
        return ZoneGeometry.occulting_from([float(z.separation(target)) for z in zones], target, eps, avoid)

    @staticmethod
    def occulting_from(separations: list[float], target: np.ndarray, eps: float, avoid: list = ()) -> int:
        """`occulting` with the zones' separations from the target already computed (in zone order)."""
        occ = next((i for i, d in enumerate(separations) if d <= eps), -1)
        if occ < 0:
            occ = next((len(separations) + k for k, z in enumerate(avoid) if z.contains(target)), -1)
        return occ

    @staticmethod
    def retreat_target(target: np.ndarray, zones: list, eps: float, standoff_deg: float,
                       avoid: list = (), near: np.ndarray | None = None, force: bool = False) -> tuple[np.ndarray, int]:
        """Substitute law target when ``target`` is unusable: (direction, index of the zone whose
        eps-layer holds it, len(zones) + k for the k-th ``avoid`` shape, or -1 when it is usable).

        The target is unusable inside a zone's eps-layer (the paper needs x_d outside every layer) or
        inside an ``avoid`` shape (a pair of zones about to merge around the spacecraft). The substitute is
        the nearest direction at least ``standoff_deg`` outside every zone and every avoid shape: rings
        around the target, the first ring with a free direction, on it the one nearest ``near`` (the
        boresight, so the spacecraft does not cross the sky for an equally good point). The standoff keeps
        a parked boresight clear of a zone sweeping towards it (the Earth from low orbit moves 0.06 deg/s)
        and out of every gap narrower than twice the standoff, so out of gaps about to merge. When nothing
        within 180 deg is free, the farthest ring's first direction is returned (the assumption check then
        reports the violation). ``force`` searches whatever the target (index len(zones) + len(avoid)).
        """
        occ = len(zones) + len(avoid) if force else ZoneGeometry.occulting(target, zones, eps, avoid)
        if occ < 0:
            return target, -1
        d_free = ZoneGeometry.clear_separation(standoff_deg, eps)
        # no direction nearer than the target's depth inside a zone plus the standoff can be free: the
        # search starts there (a target deep inside the 81 deg Earth zone would otherwise test ~100 rings
        # of polygon separations, 0.1-0.3 s, which the first 24 h soak with this search saw as cycle slips)
        depth = max([-signed_margin_deg(z, target) for z in list(zones) + list(avoid)] + [0.0])
        e1 = np.roll(target, 1) - (np.roll(target, 1) @ target) * target
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(target, e1)
        az = np.linspace(0.0, 2.0 * math.pi, ZoneGeometry.RETREAT_AZIMUTHS, endpoint=False)
        ring_dirs = np.cos(az)[:, None] * e1 + np.sin(az)[:, None] * e2
        step = math.radians(ZoneGeometry.RETREAT_RING_STEP_DEG)
        rings = int(math.pi / step)
        start = max(1, int(math.radians(depth + standoff_deg) / step))
        P = target
        batch = ZoneGeometry.RETREAT_RINGS_PER_BATCH
        for first in range(start, rings + 1, batch):
            r = step * np.arange(first, min(first + batch, rings + 1))
            P = (np.cos(r)[:, None, None] * target + np.sin(r)[:, None, None] * ring_dirs).reshape(-1, 3)
            free = np.ones(len(P), dtype=bool)
            for z in list(zones) + list(avoid):
                free &= z.separation_batch(P) > d_free
            if free.any():
                ring = int(np.flatnonzero(free)[0]) // len(az)
                cand = np.flatnonzero(free[ring * len(az):(ring + 1) * len(az)]) + ring * len(az)
                pick = cand[int(np.argmax(P[cand] @ near))] if near is not None else cand[0]
                return P[pick] / np.linalg.norm(P[pick]), occ
        return P[-1] / np.linalg.norm(P[-1]), occ


def merge_zones(zones: list, merge_gap_deg: float, keep_outside: list[np.ndarray] = (),
                keep_merged: list[list[int]] = (), dim: int = 3) -> tuple[list, list[list[int]]]:
    """(law zones, groups of input indices) after merging the zones closer than ``merge_gap_deg``
    [deg]; see `ZoneGeometry.merge` for the rules (enclosing cone, bridge, ``keep_outside`` points)."""
    return ZoneGeometry(dim, merge_gap_deg).merge(zones, keep_outside, keep_merged)
