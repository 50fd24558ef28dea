"""The flight dictionary as Open MCT domain objects (the server side of the keepout dictionary plugin).

Every telemetry channel becomes a telemetry object (``ch.<name>``) with its unit and limits; channels are
grouped as the dictionary groups them: a folder per packet (GNC, HK), and inside it a folder per
vector/indexed group (``q_est_NB`` -> ``q_est_NB_0..3``). Beside them: the event log, FDIR trips and the
command acknowledgements (telemetry objects whose points are events), the sky view, a margins overlay
plot, the alarm view, and an "Overview" flexible layout that puts key channels, alarms, events, sky and
margins on one page.

With the run's mission at hand, channels are named by what they are: ``margin_deg_0`` becomes "margin to
sun_keepout (estimate)", after the mission's own zone names, and unused zone slots leave the margins plot.
Each float channel is shown to its display resolution (``RESOLUTION_BY_UNIT``): the wire carries float32,
whose seven digits say nothing an operator can use.

The browser plugin (``static/keepout-plugin.js``) only looks objects up in this table, so the dictionary
is read in one place, here. Time on every point: ``utc`` = ground receive time [ms since 1970] (the
domain Open MCT's clocks and time conductor work in) and ``onboard_s`` = the packet's onboard time.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from comms.dictionary import Channel, TelemetryDictionary, vector_groups

if TYPE_CHECKING:
    from fsw.config import FswConfig

NAMESPACE = "keepout"
ROOT_KEY = "root"
CHANNEL_TYPE = "keepout.channel"
EVENTS_TYPE = "keepout.events"
SKY_TYPE = "keepout.sky"
EVENT_STREAMS = {
    "events": ("Event log", "every event of the flight software, with its severity"),
    "fdir": ("FDIR trips", "FDIR_TRIPPED / FDIR_CLEARED events"),
    "acks": ("Command acknowledgements", "PUS-1 verification reports (TC_ACK): acceptance success/failure and "
             "completion success/failure of each telecommand, with its sequence count and reason code"),
}
SKY_KEY = "sky"
ALARMS_KEY = "alarms"
ALARMS_TYPE = "keepout.alarms"
OVERVIEW_KEY = "overview"
KEY_CHANNELS = ("mode", "pointing_error_deg", "margin_min_deg", "active_zone", "rate_norm_deg_s", "st_valid",
                "fdir_trips", "tc_accepted", "tc_rejected", "cycle")

ONBOARD_TIME_FORMAT = "keepout.onboard"  # registered by the plugin: seconds since the mission start
_TIME_VALUES = [
    {"key": "utc", "source": "utc", "name": "Ground time", "format": "utc", "hints": {"domain": 1}},
    {"key": "onboard_s", "name": "Onboard time [s]", "format": ONBOARD_TIME_FORMAT, "hints": {"domain": 2}},
]
# Display resolution of float channels by unit: what an operator reads, not what float32 carries.
RESOLUTION_BY_UNIT = {"deg": 0.01, "deg/s": 0.001, "rad/s": 0.0001, "s": 0.01, "ms": 0.01, "N*m": 1e-6,
                      "A": 0.001, "MB": 0.1, "degC": 0.1, "rad^2": 1e-8}
UNITLESS_RESOLUTION = 0.0001  # direction cosines, quaternion components, gains


def channel_key(name: str) -> str:
    return f"ch.{name}"


def _identifier(key: str) -> dict[str, str]:
    return {"namespace": NAMESPACE, "key": key}


def resolution(channel: Channel) -> float | None:
    """The step a float channel is displayed to (None: shown as it is, integers and enumerations)."""
    if channel.type not in ("F32", "F64"):
        return None
    return RESOLUTION_BY_UNIT.get(channel.unit, UNITLESS_RESOLUTION)


def decimals(step: float) -> int:
    """Decimals that show a value to ``step`` (0.01 -> 2, 1e-6 -> 6)."""
    return max(0, math.ceil(-math.log10(step) - 1e-9))


def zone_labels(cfg: FswConfig | None) -> list[str]:
    """What each ``margin_deg_<i>`` slot measures, from the mission: the sky zones in POINTING and SAFE, the
    forbidden-attitude zones (antipodal copies after their zone) in QUATERNION mode."""
    if cfg is None:
        return []
    sky = [z.name for z in cfg.pointing.zones]
    attitude = [name for z in cfg.quaternion.zones for name in ([z.name, f"{z.name} (antipodal)"]
                                                               if z.antipodal_copy else [z.name])]
    return [" / ".join(n for n in pair if n) for pair in
            (((sky[i] if i < len(sky) else ""), (attitude[i] if i < len(attitude) else ""))
             for i in range(max(len(sky), len(attitude))))]


def display_names(dictionary: TelemetryDictionary, cfg: FswConfig | None) -> dict[str, str]:
    """Channel -> the name the console shows where the mission says more than the dictionary's index."""
    names = {f"margin_deg_{i}": f"margin to {label} (estimate)" for i, label in enumerate(zone_labels(cfg))}
    names["margin_min_deg"] = "smallest margin (estimate)"
    if cfg is not None:  # wheels in bus order RW1..RWn, as the ICD names their frames
        names.update({f"wheel_speed_rad_s_{i}": f"RW{i + 1} speed" for i in range(len(cfg.spacecraft.wheels))})
    return names


def _channel_value(channel: Channel, name: str) -> dict[str, Any]:
    value: dict[str, Any] = {"key": "value", "name": name, "unit": channel.unit, "hints": {"range": 1}}
    if channel.type == "ENUM":
        value.update(format="enum", enumerations=[{"value": i, "string": s} for i, s in enumerate(channel.enum or ())])
    elif channel.type == "BOOL":
        value.update(format="enum", enumerations=[{"value": 0, "string": "false"}, {"value": 1, "string": "true"}])
    elif channel.type in ("F32", "F64"):
        step = resolution(channel)
        value.update(format="float", formatString=f"%.{decimals(step)}f", resolution=step)
    else:
        value["format"] = "integer"
    return value


def _limits(channel: Channel) -> dict[str, list[float | None]] | None:
    if channel.limits is None or channel.type in ("ENUM", "BOOL"):
        return None
    return {"yellow": list(channel.limits.yellow), "red": list(channel.limits.red)}


def _folder(key: str, name: str, location: str, children: list[str]) -> dict[str, Any]:
    return {"identifier": _identifier(key), "name": name, "type": "folder", "location": f"{NAMESPACE}:{location}",
            "composition": [_identifier(k) for k in children]}


def build_objects(dictionary: TelemetryDictionary, title: str = "keepout",
                  cfg: FswConfig | None = None) -> dict[str, dict[str, Any]]:
    """Every Open MCT object of the plugin, keyed by identifier key (JSON-ready); ``cfg``, the run's
    flight-software configuration, names the zone and wheel channels after the mission."""
    objects: dict[str, dict[str, Any]] = {}
    names = display_names(dictionary, cfg)
    packet_folders = []
    for packet in dictionary.packets:
        folder_key = f"packet.{packet.name}"
        packet_folders.append(folder_key)
        grouped = {name: base for base, names in vector_groups(packet).items() for name in names}
        children: list[str] = []
        for channel in packet.channels:
            base = grouped.get(channel.name)
            parent = folder_key if base is None else f"group.{packet.name}.{base}"
            if base is not None and parent not in objects:
                children.append(parent)
                objects[parent] = _folder(parent, base, folder_key, [])
            if base is None:
                children.append(channel_key(channel.name))
            else:
                objects[parent]["composition"].append(_identifier(channel_key(channel.name)))
            objects[channel_key(channel.name)] = {
                "identifier": _identifier(channel_key(channel.name)), "name": names.get(channel.name, channel.name),
                "type": CHANNEL_TYPE, "location": f"{NAMESPACE}:{parent}",
                "notes": f"{channel.name}: {channel.description}",
                "telemetry": {"values": [_channel_value(channel, names.get(channel.name, channel.name)),
                                         *_TIME_VALUES]},
                "keepout": {"channel": channel.name, "packet": packet.name, "unit": channel.unit,
                            "limits": _limits(channel)},
            }
        objects[folder_key] = _folder(folder_key, f"{packet.name} ({packet.rate})", ROOT_KEY, children)
    for key, (name, notes) in EVENT_STREAMS.items():
        objects[key] = {
            "identifier": _identifier(key), "name": name, "type": EVENTS_TYPE, "location": f"{NAMESPACE}:{ROOT_KEY}",
            "notes": notes,
            "telemetry": {"values": [
                _TIME_VALUES[0], _TIME_VALUES[1],
                {"key": "severity", "name": "Severity", "format": "string"},
                {"key": "event", "name": "Event", "format": "string"},
                {"key": "message", "name": "Message", "format": "string", "hints": {"label": 0}},
            ]},
        }
    objects[SKY_KEY] = {
        "identifier": _identifier(SKY_KEY), "name": "Sky: boresight and keep-out zones", "type": SKY_TYPE,
        "location": f"{NAMESPACE}:{ROOT_KEY}",
        "telemetry": {"values": [_TIME_VALUES[0], _TIME_VALUES[1],
                                 {"key": "boresight", "name": "Boresight (RA, Dec) [deg]", "format": "string"}]},
    }
    objects["margins"] = _margins_plot(dictionary, cfg)
    objects[ALARMS_KEY] = {
        "identifier": _identifier(ALARMS_KEY), "name": "Alarms", "type": ALARMS_TYPE,
        "location": f"{NAMESPACE}:{ROOT_KEY}",
        "notes": "limit violations (RED/YELLOW from the dictionary's limits), FDIR trips and keep-out events, "
                 "each to acknowledge (served by /api/alarms, not a telemetry stream)",
    }
    key_channels = [n for n in KEY_CHANNELS if n in dictionary.channel_names]
    objects["key_channels"] = {
        "identifier": _identifier("key_channels"), "name": "Key channels", "type": "LadTable",
        "location": f"{NAMESPACE}:{ROOT_KEY}", "composition": [_identifier(channel_key(n)) for n in key_channels],
        # the names in full: the timestamp and type columns say nothing the page does not say already
        "configuration": {"hiddenColumns": {"timestamp": True, "type": True}},
    }
    objects["event_table"] = {
        "identifier": _identifier("event_table"), "name": "Events and acknowledgements", "type": "table",
        "location": f"{NAMESPACE}:{ROOT_KEY}", "composition": [_identifier("events"), _identifier("acks")],
        "configuration": {"hiddenColumns": {"name": True}},
    }
    objects[OVERVIEW_KEY] = _overview()
    objects[ROOT_KEY] = _folder(ROOT_KEY, title, "ROOT",
                                [OVERVIEW_KEY, ALARMS_KEY, "key_channels", "margins", SKY_KEY, *EVENT_STREAMS,
                                 "event_table",
                                 *packet_folders])
    objects[ROOT_KEY]["location"] = "ROOT"
    return objects


def _margins_plot(dictionary: TelemetryDictionary, cfg: FswConfig | None) -> dict[str, Any]:
    """The margins overlay plot: the zones the mission uses (every slot without a mission) and the
    smallest margin, whose limit lines (yellow 2 deg, red 0 deg) are drawn once, not once a zone."""
    slots = [c for c in dictionary.channel_names if c.startswith("margin_deg_")]
    if cfg is not None:
        slots = slots[:len(zone_labels(cfg))]
    channels = [*slots, "margin_min_deg"]
    return {"identifier": _identifier("margins"), "name": "Keep-out margins (onboard estimate) [deg]",
            "type": "telemetry.plot.overlay", "location": f"{NAMESPACE}:{ROOT_KEY}",
            "composition": [_identifier(channel_key(n)) for n in channels],
            "configuration": {"series": [{"identifier": _identifier(channel_key(n)),
                                          "limitLines": n == "margin_min_deg"} for n in channels]}}


def _overview() -> dict[str, Any]:
    """A flexible layout (Open MCT's own type): key channels and events left, sky and margins right."""
    def frame(key: str, size: int) -> dict[str, Any]:
        return {"id": f"frame-{key}", "domainObjectIdentifier": _identifier(key), "size": size, "noFrame": False}

    containers = [
        {"id": "left", "size": 50, "frames": [frame("key_channels", 34), frame(ALARMS_KEY, 30),
                                              frame("event_table", 36)]},
        {"id": "right", "size": 50, "frames": [frame(SKY_KEY, 55), frame("margins", 45)]},
    ]
    return {"identifier": _identifier(OVERVIEW_KEY), "name": "Overview", "type": "flexible-layout",
            "location": f"{NAMESPACE}:{ROOT_KEY}",
            "composition": [_identifier(k) for k in ("key_channels", ALARMS_KEY, "event_table", SKY_KEY, "margins")],
            "configuration": {"containers": containers, "rowsLayout": False, "objectStyles": {}}}


def radec_deg(v_N: Any) -> list[float] | None:
    """Right ascension in [0, 360) and declination [deg] of an N-frame direction (None if no value)."""
    x, y, z = (float(c) for c in v_N)
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0.0 or not math.isfinite(n):
        return None
    return [math.degrees(math.atan2(y, x)) % 360.0, math.degrees(math.asin(max(-1.0, min(1.0, z / n))))]
