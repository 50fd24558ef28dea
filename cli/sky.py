"""``keepout sky MISSION --at T`` (or ``--from T0 --to T1 --step S``): where the Sun, the Moon, the Earth
limb and each keep-out zone are, and when each target is free of every zone, for picking targets.

The geometry is the validator's own (`hil_sim.mission.physics_checks`): the onboard ephemeris
(`gnc.sky_ephemeris.SkyEphemeris`), the zones built by `physics_checks.SkyZones` as the flight software builds
them (physical, and inflated by the law margin plus the rebuild tolerance), the schedule of targets
`physics_checks.schedule` and the signed margin `physics_checks.signed_margin_deg`. A target is *free* at
a time when it lies outside every inflated zone: exactly the test by which `keepout config check` rejects
a target ("within the law margin of the zone"), so a target this command shows free over its commanded
interval passes that check.

Times are seconds after the mission's epoch, or UTC instants (``2026-04-25T12:30:00Z``).
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gnc.eclipse import SUN_RADIUS_KM

if TYPE_CHECKING:
    from hil_sim.mission.model import Mission
    from hil_sim.mission.physics_checks import SkyZones

EXIT_REJECTED = 2
MOON_RADIUS_KM = 1_737.4
MAX_SAMPLES = 100_000


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "sky", help="where the Sun, Moon, Earth limb and keep-out zones are, and when each target is free of them",
        description=__doc__.replace("``", "").replace("`", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mission", type=Path, help="mission YAML")
    p.add_argument("--at", default=None, metavar="T",
                   help="the instant to describe: seconds after the epoch or a UTC time (default: the start of the "
                        "range, else 0)")
    p.add_argument("--from", dest="t_from", default=None, metavar="T0",
                   help="start of the range over which each target's free windows are listed (default 0)")
    p.add_argument("--to", dest="t_to", default=None, metavar="T1",
                   help="end of that range (default: the mission's duration_s)")
    p.add_argument("--step", type=float, default=None, metavar="S",
                   help="time step of the range [s] (default: the validator's, so that no zone centre moves more "
                        "than 0.5 deg between samples)")
    p.add_argument("--plot", type=Path, default=None, metavar="FILE.png",
                   help="also draw the sky at T: zones (physical and inflated), bodies and targets")
    p.set_defaults(func=_sky)


# ---------------------------------------------------------------------------------------------
# The sky at one time
# ---------------------------------------------------------------------------------------------

@dataclass
class Body:
    name: str
    direction_N: np.ndarray
    angular_radius_deg: float


@dataclass
class ZoneAt:
    name: str
    body: str
    center_N: np.ndarray
    radius_deg: float  # the physical zone's largest angle from its centre to its boundary
    inflated_radius_deg: float  # the zone as the law flies it: + law.margin_deg + the rebuild tolerance
    physical: Any  # gnc zone objects (boundary(), signed_separation())
    inflated: Any


@dataclass
class Target:
    label: str  # where it comes from: flight_software.pointing.target_N, timeline[i]
    direction_N: np.ndarray
    t_start_s: float  # when it is the commanded target (its schedule segment)
    t_end_s: float


def bodies_at(sky: "SkyZones", t_s: float) -> list[Body]:
    """The Sun, the Moon and the Earth seen from the spacecraft at mission time ``t_s`` (onboard ephemeris)."""
    from gnc.ephemeris import moon_position_N_km, sun_position_N_km

    eph = sky.ephemeris
    jd = eph.jd0 + t_s / 86400.0
    r_sc = eph.position_N_km(t_s)
    dirs = eph.directions(t_s)
    out = []
    for name, pos, radius in (("sun", sun_position_N_km(jd), SUN_RADIUS_KM),
                              ("moon", moon_position_N_km(jd), MOON_RADIUS_KM)):
        distance = float(np.linalg.norm(np.asarray(pos, dtype=float) - r_sc))
        out.append(Body(name, np.asarray(dirs[name], dtype=float), math.degrees(math.asin(radius / distance))))
    out.append(Body("earth", np.asarray(dirs["earth"], dtype=float), eph.earth_angular_radius_deg))
    return out


def zones_at(sky: "SkyZones", t_s: float) -> list[ZoneAt]:
    """Each zone at ``t_s``, physical and inflated, with its angular radius about its centre (the largest
    angle from the centre to its boundary)."""
    out = []
    for name, body, center, phys, law in zip(sky.names, sky.bodies, sky.centers(t_s), sky.physical(t_s),
                                            sky.law(t_s)):
        c = np.asarray(center, dtype=float)
        out.append(ZoneAt(name, body, c, _radius_about(phys, c), _radius_about(law, c), phys, law))
    return out


def _radius_about(zone: Any, center: np.ndarray) -> float:
    """The largest angle [deg] from ``center`` to the zone's boundary (its radius; a cone's half-angle)."""
    boundary = np.asarray(zone.boundary(720), dtype=float)
    cosines = boundary @ (center / np.linalg.norm(center)) / np.linalg.norm(boundary, axis=1)
    return float(np.degrees(np.arccos(np.clip(cosines.min(), -1.0, 1.0))))


def targets(mission: "Mission") -> list[Target]:
    """The POINTING targets of the run in order, each with the interval it is commanded (the validator's
    schedule); a target commanded twice is listed once per interval."""
    from hil_sim.mission.physics_checks import schedule

    return [Target(s.source, np.asarray(s.target, dtype=float), s.t_start_s, s.t_end_s)
            for s in schedule(mission) if s.mode == "POINTING"]


def target_margins(sky: "SkyZones", target_N: np.ndarray, t_s: float) -> list[tuple[float, float]]:
    """(physical, inflated) signed margin [deg] of a direction to each zone at ``t_s``."""
    from hil_sim.mission.physics_checks import signed_margin_deg

    return [(signed_margin_deg(p, target_N), signed_margin_deg(l, target_N))
            for p, l in zip(sky.physical(t_s), sky.law(t_s))]


def free_samples(sky: "SkyZones", target_N: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Per time: True when ``target_N`` is outside every inflated zone (the validator's test: a target
    whose law margin is <= 0 is rejected). Rows: times; the blocking zones are in `blocking`."""
    return np.array([all(m_law > 0 for _, m_law in target_margins(sky, target_N, float(t))) for t in times],
                    dtype=bool)


def blocking(sky: "SkyZones", target_N: np.ndarray, t_s: float) -> list[str]:
    return [name for name, (_, m_law) in zip(sky.names, target_margins(sky, target_N, t_s)) if m_law <= 0]


def windows(times: np.ndarray, free: np.ndarray) -> list[tuple[float, float, bool]]:
    """Runs of equal ``free`` as (first sample time, last sample time, free)."""
    out: list[tuple[float, float, bool]] = []
    for t, f in zip(times, free):
        if out and out[-1][2] == bool(f):
            out[-1] = (out[-1][0], float(t), bool(f))
        else:
            out.append((float(t), float(t), bool(f)))
    return out


def sample_times(sky: "SkyZones", t0: float, t1: float, step_s: float | None) -> np.ndarray:
    """Times from t0 to t1 (both included) every ``step_s``; by default the validator's step, at which no
    zone centre moves more than `physics_checks.ZONE_MOTION_PER_SAMPLE_DEG` between samples."""
    from hil_sim.mission.physics_checks import ZONE_MOTION_PER_SAMPLE_DEG

    if step_s is None:
        rate = sky.max_rate_deg_s(t0)
        step_s = ZONE_MOTION_PER_SAMPLE_DEG / rate if rate > 0 else max(t1 - t0, 1.0)
    count = int(math.ceil((t1 - t0) / step_s)) + 1 if t1 > t0 else 1
    if count > MAX_SAMPLES:
        raise ValueError(f"--step {step_s:g} s gives {count} samples from {t0:g} to {t1:g} s; at most {MAX_SAMPLES}")
    return np.linspace(t0, t1, count) if count > 1 else np.array([t0])


# ---------------------------------------------------------------------------------------------
# The command
# ---------------------------------------------------------------------------------------------

def parse_time(text: str, epoch: datetime, what: str) -> float:
    """Seconds after ``epoch`` from a number of seconds or a UTC instant."""
    try:
        return float(text)
    except ValueError:
        pass
    try:
        when = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"{what} {text!r}: give seconds after the epoch (e.g. 300) or a UTC time "
                         "(e.g. 2026-04-25T12:05:00Z)") from None
    if when.tzinfo is None:
        raise ValueError(f"{what} {text!r}: give the time zone, e.g. {text}Z")
    return (when - epoch).total_seconds()


def _ra_dec(v: np.ndarray) -> tuple[float, float]:
    from hil_sim.sil.skyplot import ra_dec_deg

    ra, dec = ra_dec_deg(v)
    return float(ra[0]), float(dec[0])


def report(mission: "Mission", sky: "SkyZones", at_s: float, times: np.ndarray) -> str:
    """The text `keepout sky` prints: bodies and zones at ``at_s``, then each target at ``at_s`` and its free
    windows over ``times``."""
    epoch = mission.epoch_utc
    when = (epoch + timedelta(seconds=at_s)).strftime("%Y-%m-%dT%H:%M:%SZ")
    lines = [f"{mission.name}: the sky at t = {at_s:g} s ({when}), from the spacecraft (onboard ephemeris)", "",
             f"{'body':8s} {'RA [deg]':>9s} {'Dec [deg]':>9s} {'radius [deg]':>13s}"]
    for b in bodies_at(sky, at_s):
        ra, dec = _ra_dec(b.direction_N)
        label = "earth limb" if b.name == "earth" else b.name
        lines.append(f"{label:10s} {ra:7.2f} {dec:+9.2f} {b.angular_radius_deg:13.3f}")
    zones = zones_at(sky, at_s)
    lines += ["", f"law.margin_deg = {sky.margin_deg:g} deg; inflated = as the law flies the zone (margin + rebuild "
              "tolerance)", f"{'zone':14s} {'centre':7s} {'RA [deg]':>9s} {'Dec [deg]':>9s} {'radius [deg]':>13s} "
              f"{'inflated [deg]':>15s}"]
    for z in zones:
        ra, dec = _ra_dec(z.center_N)
        lines.append(f"{z.name[:14]:14s} {z.body:7s} {ra:9.2f} {dec:+9.2f} {z.radius_deg:13.2f} "
                     f"{z.inflated_radius_deg:15.2f}")
    if not zones:
        lines.append("(no sky zones: flight_software.pointing.zones is empty)")
    tgts = targets(mission)
    lines += ["", f"targets: margin at t = {at_s:g} s to each zone [deg] (physical / inflated); free = outside every "
              "inflated zone"]
    if not tgts:
        lines.append("(no POINTING target in this mission)")
    span = f"{times[0]:g} to {times[-1]:g} s" if len(times) > 1 else f"{times[0]:g} s"
    for tg in tgts:
        ra, dec = _ra_dec(tg.direction_N)
        margins = target_margins(sky, tg.direction_N, at_s)
        cells = ", ".join(f"{n} {p:+.2f} / {l:+.2f}" for n, (p, l) in zip(sky.names, margins))
        free_now = all(l > 0 for _, l in margins)
        lines.append(f"- {tg.label}: RA {ra:.2f}, Dec {dec:+.2f}; commanded {tg.t_start_s:g} to {tg.t_end_s:g} s; "
                     f"{'free' if free_now else 'NOT free'} at t = {at_s:g} s ({cells or 'no zones'})")
        runs = windows(times, free_samples(sky, tg.direction_N, times))
        text = []
        for a, b, free in runs:
            when_txt = f"{a:g} s" if a == b else f"{a:g} to {b:g} s"
            text.append(f"free {when_txt}" if free else
                        f"inside {', '.join(repr(n) for n in blocking(sky, tg.direction_N, a))} {when_txt}")
        lines.append(f"    over {span} ({len(times)} samples): " + "; ".join(text))
    return "\n".join(lines)


def plot(mission: "Mission", sky: "SkyZones", at_s: float, path: Path) -> Path:
    """The sky at ``at_s`` on the full-sky map of every keepout plot (hil_sim.sil.skyplot)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hil_sim.sil import skyplot

    colours = {"sun": "#dd8452", "moon": "#8172b3", "earth": "#4c72b0", "inertial": "#937860"}
    fig = plt.figure(figsize=(11, 6))
    ax = fig.add_subplot(111, projection="mollweide")
    for z in zones_at(sky, at_s):
        colour = colours.get(z.body, "k")
        skyplot.sky_line(ax, _closed(z.physical.boundary(360)), color=colour, lw=1.8, label=f"zone {z.name}")
        skyplot.sky_line(ax, _closed(z.inflated.boundary(360)), color=colour, lw=1.0, ls="--",
                         label=f"{z.name} inflated (+{sky.margin_deg:g} deg margin)")
    for b in bodies_at(sky, at_s):
        if b.name == "earth":  # the limb: the disc the Earth covers, as large as a zone in a low orbit
            from gnc.sky_zones import cone_zone

            skyplot.sky_line(ax, _closed(cone_zone(b.direction_N, b.angular_radius_deg).boundary(360)),
                             color=colours["earth"], lw=1.0, ls=":", label=f"earth limb ({b.angular_radius_deg:.1f} deg)")
        skyplot.sky_points(ax, b.direction_N, s=60, color=colours[b.name], edgecolor="k", zorder=4,
                           label=("earth centre" if b.name == "earth" else b.name))
    for k, tg in enumerate(targets(mission)):
        free = all(l > 0 for _, l in target_margins(sky, tg.direction_N, at_s))
        skyplot.sky_points(ax, tg.direction_N, s=140, marker="*", color="#55a868" if free else "#c44e52",
                           edgecolor="k", zorder=5, label=f"{tg.label} ({'free' if free else 'NOT free'})")
    skyplot.format_full_sky(ax)
    when = (mission.epoch_utc + timedelta(seconds=at_s)).strftime("%Y-%m-%d %H:%M:%S UTC")
    ax.set_title(f"{mission.name}: the sky at t = {at_s:g} s ({when})", fontsize=10, pad=14)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0.0)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _closed(points: np.ndarray) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    return np.vstack([p, p[:1]])


def _sky(args: argparse.Namespace) -> int:
    from hil_sim.mission.model import load_mission_or_report
    from hil_sim.mission.physics_checks import SkyZones, ZoneBuildError

    mission = load_mission_or_report(args.mission)
    if mission is None:
        return EXIT_REJECTED
    try:
        epoch = mission.epoch_utc
        t0 = parse_time(args.t_from, epoch, "--from") if args.t_from is not None else 0.0
        t1 = parse_time(args.t_to, epoch, "--to") if args.t_to is not None else float(mission.duration_s)
        at = parse_time(args.at, epoch, "--at") if args.at is not None else t0
        if t1 < t0:
            raise ValueError(f"--to ({t1:g} s) is before --from ({t0:g} s)")
        if args.step is not None and not args.step > 0:
            raise ValueError(f"--step {args.step:g}: give a positive number of seconds")
        if at < 0 or t0 < 0:
            raise ValueError("times before the epoch: give times at or after the mission's epoch_utc")
        sky = SkyZones(mission)
        times = sample_times(sky, t0, t1, args.step)
    except (ValueError, ZoneBuildError) as exc:
        print(f"keepout sky: {exc}", file=sys.stderr)
        return EXIT_REJECTED
    print(report(mission, sky, at, times))
    if args.plot is not None:
        print(f"wrote {plot(mission, sky, at, args.plot)}")
    return 0
