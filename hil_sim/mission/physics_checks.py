"""Load-time physics checks of a mission: is the problem the flight software will face well posed?

A schema-valid mission can still be impossible or outside the paper's guarantees. These checks run on
the whole run, because the Sun, Moon and Earth zones move:

* a target (initial or telecommanded) inside a keep-out zone (physical or as inflated for the law); a
  target on the rotating Earth (nadir, a ground point) is checked where it is at each sampled time;
* a ground target below its horizon (or under its ``min_elevation_deg``) for its whole dwell;
* the initial attitude already inside a zone;
* a zone with ``armed: inertial_targets`` (`fsw.config.SkyZoneConfig.armed`) only where the flight software
  keeps it out: for a fixed (inertial) target; a nadir or ground target is checked without it, and an
  initial boresight inside it is no error, since the flight software arms it only once the boresight has
  left it;
* a zone whose kernel g_i is not strictly inside it (the law pushes away from g_i);
* the paper's Assumption 1 (zones pairwise at least 2 delta apart) and the admissible eps interval
  (0, min(eps_bar, 1 - cos delta)) at every sampled time, for the zones as the flight software flies
  them: inflated by ``law.margin_deg`` and merged by its own `fsw.guidance.ZoneGeometry.merge` when
  closer than ``law.merge_gap_deg``, with the onboard ephemeris (`gnc.sky_ephemeris.SkyEphemeris`); a close
  pair it cannot merge (the target between them) is an error;
* kappa <= kappa_bar (StarShapedLaw: an undesired stable equilibrium may exist);
* wheels too weak for the commanded rate limit: the angular acceleration they can give about the worst
  body axis versus ``control.max_command_accel_deg_s2``, the wheel momentum headroom versus
  J * rate limit, and the braking angle at the rate limit versus the margin.

`gnc.checks.check_assumptions` does the paper's maths; this module supplies the zones over time and
turns the results into messages with the times, zone names and numbers.

`check_mission_cached` (what `keepout sil run` calls) keeps each verdict in the user cache, keyed on the
mission's full validated content, the source of every keepout module the checks import and the numeric
libraries' versions: the checks are a pure function of these, so a second run of the same mission skips
seconds of numerical search and gets the very report the search would give.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fsw.guidance.edge_rule import TARGET_IN_LAYER, clearance_needed_deg, target_layer
from fsw.guidance.pointing import ZONE_REBUILD_TOL_DEG
from gnc.ephemeris import EARTH_RADIUS_KM
from gnc.wheels import fibonacci_sphere, wheel_authority

if TYPE_CHECKING:
    from pathlib import Path

    from hil_sim.mission.model import Mission

MAX_SWEEP_SAMPLES = 240
ZONE_MOTION_PER_SAMPLE_DEG = 0.5  # sample often enough that no zone centre moves more than this between checks


Loc = tuple[str | int, ...]


@dataclass
class Finding:
    level: str  # "error" | "warning" | "info"
    check: str  # short name of the check
    message: str
    numbers: dict[str, float] = field(default_factory=dict)
    loc: Loc | None = None  # key path of the key to change in the mission file

    def __str__(self) -> str:
        return f"{self.level.upper():7s} [{self.check}] {self.message}"

    def located(self, doc: Any) -> str:
        """``file:line:col key.path: error: message`` at the key to change (``doc``: yaml_loader.Marked)."""
        from hil_sim.mission.loader import format_path

        if doc is None or self.loc is None:
            return str(self)
        line, col = doc.mark_for(self.loc, prefer_key=True)
        return f"{doc.file}:{line}:{col} {format_path(self.loc)}: {self.level}: {self.message}"


@dataclass
class PhysicsReport:
    findings: list[Finding] = field(default_factory=list)
    samples: int = 0
    reused_from: str | None = None  # the cache file this verdict was read from (check_mission_cached)

    @property
    def ok(self) -> bool:
        return not any(f.level == "error" for f in self.findings)

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.level == "error"]

    @property
    def warnings(self) -> list[Finding]:
        return [f for f in self.findings if f.level == "warning"]

    def add(self, level: str, check: str, message: str, loc: Loc | None = None, **numbers: float) -> None:
        self.findings.append(Finding(level, check, message, {k: float(v) for k, v in numbers.items()}, loc))

    def format(self, doc: Any = None, *, errors_only: bool = False) -> str:
        """One line per finding (at ``file:line:col`` of the key to change when ``doc``, the mission's
        `yaml_loader.Marked`, is given), then the verdict (left out with ``errors_only``)."""
        if errors_only:
            return "\n".join(f.located(doc) for f in self.errors)
        lines = [f.located(doc) for f in self.findings]
        verdict = "PASS" if self.ok else "FAIL"
        lines.append(f"{verdict}: {len(self.errors)} error(s), {len(self.warnings)} warning(s), "
                     f"{self.samples} time sample(s) checked")
        if self.reused_from:
            lines.append(f"(verdict of an earlier check of the same mission content with the same keepout sources "
                         f"and libraries: {self.reused_from})")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "samples": self.samples,
                "findings": [{"level": f.level, "check": f.check, "message": f.message, "numbers": f.numbers,
                              "key": None if f.loc is None else list(f.loc)} for f in self.findings]}


    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "PhysicsReport":
        """The inverse of `to_dict`."""
        return cls([Finding(f["level"], f["check"], f["message"], dict(f["numbers"]),
                            None if f["key"] is None else tuple(f["key"])) for f in data["findings"]],
                   int(data["samples"]))


def d_s_to_deg(d_s: float) -> float:
    """Spherical separation d_s = 1 - cos(angle) -> angle [deg] (sign kept)."""
    return math.copysign(math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - abs(d_s))))), d_s)


def signed_margin_deg(zone: Any, x: np.ndarray) -> float:
    return d_s_to_deg(float(zone.signed_separation(np.asarray(x, dtype=float))))


# ---------------------------------------------------------------------------------------------
# The run's schedule: which mode and which target when
# ---------------------------------------------------------------------------------------------

@dataclass
class Segment:
    t_start_s: float
    t_end_s: float
    mode: str
    target: np.ndarray  # unit 3-vector (POINTING) or quaternion (QUATERNION)
    source: str  # where the target comes from, for messages
    loc: Loc = ()  # key path of the target in the mission file
    earth: tuple | None = None  # a target on the Earth: ("nadir", None) or ("ground", GroundTargetConfig)


def _earth_target(earth: tuple | None, ephemeris) -> np.ndarray | None:
    """The Earth-fixed point [km] of a ground target (None for nadir)."""
    return None if earth[0] == "nadir" else ephemeris.ground_point_E_km(earth[1])


def target_at(seg: Segment, ephemeris, t_s: float) -> np.ndarray:
    """The segment's target direction at ``t_s``: fixed, or where its target on the Earth is then, seen
    from the onboard orbit (as the flight software follows it)."""
    if seg.earth is None:
        return seg.target
    return ephemeris.target_direction_N(t_s, _earth_target(seg.earth, ephemeris))


def earth_target_truth_N(seg: Segment, epoch_utc, t_s: np.ndarray, r_sc_N_km: np.ndarray) -> np.ndarray:
    """(n, 3) unit vectors from the spacecraft's true positions ``r_sc_N_km`` [km] at mission times ``t_s``
    to the segment's target on the Earth (the judge's truth, not the onboard orbit)."""
    from gnc.earth import direction_to_point_N, earth_fixed_to_inertial, geodetic_to_earth_fixed_km, nadir_N
    from gnc.ephemeris import julian_date

    jd0 = julian_date(epoch_utc)
    if seg.earth[0] == "nadir":
        return np.array([nadir_N(r) for r in r_sc_N_km]).reshape(-1, 3)
    g = seg.earth[1]
    point = geodetic_to_earth_fixed_km(g.latitude_deg, g.longitude_deg, g.altitude_m)
    return np.array([direction_to_point_N(r, earth_fixed_to_inertial(jd0 + t / 86400.0) @ point)
                     for t, r in zip(t_s, r_sc_N_km)]).reshape(-1, 3)


def schedule(mission: "Mission") -> list[Segment]:
    """Piecewise-constant (mode, target) over the run from the initial config and the timeline."""
    from hil_sim.mission.model import SetModeCommand, SetTargetCommand

    from gnc.sky_ephemeris import SkyEphemeris

    fsw = mission.flight_software
    mode = fsw.initial_mode
    target_dir = np.asarray(fsw.pointing.target_N, dtype=float)
    target_q = np.asarray(fsw.quaternion.target_q_NB, dtype=float)
    src_dir, src_q = "flight_software.pointing.target_N", "flight_software.quaternion.target_q_NB"
    loc_dir: Loc = ("flight_software", "pointing", "target_N")
    loc_q: Loc = ("flight_software", "quaternion", "target_q_NB")
    earth: tuple | None = None
    if fsw.pointing.target_kind != "inertial":
        earth = (fsw.pointing.target_kind, fsw.pointing.target_ground)
        key = "target_ground" if earth[0] == "ground" else "target_kind"
        src_dir, loc_dir = f"flight_software.pointing.{key}", ("flight_software", "pointing", key)
    ephemeris = SkyEphemeris(fsw)
    segments: list[Segment] = []
    t = 0.0

    def close(until: float) -> None:
        if until > t or not segments:
            if mode == "QUATERNION":
                segments.append(Segment(t, until, mode, target_q.copy(), src_q, loc_q))
                return
            seg = Segment(t, until, mode, target_dir.copy(), src_dir, loc_dir, earth)
            segments.append(replace(seg, target=target_at(seg, ephemeris, t)) if earth else seg)

    for i, entry in enumerate(mission.timeline):
        if isinstance(entry, SetModeCommand):
            close(entry.t_s)
            t, mode = entry.t_s, entry.mode
        elif isinstance(entry, SetTargetCommand):
            close(entry.t_s)
            t = entry.t_s
            direction = entry.target_direction_N()
            if direction is not None:
                target_dir, src_dir, earth = direction, f"timeline[{i}]", None
                loc_dir = ("timeline", i, "target_N" if entry.target_N is not None else "ra_dec_deg")
            elif entry.nadir or entry.ground is not None:
                earth = ("nadir", None) if entry.nadir else ("ground", entry.ground)
                src_dir, loc_dir = f"timeline[{i}]", ("timeline", i, earth[0])
            elif entry.q_target_NB is not None:
                target_q, src_q = np.asarray(entry.q_target_NB, dtype=float), f"timeline[{i}]"
                loc_q = ("timeline", i, "q_target_NB")
    close(mission.duration_s)
    return [s for s in segments if s.t_end_s > s.t_start_s or len(segments) == 1]


# ---------------------------------------------------------------------------------------------
# Zones as the flight software builds them
# ---------------------------------------------------------------------------------------------

class ZoneBuildError(ValueError):
    """A zone description that gnc cannot turn into a star-shaped set about its centre (kernel)."""

    def __init__(self, message: str, loc: Loc | None = None):
        super().__init__(message)
        self.loc = loc


def _kernel_hint(name: str, exc: Exception) -> str:
    text = f"zone '{name}' cannot be built: {exc}"
    if any(word in str(exc).lower() for word in ("star", "vert", "centre", "center", "kernel", "inside")):
        text += (". The law needs a kernel point g strictly inside the zone from which every boundary point "
                 "is seen along a geodesic inside it: for a sky zone that point is the body direction (the "
                 "origin of the angular description), so the shape must contain the origin strictly inside "
                 "and be star-shaped about it")
    return text


@dataclass
class FlownZones:
    """The law's zones at one time as the flight software flies them: after its own merging."""

    zones: list  # merged law zones
    groups: list[list[int]]  # indices into the mission's zones, one group per merged zone
    names: list[str]  # "sun", or "sun+moon" for a merged group
    unmerged: list[tuple[int, int]]  # close pairs the flight software could not merge (indices into zones)


class SkyZones:
    """Physical and law (inflated) sky zones of a mission at any time, with the onboard ephemeris.

    The law zones are inflated exactly as `fsw.guidance` inflates them (the law margin plus the rebuild
    tolerance), and `as_flown` merges them with the flight software's own `ZoneGeometry.merge`, so the
    checks judge the geometry the flight software will fly, not the zones as written.
    """

    def __init__(self, mission: "Mission"):
        from fsw.guidance import ZONE_REBUILD_TOL_DEG
        from gnc.sky_ephemeris import SkyEphemeris
        from gnc import sky_zones

        fsw = mission.flight_software
        self.ephemeris = SkyEphemeris(fsw)
        self.margin_deg = fsw.law.margin_deg
        self.merge_gap_deg = fsw.law.merge_gap_deg
        law_inflation_deg = self.margin_deg + ZONE_REBUILD_TOL_DEG
        self.names: list[str] = []
        self.bodies: list[str] = []
        self.armed: list[str] = []  # each zone's `SkyZoneConfig.armed`
        self._phys, self._law, self._fixed = [], [], []
        for z in fsw.pointing.zones:
            extra = (self.ephemeris.earth_angular_radius_deg
                     if z.body == "earth" and z.add_body_angular_radius else 0.0)
            self.names.append(z.name)
            self.bodies.append(z.body)
            self.armed.append(z.armed)
            try:
                self._phys.append(sky_zones.SkyZoneBuilder(z.geometry, 0.0, extra))
                self._law.append(sky_zones.SkyZoneBuilder(z.geometry, law_inflation_deg, extra))
                self._phys[-1].build(np.array([0.0, 0.0, 1.0]))
            except ValueError as exc:
                raise ZoneBuildError(_kernel_hint(z.name, exc), ZONES_LOC + (len(self.names) - 1, "geometry")) from None
            self._fixed.append(np.asarray(z.direction_N, dtype=float) if z.body == "inertial" else None)

    def __len__(self) -> int:
        return len(self.names)

    def centers(self, t_s: float) -> list[np.ndarray]:
        dirs = self.ephemeris.directions(t_s) if any(f is None for f in self._fixed) else {}
        return [f if f is not None else np.asarray(dirs[b], dtype=float) for f, b in zip(self._fixed, self.bodies)]

    def physical(self, t_s: float) -> list:
        return [b.build(c) for b, c in zip(self._phys, self.centers(t_s))]

    def law(self, t_s: float) -> list:
        return [b.build(c) for b, c in zip(self._law, self.centers(t_s))]

    def kept_for(self, seg: Segment) -> list[int]:
        """Indices of the zones the flight software keeps out while it flies ``seg``'s target: all of them
        for a fixed direction; for a nadir or ground target not those armed for inertial targets only,
        which it disarms at once (its target lies inside the Earth's disc)."""
        if seg.earth is None:
            return list(range(len(self.names)))
        return [k for k, armed in enumerate(self.armed) if armed != "inertial_targets"]

    def as_flown(self, law_zones: list, target: np.ndarray, indices: list[int] | None = None) -> FlownZones:
        """Merge ``law_zones`` as the flight software does with the boresight at ``target`` (where it
        settles: a merged zone must leave it outside, or the pair is bridged or left apart). ``indices``:
        the mission zone behind each of ``law_zones`` when they are not all of them (`kept_for`)."""
        from fsw.guidance import ZoneGeometry

        geometry = ZoneGeometry(3, self.merge_gap_deg)
        merged, groups = geometry.merge(list(law_zones), keep_outside=[np.asarray(target, dtype=float)])
        if indices is not None:
            groups = [[indices[j] for j in g] for g in groups]
        names = ["+".join(self.names[k] for k in g) for g in groups]
        return FlownZones(merged, groups, names, list(geometry.unmerged))

    def max_rate_deg_s(self, t_s: float, dt_s: float = 60.0) -> float:
        """Fastest apparent motion of a zone centre [deg/s] around t."""
        a, b = self.centers(t_s), self.centers(t_s + dt_s)
        rates = [math.degrees(math.acos(float(np.clip(x @ y, -1, 1)))) / dt_s for x, y in zip(a, b)]
        return max(rates, default=0.0)


def s3_zones(mission: "Mission") -> tuple[list[str], list, list]:
    """(names, physical zones, law zones inflated by margin) on S^3, as fsw.guidance builds them."""
    m = math.radians(mission.flight_software.law.margin_deg)
    names, phys, law = [], [], []
    for k, zc in enumerate(mission.flight_software.quaternion.zones):
        try:
            _append_s3_zone(zc, m, names, phys, law)
        except ValueError as exc:
            raise ZoneBuildError(_kernel_hint(zc.name, exc), S3_ZONES_LOC + (k,)) from None
    return names, phys, law


def _append_s3_zone(zc, margin_rad: float, names: list, phys: list, law: list) -> None:
    from gnc import zones as gz

    centers = [np.asarray(zc.center_q, dtype=float)]
    if zc.antipodal_copy:
        centers.append(-centers[0])
    for k, c in enumerate(centers):
        names.append(zc.name + ("" if k == 0 else " (antipode)"))
        if zc.shape == "cone":
            ha = math.radians(zc.half_angle_deg)
            phys.append(gz.ConicZone(c, ha))
            law.append(gz.ConicZone(c, ha + margin_rad))
        else:
            # margin applied per principal direction in angle, as fsw.guidance does
            a = np.asarray(zc.semi_axes, dtype=float)
            a_infl = np.tan(np.minimum(np.arctan(a) + margin_rad, math.radians(89.0)))
            phys.append(gz.StarZone.superellipsoid(c, None, a, zc.exponent))
            law.append(gz.StarZone.superellipsoid(c, None, a_infl, zc.exponent))


# ---------------------------------------------------------------------------------------------
# The checks
# ---------------------------------------------------------------------------------------------

ZONES_LOC: Loc = ("flight_software", "pointing", "zones")
S3_ZONES_LOC: Loc = ("flight_software", "quaternion", "zones")
LAW_LOC: Loc = ("flight_software", "law")
BODY_NAMES = {"sun": "the Sun", "moon": "the Moon", "earth": "the Earth"}


def check_mission(mission: "Mission", step_s: float | None = None, *, quick: bool = False) -> PhysicsReport:
    """Run every physics check on a validated mission; never raises for a bad mission, reports it.

    ``quick`` leaves out the paper's assumption sweep (seconds of numerical search per time sample):
    `keepout config validate` runs it so, and reports the same errors as `config check` for targets,
    the initial state, zone shapes, merges and wheels.
    """
    report = PhysicsReport()
    segments = schedule(mission)
    modes = {s.mode for s in segments}
    fsw = mission.flight_software
    if "POINTING" in modes and fsw.pointing.zones:
        try:
            _check_pointing(mission, segments, report, step_s, quick)
        except ZoneBuildError as exc:
            report.add("error", "kernel", str(exc), exc.loc)
    if "QUATERNION" in modes and fsw.quaternion.zones:
        try:
            _check_quaternion(mission, segments, report, quick)
        except ZoneBuildError as exc:
            report.add("error", "kernel", str(exc), exc.loc)
    if "POINTING" in modes:
        _check_ground_visibility(mission, segments, report)
    _check_wheels(mission, report)
    if not report.findings:
        report.add("info", "summary", "no problems found")
    return report


CACHE_ENV = "KEEPOUT_PHYSICS_CACHE"  # "off": always run the checks; a folder: keep the verdicts there
_CACHE_FORMAT = 1  # bump when the stored report's layout or meaning changes
CACHE_MAX_VERDICTS = 512  # the newest are kept (a few kB each): missions, sources and versions change


def verdict_key(mission: "Mission") -> str:
    """SHA-256 of everything `check_mission` depends on: the validated mission (every field, defaults
    included), the keepout sources the checks import (`gnc._numba_cache.source_digest`), the numeric
    libraries and the CPU (floating point may differ in the last bit between CPUs)."""
    import hashlib
    import json
    import platform
    import sys
    from importlib import metadata

    from gnc._numba_cache import source_digest

    versions = {}
    for dist in ("numpy", "scipy", "numba", "llvmlite", "pydantic"):  # versions only: no import
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[dist] = None
    from numba.core.registry import cpu_target

    cpu = cpu_target.target_context.codegen().magic_tuple()  # (triple, CPU name, features): numba's own key
    payload = {"format": _CACHE_FORMAT, "mission": mission.model_dump(mode="json"), "sources": source_digest(__file__),
               "versions": versions, "python": sys.version, "machine": [platform.machine(), *cpu]}
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()


def _verdict_folder() -> "Path | None":
    import os
    from pathlib import Path

    from gnc._numba_cache import user_cache_dir

    setting = os.environ.get(CACHE_ENV, "")
    if setting.lower() == "off":
        return None
    return Path(setting) if setting else user_cache_dir() / "physics_checks"


def check_mission_cached(mission: "Mission", refresh: bool = False) -> PhysicsReport:
    """`check_mission(mission)`, or its stored verdict for the same `verdict_key` (see the module doc).

    A missing, unreadable or foreign cache file means the checks run; a cache that cannot be written
    is left alone. ``KEEPOUT_PHYSICS_CACHE=off`` always runs them. ``refresh``: run them and store the
    verdict even if one is kept (the warm-up: it must compile every kernel the checks use, for the wheel)."""
    import json
    import os

    folder = _verdict_folder()
    if folder is None:
        return check_mission(mission)
    key = verdict_key(mission)
    path = folder / f"{key}.json"
    try:
        data = {} if refresh else json.loads(path.read_text())
        if data.get("key") == key:
            report = PhysicsReport.from_dict(data["report"])
            report.reused_from = str(path)
            return report
    except (OSError, ValueError, KeyError, TypeError):
        pass  # absent or unreadable: check
    report = check_mission(mission)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"key": key, "mission": mission.name, "report": report.to_dict()}))
        os.replace(tmp, path)  # atomic: two runs at once never read half a file
        _trim(folder)
    except OSError:
        pass
    return report


def _trim(folder: "Path") -> None:
    """Delete all but the CACHE_MAX_VERDICTS newest verdicts."""
    files = sorted(folder.glob("*.json"), key=lambda p: p.stat().st_mtime, reverse=True)
    for old in files[CACHE_MAX_VERDICTS:]:
        old.unlink(missing_ok=True)


def _eps_in_use(mission: "Mission", eps_max: float) -> float:
    """The eps the assumption check holds the law to: the configured eps as it is (a fixed eps that is not
    admissible is an error to report, though the flight software would fly a lower one), or with 'auto'
    the fraction of the admissible bound the flight software takes. Whether a target is usable at all is
    `fsw.guidance.edge_rule.target_layer`, the flight software's own rule."""
    law = mission.flight_software.law
    if law.eps == "auto":
        return min(law.eps_fraction * eps_max, law.eps_max_used)
    return float(law.eps)


@dataclass
class _Where:
    """What a finding is about: the time, the target's source and key, the zones and their keys."""

    t_s: float
    seg: Segment
    names: list[str]  # one per zone as the law sees it
    zone_locs: list[Loc]  # the key of the (first) mission zone behind each


def _check_assumptions_at(mission, zones, where: _Where, kappa, report, seen, law_name="star") -> float:
    """Check the law's assumptions at one time, each failure in plain words at the key to change;
    return the upper end of the admissible eps interval."""
    from gnc.checks import check_assumptions

    law = mission.flight_software.law
    target = where.seg.target
    def eps_for(eps_max: float) -> float:  # the eps the flight software would use
        return _eps_in_use(mission, eps_max) if eps_max > 0 else 1e-9

    rep = check_assumptions(target, zones, eps_for, kappa=kappa if law_name == "star" else None, law=law_name)
    eps_max = float(rep.eps_max)
    eps = eps_for(eps_max)
    kappa_low = (rep.kappa_bar is not None and math.isfinite(float(rep.kappa_bar)) and kappa is not None
                 and kappa <= float(rep.kappa_bar))
    found = False
    for msg in rep.errors:
        plain = _plain_assumption(msg, where, eps, eps_max)
        if plain is None or (kappa_low and msg.startswith("kappa =")):
            continue  # reported by another check (target, kernel, kappa): one root cause, one error
        text, loc = plain
        key = (where.seg.source, loc, _strip_numbers(text))
        found = True
        if key not in seen:
            seen.add(key)
            report.add("error", "assumptions", text, loc, t_s=where.t_s, eps=eps, eps_max=eps_max)
    if law.eps == "auto" and not eps_max > 0 and not found and (where.seg.source, "eps") not in seen:
        seen.add((where.seg.source, "eps"))
        report.add("error", "eps", f"at t = {where.t_s:.0f} s no avoidance layer fits round the zones for the "
                   f"target from {where.seg.source} (eps_max = {eps_max:.4g}): move the target away from the "
                   "zones", where.seg.loc, t_s=where.t_s, eps_max=eps_max)
    if kappa_low and "kappa" not in seen:  # one gain too low: one error, at the first target it fails for
        seen.add("kappa")
        kbar = float(rep.kappa_bar)
        report.add("error", "kappa", f"law.kappa = {kappa:.4g} is at or below kappa_bar = {kbar:.4g} for the target "
                   f"from {where.seg.source} at t = {where.t_s:.0f} s (eps = {eps:.4g}): the law can come to rest "
                   f"short of the target; raise law.kappa above {kbar:.4g}", LAW_LOC + ("kappa",),
                   t_s=where.t_s, kappa=kappa, kappa_bar=kbar)
    for msg in rep.warnings:
        key = (where.seg.source, "warning", _strip_numbers(msg))
        if key not in seen:
            seen.add(key)
            report.add("warning", "assumptions", f"t = {where.t_s:.0f} s, target from {where.seg.source}: "
                       f"{_zone_names(msg, where.names)}", where.seg.loc, t_s=where.t_s)
    return eps_max


def _plain_assumption(msg: str, where: _Where, eps: float, eps_max: float) -> tuple[str, Loc] | None:
    """A gnc.checks error (the paper's notation) in plain words with its fix and the key to change;
    None when another check already reports its cause."""
    import re

    t, src, names = f"t = {where.t_s:.0f} s", where.seg.source, where.names

    def zone(i: str) -> str:
        return f"'{names[int(i)]}'" if int(i) < len(names) else f"zone {i}"

    if msg.startswith("target x_d") or "is not strictly inside the zone" in msg:
        return None  # the target and kernel checks say it with the numbers
    if m := re.match(r"Assumption 1: zones (\d+) and (\d+) touch or overlap", msg):
        return (f"zones {zone(m[1])} and {zone(m[2])} touch or overlap at {t} as the law sees them (inflated by "
                "law.margin_deg), and the flight software does not merge them: move them apart, or raise "
                "law.merge_gap_deg so that they merge", where.zone_locs[int(m[2])])
    if m := re.match(r"eps = (\S+) is not below eps_bar < d_s\(x_d, U\) = (\S+) \(zone (\d+)", msg) \
            or (m := re.match(r"x_d is inside the eps-layer of zone (\d+)", msg)):
        z = zone(m[3] if m.re.groups == 3 else m[1])
        return (f"law.eps = {eps:.4g} is too thick for the target from {src}: at {t} the target lies in the "
                f"avoidance layer of zone {z}, where the law turns away, so the spacecraft would not settle on "
                f"it; set law.eps below {eps_max:.4g}, or eps: auto", LAW_LOC + ("eps",))
    if m := re.match(r"eps = (\S+) is not below 1 - cos\(delta\) = (\S+) \(zones (\d+) and (\d+)\)", msg):
        return (f"law.eps = {eps:.4g} is too thick for the gap between zones {zone(m[3])} and {zone(m[4])} at {t}: "
                f"their avoidance layers would touch; set law.eps below {float(m[2]):.4g}, or eps: auto",
                LAW_LOC + ("eps",))
    if m := re.match(r"Assumption 2: R_(\d+) and R_(\d+) overlap", msg):
        return (f"seen from the target from {src}, zones {zone(m[1])} and {zone(m[2])} lie one behind the other at "
                f"{t}: a path round one can be sent into the other's avoidance layer and back; move the target so "
                "that they do not shadow each other, or thin the layer (law.eps_max_used)", where.seg.loc)
    if m := re.match(r"zone (\d+): the geodesic from x_d to -g_\d+ passes through the zone", msg):
        return (f"zone {zone(m[1])} lies across the great circle from the target from {src} to the point opposite "
                f"the zone's centre at {t}: the law can stall there whatever law.kappa; move the target",
                where.seg.loc)
    if m := re.match(r"zone (\d+): -g_\d+ = .* lies in the zone", msg):
        return (f"zone {zone(m[1])} reaches the point opposite its own centre: the law needs every zone smaller "
                "than a hemisphere; make it smaller", where.zone_locs[int(m[1])])
    if m := re.match(r"zone (\d+): g_\d+ = -x_d", msg):
        return (f"the target from {src} is exactly opposite the centre of zone {zone(m[1])} at {t}: the law has no "
                "way round it; move the target a little", where.seg.loc)
    return f"{t}, target from {src}: {_zone_names(msg, names)}", where.seg.loc


def _zone_names(msg: str, names: list[str]) -> str:
    import re
    return re.sub(r"\bzone (\d+)\b", lambda m: f"zone '{names[int(m[1])]}'" if int(m[1]) < len(names) else m[0], msg)


def _strip_numbers(text: str) -> str:
    import re
    return re.sub(r"[-+]?\d[\d.eE+-]*", "#", text)


def _ra_dec(v: np.ndarray) -> str:
    ra = math.degrees(math.atan2(float(v[1]), float(v[0]))) % 360.0
    dec = math.degrees(math.asin(max(-1.0, min(1.0, float(v[2])))))
    return f"({ra:.1f}, {dec:.1f})"


def _sweep_times(segment: Segment, sky: SkyZones, step_s: float | None) -> np.ndarray:
    span = segment.t_end_s - segment.t_start_s
    if step_s is None:
        rate = sky.max_rate_deg_s(segment.t_start_s)
        if segment.earth is not None:  # the target moves too, at most as fast as a point straight below
            r_km = sky.ephemeris.radius_km
            rate = max(rate, math.degrees(sky.ephemeris.n_rad_s * r_km / (r_km - EARTH_RADIUS_KM)))
        step_s = ZONE_MOTION_PER_SAMPLE_DEG / rate if rate > 0 else span
    count = int(min(MAX_SWEEP_SAMPLES, max(1, math.ceil(span / max(step_s, 1e-3))))) + 1
    return np.linspace(segment.t_start_s, segment.t_end_s, count)


def _hold(held: dict[str, list[float]], name: str, t_s: float) -> None:
    """Extend zone ``name``'s window of covering the commanded target to ``t_s`` (its first window only)."""
    window = held.setdefault(name, [t_s, t_s])
    if t_s >= window[1]:
        window[1] = t_s


def _target_in_layer(seg: Segment, t: float, name: str, occ: int, eps: float, need_deg: float) -> str:
    """The target-in-an-eps-layer error in plain words, with the flight software's event and the move."""
    return (f"the target from {seg.source} at RA/Dec {_ra_dec(seg.target)} is outside zone '{name}' as the law "
            f"sees it (inflated by law.margin_deg), but inside its eps-layer at t = {t:.0f} s (eps = {eps:.3g}): "
            f"the flight software would hold short of it (ASSUMPTION_VIOLATED \"{TARGET_IN_LAYER.format(zone=occ)}\"); "
            f"move it at least {need_deg:.2f} deg further from the zone")


def _target_in_zone(seg: Segment, t: float, k: int, sky: SkyZones, m_phys: float, need_deg: float) -> str:
    """The target-inside-a-zone error in plain words: where the target and the zone's centre are, what the
    flight software would do, and how far to move the target (``need_deg``: out of the inflated zone and
    its eps-layer)."""
    body = sky.bodies[k]
    centre = BODY_NAMES.get(body, "the zone's centre")
    here = f"the target from {seg.source} at RA/Dec {_ra_dec(seg.target)}"
    there = f"{centre} is at RA/Dec {_ra_dec(sky.centers(t)[k])}"
    move = (f"move it at least {need_deg:.2f} deg further from {centre} (out of the zone as the law flies it, "
            f"inflated by law.margin_deg = {sky.margin_deg:g} deg and the {ZONE_REBUILD_TOL_DEG:g} deg rebuild "
            "tolerance, and out of the law's eps-layer)")
    if m_phys <= 0:
        return f"{here} is {-m_phys:.1f} deg inside zone '{sky.names[k]}' at t = {t:.0f} s: {there}; {move}"
    return (f"{here} is only {m_phys:.2f} deg outside zone '{sky.names[k]}' at t = {t:.0f} s, inside it as the "
            "law flies it, so the flight software would hold short of it "
            f"(ASSUMPTION_VIOLATED \"target in the eps-layer of zone ...\"): {there}; {move}")


def _check_pointing(mission, segments, report, step_s, quick: bool = False) -> None:
    sky = SkyZones(mission)
    seen: set = set()
    worst_eps_max = math.inf
    _check_initial_boresight(mission, sky, report)
    for seg in (s for s in segments if s.mode == "POINTING"):
        times = _sweep_times(seg, sky, step_s)
        report.samples += len(times)
        held: dict[str, list[float]] = {}  # zone -> [from, to] while it covers a target already commanded
        for i, t in enumerate(times):
            now = replace(seg, target=target_at(seg, sky.ephemeris, float(t))) if seg.earth else seg
            eps_max = _check_pointing_at(mission, sky, now, i, float(t), held, report, seen, quick)
            if math.isfinite(eps_max):
                worst_eps_max = min(worst_eps_max, eps_max)
        _report_held_targets(seg, held, report, seen)
    if math.isfinite(worst_eps_max):
        eps = _eps_in_use(mission, worst_eps_max)
        report.add("info", "eps", f"POINTING: smallest admissible eps upper bound over the run {worst_eps_max:.4g}; "
                   f"eps in use {eps:.4g}", eps_max=worst_eps_max, eps=eps)


def _check_initial_boresight(mission, sky: SkyZones, report) -> None:
    """The initial boresight (truth) must not start inside a physical zone, but for one armed for inertial
    targets only: the flight software starts with it disarmed and arms it once the boresight has left it
    (an info when the initial target is a fixed direction; nothing when it is on the Earth)."""
    from gnc.attitude import quat_rotate
    y0 = np.asarray(quat_rotate(np.asarray(mission.initial_state.q_NB), np.asarray(mission.spacecraft.instrument_boresight_B)))
    fixed_target = mission.flight_software.pointing.target_kind == "inertial"
    for k, zone in enumerate(sky.physical(0.0)):
        m = signed_margin_deg(zone, y0)
        if m <= 0 and sky.armed[k] == "inertial_targets":
            if fixed_target:
                report.add("info", "initial-state", f"the instrument boresight starts at RA/Dec {_ra_dec(y0)}, "
                           f"{-m:.2f} deg inside zone '{sky.names[k]}' ({BODY_NAMES.get(sky.bodies[k], 'its centre')} "
                           f"is at RA/Dec {_ra_dec(sky.centers(0.0)[k])}), which is kept out for inertial targets "
                           "only (armed: inertial_targets): the flight software arms it once the boresight has "
                           "left it as the law sees it (inflated by law.margin_deg)", ("initial_state",),
                           margin_deg=m)
        elif m <= 0:
            report.add("error", "initial-state", f"the instrument boresight starts at RA/Dec {_ra_dec(y0)}, "
                       f"{-m:.2f} deg inside zone '{sky.names[k]}' ({BODY_NAMES.get(sky.bodies[k], 'its centre')} is "
                       f"at RA/Dec {_ra_dec(sky.centers(0.0)[k])}): start outside it, e.g. give initial_state as "
                       "RA/Dec + roll away from the zone", ("initial_state",), margin_deg=m)


def _check_pointing_at(mission, sky: SkyZones, seg, i: int, t: float, held: dict[str, list[float]], report,
                       seen: set, quick: bool) -> float:
    """Sample i (time t) of a POINTING segment: the target clear of the zones and their layers as the law
    flies them, the merges, then (unless ``quick``) the assumptions; returns their eps_max (inf: none)."""
    phys, law_zones = sky.physical(t), sky.law(t)
    kept = sky.kept_for(seg)
    if _target_in_law_zones(mission, sky, seg, i, t, phys, law_zones, kept, held, report, seen):
        return math.inf  # the assumptions fail with it: one root cause, one error
    if not kept:
        return math.inf  # every zone disarmed for this target: nothing for the law to keep out
    if len(kept) == len(law_zones):
        flown = sky.as_flown(law_zones, seg.target)
    else:
        flown = sky.as_flown([law_zones[k] for k in kept], seg.target, kept)
    if _target_in_flown_layer(mission, seg, i, t, flown, held, report, seen):
        return math.inf
    _report_merges(sky, seg, t, flown, report, seen)
    if flown.unmerged or quick:
        return math.inf
    where = _Where(t, seg, flown.names, [ZONES_LOC + (g[0],) for g in flown.groups])
    return _check_assumptions_at(mission, flown.zones, where, mission.flight_software.law.kappa, report, seen)


def _target_in_law_zones(mission, sky: SkyZones, seg, i: int, t: float, phys: list, law_zones: list,
                         kept: list[int], held: dict[str, list[float]], report, seen: set) -> bool:
    """Whether the target lies in a zone the flight software keeps out for it (``kept``, indices into
    ``phys`` and ``law_zones``) as the law sees it (inflated): an error at the segment's start, later a zone
    that moved over it (held); every zone's kernel checked once on the way, kept or not (its shape is
    flown with other targets)."""
    target_inside = False
    kept_set = set(kept)
    kept_law = law_zones if len(kept) == len(law_zones) else [law_zones[k] for k in kept]
    for k, (zp, zl) in enumerate(zip(phys, law_zones)):
        _kernel_check(sky.names[k], zp, report, seen, ZONES_LOC + (k, "geometry"))
        if k not in kept_set:
            continue
        m_phys, m_law = signed_margin_deg(zp, seg.target), signed_margin_deg(zl, seg.target)
        if m_law <= 0:
            target_inside = True
            if i > 0:
                _hold(held, sky.names[k], t)
            elif (seg.source, sky.names[k]) not in seen:
                seen.add((seg.source, sky.names[k]))
                need = clearance_needed_deg(seg.target, zl, kept_law, mission.flight_software.law,
                                            start_deg=max(0.0, -m_law))
                report.add("error", "target", _target_in_zone(seg, t, k, sky, m_phys, need),
                           seg.loc, t_s=t, margin_deg=m_phys, move_deg=need)
    return target_inside


def _target_in_flown_layer(mission, seg, i: int, t: float, flown, held: dict[str, list[float]], report,
                           seen: set) -> bool:
    """Whether the target lies outside the inflated zones but in one's eps-layer, where the law cannot fly
    to it (an error at the segment's start, later held)."""
    occ, eps = target_layer(seg.target, flown.zones, mission.flight_software.law, flown.unmerged)
    if occ < 0:
        return False
    if i > 0:
        _hold(held, flown.names[occ], t)
    elif (seg.source, flown.names[occ]) not in seen:
        seen.add((seg.source, flown.names[occ]))
        need = clearance_needed_deg(seg.target, flown.zones[occ], flown.zones,
                                    mission.flight_software.law, flown.unmerged)
        report.add("error", "target", _target_in_layer(seg, t, flown.names[occ], occ, eps, need),
                   seg.loc, t_s=t, eps=eps, move_deg=need)
    return True


def _report_merges(sky: SkyZones, seg, t: float, flown, report, seen: set) -> None:
    """Zones flown as one (info, once each), and zones too close to fly apart that cannot merge (error)."""
    for group, name in zip(flown.groups, flown.names):
        if len(group) > 1 and ("merged", name) not in seen:
            seen.add(("merged", name))
            report.add("info", "merge", f"t = {t:.0f} s: zones {' and '.join(repr(sky.names[k]) for k in group)} "
                       f"are closer than law.merge_gap_deg = {sky.merge_gap_deg:g} deg: the flight software "
                       "flies them as one zone", t_s=t)
    for i, j in flown.unmerged:
        if (seg.source, "unmerged", i, j) in seen:
            continue
        seen.add((seg.source, "unmerged", i, j))
        gap = _cap_gap_deg(flown.zones[i], flown.zones[j])
        report.add("error", "merge", f"t = {t:.0f} s: zones '{flown.names[i]}' and '{flown.names[j]}' are "
                   f"{gap:.2f} deg apart as the law sees them (inflated by law.margin_deg), closer than "
                   f"law.merge_gap_deg = {sky.merge_gap_deg:g} deg, but the flight software cannot merge "
                   f"them: the target from {seg.source} lies between them, so it would steer out of the "
                   "gap and never reach the target; move the target out of the gap", seg.loc,
                   t_s=t, gap_deg=gap)


def _report_held_targets(seg, held: dict[str, list[float]], report, seen: set) -> None:
    """A warning per zone that covered the segment's target for a while after it was commanded."""
    for name, (t_from, t_to) in held.items():
        if (seg.source, name) in seen:
            continue  # refused at its command time already: one root cause, one finding
        report.add("warning", "target", f"from t = {t_from:.0f} s to {t_to:.0f} s zone '{name}' (as the law sees "
                   f"it: inflated by law.margin_deg) covers the target from {seg.source}, commanded at t = "
                   f"{seg.t_start_s:.0f} s: the flight software then holds outside it (ASSUMPTION_VIOLATED "
                   f"\"{TARGET_IN_LAYER.format(zone=name)}\") and resumes the slew when the zone has moved "
                   "off; the target is not reached in that window", seg.loc, t_s=t_from)


VISIBILITY_STEP_S = 5.0  # a pass over a ground target from low orbit lasts minutes; its elevation peak, seconds
VISIBILITY_LOOKAHEAD_S = 86400.0  # how far past a dwell to look for the target's next pass


def _check_ground_visibility(mission, segments: list[Segment], report) -> None:
    """A ground target must rise above its ``min_elevation_deg`` (0: its horizon) at some time of its dwell
    in POINTING, seen from the onboard orbit; otherwise the instrument would stare into the Earth's limb or
    beyond. An error at the target's key, with the time it next rises that high."""
    from gnc.sky_ephemeris import SkyEphemeris

    ephemeris = SkyEphemeris(mission.flight_software)
    dwells: dict[str, list[Segment]] = {}
    for seg in segments:
        if seg.mode == "POINTING" and seg.earth is not None and seg.earth[0] == "ground":
            dwells.setdefault(seg.source, []).append(seg)
    for source, segs in dwells.items():
        ground = segs[0].earth[1]
        times = np.concatenate([_dwell_times(s.t_start_s, s.t_end_s) for s in segs])
        elevations = _elevations_deg(ephemeris, ground, times)
        best = int(np.argmax(elevations))
        if elevations[best] >= ground.min_elevation_deg:
            seen = times[elevations >= ground.min_elevation_deg]
            report.add("info", "visibility", f"the ground target from {source} is above {ground.min_elevation_deg:g} "
                       f"deg elevation from t = {seen[0]:.0f} s to {seen[-1]:.0f} s of its dwell (highest "
                       f"{elevations[best]:.1f} deg at t = {times[best]:.0f} s)", segs[0].loc,
                       max_elevation_deg=float(elevations[best]), t_s=float(times[best]))
            continue
        report.add("error", "visibility", _below_horizon(ephemeris, ground, source, segs, elevations[best]),
                   segs[0].loc, max_elevation_deg=float(elevations[best]), t_s=segs[0].t_start_s)


def _dwell_times(t0: float, t1: float) -> np.ndarray:
    return np.linspace(t0, t1, max(2, int(math.ceil((t1 - t0) / VISIBILITY_STEP_S)) + 1))


def _elevations_deg(ephemeris, ground, times: np.ndarray) -> np.ndarray:
    """The spacecraft's elevation above the ground target's horizon [deg] at ``times``, onboard orbit."""
    from gnc.earth import earth_fixed_to_inertial, elevation_deg

    out = np.empty(len(times))
    for k, t in enumerate(times):
        r_E = earth_fixed_to_inertial(ephemeris.jd0_utc + t / 86400.0).T @ ephemeris.position_N_km(float(t))
        out[k] = elevation_deg(ground.latitude_deg, ground.longitude_deg, ground.altitude_m, r_E)
    return out


def _below_horizon(ephemeris, ground, source: str, segs: list[Segment], best_deg: float) -> str:
    """The message of a ground target never seen high enough in its dwell, with its next pass as the fix."""
    t0, t1 = segs[0].t_start_s, segs[-1].t_end_s
    where = f"({ground.latitude_deg:g}, {ground.longitude_deg:g})"
    text = (f"the ground target from {source} at latitude, longitude {where} deg stays below "
            f"{ground.min_elevation_deg:g} deg elevation for its whole dwell from t = {t0:.0f} s to {t1:.0f} s "
            f"(highest {best_deg:.1f} deg): the spacecraft is below its horizon, the boresight would look "
            "through the Earth; ")
    later = _dwell_times(t1, t1 + VISIBILITY_LOOKAHEAD_S)
    above = np.nonzero(_elevations_deg(ephemeris, ground, later) >= ground.min_elevation_deg)[0]
    if len(above):
        rise = float(later[above[0]])
        return text + (f"it next rises above {ground.min_elevation_deg:g} deg at t = {rise:.0f} s: command it at "
                       f"t_s >= {rise:.0f} (and keep it until its pass is over), choose a target under the "
                       "orbit's ground track, or lower min_elevation_deg")
    return text + ("it does not rise that high in the day after it either: choose a target under the orbit's "
                   "ground track or lower min_elevation_deg")


def _cap_gap_deg(zone_a, zone_b) -> float:
    """Angle between the bounding caps of two zones [deg] (negative when they overlap)."""
    (a, ra), (b, rb) = zone_a.bounding_cap, zone_b.bounding_cap
    return math.degrees(math.acos(max(-1.0, min(1.0, float(np.dot(a, b))))) - ra - rb)


def _kernel_check(name: str, zone, report: PhysicsReport, seen: set, loc: Loc) -> None:
    if ("kernel", name) in seen:
        return
    seen.add(("kernel", name))
    g = np.asarray(zone.kernel, dtype=float)
    s = float(zone.signed_separation(g))
    if not (zone.contains(g) and s < 0):
        report.add("error", "kernel", f"zone '{name}': its centre is not strictly inside the zone (signed "
                   f"separation {s:.3g}); the law steers away from the centre, so the shape must contain it, with "
                   "every boundary point in straight view from it", loc, signed_separation=s)


def _check_quaternion(mission, segments, report, quick: bool = False) -> None:
    fsw = mission.flight_software
    names, phys, law_zones = s3_zones(mission)
    zone_locs = [S3_ZONES_LOC + (k,) for k, zc in enumerate(fsw.quaternion.zones)
                 for _ in range(2 if zc.antipodal_copy else 1)]
    all_cones = all(z.shape == "cone" for z in fsw.quaternion.zones)
    gradient = fsw.quaternion.law == "gradient" or (fsw.quaternion.law == "auto" and all_cones)
    kappa = None if gradient else fsw.law.kappa
    seen: set = set()
    for name, zone, loc in zip(names, phys, zone_locs):
        _kernel_check(name, zone, report, seen, loc)
    q0 = np.asarray(mission.initial_state.q_NB, dtype=float)
    for seg in (s for s in segments if s.mode == "QUATERNION"):
        report.samples += 1
        # the flight software lifts the attitude into the target's hemisphere on entry (fsw.guidance)
        x0 = q0 if float(q0 @ seg.target) >= 0 else -q0
        target_inside = False
        for name, zp, zl in zip(names, phys, law_zones):
            m_phys, m_law = signed_margin_deg(zp, seg.target), signed_margin_deg(zl, seg.target)
            if m_law <= 0:
                target_inside = True
                what = (f"{-m_phys:.2f} deg inside" if m_phys <= 0 else
                        f"only {m_phys:.2f} deg outside (within the law margin of)")
                report.add("error", "target", f"the attitude target from {seg.source} is {what} the forbidden-"
                           f"attitude zone '{name}' (angles on S^3, half the rotation angle): move it at least "
                           f"{-m_law:.2f} deg on S^3 ({-2 * m_law:.2f} deg of rotation) away", seg.loc, margin_deg=m_phys)
            if seg.t_start_s == 0.0 and signed_margin_deg(zp, x0) <= 0:
                report.add("error", "initial-state", f"the initial attitude is inside the forbidden-attitude zone "
                           f"'{name}': start outside it", ("initial_state", "q_NB"))
        if target_inside:
            continue
        occ, eps = target_layer(seg.target, law_zones, fsw.law)
        if occ >= 0:  # outside the inflated zone, inside its eps-layer: the law does not come to rest there
            need = clearance_needed_deg(seg.target, law_zones[occ], law_zones, fsw.law)
            report.add("error", "target", f"the attitude target from {seg.source} is outside the forbidden-attitude "
                       f"zone '{names[occ]}' as the law sees it, but inside its eps-layer (eps = {eps:.3g}), where the "
                       f"law does not come to rest at it: move it at least {need:.2f} deg on S^3 ({2 * need:.2f} deg "
                       "of rotation) away", seg.loc, eps=eps, move_deg=need)
            continue
        if quick:
            continue
        where = _Where(seg.t_start_s, seg, names, zone_locs)
        eps_max = _check_assumptions_at(mission, law_zones, where, kappa, report, seen,
                                        law_name="gradient" if gradient else "star")
        if math.isfinite(eps_max):
            report.add("info", "eps", f"QUATERNION ({'GradientLaw' if gradient else 'StarShapedLaw'}): eps upper "
                       f"bound {eps_max:.4g}, eps in use {_eps_in_use(mission, eps_max):.4g}", eps_max=eps_max)


def _check_braking(mission, report) -> float:
    """The flight software's rules for a rate limit (`fsw.guidance.slew_limits.rate_limit_problem`: the
    braking distance and the sensors' range, the ones SET_GAINS is judged by onboard) on the configured limit
    and on every SET_GAINS of the timeline, with the gains in force when it is sent. Returns the braking
    distance at the configured rate limit [deg]."""
    from fsw.guidance.slew_limits import braking_distance_deg, rate_limit_problem

    fsw = mission.flight_software
    accel = fsw.control.max_command_accel_deg_s2
    rate, eps = fsw.spacecraft.max_rate_deg_s, fsw.law.eps
    refused = rate_limit_problem(rate, eps, fsw, accel)
    if refused is not None:
        report.add("error", "braking", f"flight_software.spacecraft.max_rate_deg_s: {refused[1]}",
                   ("flight_software", "spacecraft", "max_rate_deg_s"))
    first = braking_distance_deg(rate, accel, fsw.control.rate_bandwidth_rad_s)
    for i, entry in enumerate(mission.timeline):
        if entry.command != "SET_GAINS":
            continue
        rate = entry.rate_limit_deg_s if entry.rate_limit_deg_s is not None else rate
        eps = entry.eps if entry.eps is not None else eps
        refused = rate_limit_problem(rate, eps, fsw, accel)
        if refused is not None:
            report.add("error", "braking", f"timeline[{i}] SET_GAINS at {entry.t_s:g} s would be rejected onboard: "
                       f"{refused[1]}", ("timeline", i, "rate_limit_deg_s"))
    return first


def momentum_exceeded_at_s(J_B: np.ndarray, omega0_B: np.ndarray, torque_B: np.ndarray, axes: np.ndarray,
                           headroom_Nms: np.ndarray, duration_s: float, samples: int = 2001) -> tuple[float, float, float]:
    """When the momentum the wheels must hold first exceeds what they can take up, holding attitude.

    The wheels must absorb the body's initial momentum J omega0 and the constant disturbance torque's
    integral (constant in body axes while the attitude is held: the budget of a mission without momentum
    management). Returns (the first time it exceeds the capacity along its direction [s] (inf: never within
    ``duration_s``), the momentum needed then or at the end [N m s], the capacity along it [N m s])."""
    t = np.linspace(0.0, duration_s, samples)
    H = (J_B @ omega0_B)[None, :] + t[:, None] * torque_B[None, :]
    size = np.linalg.norm(H, axis=1)
    dirs = np.where(size[:, None] > 0.0, H / np.where(size > 0.0, size, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
    capacity = wheel_authority(axes, headroom_Nms, dirs)
    over = np.nonzero(size > capacity)[0]
    k = int(over[0]) if over.size else samples - 1
    return (float(t[k]) if over.size else math.inf), float(size[k]), float(capacity[k])


def _check_momentum_budget(mission, report, axes: np.ndarray, headroom: np.ndarray) -> None:
    """Refuse a mission whose wheels cannot hold the momentum it will accumulate: a saturated wheel can
    no longer steer the boresight away from a zone, and keepout has no momentum management on the missions
    this checks (magnetorquers are not modelled)."""
    sc = mission.spacecraft
    J = np.asarray(sc.inertia_B_kgm2, dtype=float)
    omega0 = np.asarray(mission.initial_state.omega_BN_B_rad_s, dtype=float)
    torque = np.asarray(sc.disturbance.constant_B_Nm, dtype=float)
    t_over, need, cap = momentum_exceeded_at_s(J, omega0, torque, axes, headroom, float(mission.duration_s))
    if t_over == 0.0:
        report.add("error", "momentum", f"the initial body rate holds {need:.4g} N m s, more than the wheels can "
                   f"take up along it ({cap:.4g} N m s up to {mission.requirements.max_wheel_speed_fraction:g} of "
                   "their speed limit): the flight software could never stop the rotation; lower "
                   "initial_state.omega_BN_B_rad_s", ("initial_state", "omega_BN_B_rad_s"),
                   momentum_Nms=need, capacity_Nms=cap)
    elif math.isfinite(t_over):
        report.add("error", "momentum", f"the constant disturbance torque ({np.linalg.norm(torque):.3g} N m) fills "
                   f"the wheels' momentum capacity at t = {t_over:.0f} s of the {mission.duration_s:g} s mission "
                   f"({need:.4g} N m s against {cap:.4g} N m s up to {mission.requirements.max_wheel_speed_fraction:g} "
                   "of their speed limit); a saturated wheel cannot steer the boresight away from a zone and this "
                   "mission has no momentum management: shorten duration_s, lower "
                   "spacecraft.disturbance.constant_B_Nm, or fit larger wheels",
                   ("spacecraft", "disturbance", "constant_B_Nm"), exceeded_at_s=t_over, momentum_Nms=need,
                   capacity_Nms=cap)
    else:
        report.add("info", "momentum", f"momentum budget: {need:.4g} N m s at the end of the mission against "
                   f"{cap:.4g} N m s of wheel capacity along it", momentum_Nms=need, capacity_Nms=cap)


def _check_wheels(mission, report) -> None:
    sc = mission.spacecraft
    fsw = mission.flight_software
    J = np.asarray(sc.inertia_B_kgm2, dtype=float)
    axes = np.asarray([w.axis_B for w in sc.wheels])
    d = fibonacci_sphere(2000)
    torque = wheel_authority(axes, np.array([w.max_torque_Nm for w in sc.wheels]), d)
    Jd = np.einsum("ij,mj->mi", J, d)
    inertia_along = np.einsum("mi,mi->m", d, Jd)
    # the body acceleration along d needs torque J d alpha (gyroscopic terms are small at these rates)
    accel = torque / np.linalg.norm(Jd, axis=1)
    worst = int(np.argmin(accel))
    accel_avail_deg_s2 = math.degrees(float(accel[worst]))
    accel_cmd = fsw.control.max_command_accel_deg_s2
    rate_limit = fsw.spacecraft.max_rate_deg_s
    axis = np.round(d[worst], 3).tolist()
    if accel_avail_deg_s2 < accel_cmd:
        report.add("error", "wheels", f"the wheels can accelerate the body at only {accel_avail_deg_s2:.4g} deg/s^2 "
                   f"about body axis {axis}, below the commanded-rate slew limit control.max_command_accel_deg_s2 "
                   f"= {accel_cmd:g}: the rate loop saturates and lags the law; lower it to {accel_avail_deg_s2:.3g} or "
                   "fit stronger wheels", ("flight_software", "control", "max_command_accel_deg_s2"),
                   accel_avail_deg_s2=accel_avail_deg_s2,
                   accel_cmd_deg_s2=accel_cmd)
    speeds = mission.initial_state.wheel_speeds_rad_s or [0.0] * len(sc.wheels)
    headroom = np.array([w.spin_inertia_kgm2 * max(0.0, mission.requirements.max_wheel_speed_fraction * w.max_speed_rad_s
                                         - abs(s)) for w, s in zip(sc.wheels, speeds)])
    # body momentum J omega along d must come from the wheels: reachable |omega| = h(J d)/|J d|
    momentum = wheel_authority(axes, headroom, Jd / np.linalg.norm(Jd, axis=1, keepdims=True))
    rate_avail = momentum / np.linalg.norm(Jd, axis=1)
    worst_m = int(np.argmin(rate_avail))
    rate_avail_deg_s = math.degrees(float(rate_avail[worst_m]))
    if rate_avail_deg_s < rate_limit:
        report.add("error", "wheels", f"wheel momentum (up to {mission.requirements.max_wheel_speed_fraction:g} of "
                   f"max speed) allows only {rate_avail_deg_s:.4g} deg/s about body axis "
                   f"{np.round(d[worst_m], 3).tolist()}, below the rate limit spacecraft.max_rate_deg_s = {rate_limit:g}; "
                   f"lower it to {rate_avail_deg_s:.3g}", ("flight_software", "spacecraft", "max_rate_deg_s"),
                   rate_avail_deg_s=rate_avail_deg_s, rate_limit_deg_s=rate_limit)
    _check_momentum_budget(mission, report, axes, headroom)
    braking_deg = _check_braking(mission, report)
    report.add("info", "wheels", f"worst-axis authority: {accel_avail_deg_s2:.4g} deg/s^2 (commanded "
               f"{accel_cmd:g}), {rate_avail_deg_s:.4g} deg/s momentum-limited rate (limit {rate_limit:g}), braking "
               f"angle {braking_deg:.2f} deg", accel_avail_deg_s2=accel_avail_deg_s2, rate_avail_deg_s=rate_avail_deg_s,
               braking_deg=braking_deg)
    if len(fsw.spacecraft.wheels) == len(sc.wheels):
        for i, (wk, wt) in enumerate(zip(fsw.spacecraft.wheels, sc.wheels)):
            err = math.degrees(math.acos(float(np.clip(np.dot(wk.axis_B, wt.axis_B), -1, 1))))
            if err > 1.0:
                report.add("warning", "knowledge", f"wheel {i}: the flight software's axis is {err:.1f} deg from the "
                           "true axis", ("flight_software", "spacecraft", "wheels", i), axis_error_deg=err)
    b_err = math.degrees(math.acos(float(np.clip(np.dot(fsw.pointing.boresight_B, sc.instrument_boresight_B), -1, 1))))
    if b_err > 0.05:
        report.add("warning", "knowledge", f"flight_software.pointing.boresight_B is {b_err:.2f} deg from the true "
                   "spacecraft.instrument_boresight_B: this misalignment eats into the keep-out margin",
                   ("flight_software", "pointing", "boresight_B"), boresight_error_deg=b_err)
