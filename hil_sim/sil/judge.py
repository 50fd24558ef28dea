"""Judge a SIL run against the mission's requirements and write ``summary.json``.

Truth (``truth.npz``, recorded by the simulator every GNC tick) decides the physical requirements; the
ground archive (the flight software's own telemetry) supplies what only the flight software knows:
cycle slips and FDIR events.

Requirements (``Mission.requirements``):

* keep-out, per zone: the minimum signed margin [deg] of the instrument boresight (truth attitude and
  true boresight) to the PHYSICAL zone (no law margin), built with `gnc.sky_zones` around the truth Sun,
  Moon and Earth directions as they moved, must exceed ``min_keepout_margin_deg``. S^3 (forbidden
  attitude) zones are judged on the truth quaternion lifted as the flight software lifts it (sign in
  the target's hemisphere when a target is set, continuous afterwards);
* settling: each commanded target is reached and held within ``settling_tolerance_deg`` by the end of
  the time it is commanded (optionally within ``max_settling_time_s``);
* final pointing (or attitude) error, truth, at the end of the run;
* peak wheel speed as a fraction of each wheel's limit;
* cycle slips: lockstep: ticks the flight software never answered with CYCLE_DONE (simulated time waits
  for it, so host-time overruns, reported alongside, cannot hurt the loop); real time: the flight
  software's GNC slip counter, and apart from it the ticks lost on the host (CYCLE_DONE after the next tick
  began), at most ``HOST_LOST_TICK_FRACTION`` of the ticks;
* FDIR: the expected FDIR trips occurred; no more unexpected ones than allowed;
* instrument exposure (missions with a door, ``spacecraft.door``): the time the boresight spent inside a
  physical sky zone with the door not fully closed (door truth: ``door_position`` > 0), at most
  ``max_instrument_exposure_s``. Reported for every mission in ``summary.json`` (``exposure``; without a
  door the instrument is always open) with its depth, the deepest margin among those samples.

Armed zones: a sky zone with ``armed: inertial_targets`` counts, in every requirement and figure above, only
on its armed samples (`ZoneSeries.judged`), which the judge derives from the mission's commanded POINTING
targets and the truth alone, never from the flight software's own arming: not while a nadir or ground
target is commanded; after an inertial target (``target_N``, ``ra_dec_deg``) is commanded, from the first
sample whose true margin exceeds ``law.margin_deg`` (clear of the zone as the law sees it, where the
flight software arms it), and from then on until a nadir or ground target is commanded again (a
further inertial target, or a mode change, leaves it armed). A zone never armed is reported as not judged.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gnc.ephemeris import EARTH_RADIUS_KM
from hil_sim.mission.physics_checks import d_s_to_deg, earth_target_truth_N, schedule

ZONE_REBUILD_DEG = 0.001  # rebuild a moving star zone when its centre moved more than this (margin error bound)


@dataclass
class ZoneSeries:
    name: str
    kind: str  # "sky" or "attitude"
    margin_deg: np.ndarray  # per truth sample, signed; NaN where not judged (see judged)
    boundary_history: list  # [(t_s, boundary points (m, 3))] for sky zones (plots)
    # the samples the zone is judged on (a zone armed only for inertial targets); None: every sample. The
    # mask, not NaN alone, decides: a NaN margin of an always-judged zone (NaN truth) must still fail
    judged: np.ndarray | None = None


def zone_minimum(zone: ZoneSeries) -> tuple[int, float] | None:
    """(sample, margin [deg]) of the zone's smallest judged margin; None when no sample is judged."""
    m = zone.margin_deg
    if zone.judged is None:
        if not len(m):
            return None
        i = int(np.argmin(m))
    else:
        idx = np.flatnonzero(zone.judged)
        if not len(idx):
            return None
        i = int(idx[np.argmin(m[idx])])
    return i, float(m[i])


TRUTH_KEYS = {"t_s": (0,), "q_NB": (0, 4), "omega_BN_B": (0, 3), "wheel_speed_rad_s": (0, 0),
              "wheel_torque_Nm": (0, 0), "sun_N": (0, 3), "moon_N": (0, 3), "earth_N": (0, 3), "r_sc_N_km": (0, 3),
              "cycle_done": (0,)}


def load_truth(run_dir: Path) -> dict[str, np.ndarray]:
    """The simulator's truth record; empty arrays when the run stopped before recording anything."""
    path = Path(run_dir) / "truth.npz"
    if not path.exists():
        return {k: np.zeros(shape) for k, shape in TRUTH_KEYS.items()}
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def boresight_N(q_NB: np.ndarray, b_B: np.ndarray) -> np.ndarray:
    """Rows: R(q_NB) b_B for every quaternion row (scalar first)."""
    from gnc.attitude import quat_to_dcm

    return np.einsum("nij,j->ni", quat_to_dcm(q_NB), b_B) if len(q_NB) else np.zeros((0, 3))


def instrument_exposure(t: np.ndarray, sky_zones: list[ZoneSeries], door_position: np.ndarray | None) -> dict[str, Any]:
    """The instrument's exposure on truth: the samples where the boresight is inside a physical sky zone
    (signed margin < 0) while the door is not fully closed (``door_position`` > 0, 0 closed .. 1 open; None:
    no door, always open). ``exposure_s``: their time, each sample standing for the interval to the next;
    ``depth_deg``: how deep the deepest of them is (0 when none); ``inside_s``: the time inside a zone,
    door or not; ``first_t_s``: the first exposed sample's time (None when none)."""
    out: dict[str, Any] = {"door": door_position is not None, "exposure_s": 0.0, "depth_deg": 0.0, "inside_s": 0.0,
                           "first_t_s": None}
    n = len(t)
    if n == 0 or not sky_zones:
        return out
    margin = np.min(np.vstack([_judged_or_inf(z) for z in sky_zones]), axis=0)
    inside = margin < 0.0
    exposed = inside if door_position is None else inside & (np.asarray(door_position, dtype=float) > 0.0)
    dt = np.diff(np.asarray(t, dtype=float))
    weight = np.append(dt, dt[-1] if len(dt) else 0.0)
    out["inside_s"] = float(weight[inside].sum())
    if exposed.any():
        out["exposure_s"] = float(weight[exposed].sum())
        out["depth_deg"] = float(-margin[exposed].min())
        out["first_t_s"] = float(t[int(np.argmax(exposed))])
    return out


def _judged_or_inf(zone: ZoneSeries) -> np.ndarray:
    # an unjudged sample is no exposure, whatever another zone's margin there
    m = np.asarray(zone.margin_deg, dtype=float)
    return m if zone.judged is None else np.where(zone.judged, m, math.inf)


def _signed_margins(zone, X: np.ndarray) -> np.ndarray:
    d = np.asarray(zone.separation_batch(X), dtype=float)
    out = np.degrees(np.arccos(np.clip(1.0 - d, -1.0, 1.0)))
    inside = d <= 0.0
    for i in np.nonzero(inside)[0]:
        out[i] = d_s_to_deg(float(zone.signed_separation(X[i])))
    return out


# Minimum-only judging (`sky_zone_series(..., minimum_only=True)`): a stretch of the run is left
# unevaluated only when its lower bound exceeds the best evaluated margin by this much [deg], far above the
# rounding of either (the margin's arccos near 0 is good to ~1e-6 deg).
SKIP_SLACK_DEG = 1e-3

def sky_zone_series(mission, truth: dict[str, np.ndarray], y_N: np.ndarray, *,
                    minimum_only: bool = False) -> list[ZoneSeries]:
    """Signed margins of the boresight to each physical sky zone, with the truth ephemeris.

    ``minimum_only`` (fast mode's judge, which reads only each zone's minimum margin and its last
    boundary): a star zone (whose exact search structure costs ~15 ms to build, its margin ~3 us per
    sample) is built and evaluated only where the run can hold its minimum. Each sample's margin is
    bounded below by its angle to the zone's centre minus the zone's largest angular radius; stretches
    (one zone each) are taken in increasing order of that bound, the sample of lowest bound first, and in
    each only the samples whose bound does not exceed the best margin found (+ SKIP_SLACK_DEG) are
    evaluated, until a stretch's lowest bound exceeds it. ``margin_deg`` holds the lower bound on the
    samples left out, and ``boundary_history`` only its last entry. The minimum is the full series' own
    (the same zones on the same samples). Once a margin is negative (the boresight inside a zone) every
    sample is evaluated.

    A zone with ``armed: inertial_targets`` is judged on its armed samples only (`pointing_spans`,
    `armed_samples`): ``judged`` holds them, ``margin_deg`` is NaN elsewhere, and with ``minimum_only`` its
    minimum is that of its armed samples."""
    from gnc import sky_zones

    out = []
    t = truth["t_s"]
    zones = mission.flight_software.pointing.zones
    spans = pointing_spans(mission, t) if any(z.armed == "inertial_targets" for z in zones) else None
    arm = _Arming.of(mission, t)
    for z in zones:
        arming = spans if z.armed == "inertial_targets" else None
        centers, extra = _zone_centers(z, truth, t)
        builder = sky_zones.SkyZoneBuilder(z.geometry, 0.0, extra)
        if z.geometry.shape == "cone":
            series = _cone_series(z, builder, centers, extra, y_N, t, minimum_only)
        else:
            stretches = _stretches(centers, t)
            shown = _shown_stretches(stretches, t)
            if minimum_only:
                out.append(_star_series_minimum(z, builder, stretches, shown, y_N, t, arming, arm))
                continue
            series = _star_series_full(z, builder, stretches, set(shown), y_N, t)
        if arming is not None:
            margins = series.margin_deg
            series.judged = armed_samples(arming, len(t), lambda a, b: arm.first(margins, a, b))
            series.margin_deg = np.where(series.judged, margins, math.nan)
        out.append(series)
    return out


def pointing_spans(mission, t: np.ndarray) -> list[tuple[int, int, bool]]:
    """(first sample, end sample, on the Earth) per segment of `schedule` (the samples `error_series` gives
    it): whether the POINTING target in force is nadir or a ground point rather than a fixed direction. The
    initial target is ``pointing.target_kind``'s, then each SET_TARGET's; an attitude target (QUATERNION)
    leaves the POINTING target as it was, which is why the kind is read from the commands and not from the
    segments (a QUATERNION segment does not carry it)."""
    from hil_sim.mission.model import SetTargetCommand

    changes = [(0.0, mission.flight_software.pointing.target_kind != "inertial")]
    changes += [(e.t_s, e.target_direction_N() is None) for e in mission.timeline
                if isinstance(e, SetTargetCommand) and e.q_target_NB is None]
    segments = schedule(mission)
    spans = []
    for s in segments:
        sel = np.flatnonzero(_segment_samples(t, s, s is segments[-1]))
        if len(sel):
            on_earth = [earth for t_s, earth in changes if t_s <= s.t_start_s + 1e-9][-1]
            spans.append((int(sel[0]), int(sel[-1]) + 1, on_earth))
    return spans


def armed_samples(spans: Sequence[tuple[int, int, bool]], n: int,
                  first_positive: Callable[[int, int], int | None]) -> np.ndarray:
    """The samples (of ``n``) an ``inertial_targets`` zone is judged on, over `pointing_spans`' ``spans``:
    none while the target is on the Earth; in a span of an inertial target, from ``first_positive(a, b)``
    (the first sample in [a, b) where the boresight has left the zone as the law sees it, and can stop short
    of it from the rate it closes on it, None when none: `_Arming`, the flight software's own rule,
    `PointingGuidance.armable`, on the truth) to the span's end, and every sample
    of the inertial spans that follow until a target on the Earth. The flight software too keeps the zone
    armed across inertial targets and modes, so a boresight inside it at a command's time is a violation.
    Judged from a margin of 0 instead, the smallest margin would be the arming sample's own, a few
    thousandths of a degree, whatever the law did afterwards."""
    armed = np.zeros(n, dtype=bool)
    on = False
    for a, b, on_earth in spans:
        if on_earth:
            on = False
            continue
        k = a if on else first_positive(a, b)
        if k is not None:
            armed[k:b] = True
            on = True
    return armed


@dataclass
class _Arming:
    """When an ``inertial_targets`` zone is armed on an inertial target: at the first sample whose true
    margin exceeds law.margin_deg (outside the zone as the law sees it) and from which the boresight can
    stop outside the zone (`fsw.guidance.slew_limits.braking_distance_deg` of the rate its margin falls at,
    at the configured slew limits) with the braking reserve to spare."""

    t: np.ndarray
    level: float
    accel_deg_s2: float
    bandwidth_rad_s: float

    @classmethod
    def of(cls, mission, t: np.ndarray) -> "_Arming":
        fsw = mission.flight_software
        return cls(t, fsw.law.margin_deg, fsw.control.max_command_accel_deg_s2, fsw.control.rate_bandwidth_rad_s)

    def first(self, margins: np.ndarray, a: int, b: int) -> int | None:
        """The first armed sample in [a, b) of the exact ``margins`` (``margins[a - 1]`` too, when a > 0)."""
        from fsw.guidance.slew_limits import armable

        lo = max(a - 1, 0)
        m, t = margins[lo:b], self.t[lo:b]
        closing = np.zeros(len(m))
        closing[1:] = (m[:-1] - m[1:]) / np.maximum(np.diff(t), 1e-9)
        # the flight software's rule on the truth: its margin from the zone as the law sees it
        ok = np.flatnonzero(armable(m - self.level, closing, self.level, self.accel_deg_s2, self.bandwidth_rad_s))
        ok = ok[ok + lo >= a]
        return lo + int(ok[0]) if len(ok) else None


def _zone_centers(z, truth: dict[str, np.ndarray], t: np.ndarray) -> tuple[np.ndarray, float]:
    """The zone's centre at every sample, and what it adds to the zone's size [deg] (the Earth's angular
    radius, for an Earth zone that asks for it)."""
    if z.body == "inertial":
        centers = np.repeat(np.asarray(z.direction_N, dtype=float)[None, :], len(t), axis=0)
    else:
        centers = truth[f"{z.body}_N"]
    extra = 0.0
    if z.body == "earth" and z.add_body_angular_radius and len(t):
        r = float(np.linalg.norm(truth["r_sc_N_km"][0]))
        extra = math.degrees(math.asin(min(1.0, (EARTH_RADIUS_KM + (z.atmosphere_height_km or 0.0)) / r)))
    return centers, extra


def _cone_series(z, builder, centers: np.ndarray, extra: float, y_N: np.ndarray, t: np.ndarray,
                 minimum_only: bool) -> ZoneSeries:
    """A cone is exact at every sample: the angle to the centre minus the half-angle."""
    c = centers / np.linalg.norm(centers, axis=1, keepdims=True)
    margins = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", y_N, c), -1.0, 1.0))) \
        - (z.geometry.half_angle_deg + extra)
    ks = range(0, len(t), max(1, int(30.0 / max(t[1] - t[0], 1e-9))) if len(t) > 1 else 1)
    if minimum_only:
        ks = ks[-1:]
    history = [(float(t[k]), np.asarray(builder.build(c[k]).boundary(180))) for k in ks]
    return ZoneSeries(z.name, "sky", margins, history)


def _stretches(centers: np.ndarray, t: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    """(start, stop, centre) of the stretches of samples judged against one zone: rebuilt when its centre
    moved (ZONE_REBUILD_DEG)."""
    stretches = []
    start = 0
    cos_tol = math.cos(math.radians(ZONE_REBUILD_DEG))
    while start < len(t):
        c0 = centers[start] / np.linalg.norm(centers[start])
        moved = (centers[start:] @ c0) / np.linalg.norm(centers[start:], axis=1) < cos_tol
        stop = start + (int(np.argmax(moved)) if moved.any() else len(t) - start)
        stop = max(stop, start + 1)
        stretches.append((start, stop, c0))
        start = stop
    return stretches


def _shown_stretches(stretches: list, t: np.ndarray) -> list[int]:
    """The stretches whose zone boundary is kept for the plots: one every 30 s or more."""
    shown: list[int] = []
    for i, (start, _, _) in enumerate(stretches):
        if not shown or t[start] - t[stretches[shown[-1]][0]] >= 30.0:
            shown.append(i)
    return shown


def _star_series_full(z, builder, stretches: list, shown_set: set[int], y_N: np.ndarray,
                      t: np.ndarray) -> ZoneSeries:
    """Every sample of every stretch evaluated, the shown stretches' boundaries kept."""
    margins = np.empty(len(t))
    history = []
    for i, (start, stop, c0) in enumerate(stretches):
        zone = builder.build(c0)
        margins[start:stop] = _signed_margins(zone, y_N[start:stop])
        if i in shown_set:
            history.append((float(t[start]), np.asarray(zone.boundary(180))))
    return ZoneSeries(z.name, "sky", margins, history)


def _stretch_lower_bounds(builder, stretches: list, y_N: np.ndarray) -> list[np.ndarray]:
    """Per stretch, each sample's lower bound of its margin: the angle to the centre minus the zone's
    largest angular radius (-inf where no radius bound is known)."""
    radius_deg = _star_radius_bound_deg(builder)
    bounds = []
    for start, stop, c0 in stretches:
        if radius_deg is None:
            bounds.append(np.full(stop - start, -math.inf))
            continue
        y = y_N[start:stop]
        angle_deg = np.degrees(2.0 * np.arctan2(np.linalg.norm(y - c0, axis=1), np.linalg.norm(y + c0, axis=1)))
        bounds.append(np.where(np.isnan(angle_deg), -math.inf, angle_deg - radius_deg))
    return bounds


def _star_series_minimum(z, builder, stretches: list, shown: list[int], y_N: np.ndarray,
                         t: np.ndarray, arming: list[tuple[int, int, bool]] | None = None,
                         arm: "_Arming | None" = None) -> ZoneSeries:
    """The minimum-only series (see sky_zone_series): lower bounds where no sample can hold the minimum.
    ``arming``: `pointing_spans` for a zone judged only on its armed samples (None: every sample), armed
    by ``arm`` (`armed_samples`)."""
    bounds = _stretch_lower_bounds(builder, stretches, y_N)
    margins = np.empty(len(t))
    for (start, stop, _), b in zip(stretches, bounds):
        margins[start:stop] = b
    evaluated = np.zeros(len(t), dtype=bool)
    built = {}

    def compute(i: int, sel: np.ndarray) -> np.ndarray:
        # the margins of samples sel of stretch i: per sample the full series' own values
        start, stop, c0 = stretches[i]
        sel = sel[~evaluated[start:stop][sel]]
        if not len(sel):
            return sel.astype(float)
        if i not in built:
            built[i] = builder.build(c0)
        m = _signed_margins(built[i], np.ascontiguousarray(y_N[start:stop][sel]))
        margins[start + sel] = m
        evaluated[start + sel] = True
        return m

    judged = None
    best = math.inf
    if arming is not None:
        judged = armed_samples(arming, len(t), _lazy_first_armed(stretches, margins, compute, arm))
        # samples the arming already evaluated hold exact margins: the armed ones count for the minimum
        done = evaluated & judged
        best = float(margins[done].min()) if done.any() else math.inf
        # an unarmed sample never holds the minimum
        bounds = [np.where(judged[start:stop], b, math.inf) for (start, stop, _), b in zip(stretches, bounds)]
    lowest = np.array([b.min() if len(b) else math.inf for b in bounds])

    def evaluate(i: int, sel: np.ndarray) -> None:
        nonlocal best
        m = compute(i, sel)
        if len(m):
            best = min(best, float(m.min()))

    def candidates(i: int) -> np.ndarray:
        start, stop, _ = stretches[i]
        return np.arange(len(bounds[i])) if judged is None else np.flatnonzero(judged[start:stop])

    for i in np.argsort(lowest, kind="stable"):
        if lowest[i] == math.inf:
            break  # no armed sample here nor in the stretches after it
        if best >= 0.0 and lowest[i] > best + SKIP_SLACK_DEG:
            break  # this stretch and all after it cannot hold the minimum
        if best == math.inf:  # the sample of lowest bound first: its margin bounds the minimum
            evaluate(i, np.array([int(np.argmin(bounds[i]))]))
        evaluate(i, candidates(i) if best < 0.0 else np.flatnonzero(~(bounds[i] > best + SKIP_SLACK_DEG)))
    if best < 0.0:  # inside a zone: every sample judged
        for i in range(len(stretches)):
            evaluate(i, candidates(i))
    if judged is not None:
        margins[~judged] = math.nan
    history = []
    if shown:
        i = shown[-1]
        # only its boundary, when the stretch was never built: the search structure is not needed for a plot
        zone = built[i] if i in built else _boundary_only_zone(builder, stretches[i][2])
        history.append((float(t[stretches[i][0]]), np.asarray(zone.boundary(180))))
    return ZoneSeries(z.name, "sky", margins, history, judged)


def _lazy_first_armed(stretches: list, margins: np.ndarray, compute: Callable[[int, np.ndarray], np.ndarray],
                      arm: "_Arming") -> Callable[[int, int], int | None]:
    """`armed_samples`' first_positive on a minimum-only series (``margins``: lower bounds, exact where
    ``compute`` evaluated them): samples are evaluated in order, in blocks doubling in size, each block
    exactly (the rate the margin falls at needs every sample's), with the sample before it, so only the
    stretches up to where the zone is armed are built."""
    starts = np.array([s[0] for s in stretches])

    def first_positive(a: int, b: int) -> int | None:
        k, size = a, 1
        while k < b:
            stop = min(b, k + size)
            lo_block = max(k - 1, 0)
            first, last = np.searchsorted(starts, [lo_block, stop - 1], "right")
            for i in range(int(first) - 1, int(last)):
                start, end, _ = stretches[i]
                lo, hi = max(lo_block, start), min(stop, end)
                compute(i, np.arange(lo, hi) - start)
            found = arm.first(margins, k, stop)
            if found is not None:
                return found
            k, size = stop, 2 * size
        return None

    return first_positive


def _star_radius_bound_deg(builder) -> float | None:
    """An upper bound [deg] of the angular radius of the zones ``builder`` builds (about their centre), or
    None when unknown. The zone is the central projection of a planar set about the centre, so its angular
    radius is arctan of the set's largest planar radius: a polygon's largest vertex; a superellipse
    |x/A|^p + |y/B|^p <= 1 within max(A, B) for p <= 2 (|u|_2 <= |u|_p), within its box's corner otherwise."""
    from gnc import sky_zones

    if not builder.exact:
        return builder.max_radius_deg  # the polygon on builder.vertices_tan, whose largest radius this is
    if builder.kind == "superellipse":
        A = [math.tan(math.radians(a)) for a in sky_zones._shape_get(builder.shape, "semi_axes_deg")]
        p = float(sky_zones._shape_get(builder.shape, "exponent", 2.0))
        r = max(A) if p <= 2.0 else math.hypot(*A)
    elif builder.kind == "polygon":
        r = float(np.max(np.linalg.norm(sky_zones._polygon_tangent_vertices(
            sky_zones._shape_get(builder.shape, "vertices_deg")), axis=1)))
    else:
        return None
    return math.degrees(math.atan(r))


def _boundary_only_zone(builder, c0: np.ndarray):
    """The zone ``builder.build(c0)`` for its boundary only: an exact superellipse keeps its geometry but
    gets the smallest search structure (a build's cost; `boundary` reads only the geometry)."""
    from gnc import sky_zones, zones

    if not (builder.exact and builder.kind == "superellipse"):
        return builder.build(c0)
    c = sky_zones._center(c0)
    A = [math.tan(math.radians(a)) for a in sky_zones._shape_get(builder.shape, "semi_axes_deg")]
    return zones.StarZone.superellipsoid(c, sky_zones.sky_frame(c, builder.orientation_deg).T, np.asarray(A),
                                         float(sky_zones._shape_get(builder.shape, "exponent", 2.0)),
                                         resolution=(1, 1))


def lifted_quaternions(mission, truth: dict[str, np.ndarray]) -> np.ndarray:
    """The truth attitude as the flight software's law sees it on S^3 (see fsw.guidance.quaternion 'Double cover')."""
    q = np.array(truth["q_NB"], dtype=float)
    if not len(q):
        return q
    t = truth["t_s"]
    starts = [(s.t_start_s, s.target) for s in schedule(mission) if s.mode == "QUATERNION"]
    out = np.empty_like(q)
    prev = None
    k = 0
    for i in range(len(q)):
        x = q[i]
        target = None
        while k < len(starts) and t[i] >= starts[k][0] - 1e-9:
            target = starts[k][1]
            k += 1
        if target is not None:
            if float(x @ target) < 0:  # a new target: lift into its hemisphere
                x = -x
        elif prev is not None and float(x @ prev) < 0:  # otherwise keep the sign continuous
            x = -x
        out[i] = x
        prev = x
    return out


def attitude_zone_series(mission, q_lift: np.ndarray) -> list[ZoneSeries]:
    from hil_sim.mission.physics_checks import s3_zones

    names, phys, _ = s3_zones(mission)
    return [ZoneSeries(n, "attitude", _signed_margins(z, q_lift) if len(q_lift) else np.zeros(0), [])
            for n, z in zip(names, phys)]


def error_series(mission, truth: dict[str, np.ndarray], y_N: np.ndarray) -> tuple[np.ndarray, list]:
    """Truth error [deg] to the target active at each sample (pointing angle or attitude angle)."""
    from gnc.attitude import attitude_error_angle

    t = truth["t_s"]
    err = np.full(len(t), np.nan)
    segments = schedule(mission)
    for s in segments:
        sel = _segment_samples(t, s, s is segments[-1])
        if s.mode == "POINTING" and s.earth is not None:  # where the target on the Earth truly is
            target = earth_target_truth_N(s, mission.epoch_utc, t[sel], truth["r_sc_N_km"][sel])
            err[sel] = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", y_N[sel], target), -1.0, 1.0)))
        elif s.mode == "POINTING":
            err[sel] = np.degrees(np.arccos(np.clip(y_N[sel] @ s.target, -1.0, 1.0)))
        elif s.mode == "QUATERNION":
            err[sel] = [math.degrees(attitude_error_angle(q, s.target)) for q in truth["q_NB"][sel]]
    return err, segments


def _segment_samples(t: np.ndarray, s, last: bool) -> np.ndarray:
    """The samples a `schedule` segment owns: [start, end), the last one every sample from its start on."""
    return (t >= s.t_start_s - 1e-6) & ((t < s.t_end_s - 1e-6) | last)


def settling(mission, t: np.ndarray, err: np.ndarray, segments) -> list[dict[str, Any]]:
    """Per commanded target: when it was first commanded, when the error entered the tolerance for good."""
    tol = mission.requirements.settling_tolerance_deg
    spans: list[dict[str, Any]] = []
    for s in segments:
        if s.mode not in ("POINTING", "QUATERNION"):
            continue
        if spans and spans[-1]["mode"] == s.mode and np.allclose(spans[-1]["target"], s.target) \
                and abs(spans[-1]["t_end_s"] - s.t_start_s) < 1e-9:
            spans[-1]["t_end_s"] = s.t_end_s  # same target re-commanded (e.g. mode restored): one span
            continue
        spans.append({"mode": s.mode, "target": s.target, "source": s.source, "t_start_s": s.t_start_s,
                      "t_end_s": s.t_end_s})
    out = []
    for k, span in enumerate(spans):
        last = k == len(spans) - 1
        # a span owns [start, end); the sample at its end already belongs to the next target
        sel = (t >= span["t_start_s"] - 1e-6) & ((t < span["t_end_s"] - 1e-6) | last)
        ts, es = t[sel], err[sel]
        settled_at = None
        if len(es) and np.isfinite(es[-1]) and es[-1] < tol:
            above = np.nonzero(~(es < tol))[0]
            settled_at = float(ts[above[-1] + 1]) if len(above) else float(ts[0])
        # The configured initial target is a requirement only when it is the mission's manoeuvre (nothing
        # commanded after it); before a timeline slew it is a hold that dispersed initial attitudes need
        # not finish.
        judged = last or str(span["source"]).startswith("timeline")
        out.append({"target_from": span["source"], "mode": span["mode"], "judged": judged,
                    "commanded_at_s": span["t_start_s"],
                    "until_s": span["t_end_s"], "settled_at_s": settled_at,
                    "settling_time_s": None if settled_at is None else settled_at - span["t_start_s"],
                    "final_error_deg": float(es[-1]) if len(es) else None})
    return out


def add_torque_variation(spans: list[dict[str, Any]], t: np.ndarray, wheel_torque_Nm: np.ndarray) -> None:
    """Each settling span gets ``torque_variation_Nm``: the total variation of the wheel torque commands
    over the span, sum over samples and wheels of |tau_k - tau_(k-1)| [N m]. A smooth slew needs about
    4 x the torque limit per wheel (up, down, and the same to brake); a chattering one many times that
    (design note 13)."""
    tau = np.asarray(wheel_torque_Nm, dtype=float)
    if tau.ndim != 2 or len(tau) != len(t) or len(t) < 2:
        return
    steps = np.abs(np.diff(tau, axis=0)).sum(axis=1)  # step k: between samples k and k + 1
    for k, span in enumerate(spans):
        last = k == len(spans) - 1
        sel = (t[1:] > span["commanded_at_s"] + 1e-6) & ((t[1:] < span["until_s"] - 1e-6) | last)
        span["torque_variation_Nm"] = float(steps[sel].sum())


def rate_limit_series(mission, t: np.ndarray, gains_set: Sequence[tuple[float, float]] = ()) -> np.ndarray:
    """The body-rate limit [rad/s] in force at each time: the flight software's configured one, then each
    rate limit the flight software acknowledged (``gains_set``: (onboard time [s], rate limit [deg/s]) of its
    GAINS_SET events, `acknowledged_rate_limits`), from its time on. A SET_GAINS the flight software refused
    changes nothing, so the judge never takes the timeline's word for it."""
    limit = np.full(len(t), math.radians(mission.flight_software.spacecraft.max_rate_deg_s))
    for t_s, rate_deg_s in sorted(gains_set):
        limit[t >= t_s] = math.radians(rate_deg_s)
    return limit


def acknowledged_rate_limits_of_run(run_dir: Path) -> list[tuple[float, float]]:
    """`acknowledged_rate_limits` of a run folder's ground event archive."""
    return acknowledged_rate_limits([(e.get("time_s", 0.0), e.get("event"), e.get("args", {}))
                                     for e in _ground_events(run_dir)])


def acknowledged_rate_limits(events: Sequence[tuple[float, str, dict]]) -> list[tuple[float, float]]:
    """(time, rate limit) of every GAINS_SET event among (time [s], name, args) events."""
    return [(float(t), float(a["rate_limit_deg_s"])) for t, name, a in events
            if name == "GAINS_SET" and "rate_limit_deg_s" in a]


def peak_body_rate_fraction(mission, truth: dict[str, np.ndarray],
                            gains_set: Sequence[tuple[float, float]] = ()) -> tuple[float, float]:
    """(peak of true |omega_BN_B| / the rate limit in force (`rate_limit_series`), its time [s]). Samples
    before the body rate first comes within the limit (a tumbling start being damped) are not judged."""
    t = truth["t_s"]
    if len(t) == 0:
        return math.nan, math.nan
    frac = np.linalg.norm(truth["omega_BN_B"], axis=1) / rate_limit_series(mission, t, gains_set)
    within = np.flatnonzero(frac <= 1.0)
    if not len(within):
        return float(frac.max()), float(t[int(np.argmax(frac))])
    i = within[0] + int(np.argmax(frac[within[0]:]))
    return float(frac[i]), float(t[i])


def _ground_events(run_dir: Path) -> list[dict[str, Any]]:
    path = run_dir / "ground" / "events.jsonl"
    if not path.exists():
        return []
    events = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            events.append(json.loads(line))
        except ValueError:
            continue
    return events


def _hk_last(run_dir: Path, names: tuple[str, ...]) -> dict[str, Any]:
    """Last value of housekeeping channels from the decoded ground archive."""
    path = run_dir / "ground" / "tm_decoded.jsonl"
    last: dict[str, Any] = {}
    if not path.exists():
        return last
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        values = rec.get("values") or {}
        if rec.get("packet") == "HK":
            for n in names:
                if n in values:
                    last[n] = values[n]
    return last


def _event_name(e: dict[str, Any]) -> str:
    return str(e.get("name") or e.get("event") or "")


def _event_args(e: dict[str, Any]) -> dict[str, Any]:
    return e.get("args") or e.get("values") or {}


# Telemetry completeness: packets a run may miss at its ends (the first cycle before the ground saw the
# flight software start, the last cycle after the simulator's last tick) without having lost any
TM_END_SLACK_PACKETS = 2


def telemetry_completeness(ground: dict[str, Any], sim_s: float, rates) -> tuple[bool, str]:
    """Did the ground receive all the telemetry of ``sim_s`` simulated seconds? (no sequence gaps, and
    the GNC and housekeeping packet counts match the simulated time at the flight software's rates)."""
    from comms.dictionary import GNC_APID, HK_APID

    if not ground:
        return False, "the ground wrote no ground_summary.json: it did not end normally"
    per_apid = ground.get("per_apid", {})
    problems = []
    if ground.get("missing_packets", 0):
        problems.append(f"{ground['missing_packets']} packets missing in sequence-count gaps")
    for name, apid, rate_hz in (("GNC", GNC_APID, rates.gnc_rate_hz), ("HK", HK_APID, rates.housekeeping_rate_hz)):
        received = int(per_apid.get(f"{apid:#05x}", {}).get("received", 0))
        expected = int(math.floor(sim_s * rate_hz + 1e-9))
        if received < expected - TM_END_SLACK_PACKETS:
            problems.append(f"{name}: {received} packets received of {expected} for {sim_s:.1f} s at {rate_hz:g} Hz")
    return not problems, "; ".join(problems) or "no gaps; packet counts match the simulated time"


class _Requirements:
    """The requirement rows of a summary, in the order they are judged."""

    def __init__(self) -> None:
        self.results: list[dict[str, Any]] = []

    def requirement(self, name: str, value: Any, limit: Any, passed: bool, detail: str = "", unit: str = "") -> None:
        # value and limit in the same unit (``unit``), numbers rounded for a person to read
        self.results.append({"name": name, "value": _rounded(value), "unit": unit, "limit": limit,
                             "pass": bool(passed), "detail": detail})

    def not_judged(self, name: str, why: str, value: str = "not reached") -> None:
        # a requirement the run could not reach: shown, and kept out of the verdict
        self.results.append({"name": name, "value": value, "unit": "", "limit": "-", "pass": True,
                             "judged": False, "detail": why})


def evaluate(run_dir: Path, mission, *, interrupted: bool = False, status: str | None = None,
             planned_duration_s: float | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(summary dict for JSON, series for plots).

    ``status``: how the run ended (hil_sim.sil.orchestrator: ``completed``, ``interrupted``, ``crashed: ...``); a
    completed run whose ground lost telemetry becomes ``incomplete telemetry``. Only a completed run
    can pass. ``planned_duration_s``: the mission file's own duration when the run was shortened
    (``--duration``): a target whose settling deadline lies beyond the run's end is reported as not
    judged (it had no chance to settle) instead of failed; the keep-out margins, wheel, rate and
    event requirements are judged as always."""
    run_dir = Path(run_dir)
    status = status or ("interrupted" if interrupted else "completed")
    req = mission.requirements
    truth = load_truth(run_dir)
    t = truth["t_s"]
    y_N, zones, q_lift, err, segments, settle = _judged_series(mission, truth)
    reqs = _Requirements()

    sim_stats = _read_json(run_dir / "simulator.json")
    if len(t) < 2:
        reqs.requirement("truth recorded", int(len(t)), ">= 2", False, "the run produced no truth samples", "samples")
    if sim_stats.get("aborted"):
        reqs.requirement("run completed", "no", "yes", False, str(sim_stats["aborted"]))
    _judge_keepout_margins(reqs, zones, t, req)
    unjudged_last = _judge_settling(reqs, settle, t, req, planned_duration_s)
    _judge_final_error(reqs, err, t, req, unjudged_last)
    if len(t):
        _judge_wheel_speed_and_body_rate(reqs, run_dir, mission, truth)
    hk = _hk_last(run_dir, ("slips_gnc", "cycles", "fdir_trips", "bus_crc_errors", "bus_alive_errors",
                            "bus_timeouts", "tc_accepted", "tc_rejected"))
    _judge_cycle_slips(reqs, sim_stats, hk, req)
    events = _ground_events(run_dir)
    trips = _judge_fdir_events(reqs, events, req)
    if req.max_detumble_time_s is not None:
        _judge_detumble(reqs, events, req.max_detumble_time_s)
    exposure = instrument_exposure(t, [z for z in zones if z.kind == "sky"], truth.get("door_position"))
    if mission.spacecraft.door is not None:
        _judge_exposure(reqs, exposure, t, truth, req)
    ground = _read_json(run_dir / "ground" / "ground_summary.json")
    wall = float(sim_stats.get("wall_s", 0.0) or 0.0)
    sim_s = float(sim_stats.get("sim_s", 0.0) or 0.0)
    tm_complete, tm_detail = telemetry_completeness(ground, sim_s, mission.flight_software.rates)
    if status == "completed" and not tm_complete:
        status = "incomplete telemetry"
    summary = {
        "mission": mission.name,
        "run_dir": str(run_dir),
        "status": status,
        "config_sha256": _read_text(run_dir / "mission.yaml.sha256").split(" ")[0],
        "bus": sim_stats.get("bus"),
        "interrupted": status == "interrupted",
        "simulated_s": sim_s,
        "wall_s": wall,
        "speed_x_realtime": sim_s / wall if wall > 0 else None,
        "telemetry_complete": {"complete": tm_complete, "detail": tm_detail},
        "pass": all(r["pass"] for r in reqs.results) and status == "completed",
        "requirements": reqs.results,
        "zones": {z.name: {"kind": z.kind, "min_margin_deg": None if (low := zone_minimum(z)) is None else low[1]}
                  for z in zones},
        "exposure": exposure,
        "settling": settle,
        "fdir_trips": trips,
        "events": {"total": len(events), "by_name": _count(_event_name(e) for e in events)},
        "housekeeping_last": hk,
        "telemetry": ground,
        "simulator": {k: sim_stats.get(k) for k in ("ticks", "frames_sent", "cycle_done", "cycle_done_timeouts",
                                                      "cycle_done_late", "wheel_commands", "candump_frames")},
    }
    series = {"t_s": t, "error_deg": err, "zones": zones, "y_N": y_N, "q_lift": q_lift, "truth": truth,
              "segments": segments}
    return summary, series


def _judged_series(mission, truth: dict[str, np.ndarray]) -> tuple:
    """What the requirements are judged on: (boresight y_N, zone margin series, lifted quaternions, pointing
    error, its target segments, settling per target)."""
    t = truth["t_s"]
    b_B = np.asarray(mission.spacecraft.instrument_boresight_B, dtype=float)
    y_N = boresight_N(truth["q_NB"], b_B)
    zones = sky_zone_series(mission, truth, y_N) if mission.flight_software.pointing.zones else []
    q_lift = lifted_quaternions(mission, truth)
    if mission.flight_software.quaternion.zones:
        zones += attitude_zone_series(mission, q_lift)
    err, segments = error_series(mission, truth, y_N)
    settle = settling(mission, t, err, segments)
    if "wheel_torque_Nm" in truth:
        add_torque_variation(settle, t, truth["wheel_torque_Nm"])
    return y_N, zones, q_lift, err, segments, settle


def _judge_keepout_margins(reqs: _Requirements, zones: list[ZoneSeries], t: np.ndarray, req) -> None:
    for z in zones:
        low = zone_minimum(z)
        if low is not None:
            i, value = low
            armed = "" if z.judged is None else ", armed samples only"
            reqs.requirement(f"keep-out margin {z.name}", value,
                             f"> {_num(req.min_keepout_margin_deg)}", value > req.min_keepout_margin_deg,
                             f"minimum signed margin to the physical {z.kind} zone at t = {t[i]:.1f} s{armed}", "deg")
        elif z.judged is not None and len(z.judged):
            reqs.not_judged(f"keep-out margin {z.name}", "armed only for inertial targets, and never armed: no "
                            "inertial target was commanded with the boresight outside the zone", "never armed")


def _judge_settling(reqs: _Requirements, settle: list[dict[str, Any]], t: np.ndarray, req,
                    planned_duration_s: float | None) -> bool:
    """One requirement per judged target; a target of a shortened run whose deadline lies beyond the run's
    end is not judged. Returns whether that happened to the last target."""
    t_end = float(t[-1]) if len(t) else 0.0
    cut_short = planned_duration_s is not None and t_end < planned_duration_s - 1e-6
    unjudged_last = False
    for s in (s for s in settle if s["judged"]):
        deadline_s = (s["commanded_at_s"] + req.max_settling_time_s if req.max_settling_time_s is not None
                      else planned_duration_s if cut_short else s["until_s"])
        if cut_short and s["settled_at_s"] is None and deadline_s > t_end + 1e-6:
            s["judged"] = False
            unjudged_last = s is settle[-1]
            reqs.not_judged(f"settling ({s['target_from']})",
                            f"the run was shortened to {t_end:.0f} s, before this target's settling deadline at "
                            f"{deadline_s:.0f} s (commanded at {s['commanded_at_s']:.1f} s)")
            continue
        ok = s["settled_at_s"] is not None
        # the value is a time after the command, so the limit is one too: the time left before the next
        # target (or the end), or max_settling_time_s when it is shorter
        span_s = s["until_s"] - s["commanded_at_s"]
        limit_s = span_s if req.max_settling_time_s is None else min(span_s, req.max_settling_time_s)
        if req.max_settling_time_s is not None:
            ok = ok and s["settling_time_s"] <= req.max_settling_time_s
        final = s["final_error_deg"]
        reqs.requirement(f"settling ({s['target_from']})", "not settled" if s["settling_time_s"] is None
                         else s["settling_time_s"], f"<= {_num(limit_s)}", ok,
                         f"to within {_num(req.settling_tolerance_deg)} deg of the target commanded at "
                         f"{s['commanded_at_s']:.1f} s; final error "
                         + (f"{final:.4f} deg" if final is not None else "unknown (no samples)"), "s")
    return unjudged_last


def _judge_final_error(reqs: _Requirements, err: np.ndarray, t: np.ndarray, req, unjudged_last: bool) -> None:
    """The truth error at the end; not judged when the last target's settling was not."""
    if unjudged_last:
        final = float(err[-1]) if len(t) else math.nan
        # the error at the end is still what a person flying a shortened run wants to see
        reqs.not_judged("final pointing error", "the run was shortened before the last target's settling deadline",
                        f"not reached ({_rounded(final)} deg at the end)" if math.isfinite(final) else "not reached")
    elif len(t) and not np.isfinite(err).any():
        # a run held in SAFE from start to end (the star tracker lost for good, say) has no target to judge
        reqs.not_judged("final pointing error", "no pointing target was active at any time (SAFE throughout)",
                        "no target")
    elif len(t):
        final = float(err[-1])
        reqs.requirement("final pointing error", final, f"< {_num(req.max_final_pointing_error_deg)}",
                         math.isfinite(final) and final < req.max_final_pointing_error_deg,
                         "truth error to the active target at the end", "deg")


def _judge_wheel_speed_and_body_rate(reqs: _Requirements, run_dir: Path, mission, truth: dict[str, np.ndarray]) -> None:
    req = mission.requirements
    limits = np.array([w.max_speed_rad_s for w in mission.spacecraft.wheels])
    frac = np.abs(truth["wheel_speed_rad_s"]) / limits[None, :]
    peak = float(frac.max())
    w = int(np.argmax(frac.max(axis=0)))
    reqs.requirement("peak wheel speed", 100.0 * peak, f"<= {_num(100.0 * req.max_wheel_speed_fraction)}",
                     peak <= req.max_wheel_speed_fraction,
                     f"wheel {w + 1}: {float(np.abs(truth['wheel_speed_rad_s'][:, w]).max()):.1f} rad/s of "
                     f"{limits[w]:.0f} rad/s", "% of max")
    rate_frac, rate_t = peak_body_rate_fraction(mission, truth, acknowledged_rate_limits_of_run(run_dir))
    reqs.requirement("peak body rate", round(100.0 * rate_frac, 2), f"<= {_num(100.0 * req.max_body_rate_fraction)}",
                     rate_frac <= req.max_body_rate_fraction,
                     f"true |omega| / the configured rate limit, at t = {rate_t:.1f} s", "% of max")


# Real time on a host that is not the flight computer: ticks whose CYCLE_DONE the simulator did not get before
# the next tick began, at most one in 500 (docs/operations.md, real time). The flight software's own overruns
# are judged strictly (requirements.max_cycle_slips).
HOST_LOST_TICK_FRACTION = 0.002


def _judge_cycle_slips(reqs: _Requirements, sim_stats: dict[str, Any], hk: dict[str, Any], req) -> None:
    missed = int(sim_stats.get("cycle_done_timeouts", 0)) + int(sim_stats.get("cycle_done_late", 0))
    fsw_slips = int(hk["slips_gnc"]) if "slips_gnc" in hk else None
    if sim_stats.get("clock") == "realtime":
        # real time: a slip is a cycle that overran its period, as the flight software counts them (the
        # mission's requirement); a tick whose answer the simulator did not get in time is the SIL host's
        # delivery, judged apart against a documented tolerance (docs/operations.md, real time)
        reqs.requirement("cycle slips", "unknown" if fsw_slips is None else fsw_slips, f"<= {req.max_cycle_slips}",
                         fsw_slips is not None and fsw_slips <= req.max_cycle_slips,
                         "flight software GNC cycles that overran their period" if fsw_slips is not None
                         else "no housekeeping telemetry reached the ground: slips unknown")
        ticks = int(sim_stats.get("ticks", 0))
        allowed = int(HOST_LOST_TICK_FRACTION * ticks)
        reqs.requirement("ticks lost on the host", missed, f"<= {allowed}", missed <= allowed,
                         f"CYCLE_DONE late or missing, of {ticks} ticks (tolerance {100 * HOST_LOST_TICK_FRACTION:g} %: "
                         f"the flight software flew those cycles on inputs one period old)")
    else:
        # lockstep: simulated time waits for the flight software, so a slow cycle on the host cannot
        # hurt the loop; what can is a tick the flight software never answered
        reqs.requirement("cycle slips", missed, f"<= {req.max_cycle_slips}", missed <= req.max_cycle_slips,
                         f"lockstep ticks without CYCLE_DONE: {missed}; host-time overruns counted by the flight "
                         f"software (not a loop fault in lockstep): {fsw_slips}")


def _judge_fdir_events(reqs: _Requirements, events: list[dict[str, Any]], req) -> list[str]:
    """The expected FDIR trips all seen, few unexpected ones; returns the trips (monitor names) in order."""
    trips = [str(_event_args(e).get("monitor", "?")) for e in events if _event_name(e) == "FDIR_TRIPPED"]
    expected = list(req.expected_fdir_events)
    missing = [m for m in expected if m not in trips]
    unexpected = [m for m in trips if m not in expected]
    occurred = [m for m in dict.fromkeys(trips) if m in expected]
    reqs.requirement("expected FDIR events", ", ".join(occurred) or "none", ", ".join(expected) or "none", not missing,
                     ("missing: " + ", ".join(missing)) if missing else "all occurred")
    reqs.requirement("unexpected FDIR events", len(unexpected), f"<= {req.max_unexpected_fdir_events}",
                     len(unexpected) <= req.max_unexpected_fdir_events, ", ".join(unexpected) or "none")
    return trips


def _judge_detumble(reqs: _Requirements, events: list[dict[str, Any]], limit_s: float) -> None:
    """DETUMBLE_COMPLETE raised by ``limit_s`` (onboard time, as the flight software reports it)."""
    done = [float(_event_args(e).get("t_s", math.nan)) for e in events if _event_name(e) == "DETUMBLE_COMPLETE"]
    at = done[0] if done else None
    reqs.requirement("detumble complete", at if at is not None else "never", f"<= {_num(limit_s)}",
                     at is not None and at <= limit_s,
                     "DETUMBLE_COMPLETE: the gyro's rate below the threshold for the dwell" if at is not None
                     else "no DETUMBLE_COMPLETE event reached the ground", "s")


def _judge_exposure(reqs: _Requirements, exposure: dict[str, Any], t: np.ndarray, truth: dict[str, np.ndarray],
                    req) -> None:
    """Time inside a sky zone with the door open (a run without door truth cannot pass)."""
    first = exposure["first_t_s"]
    reqs.requirement("instrument exposure", exposure["exposure_s"], f"<= {_num(req.max_instrument_exposure_s)}",
                     exposure["exposure_s"] <= req.max_instrument_exposure_s
                     and (len(t) < 2 or "door_position" in truth),
                     ("no door truth recorded" if len(t) >= 2 and "door_position" not in truth
                      else f"inside a sky zone with the door open, {exposure['depth_deg']:.3f} deg deep at most, "
                      f"from t = {first:.1f} s" if first is not None
                      else f"never inside a sky zone with the door open (inside, door closed: "
                      f"{exposure['inside_s']:.1f} s)"), "s")


def summary_json(summary: dict[str, Any]) -> str:
    return json.dumps(summary, indent=1, default=_json_default) + "\n"


def write_summary(run_dir: Path, mission, *, interrupted: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    """Evaluate and write summary.json; returns (summary, series for the plots)."""
    summary, series = evaluate(run_dir, mission, interrupted=interrupted)
    (Path(run_dir) / "summary.json").write_text(summary_json(summary))
    return summary, series


def _num(value: float) -> str:
    """A number as a person writes it: 4 significant digits, no float noise (139.9, 0.05, 1.2e-05)."""
    return f"{float(value):.4g}"


def _rounded(value: Any) -> Any:
    """Requirement values rounded to 4 significant digits (summary.json and the table alike)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return float(_num(v)) if math.isfinite(v) else v
    return value


def _cell(value: Any, unit: str = "") -> str:
    """A table cell: a number with its unit; a limit such as "<= 250" gets the unit after its number."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (list, tuple)):
        return ", ".join(str(v) for v in value) or "none"
    if isinstance(value, (int, float)):
        text = _num(value) if isinstance(value, float) else str(value)
        return f"{text} {unit}".strip()
    text = str(value)
    return f"{text} {unit}" if unit and text[-1:].isdigit() else text


def format_summary(summary: dict[str, Any], total_wall_s: float | None = None) -> str:
    """The requirement table and the verdict line. ``total_wall_s``: wall time of the whole command, start-up
    included (the summary's own ``wall_s`` is the simulation loop alone)."""
    rows = [(r["name"][:38], _cell(r["value"], r.get("unit", "")), _cell(r["limit"], r.get("unit", ""))[:22],
             "n/a" if r.get("judged") is False else "PASS" if r["pass"] else "FAIL") for r in summary["requirements"]]
    width = max([20] + [len(value) for _, value, _, _ in rows])  # a value is never cut: it is what was measured
    lines = [f"{'requirement':38s} {'value':>{width}s}  {'limit':22s} result"]
    lines += [f"{name:38s} {value:>{width}s}  {limit:22s} {result}" for name, value, limit, result in rows]
    speed = summary.get("speed_x_realtime")
    status = summary.get("status", "completed")
    verdict = "PASS" if summary["pass"] else ("FAIL" if status == "completed" else status.split(":")[0].upper())
    if status != "completed":
        lines.append(f"status: {status}")
    loop = f"{summary['wall_s']:.1f} s flying" + (f", x{speed:.1f}" if speed else "")
    wall = (f"{total_wall_s:.1f} s wall including start-up ({loop})" if total_wall_s is not None
            else f"{summary['wall_s']:.1f} s wall{f', x{speed:.1f}' if speed else ''}")
    lines.append(f"{verdict}: {summary['mission']} ({summary['simulated_s']:.1f} s simulated in {wall}) -> "
                 f"{summary['run_dir']}")
    return "\n".join(lines)


def _count(names) -> dict[str, int]:
    out: dict[str, int] = {}
    for n in names:
        out[n] = out.get(n, 0) + 1
    return out


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _read_text(path: Path) -> str:
    try:
        return path.read_text().strip()
    except OSError:
        return ""


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return str(value)
