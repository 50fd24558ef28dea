"""Guidance: the modes (SAFE, POINTING, QUATERNION), the keep-out zones, and the paper's laws.

Each GNC cycle the active mode turns the attitude estimate into a body-rate command ``omega_cmd_BN_B``:

* POINTING: the instrument boresight ``y_N = R_NB b_B`` is the state on S^2. Sun, Moon and Earth zones
  are rebuilt from the onboard ephemeris (`gnc.sky_zones`), inflated by ``law.margin_deg``; the
  `gnc.laws.StarShapedLaw` gives ``u`` and `gnc.attitude.pointing_rate_command` gives
  ``omega = b^x R^T u`` (no component about the boresight). A separate proportional roll law turns
  about the boresight so that ``roll_axis_B`` lines up with ``roll_reference_N`` in the plane normal to
  the boresight (it cannot move the boresight, so it cannot affect keep-out).
* QUATERNION: the state is the attitude quaternion on S^3, zones are forbidden-attitude sets on S^3.
  `GradientLaw` when every zone is a cone (and law is 'auto' or 'gradient'), else `StarShapedLaw`;
  ``omega = 2 A(q)^T u``.
* SAFE: rate damping (omega_cmd = 0) until the rate stays below a threshold for 1 s, then the
  configured body axis is turned to the Sun (same S^2 map without zones).

Rate command scaling. ``omega_law`` is multiplied by ``min(1, omega_max / |omega_law|)``: a positive,
state-dependent time scaling. It changes the speed along the kinematic closed-loop path but not the path
itself, so the paper's safety and convergence results carry over to the scaled command.

Double cover (QUATERNION). q and -q are the same attitude, but the paper's law lives on S^3 where they are
different points (its seven-cone example even puts a zone at -x_d). Choice: the law sees a *continuous
lift* of the estimate. On entering the mode and on every new target the sign is chosen in the target's
hemisphere (q . x_d >= 0, the shorter rotation); afterwards the sign is kept continuous from cycle to cycle
(flip whenever q_est . q_prev < 0). The closed loop is then exactly the paper's continuous system on S^3, so
its guarantees apply to the lifted path, there is no chattering at q . x_d = 0, and no unwinding is forced
unless the zones demand it. A zone's physical set of attitudes is both +U and -U; a zone that must be
avoided on both sheets sets ``antipodal_copy: true`` (the default is false so that the paper's S^3
problems are reproduced exactly). Consequence for the paper's seven-cone example: with this lift the cone
at -x_d is never approached and the cones at +-e2..e4 (the 180 deg rotations) lie on the lifted start's
far boundary, so the example converges without touching them; a zone that really stands between the
start and the target (tests/fsw/test_closed_loop.py, the paper's S^3 star zone with its antipodal copy)
is gone around by the StarShapedLaw.

Keep-out margin: how to choose ``law.margin_deg``. The law guarantees d_s(y, U_infl) > 0 only for the
kinematic system ydot = P(y)u. The real loop lags it, so the boresight can cross into the inflated layer
by the lag error; the requirement is judged on the physical zones, so choose

    margin_deg >= ephemeris error + estimation error + tracking overshoot + rebuild tolerance

* ephemeris: Moon 0.3 deg (gnc.ephemeris, max), Sun 0.01 deg, Earth (onboard orbit) as good as the orbit;
* estimation: 3 sigma of the attitude estimate, sqrt(cov_trace) (~0.01 deg with a star tracker; grows
  while coasting: the estimator's coasting time bounds it);
* tracking overshoot: when the law turns the rate command in the eps-layer, the rate loop needs about
  ``1 / rate_bandwidth`` seconds to follow and the wheels decelerate at most at ``alpha = tau_eff / J``,
  so the boresight can run past the kinematic path by at most about
  ``omega_max^2 / (2 alpha) + omega_max / rate_bandwidth`` (rad): ~1 deg + ~1 deg for 1 deg/s, 1 rad/s,
  0.5 deg/s^2. That bound is pessimistic because the law turns gradually across its layer. Measured
  (bench/fsw.py margin study; 120 deg slew at 1 deg/s past a star-shaped Sun zone and a Moon cone,
  hil_sim spacecraft 20/25/15 kg m^2, four 0.2 N m wheels, noisy gyro and star tracker, 10 Hz):

      margin_deg   kinematic-law minimum   real-loop minimum   consumed by the loop
         0.0              2.68 deg             2.69 deg              0.0 deg
         1.0              3.39                 3.36                  0.03
         2.0              4.09                 3.86                  0.23
         3.0              4.78                 4.42                  0.35
         5.0              6.14                 5.50                  0.64

  (the kinematic law itself stays ~2.7 deg outside the inflated boundary here; a grazing path can come
  arbitrarily close, so the law's standoff must not be counted on);
* nothing for the zone rebuild tolerance: zones are rebuilt only when their centre has moved by
  ``ZONE_REBUILD_TOL_DEG`` (0.1 deg; in LEO the Earth moves 0.06 deg/s, so about every 2 s instead of
  every cycle), and the law's zones carry that tolerance as extra inflation, while the physical margins
  are corrected by the drift since the build (moving a set by d changes a distance by at most d).

Rule: margin_deg = 0.3 (Moon ephemeris) + 3 sigma attitude (sqrt(cov_trace), longest expected coast)
+ the larger of the measured loop consumption and half the overshoot bound above, rounded up; 2-3 deg for
the default spacecraft at 1 deg/s. Re-measure with ``bench/fsw.py --skip-cycle --skip-realtime`` after
changing the rate limit, k1, the rate bandwidth or the wheels; the tracking term grows with
omega_max^2 / alpha. ``KEEP_OUT_MARGIN_LOW`` (yellow limit) tells
operations when the loop eats more of the margin than budgeted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fsw.assumption_check import CheckResult
from fsw.path_guidance import PathFollower, path_length_deg, plan_path
from gnc import sky_zones
from gnc.attitude import (
    attitude_error_angle,
    pointing_rate_command_nb,
    quat_to_dcm_nb,
    quaternion_rate_command_nb,
)
from gnc.ephemeris import EARTH_RADIUS_KM, julian_date_tdb, moon_position_N_km, sun_position_N_km

ZONE_REBUILD_TOL_DEG = 0.1  # extra inflation of the law's zones covering their motion between rebuilds
LAW_REBUILD_TRIGGER_DEG = 0.08
PHYS_REBUILD_TOL_DEG = 0.5
EPHEMERIS_NODE_S = 10.0
_MU_EARTH_KM3_S2 = 398600.4418
_BODY_CODES = {"sun": "SUN", "moon": "MOON", "earth": "EARTH", "inertial": "INERTIAL"}


def _norm(v: np.ndarray) -> float:
    # np.linalg.norm of a real 1-D array is sqrt(v.dot(v)): the same number, without its ~3 us of checks
    return math.sqrt(v.dot(v))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / _norm(v)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])))))


def d_s_to_deg(d_s: float) -> float:
    """Spherical separation d_s = 1 - cos(angle) -> angle in degrees, sign kept (negative inside)."""
    mag = math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - abs(d_s)))))
    return mag if d_s >= 0 else -mag


def signed_margin_deg(zone, x: np.ndarray) -> float:
    """Signed angular distance [deg] from the zone boundary (negative inside)."""
    return d_s_to_deg(float(zone.signed_separation(x)))


class SkyEphemeris:
    """Onboard directions of the Sun, Moon and Earth from the spacecraft (N frame) at mission time t."""

    def __init__(self, cfg):
        self.jd0 = julian_date_tdb(cfg.epoch_utc)
        o = cfg.orbit
        self.radius_km = o.radius_km
        self.n_rad_s = math.sqrt(_MU_EARTH_KM3_S2 / o.radius_km**3)
        i, raan = math.radians(o.inclination_deg), math.radians(o.raan_deg)
        self.u0 = math.radians(o.arg_latitude_at_epoch_deg)
        node = np.array([math.cos(raan), math.sin(raan), 0.0])
        # in-plane axis 90 deg ahead of the ascending node
        self.p_hat = node
        self.q_hat = np.array([-math.sin(raan) * math.cos(i), math.cos(raan) * math.cos(i), math.sin(i)])
        self.earth_angular_radius_deg = math.degrees(math.asin(EARTH_RADIUS_KM / o.radius_km))
        self._nodes: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def position_N_km(self, t_s: float) -> np.ndarray:
        u = self.u0 + self.n_rad_s * t_s
        return self.radius_km * (math.cos(u) * self.p_hat + math.sin(u) * self.q_hat)

    def _geocentric(self, node: int) -> tuple[np.ndarray, np.ndarray]:
        if node not in self._nodes:
            if len(self._nodes) > 4:
                self._nodes.clear()
            jd = self.jd0 + node * EPHEMERIS_NODE_S / 86400.0
            self._nodes[node] = (np.asarray(sun_position_N_km(jd), dtype=float), np.asarray(moon_position_N_km(jd), dtype=float))
        return self._nodes[node]

    def directions(self, t_s: float) -> dict[str, np.ndarray]:
        """Unit vectors from the spacecraft to the Sun, Moon and Earth centre in N.

        The analytic series are evaluated every EPHEMERIS_NODE_S seconds and interpolated linearly in
        between (error < 1e-6 deg for the Moon over 10 s, far below the series' own 0.3 deg); the
        spacecraft position (parallax) is evaluated every call.
        """
        k = math.floor(t_s / EPHEMERIS_NODE_S)
        f = t_s / EPHEMERIS_NODE_S - k
        s0, m0 = self._geocentric(k)
        s1, m1 = self._geocentric(k + 1)
        r = self.position_N_km(t_s)
        sun = s0 + f * (s1 - s0) - r
        moon = m0 + f * (m1 - m0) - r
        return {"sun": sun / _norm(sun), "moon": moon / _norm(moon), "earth": -r / _norm(r)}


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


@dataclass
class GuidanceOutput:
    omega_cmd_BN_B: np.ndarray
    mode: str
    safe_phase: str = "NONE"
    active_zone: int = -1
    eps: float = float("nan")
    eps_max: float = float("nan")
    margins_deg: list[float] = field(default_factory=list)
    margin_min_deg: float = float("nan")
    pointing_error_deg: float = float("nan")
    att_error_deg: float = float("nan")
    roll_error_deg: float = float("nan")
    boresight_N: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    target_N: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    q_target_NB: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    zones_merged: bool = False
    assumptions_ok: bool = True
    sun_N: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    moon_N: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    zone_count: int = 0
    zone_bodies: list[str] = field(default_factory=list)


def _saturate(omega: np.ndarray, max_rate_rad_s: float) -> np.ndarray:
    n = _norm(np.asarray(omega, dtype=float))
    return omega * (max_rate_rad_s / n) if n > max_rate_rad_s else omega


def _make_star_law(target, zones, k1, kappa, eps):
    from gnc.laws import StarShapedLaw

    return StarShapedLaw(target, zones, k1=k1, kappa=kappa, eps=eps)


def _make_gradient_law(target, zones, k1, eps):
    from gnc.laws import GradientLaw

    return GradientLaw(target, zones, k1=k1, eps=eps)


class ZoneGeometry:
    """The law's view of a set of zones for one target: merging, admissible eps, retreat target."""

    def __init__(self, dim: int, merge_gap_deg: float):
        self.dim = dim
        self.merge_gap_rad = math.radians(merge_gap_deg)
        self.groups: list[list[int]] = []
        self.pending: list = []  # would-be shapes of close pairs that could not merge around the boresight
        self.unmerged: list[tuple[int, int]] = []  # every close pair left separate, as indices into merge()'s output

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
        for z in zones:
            bound = min(bound, float(z.separation(target)))
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
        occ = next((i for i, z in enumerate(zones) if float(z.separation(target)) <= eps), -1)
        if occ < 0:
            occ = next((len(zones) + k for k, z in enumerate(avoid) if z.contains(target)), -1)
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


class Guidance:
    """Mode logic and guidance laws; `step` runs once per GNC cycle."""

    MODES = ("SAFE", "POINTING", "QUATERNION")

    def __init__(self, cfg, events=None):
        self.cfg = cfg
        self.events = events or (lambda name, **args: None)
        self.mode = cfg.initial_mode
        self.k1 = cfg.law.k1
        self.kappa = cfg.law.kappa
        self.eps_cfg = cfg.law.eps
        self.max_rate_rad_s = math.radians(cfg.spacecraft.max_rate_deg_s)
        self.ephem = SkyEphemeris(cfg)
        p = cfg.pointing
        self.b_B = np.asarray(p.boresight_B, dtype=float)
        self.target_N = np.asarray(p.target_N, dtype=float)
        self.roll_axis_B = np.asarray(p.roll_axis_B, dtype=float)
        self.roll_ref_N = np.asarray(p.roll_reference_N, dtype=float)
        self.q_target = np.asarray(cfg.quaternion.target_q_NB, dtype=float)
        self.sun_axis_B = np.asarray(cfg.safe.sun_axis_B, dtype=float)
        self.no_fix_s = 0.0
        self.acquisition_omega_B = _acquisition_rate_B(cfg, self.b_B)
        margin = cfg.law.margin_deg
        self.slots: list[_SkySlot] = []
        for i, z in enumerate(p.zones):
            extra = self.ephem.earth_angular_radius_deg if (z.body == "earth" and z.add_body_angular_radius) else 0.0
            fixed = np.asarray(z.direction_N, dtype=float) if z.body == "inertial" else None
            self.slots.append(
                _SkySlot(
                    i, z.name, z.body,
                    sky_zones.SkyZoneBuilder(z.geometry, 0.0, extra, fast=True),
                    sky_zones.SkyZoneBuilder(z.geometry, margin + ZONE_REBUILD_TOL_DEG, extra),
                    fixed,
                )
            )
        self.sky_geometry = ZoneGeometry(3, cfg.law.merge_gap_deg)
        if self.slots:
            _warm_batch_kernels([s.builder_law for s in self.slots])
        self._sky_law = None
        self._sky_law_key = None
        self._sky_groups: list[list[int]] = []
        self._sky_law_zones: list = []
        self._build_s3_zones()
        self._s3_law = None
        self._q_lift: np.ndarray | None = None
        # SAFE mode state
        self.safe_phase = "RATE_DAMPING"
        self._damped_s = 0.0
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
        # path guidance: the follower of the planned slew path, the law's aim on it, when it was planned
        self._follower: PathFollower | None = None
        self._aim: np.ndarray = self.target_N
        self._aim_k = -1
        self._plan_due = True
        self._planned_t = -math.inf
        self.last_t_s = 0.0

    # ------------------------------------------------------------------------------ configuration
    def _build_s3_zones(self) -> None:
        from gnc import zones as gz

        m = math.radians(self.cfg.law.margin_deg)
        self.s3_phys, self.s3_law_zones, self.s3_names = [], [], []
        for zc in self.cfg.quaternion.zones:
            centers = [np.asarray(zc.center_q, dtype=float)]
            if zc.antipodal_copy:
                centers.append(-centers[0])
            for c in centers:
                if zc.shape == "cone":
                    ha = math.radians(zc.half_angle_deg)
                    self.s3_phys.append(gz.ConicZone(c, ha))
                    self.s3_law_zones.append(gz.ConicZone(c, ha + m))
                else:
                    a = np.asarray(zc.semi_axes, dtype=float)
                    # margin applied per principal direction in angle (exact along the semi-axes)
                    a_infl = np.tan(np.minimum(np.arctan(a) + m, math.radians(89.0)))
                    self.s3_phys.append(gz.StarZone.superellipsoid(c, None, a, zc.exponent))
                    self.s3_law_zones.append(gz.StarZone.superellipsoid(c, None, a_infl, zc.exponent))
                self.s3_names.append(zc.name)
        law = self.cfg.quaternion.law
        all_cones = all(z.shape == "cone" for z in self.cfg.quaternion.zones)
        self.s3_use_gradient = law == "gradient" or (law == "auto" and all_cones)

    def set_mode(self, mode: str) -> None:
        if mode not in self.MODES:
            raise ValueError(f"unknown mode {mode!r}; allowed: {self.MODES}")
        self.mode = mode
        self._drop_path()
        if mode == "SAFE":
            self.safe_phase = "RATE_DAMPING"
            self._damped_s = 0.0
        if mode == "QUATERNION":
            self._q_lift = None
        self._checks_dirty = True

    def set_gains(self, k1: float, kappa: float, eps: float | str, rate_limit_deg_s: float) -> None:
        if not (k1 > 0 and kappa > 0 and rate_limit_deg_s > 0):
            raise ValueError("k1, kappa and rate limit must be positive")
        if eps != "auto" and not (0.0 < float(eps) < 1.0):
            raise ValueError("eps must be in (0, 1) or 'auto'")
        self.k1, self.kappa, self.eps_cfg = float(k1), float(kappa), eps
        self.max_rate_rad_s = math.radians(rate_limit_deg_s)
        self._sky_law_key = None
        self._s3_law = None
        self._checks_dirty = True

    def target_violation(self, kind: str, value: np.ndarray) -> tuple[int, float] | None:
        """(zone index, margin deg) when a candidate target lies inside an (inflated) zone, else None."""
        if kind == "DIRECTION":
            self._update_sky(self.last_t_s)
            x = _unit(np.asarray(value, dtype=float))
            for s in self.slots:
                m = signed_margin_deg(s.law, x)
                if m <= 0.0:
                    return s.index, m
            return None
        q = _unit(np.asarray(value, dtype=float))
        for i, z in enumerate(self.s3_law_zones):
            m = signed_margin_deg(z, q)
            if m <= 0.0:
                return i, m
        return None

    def set_target_direction(self, target_N: np.ndarray) -> None:
        self.target_N = _unit(np.asarray(target_N, dtype=float))
        self._drop_path()
        self._sky_law_key = None
        self._checks_dirty = True

    def set_target_quaternion(self, q_NB: np.ndarray) -> None:
        self.q_target = _unit(np.asarray(q_NB, dtype=float))
        self._q_lift = None
        self._s3_law = None
        self._checks_dirty = True

    # ------------------------------------------------------------------------------------ zones
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
                first = True
                continue
            law_drift = _angle_deg(c, s.built_center_law) / LAW_REBUILD_TRIGGER_DEG
            phys_drift = _angle_deg(c, s.built_center) / PHYS_REBUILD_TOL_DEG
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
        return first or worst_kind == "law"

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
        auto = self.eps_cfg == "auto"
        eps = min(self.cfg.law.eps_fraction * eps_max, self.cfg.law.eps_max_used) if auto else float(self.eps_cfg)
        if not auto and eps >= eps_max:
            eps = self.cfg.law.eps_fraction * eps_max
        return max(eps, 1e-6)

    # ------------------------------------------------------------------------------------- modes
    def step(self, t_s: float, dt_s: float, q_NB: np.ndarray | None, omega_BN_B: np.ndarray) -> GuidanceOutput:
        self.last_t_s = t_s
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

    def _sky_margins(self, y_N: np.ndarray) -> tuple[list[float], float]:
        """Signed physical margins [deg], conservative: minus the zone's drift since it was built."""
        margins = []
        for s in self.slots:
            margins.append(signed_margin_deg(s.phys, y_N) - _angle_deg(s.center_N, s.built_center))
        return margins, (min(margins) if margins else float("nan"))

    def _pointing(self, t_s: float, q: np.ndarray, omega: np.ndarray) -> GuidanceOutput:
        rebuilt = self._update_sky(t_s)
        R = quat_to_dcm_nb(q)
        y = R @ self.b_B
        out = GuidanceOutput(np.zeros(3), "POINTING", boresight_N=y, target_N=self.target_N.copy())
        out.sun_N, out.moon_N = self._dirs.get("sun", out.sun_N), self._dirs.get("moon", out.moon_N)
        u = self.k1 * self.target_N
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
            u = self.k1 * np.asarray(u_law, dtype=float)
            out.eps, out.eps_max = self._sky_eps, self._sky_eps_max
            out.active_zone = -1 if zone is None else self._sky_groups[zone][0]
            out.margins_deg, out.margin_min_deg = self._sky_margins(y)
            out.zones_merged = any(len(g) > 1 for g in self._sky_groups)
            out.zone_count = len(self.slots)
            out.zone_bodies = [_BODY_CODES[s.body] for s in self.slots]
        out.assumptions_ok = self.assumptions_ok
        omega_law = pointing_rate_command_nb(q, self.b_B, np.ascontiguousarray(u))
        omega_cmd = _saturate(np.asarray(omega_law), self.max_rate_rad_s)
        roll_err = self._roll_error(R, y)
        omega_roll = self.cfg.pointing.roll_gain_1_s * roll_err * self.b_B
        out.omega_cmd_BN_B = omega_cmd + _saturate(omega_roll, 0.5 * self.max_rate_rad_s)
        out.pointing_error_deg = math.degrees(math.acos(max(-1.0, min(1.0, float(y @ self.target_N)))))
        out.roll_error_deg = math.degrees(roll_err)
        return out

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

    # ----------------------------------------------------------------------------- path guidance
    def _drop_path(self) -> None:
        """Forget the planned path; the next law rebuild plans one for the current target."""
        self._follower = None
        self._aim, self._aim_k = self.target_N, -1
        self._plan_due = True

    def _plan(self, t_s: float, y: np.ndarray, obstacles: list) -> None:
        """Plan the slew from the boresight ``y`` round ``obstacles`` (the law's zones after merging, and
        the shapes of pairs about to merge); follow it only when the great circle is blocked. A plan that
        fails keeps the path being followed (if any), to be checked again a replan period later: the law
        keeps every zone safe either way."""
        self._plan_due = False
        cfg = self.cfg.pointing.path
        if not cfg.enabled:
            return
        self._planned_t = t_s
        vertices = plan_path(y, self.target_N, obstacles, cfg.standoff_deg, cfg.polygon_sides)
        if vertices is None:
            return
        if len(vertices) <= 2:
            self._follower, self._aim, self._aim_k = None, self.target_N, -1
            return
        replanned = self._follower is not None
        # far enough ahead that the law's rate, k1 sin(angle to its target), stays at the rate limit
        saturating = math.degrees(math.asin(min(1.0, 1.25 * self.max_rate_rad_s / self.k1)))
        self._follower = PathFollower(vertices, max(cfg.lookahead_deg, saturating))
        self._aim_k = -1
        self._advance_aim(y)
        if not replanned:
            length = path_length_deg(vertices)
            self.events("PATH_PLANNED", length_deg=length, detour_deg=length - _angle_deg(y, self.target_N),
                        legs=len(vertices) - 1)

    def _path_blocked(self, t_s: float, obstacles: list) -> bool:
        """Every replan_period_s: does a zone (they move) now come within half the standoff of the rest
        of the path? Then it is planned again from the boresight. A path that is still clear is kept: a
        plan from a boresight that has cut a corner towards a zone would hug that zone."""
        f, cfg = self._follower, self.cfg.pointing.path
        if f is None or t_s - self._planned_t < cfg.replan_period_s:
            return False
        self._planned_t = t_s
        rest = f.path[f.index:]
        d = 1.0 - math.cos(math.radians(0.5 * cfg.standoff_deg))
        return any(bool(np.any(z.separation_batch(rest) <= d)) for z in obstacles)

    def _aim_moved(self, t_s: float, y: np.ndarray) -> bool:
        """True when the law must be rebuilt: the aim moved along the path, the path ended, or it is time
        to check the path against the moved zones."""
        f = self._follower
        if f is None:
            return False
        if t_s - self._planned_t >= self.cfg.pointing.path.replan_period_s:
            return True  # time to check the path against the zones as they are now (`_path_blocked`)
        return self._advance_aim(y)

    def _advance_aim(self, y: np.ndarray) -> bool:
        """Move the law's aim to the path point ahead of the boresight ``y``; True if it moved."""
        f = self._follower
        k = f.aim_index(y)
        if k == self._aim_k:
            return False
        if k == len(f.path) - 1:  # the last leg is the paper's law to the real target
            self._follower, self._aim, self._aim_k = None, self.target_N, -1
        else:
            self._aim, self._aim_k = f.path[k], k
        return True

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

    def _roll_error(self, R: np.ndarray, y_N: np.ndarray) -> float:
        """Angle [rad] about the boresight from roll_axis_B's projection to the reference's projection."""
        b = self.b_B
        ref_N = self.roll_ref_N
        if abs(float(ref_N @ y_N)) > 0.95:  # reference nearly along the boresight: use another axis
            ref_N = np.array([1.0, 0.0, 0.0]) if abs(y_N[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        r_B = R.T @ ref_N
        a = self.roll_axis_B - (self.roll_axis_B @ b) * b
        r = r_B - (r_B @ b) * b
        axr = (a[1] * r[2] - a[2] * r[1], a[2] * r[0] - a[0] * r[2], a[0] * r[1] - a[1] * r[0])
        return math.atan2(b[0] * axr[0] + b[1] * axr[1] + b[2] * axr[2], float(a @ r))

    def _quaternion(self, t_s: float, q: np.ndarray) -> GuidanceOutput:
        xd = self.q_target
        if self._q_lift is None:
            x = q if float(q @ xd) >= 0.0 else -q
        else:
            x = q if float(q @ self._q_lift) >= 0.0 else -q
        self._q_lift = x
        out = GuidanceOutput(np.zeros(3), "QUATERNION", q_target_NB=xd.copy())
        if self.s3_law_zones:
            if self._s3_law is None:
                eps_max = ZoneGeometry.fast_eps_max(xd, self.s3_law_zones)
                eps = self._eps_for(max(eps_max, 1e-5))
                self._s3_eps, self._s3_eps_max = eps, eps_max
                self._current_eps = eps
                if self.s3_use_gradient:
                    self._s3_law = _make_gradient_law(xd, self.s3_law_zones, 1.0, eps)
                else:
                    self._s3_law = _make_star_law(xd, self.s3_law_zones, 1.0, self.kappa, eps)
            u_law, zone = self._s3_law.control_and_zone(x)
            u = self.k1 * np.asarray(u_law, dtype=float)
            out.eps, out.eps_max = self._s3_eps, self._s3_eps_max
            out.active_zone = -1 if zone is None else int(zone)
            margins = [signed_margin_deg(z, x) for z in self.s3_phys]
            out.margins_deg, out.margin_min_deg = margins, min(margins)
            out.zone_count = len(self.s3_phys)
            out.zone_bodies = ["ATTITUDE"] * len(self.s3_phys)
        else:
            u = self.k1 * xd
        out.assumptions_ok = self.assumptions_ok
        omega = quaternion_rate_command_nb(np.ascontiguousarray(x), np.ascontiguousarray(u))
        out.omega_cmd_BN_B = _saturate(np.asarray(omega), self.max_rate_rad_s)
        out.att_error_deg = math.degrees(float(attitude_error_angle(q, xd)))
        R = quat_to_dcm_nb(q)
        out.boresight_N = R @ self.b_B
        return out

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
