"""Decoded telemetry -> Open MCT points, for history (from the archive) and real time (from the link).

One ``PointMaker`` per stream of packets: channel packets give one row per packet (stored compactly in
``History``; points are built on request); events give event points (FDIR trips also on their own
stream); ``TC_ACK`` verification reports give acknowledgement points; GNC packets give sky points
(boresight, target, body directions and the keep-out zone outlines as right ascension / declination), at
most one per ``SKY_PERIOD_S`` of onboard time so the trail stays light.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from comms.dictionary import TelemetryDictionary
from ground.archive import RAW_ARCHIVE, raw_records
from ground.verify import ACK_PACKET
from ground.web.alarms import AlarmBook
from ground.web.catalog import SKY_KEY, channel_key, radec_deg

if TYPE_CHECKING:
    from fsw.config import FswConfig
    from comms.telemetry import DecodedTm

SKY_PERIOD_S = 1.0  # onboard seconds between sky points
ZONE_OUTLINE_POINTS = 48
FDIR_EVENTS = ("FDIR_TRIPPED", "FDIR_CLEARED")
TIME_DOMAINS = ("utc", "onboard_s")


def ack_point(dictionary: TelemetryDictionary, utc: float, packet: DecodedTm) -> dict[str, Any]:
    """A command acknowledgement (a ``TC_ACK`` verification report) as an event-like point."""
    from ground.verify import Ack

    v = packet.values
    ack = Ack(v["ack_report"], int(v["ack_request_id"]), int(v["ack_tc_seq"]), int(v["ack_opcode"]), v["ack_code"],
              packet.time_s)
    failed = ack.report.endswith("FAILURE")
    return {"id": "acks", "utc": utc, "onboard_s": round(packet.time_s, 3), "severity": "WARNING_HI" if failed else "COMMAND",
            "event": ack.report, "message": ack.describe(dictionary).split(ack.report, 1)[-1].strip()}


class SkyModel:
    """Zone outlines around the moving Sun/Moon/Earth directions, from the run's flight-software config.

    The Sun and Moon come from telemetry (the flight software's own ephemeris); the Earth direction is the
    same onboard orbit model the flight software uses (``gnc.sky_ephemeris.SkyEphemeris``), evaluated at the
    packet's onboard time.
    """

    def __init__(self, cfg: FswConfig | None) -> None:
        from gnc.sky_zones import radial_profile_deg

        self.zones: list[tuple[str, str, np.ndarray, np.ndarray, float, np.ndarray | None]] = []
        self.ephemeris = None
        if cfg is None:
            return
        from gnc.sky_ephemeris import SkyEphemeris

        self.ephemeris = SkyEphemeris(cfg)
        phi = np.linspace(0.0, 2.0 * math.pi, ZONE_OUTLINE_POINTS, endpoint=False)
        for zone in cfg.pointing.zones:
            extra = self.ephemeris.earth_angular_radius_deg if zone.body == "earth" and zone.add_body_angular_radius else 0.0
            _, theta_deg = radial_profile_deg(zone.geometry, phi)
            fixed = np.asarray(zone.direction_N, dtype=float) if zone.direction_N is not None else None
            self.zones.append((zone.name, zone.body, phi, np.radians(theta_deg + extra),
                               float(getattr(zone.geometry, "orientation_deg", 0.0)), fixed))

    def outlines(self, centres_N: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        """Each zone's outline as [[ra, dec], ...] around its current centre."""
        from gnc.sky_zones import sky_frame

        out = []
        for name, body, phi, theta, orientation_deg, fixed in self.zones:
            centre = fixed if fixed is not None else centres_N.get(body)
            if centre is None or not np.all(np.isfinite(centre)):
                continue
            centre = centre / np.linalg.norm(centre)
            x_N, y_N = sky_frame(centre, orientation_deg)
            points = (np.cos(theta)[:, None] * centre
                      + np.sin(theta)[:, None] * (np.cos(phi)[:, None] * x_N + np.sin(phi)[:, None] * y_N))
            out.append({"name": name, "body": body, "centre": radec_deg(centre),
                        "outline": [radec_deg(p) for p in points]})
        return out


@dataclass
class History:
    """Everything a history request needs, kept compactly: rows of channel packets, event and sky points."""

    rows: dict[str, tuple[list[float], list[float], list[tuple[Any, ...]]]] = field(default_factory=dict)
    points: dict[str, list[dict[str, Any]]] = field(default_factory=dict)  # events, fdir, acks, sky

    def query(self, key: str, columns: dict[str, tuple[str, int]], start: float, end: float,
              latest: bool = False, outline: str = "all", domain: str = "utc") -> list[dict[str, Any]]:
        """Points of stream ``key`` with ``start <= time <= end`` (only the last one if ``latest``), in the
        time ``domain``: ``utc`` (ground receive time [ms]) or ``onboard_s`` (onboard time [s], what a
        replay is plotted against: the packets' own clock, not the moment they reached the ground)."""
        if domain not in TIME_DOMAINS:
            raise ValueError(f"domain must be one of {', '.join(TIME_DOMAINS)}")
        where = columns.get(key)
        if where is not None:
            packet, index = where
            utcs, onboard, rows = self.rows.get(packet, ([], [], []))
            times = utcs if domain == "utc" else onboard
            lo, hi = bisect.bisect_left(times, start), bisect.bisect_right(times, end)
            span = range(hi - 1, hi) if latest and hi > lo else range(lo, hi)
            return [{"id": key, "utc": utcs[i], "onboard_s": onboard[i], "value": rows[i][index]}
                    for i in span if rows[i][index] is not None]
        points = self.points.get(key, [])
        times = [p[domain] for p in points]
        lo, hi = bisect.bisect_left(times, start), bisect.bisect_right(times, end)
        selected = points[hi - 1:hi] if latest and hi > lo else points[lo:hi]
        if key == SKY_KEY and outline == "last" and len(selected) > 1:  # the trail needs the boresight only
            selected = [{k: v for k, v in p.items() if k != "zones"} for p in selected[:-1]] + selected[-1:]
        return selected


class PointMaker:
    """Turns decoded packets into Open MCT points (``points``) and into ``History`` (``record``)."""

    def __init__(self, dictionary: TelemetryDictionary, cfg: FswConfig | None = None) -> None:
        self.dictionary = dictionary
        self.sky = SkyModel(cfg)
        self.columns: dict[str, tuple[str, int]] = {}  # channel key -> (packet, index in the row)
        self._enums: dict[str, dict[str, int]] = {}
        self._names: dict[str, list[str]] = {}
        for packet in dictionary.packets:
            self._names[packet.name] = [c.name for c in packet.channels]
            for i, channel in enumerate(packet.channels):
                self.columns[channel_key(channel.name)] = (packet.name, i)
                if channel.enum:
                    self._enums[channel.name] = {name: i for i, name in enumerate(channel.enum)}
        self._last_sky_s = -math.inf

    def row(self, packet: DecodedTm) -> tuple[Any, ...]:
        """The packet's channel values as JSON-ready numbers (enum index, bool 0/1, None for no value)."""
        out = []
        for name in self._names[packet.packet]:
            value = packet.values.get(name)
            if isinstance(value, str):
                value = self._enums.get(name, {}).get(value)
            elif isinstance(value, bool):
                value = int(value)
            elif isinstance(value, float) and not math.isfinite(value):
                value = None
            out.append(value)
        return tuple(out)

    def stream_points(self, rx_time_s: float, packet: DecodedTm) -> list[dict[str, Any]]:
        """Event and sky points of one packet (channel points come from ``row``)."""
        utc = rx_time_s * 1000.0
        if packet.kind == "event":
            point = {"utc": utc, "onboard_s": round(packet.time_s, 3), "severity": packet.severity, "event": packet.event,
                     "message": packet.message}
            keys = ["events", "fdir"] if packet.event in FDIR_EVENTS else ["events"]
            return [{"id": key, **point} for key in keys]
        if packet.packet == ACK_PACKET:
            return [ack_point(self.dictionary, utc, packet)]
        if packet.packet == "GNC" and packet.time_s >= self._last_sky_s + SKY_PERIOD_S:
            self._last_sky_s = packet.time_s
            return [self._sky_point(utc, packet)]
        return []

    def _sky_point(self, utc: float, packet: DecodedTm) -> dict[str, Any]:
        v = packet.values

        def vec(base: str) -> np.ndarray:
            return np.array([v.get(f"{base}_x", math.nan), v.get(f"{base}_y", math.nan), v.get(f"{base}_z", math.nan)],
                            dtype=float)

        centres = {"sun": vec("sun_N"), "moon": vec("moon_N")}
        if self.sky.ephemeris is not None:
            centres["earth"] = self.sky.ephemeris.directions(packet.time_s)["earth"]
        boresight = radec_deg(vec("boresight_N"))
        return {"id": SKY_KEY, "utc": utc, "onboard_s": packet.time_s,
                "boresight": boresight, "target": radec_deg(vec("target_N")),
                "bodies": {name: radec_deg(c) for name, c in centres.items() if np.all(np.isfinite(c))},
                "margin_min_deg": _number(v.get("margin_min_deg")), "mode": v.get("mode"),
                "zones": self.sky.outlines(centres)}

    def record(self, history: History, rx_time_s: float, packet: DecodedTm) -> None:
        if packet.kind == "channels":
            utcs, onboard, rows = history.rows.setdefault(packet.packet, ([], [], []))
            utcs.append(rx_time_s * 1000.0)
            onboard.append(packet.time_s)
            rows.append(self.row(packet))
        for point in self.stream_points(rx_time_s, packet):
            history.points.setdefault(point["id"], []).append(point)


def _number(value: Any) -> float | None:
    return value if isinstance(value, (int, float)) and math.isfinite(value) else None


class ArchiveReader:
    """Reads a growing ``tm_raw.bin`` incrementally into a ``History`` (a live run's archive grows while
    it is browsed; a torn final record is read again on the next refresh)."""

    def __init__(self, archive_dir: Path, maker: PointMaker, alarms: AlarmBook | None = None) -> None:
        self.path = Path(archive_dir) / RAW_ARCHIVE
        self.maker = maker
        self.alarms = alarms
        self.history = History()
        self.offset = 0
        self.decode_errors = 0

    def refresh(self) -> int:
        """Read what was appended since the last call; returns the number of packets read."""
        from comms.telemetry import TelemetryDecodeError, decode_tm_packet

        if not self.path.exists():
            return 0
        count = 0
        for rx_time_s, raw, self.offset in raw_records(self.path, self.offset):
            count += 1
            try:
                packet = decode_tm_packet(self.maker.dictionary, raw)
            except (TelemetryDecodeError, ValueError):
                self.decode_errors += 1
                continue
            self.maker.record(self.history, rx_time_s, packet)
            if self.alarms is not None:
                self.alarms.observe(rx_time_s, packet)
        return count

    def span_ms(self) -> tuple[float, float] | None:
        """First and last ground receive time in the archive [ms], or None when it is empty."""
        return self.span("utc")

    def span(self, domain: str) -> tuple[float, float] | None:
        """First and last time of the archive in a time domain (``TIME_DOMAINS``), or None when it is empty."""
        column = TIME_DOMAINS.index(domain)
        times = [rows[column][0] for rows in self.history.rows.values() if rows[column]]
        ends = [rows[column][-1] for rows in self.history.rows.values() if rows[column]]
        times += [p[0][domain] for p in self.history.points.values() if p]
        ends += [p[-1][domain] for p in self.history.points.values() if p]
        return (min(times), max(ends)) if times else None
