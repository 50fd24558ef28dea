"""The keepout telemetry dictionary: every telemetry channel, event and telecommand, declared once.

Following F Prime, the flight software and the ground tools read the same dictionary: the flight side
builds packets from it (``fsw.telemetry``), decodes telecommands with it (``fsw.telecommand``), and the
ground (the ``ground`` package) decodes and limit-checks telemetry with it. ``config/telemetry_dictionary.json``
is generated from this module (``keepout config dictionary``) and a test keeps the committed file equal to
the generated one.

Conventions (stable names: the flight app and ground refer to them):

- Vectors are spread over scalar channels named ``<base>_x/_y/_z`` (3-vectors, frame suffix in the base
  name, e.g. ``omega_est_BN_B_x``); quaternions ``<base>_0.._3`` scalar first (``q_est_NB_0`` = eta);
  per-wheel and per-zone channels ``<base>_0..<base>_5``. ``TelemetrySender.send_channels`` also accepts
  the base name with a sequence value and spreads it.
- Units are in the channel name where a GNC engineer expects them (``_deg``, ``_rad_s``, ``_Nm``, ``_ms``)
  and always in ``unit``.
- Limits: ``yellow``/``red`` are (low, high) bounds; ``None`` on a side means no limit on that side. A
  value is RED when outside the red bounds, YELLOW when outside the yellow bounds, else GREEN.

Wire format (all big-endian), CCSDS 133.0-B-2 space packets built with ``spacepackets``:

- Telemetry (packet type TM, secondary header flag set): 6-byte primary header, secondary header
  ``time_s`` (float64, onboard time in seconds), then the channel values in declaration order, then a
  CRC-16/CCITT-FALSE over everything before it. One APID per packet definition; events use ``EVENT_APID``
  with payload ``event id (u16), severity (u8), args...``.
- Telecommands (packet type TC, no secondary header): primary header with ``TC_APID``, ``opcode (u16)``,
  args in declaration order, CRC-16/CCITT-FALSE. Strings are ``u8 length + UTF-8 bytes``.
- Every telecommand is acknowledged in the ``TC_ACK`` telemetry packet (``TC_ACK_APID``), as PUS service 1:
  acceptance success/failure and completion success/failure with a reason code from ``TC_REASONS``.
"""
from __future__ import annotations

import enum
import json
import math
import operator
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

DICTIONARY_VERSION = "1.0"

# APIDs (11 bits). TM packets each get their own APID so that sequence counts are per stream.
GNC_APID = 0x010
HK_APID = 0x011
EVENT_APID = 0x012
TC_ACK_APID = 0x013  # telecommand verification reports (the role of PUS service 1)
TC_APID = 0x050

# Default UDP ports on loopback (the mission config may override host and ports).
DEFAULT_TM_PORT = 50100  # same defaults as fsw.config.TmTcConfig
DEFAULT_TC_PORT = 50101
DEFAULT_HOST = "127.0.0.1"

TM_SECONDARY_HEADER = struct.Struct("!d")  # onboard time, s
CRC_LEN = 2
MAX_TC_PACKET_LEN = 256  # bytes; larger telecommand packets are rejected as format errors
MAX_STRING_LEN = 120  # bytes of UTF-8 in a string argument

MAX_WHEELS = 6  # RW1..RW6: the wheels the bus ICD has frames for (tests/fsw/test_bus_icd.py checks it)
N_ZONES_MAX = 6


class Severity(str, enum.Enum):
    """Event severities (F Prime's set), most to least severe."""

    FATAL = "FATAL"
    WARNING_HI = "WARNING_HI"
    WARNING_LO = "WARNING_LO"
    COMMAND = "COMMAND"
    ACTIVITY_HI = "ACTIVITY_HI"
    ACTIVITY_LO = "ACTIVITY_LO"
    DIAGNOSTIC = "DIAGNOSTIC"

    @property
    def code(self) -> int:
        return list(Severity).index(self)

    @classmethod
    def from_code(cls, code: int) -> "Severity":
        members = list(cls)
        if not 0 <= code < len(members):
            raise ValueError(f"unknown severity code {code}; allowed 0..{len(members) - 1}")
        return members[code]


class LimitState(str, enum.Enum):
    GREEN = "GREEN"
    YELLOW = "YELLOW"
    RED = "RED"


# type name -> struct code. ENUM is a u8 index into the declared names; STRING is variable length.
_STRUCT_CODES = {
    "BOOL": "?",
    "U8": "B",
    "I8": "b",
    "U16": "H",
    "I16": "h",
    "U32": "I",
    "I32": "i",
    "F32": "f",
    "F64": "d",
    "ENUM": "B",
}
TYPES = tuple(_STRUCT_CODES) + ("STRING",)
_INT_RANGES = {
    "U8": (0, 2**8 - 1),
    "I8": (-(2**7), 2**7 - 1),
    "U16": (0, 2**16 - 1),
    "I16": (-(2**15), 2**15 - 1),
    "U32": (0, 2**32 - 1),
    "I32": (-(2**31), 2**31 - 1),
}


class DictionaryError(ValueError):
    """A dictionary definition is inconsistent, or a name is not in the dictionary."""


@dataclass(frozen=True)
class Limits:
    """Yellow and red limits as (low, high); None on a side means unlimited on that side."""

    yellow: tuple[float | None, float | None] = (None, None)
    red: tuple[float | None, float | None] = (None, None)

    def check(self, value: float) -> LimitState:
        """Limit state of ``value``. NaN means "no value" (an unused zone slot, nothing measured yet)
        and is not a limit violation: GREEN."""
        if isinstance(value, float) and math.isnan(value):
            return LimitState.GREEN
        if _outside(value, self.red):
            return LimitState.RED
        if _outside(value, self.yellow):
            return LimitState.YELLOW
        return LimitState.GREEN


def _outside(value: float, bounds: tuple[float | None, float | None]) -> bool:
    low, high = bounds
    return (low is not None and value < low) or (high is not None and value > high)


@dataclass(frozen=True)
class Channel:
    """One telemetry channel (a scalar). ``enum`` lists names for type ENUM (index on the wire)."""

    name: str
    type: str
    unit: str
    description: str
    limits: Limits | None = None
    enum: tuple[str, ...] | None = None
    no_value: float | int | None = None  # wire value meaning "no value" (default: NaN, or 0 for integers)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "name": self.name, "type": self.type, "unit": self.unit, "description": self.description,
        }
        if self.limits is not None:
            out["limits"] = {"yellow": list(self.limits.yellow), "red": list(self.limits.red)}
        if self.enum is not None:
            out["enum"] = list(self.enum)
        if self.no_value is not None:
            out["no_value"] = self.no_value
        return out


@dataclass(frozen=True)
class Arg:
    """A typed argument of an event or a telecommand, with an optional inclusive range."""

    name: str
    type: str
    unit: str = ""
    description: str = ""
    min: float | None = None
    max: float | None = None
    enum: tuple[str, ...] | None = None
    default: Any = None  # telecommand args only: used when the sender omits trailing args

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "type": self.type, "unit": self.unit,
                               "description": self.description}
        for key in ("min", "max", "default"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.enum is not None:
            out["enum"] = list(self.enum)
        return out


@dataclass(frozen=True)
class PacketDef:
    """A telemetry packet: an APID and an ordered list of channels, sent at ``rate``."""

    name: str
    apid: int
    rate: str
    description: str
    channels: tuple[Channel, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "apid": self.apid, "rate": self.rate, "description": self.description,
                "channels": [c.to_dict() for c in self.channels]}


@dataclass(frozen=True)
class EventDef:
    """An event: id, severity, typed args and a message format (``str.format`` with the arg names).

    ``throttle`` (if set) is the most events of this kind sent per ``throttle_window_s``; the rest are
    counted as throttled, so a repeating fault cannot flood the downlink.
    """

    name: str
    id: int
    severity: Severity
    format: str
    args: tuple[Arg, ...] = ()
    throttle: int | None = None
    throttle_window_s: float = 10.0

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "id": self.id, "severity": self.severity.value,
                               "format": self.format, "args": [a.to_dict() for a in self.args]}
        if self.throttle is not None:
            out["throttle"] = self.throttle
            out["throttle_window_s"] = self.throttle_window_s
        return out


@dataclass(frozen=True)
class CommandDef:
    """A telecommand: opcode and typed args (validated by the dispatcher before any handler runs).

    ``failure_codes`` are the reason codes (``TC_REASON_CODES``) its own handler may answer with, on top
    of the checks every telecommand goes through (``TC_COMMON_FAILURE_CODES``).
    """

    name: str
    opcode: int
    description: str
    args: tuple[Arg, ...] = ()
    failure_codes: tuple[str, ...] = ()

    @property
    def acknowledgement(self) -> dict[str, Any]:
        """What the flight software reports for this command (documented in the JSON export)."""
        return {"success": ["ACCEPTANCE_SUCCESS", "COMPLETION_SUCCESS"],
                "acceptance_failure_codes": [*TC_COMMON_FAILURE_CODES, *self.failure_codes],
                "completion_failure_codes": list(TC_COMPLETION_FAILURE_CODES)}

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "opcode": self.opcode, "description": self.description,
                               "args": [a.to_dict() for a in self.args]}
        if self.failure_codes:
            out["failure_codes"] = list(self.failure_codes)
        out["acknowledgement"] = self.acknowledgement
        return out


@dataclass
class TelemetryDictionary:
    """Lookup tables over packets, channels, events and commands, with consistency checks."""

    packets: tuple[PacketDef, ...]
    events: tuple[EventDef, ...]
    commands: tuple[CommandDef, ...]
    version: str = DICTIONARY_VERSION
    tc_apid: int = TC_APID
    event_apid: int = EVENT_APID
    _packet_by_name: dict[str, PacketDef] = field(init=False, repr=False)
    _packet_by_apid: dict[int, PacketDef] = field(init=False, repr=False)
    _channel_by_name: dict[str, tuple[PacketDef, Channel]] = field(init=False, repr=False)
    _event_by_name: dict[str, EventDef] = field(init=False, repr=False)
    _event_by_id: dict[int, EventDef] = field(init=False, repr=False)
    _command_by_name: dict[str, CommandDef] = field(init=False, repr=False)
    _command_by_opcode: dict[int, CommandDef] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._packet_by_name = _unique({p.name: p for p in self.packets}, self.packets, "packet name")
        self._packet_by_apid = _unique({p.apid: p for p in self.packets}, self.packets, "packet APID")
        if self.event_apid in self._packet_by_apid or self.tc_apid in self._packet_by_apid:
            raise DictionaryError("event/TC APID collides with a telemetry packet APID")
        self._channel_by_name = {}
        for packet in self.packets:
            for channel in packet.channels:
                _check_type(channel.type, channel.name, channel.enum)
                if channel.type == "STRING":
                    raise DictionaryError(f"channel {channel.name}: STRING channels are not supported")
                if channel.name in self._channel_by_name:
                    raise DictionaryError(f"channel {channel.name} declared twice")
                self._channel_by_name[channel.name] = (packet, channel)
        self._event_by_name = _unique({e.name: e for e in self.events}, self.events, "event name")
        self._event_by_id = _unique({e.id: e for e in self.events}, self.events, "event id")
        self._command_by_name = _unique({c.name: c for c in self.commands}, self.commands, "command name")
        self._command_by_opcode = _unique({c.opcode: c for c in self.commands}, self.commands, "opcode")
        for definition in (*self.events, *self.commands):
            for arg in definition.args:
                _check_type(arg.type, f"{definition.name}.{arg.name}", arg.enum)
        for command in self.commands:
            unknown = set(command.failure_codes) - set(TC_REASON_CODES)
            if unknown:
                raise DictionaryError(f"command {command.name}: failure codes {sorted(unknown)} not in "
                                      f"TC_REASON_CODES")

    # ---- lookups (errors name what exists) ----
    def packet(self, name: str) -> PacketDef:
        try:
            return self._packet_by_name[name]
        except KeyError:
            raise DictionaryError(f"unknown packet {name!r}; known: {sorted(self._packet_by_name)}") from None

    def packet_by_apid(self, apid: int) -> PacketDef | None:
        return self._packet_by_apid.get(apid)

    def channel(self, name: str) -> Channel:
        try:
            return self._channel_by_name[name][1]
        except KeyError:
            raise DictionaryError(f"unknown channel {name!r}") from None

    def channel_packet(self, name: str) -> PacketDef:
        return self._channel_by_name[name][0]

    @property
    def channel_names(self) -> list[str]:
        return list(self._channel_by_name)

    def event(self, name: str) -> EventDef:
        try:
            return self._event_by_name[name]
        except KeyError:
            raise DictionaryError(f"unknown event {name!r}; known: {sorted(self._event_by_name)}") from None

    def event_by_id(self, event_id: int) -> EventDef | None:
        return self._event_by_id.get(event_id)

    def command(self, name_or_opcode: str | int) -> CommandDef:
        table: Mapping[Any, CommandDef]
        table = self._command_by_opcode if isinstance(name_or_opcode, int) else self._command_by_name
        try:
            return table[name_or_opcode]
        except KeyError:
            raise DictionaryError(
                f"unknown command {name_or_opcode!r}; known: {sorted(self._command_by_name)}"
            ) from None

    def command_by_opcode(self, opcode: int) -> CommandDef | None:
        return self._command_by_opcode.get(opcode)

    # ---- JSON ----
    def to_dict(self) -> dict[str, Any]:
        return {
            "version": self.version,
            "format": {
                "byte_order": "big-endian",
                "tm_secondary_header": [{"name": "time_s", "type": "F64", "unit": "s"}],
                "crc": "CRC-16/CCITT-FALSE over the whole packet before the CRC",
                "event_payload": ["event_id U16", "severity U8 (index into severities)", "args..."],
                "tc_payload": ["opcode U16", "args...", "crc U16"],
                "string": "U8 length + UTF-8 bytes",
                "enum": "U8 index into the listed names",
            },
            "severities": [s.value for s in Severity],
            "apids": {"tc": self.tc_apid, "event": self.event_apid},
            "tc_verification": {
                "packet": "TC_ACK",
                "description": TC_VERIFICATION_DOC,
                "reports": [{"name": name, "pus_subtype": subtype} for name, subtype in TC_ACK_REPORTS],
                "reason_codes": [{"code": code, "name": name, "description": TC_REASON_DOCS[name]}
                                 for code, name in enumerate(TC_REASON_CODES)],
            },
            "ports": {"tm": DEFAULT_TM_PORT, "tc": DEFAULT_TC_PORT, "host": DEFAULT_HOST},
            "packets": [p.to_dict() for p in self.packets],
            "events": [e.to_dict() for e in self.events],
            "commands": [c.to_dict() for c in self.commands],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1) + "\n"

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "TelemetryDictionary":
        """Rebuild a dictionary from its JSON form (so a ground station needs only the JSON file)."""
        try:
            packets = tuple(
                PacketDef(p["name"], int(p["apid"]), p["rate"], p["description"],
                          tuple(_channel_from_dict(c) for c in p["channels"]))
                for p in data["packets"]
            )
            events = tuple(
                EventDef(e["name"], int(e["id"]), Severity(e["severity"]), e["format"],
                         tuple(_arg_from_dict(a) for a in e["args"]), e.get("throttle"),
                         float(e.get("throttle_window_s", 10.0)))
                for e in data["events"]
            )
            commands = tuple(
                CommandDef(c["name"], int(c["opcode"]), c["description"],
                           tuple(_arg_from_dict(a) for a in c["args"]), tuple(c.get("failure_codes", ())))
                for c in data["commands"]
            )
            return cls(packets, events, commands, version=data["version"],
                       tc_apid=int(data["apids"]["tc"]), event_apid=int(data["apids"]["event"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise DictionaryError(f"malformed dictionary JSON: {exc!r}") from exc

    @classmethod
    def load(cls, path: str | Path) -> "TelemetryDictionary":
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise DictionaryError(f"{path}: cannot read dictionary JSON: {exc}") from exc
        return cls.from_dict(data)


def _unique(table: dict, items: Sequence, what: str) -> dict:
    if len(table) != len(items):
        raise DictionaryError(f"duplicate {what} in dictionary")
    return table


def _check_type(type_name: str, where: str, enum_names: tuple[str, ...] | None) -> None:
    if type_name not in TYPES:
        raise DictionaryError(f"{where}: type {type_name!r} not one of {TYPES}")
    if (type_name == "ENUM") != (enum_names is not None):
        raise DictionaryError(f"{where}: ENUM needs enum names and only ENUM may have them")


def _limits_from_dict(data: Mapping[str, Any] | None) -> Limits | None:
    if data is None:
        return None
    return Limits(tuple(data["yellow"]), tuple(data["red"]))  # type: ignore[arg-type]


def _channel_from_dict(data: Mapping[str, Any]) -> Channel:
    enum_names = tuple(data["enum"]) if "enum" in data else None
    return Channel(data["name"], data["type"], data["unit"], data["description"],
                   _limits_from_dict(data.get("limits")), enum_names, data.get("no_value"))


def _arg_from_dict(data: Mapping[str, Any]) -> Arg:
    enum_names = tuple(data["enum"]) if "enum" in data else None
    return Arg(data["name"], data["type"], data.get("unit", ""), data.get("description", ""),
               data.get("min"), data.get("max"), enum_names, data.get("default"))


# ---------------------------------------------------------------------------------------------
# The keepout dictionary
# ---------------------------------------------------------------------------------------------
MODES = ("SAFE", "POINTING", "QUATERNION", "DETUMBLE")  # codes 0-3: append, never reorder
SAFE_PHASES = ("NONE", "RATE_DAMPING", "SUN_ACQUISITION", "SUN_POINTING")
BLIND_SOURCES = ("NONE", "SUN", "MOON", "RATE")  # matches the bus ST_QUAT blind_source coding
FDIR_STATES = ("NOMINAL", "PERSISTING", "TRIPPED", "DISABLED")
FDIR_MONITORS = ("IMU_STALE", "ST_STALE", "ST_CORRUPT", "IMU_CORRUPT", "INNOVATION", "WHEEL_FAULT",
                 "WHEEL_SPEED", "KEEP_OUT_MARGIN", "CYCLE_SLIP", "ESTIMATOR_DIVERGENCE")
FDIR_ACTIONS = ("NONE", "EVENT_ONLY", "REJECT_SENSOR", "ISOLATE_WHEEL", "ENTER_SAFE", "RESET_ESTIMATOR")
ZONE_BODIES = ("SUN", "MOON", "EARTH", "INERTIAL", "ATTITUDE", "MERGED")
RATE_GROUPS = ("GNC", "HK")
SENSORS = ("IMU", "STAR_TRACKER", "WHEEL")
TC_ERRORS = ("INVALID_OPCODE", "VALIDATION", "FORMAT", "EXECUTION", "SECURITY")
# the aperture door (fsw.door): why it closes, what its drive or the flight software found wrong, its ends
DOOR_REASONS = ("NONE", "PREDICTED_ENTRY", "KEEP_OUT_VIOLATION", "NO_ATTITUDE", "DETUMBLE")
DOOR_FAULTS = ("STALLED", "COMMAND_TIMEOUT", "NO_STATUS", "NOT_CLOSED", "NOT_OPEN")
DOOR_STATES = ("CLOSED", "OPEN", "CLOSING", "OPENING", "STOPPED")
# the Earth's shadow as the flight software knows it (fsw.eclipse); UNKNOWN without onboard orbit knowledge
ECLIPSE_STATES = ("UNKNOWN", "SUNLIT", "PENUMBRA", "UMBRA")

# Telecommand verification, after PUS service 1 (ECSS-E-ST-70-41C ch. 6.1): every telecommand gets an
# acceptance report (success or failure with a reason code) and, once accepted, a completion report. They
# travel in the TC_ACK packet and quote the command's request id (its first four octets: version, type,
# APID, sequence flags and count) and sequence count, so the sender can match them.
TC_ACK_REPORTS = (("ACCEPTANCE_SUCCESS", 1), ("ACCEPTANCE_FAILURE", 2),
                  ("COMPLETION_SUCCESS", 7), ("COMPLETION_FAILURE", 8))  # (name, PUS subtype)
TC_VERIFICATION_DOC = (
    "every telecommand is answered by a TC_ACK packet: ACCEPTANCE_SUCCESS or ACCEPTANCE_FAILURE (with a "
    "reason code) once the packet, its arguments and the handler's own checks passed or failed; an accepted "
    "command is then answered by COMPLETION_SUCCESS or COMPLETION_FAILURE (with a reason code). A rejected "
    "command changed nothing on board. Each report quotes the command's request id (its first four octets) "
    "and sequence count."
)
# (name, error class of TC_ERRORS, description); the code on the wire is the position in this table.
TC_REASONS: tuple[tuple[str, str, str], ...] = (
    ("NONE", "", "no failure (success reports)"),
    ("PACKET_TOO_SHORT", "FORMAT", "datagram shorter than header + opcode + CRC (10 bytes)"),
    ("PACKET_TOO_LONG", "FORMAT", f"datagram longer than {MAX_TC_PACKET_LEN} bytes"),
    ("BAD_HEADER", "FORMAT", "CCSDS version not 0, not a TC, segmented, or secondary header flag set"),
    ("WRONG_APID", "FORMAT", "APID is not the telecommand APID"),
    ("LENGTH_MISMATCH", "FORMAT", "packet length field disagrees with the datagram length"),
    ("CRC_MISMATCH", "FORMAT", "CRC-16/CCITT-FALSE check failed"),
    ("UNKNOWN_OPCODE", "INVALID_OPCODE", "opcode not in the dictionary"),
    ("NO_HANDLER", "INVALID_OPCODE", "command in the dictionary but not handled by this flight software"),
    ("ARGS_TRUNCATED", "FORMAT", "packet ends before the last argument"),
    ("TRAILING_BYTES", "FORMAT", "bytes after the last argument"),
    ("BAD_ENUM", "VALIDATION", "enumerated argument index outside the declared names"),
    ("ARG_OUT_OF_RANGE", "VALIDATION", "argument outside its declared range, or not finite"),
    ("TARGET_NOT_UNIT", "VALIDATION", "target direction or quaternion is not of unit norm"),
    ("TARGET_IN_KEEP_OUT", "VALIDATION", "target lies inside a keep-out zone (TARGET_REJECTED event names it)"),
    ("GAINS_INADMISSIBLE", "VALIDATION", "gains refused by the law (e.g. eps outside the admissible interval)"),
    ("EXECUTION_FAILED", "EXECUTION", "the handler failed while executing an accepted command"),
    # link security (comms.link_security): only REPLAY and OUTSIDE_WINDOW are ever acknowledged (the packet
    # authenticated); the others are counted in housekeeping and not answered
    ("UNAUTHENTICATED", "SECURITY", "no security header, or another security parameter index (not answered)"),
    ("BAD_MAC", "SECURITY", "the MAC does not verify: forged or signed with another key (not answered)"),
    ("REPLAY", "SECURITY", "security sequence number not above the last accepted one: a replay"),
    ("OUTSIDE_WINDOW", "SECURITY", "security sequence number beyond the anti-replay window: send SEC_RESYNC"),
    # appended: the wire code is the position in this table
    ("BRAKING_DISTANCE", "VALIDATION", "stopping from the rate limit takes more than the margin and eps-layer allow"),
    ("RATE_ABOVE_SENSOR_LIMIT", "VALIDATION", "rate limit above the star tracker's tracking rate or the gyro's range"),
    ("WHEEL_AUTHORITY", "VALIDATION", "rate limit above what the wheels left can give"),
)
TC_REASON_CODES = tuple(name for name, _, _ in TC_REASONS)
TC_REASON_CLASS = {name: error_class for name, error_class, _ in TC_REASONS}
TC_REASON_DOCS = {name: doc for name, _, doc in TC_REASONS}
TC_COMMON_FAILURE_CODES = ("PACKET_TOO_SHORT", "PACKET_TOO_LONG", "BAD_HEADER", "WRONG_APID", "LENGTH_MISMATCH",
                           "CRC_MISMATCH", "UNKNOWN_OPCODE", "NO_HANDLER", "ARGS_TRUNCATED", "TRAILING_BYTES",
                           "BAD_ENUM", "ARG_OUT_OF_RANGE", "REPLAY", "OUTSIDE_WINDOW")
TC_COMPLETION_FAILURE_CODES = ("EXECUTION_FAILED",)
TARGET_KINDS = ("DIRECTION", "QUATERNION", "NADIR", "GROUND")
MODE_REASONS = ("INIT", "TELECOMMAND", "FDIR", "AUTONOMOUS")
PLUGIN_KINDS = ("GUIDANCE", "ESTIMATOR")  # fsw.plugins: which part of the GNC a plug-in replaces

# Wheel speed limits: typical small-satellite reaction wheels saturate at ~6000 rpm (628 rad/s).
_WHEEL_SPEED_LIMITS = Limits(yellow=(-500.0, 500.0), red=(-600.0, 600.0))
# Signed separation from the physical keep-out zone in degrees: negative means inside the zone.
_MARGIN_LIMITS = Limits(yellow=(2.0, None), red=(0.0, None))


def _vec3(base: str, unit: str, description: str, limits: Limits | None = None,
          type_name: str = "F32") -> list[Channel]:
    return [Channel(f"{base}_{axis}", type_name, unit, f"{description} ({axis})", limits)
            for axis in "xyz"]


def _quat(base: str, description: str) -> list[Channel]:
    parts = ("eta (scalar)", "q1", "q2", "q3")
    return [Channel(f"{base}_{i}", "F64", "", f"{description}, {parts[i]}") for i in range(4)]


def _indexed(base: str, count: int, type_name: str, unit: str, description: str,
             limits: Limits | None = None) -> list[Channel]:
    return [Channel(f"{base}_{i}", type_name, unit, f"{description} [{i}]", limits) for i in range(count)]


_GNC_CHANNELS: list[Channel] = [
    Channel("cycle", "U32", "", "GNC cycle counter"),
    Channel("mode", "ENUM", "", "flight mode", enum=MODES),
    Channel("safe_phase", "ENUM", "", "SAFE mode phase", enum=SAFE_PHASES),
    *_quat("q_est_NB", "estimated attitude q_NB (body to inertial)"),
    *_vec3("omega_est_BN_B", "rad/s", "estimated body rate of B wrt N in B"),
    *_vec3("omega_cmd_BN_B", "rad/s", "commanded body rate of B wrt N in B"),
    Channel("rate_norm_deg_s", "F32", "deg/s", "norm of the estimated body rate",
            Limits(yellow=(None, 3.0), red=(None, 5.0))),
    *_vec3("bias_est_B", "rad/s", "estimated gyro bias in B"),
    Channel("cov_trace", "F32", "rad^2", "trace of the attitude error covariance (grows while coasting)",
            Limits(yellow=(None, 3e-4), red=(None, 3e-3))),
    Channel("st_age_s", "F32", "s", "time since the last accepted star-tracker update",
            Limits(yellow=(None, 10.0), red=(None, 60.0))),
    *_vec3("boresight_N", "", "instrument boresight in N (estimated)"),
    *_vec3("target_N", "", "pointing target direction in N"),
    *_quat("q_target_NB", "target attitude q_NB (QUATERNION mode)"),
    Channel("pointing_error_deg", "F32", "deg", "angle between boresight and target"),
    Channel("att_error_deg", "F32", "deg", "attitude error angle to the target attitude"),
    Channel("roll_error_deg", "F32", "deg", "roll error about the boresight"),
    Channel("active_zone", "I8", "", "zone whose eps-layer the law is in (-1: none)", no_value=-1),
    Channel("zone_count", "U8", "", "number of keep-out zones in use"),
    *_indexed("margin_deg", N_ZONES_MAX, "F32", "deg",
              "signed separation from physical keep-out zone (negative inside; NaN unused)",
              _MARGIN_LIMITS),
    Channel("margin_min_deg", "F32", "deg", "smallest signed separation over all physical zones",
            _MARGIN_LIMITS),
    Channel("eps", "F32", "", "eps-layer width of the law in d_s units (1 - cos)"),
    Channel("eps_max", "F32", "", "upper end of the admissible eps interval"),
    Channel("kappa", "F32", "", "star-shaped law gain kappa"),
    Channel("k1", "F32", "", "law gain k1"),
    Channel("zones_merged", "BOOL", "", "two zones replaced by one conservative zone"),
    Channel("assumptions_ok", "BOOL", "", "paper's assumptions hold for the current geometry"),
    *_vec3("torque_cmd_B_Nm", "N*m", "commanded body torque in B"),
    Channel("torque_scale", "F32", "", "scale applied to fit wheel torque limits (1: none)",
            Limits(yellow=(0.999, None), red=(None, None))),
    *_indexed("wheel_speed_rad_s", MAX_WHEELS, "F32", "rad/s", "reaction wheel speed",
              _WHEEL_SPEED_LIMITS),
    *_indexed("wheel_torque_cmd_Nm", MAX_WHEELS, "F32", "N*m", "reaction wheel torque command"),
    *_vec3("sun_N", "", "onboard Sun direction in N"),
    *_vec3("moon_N", "", "onboard Moon direction in N"),
    Channel("st_valid", "BOOL", "", "star-tracker sample valid this cycle"),
    Channel("imu_valid", "BOOL", "", "IMU sample valid this cycle"),
    Channel("st_blind_source", "ENUM", "", "reason the star tracker is blind", enum=BLIND_SOURCES),
    Channel("exec_time_ms", "F32", "ms", "GNC cycle execution time",
            Limits(yellow=(None, 2.0), red=(None, 10.0))),
]


def _fdir_channels() -> list[Channel]:
    return [Channel(f"fdir_{m.lower()}", "ENUM", "", f"FDIR monitor {m} state", enum=FDIR_STATES)
            for m in FDIR_MONITORS]


_HK_CHANNELS: list[Channel] = [
    Channel("uptime_s", "F64", "s", "time since flight software start"),
    Channel("hk_mode", "ENUM", "", "flight mode", enum=MODES),
    Channel("cycles", "U32", "", "GNC cycles executed"),
    Channel("slips_gnc", "U32", "", "GNC rate-group cycle slips", Limits(yellow=(None, 0), red=(None, 10))),
    Channel("slips_hk", "U32", "", "housekeeping rate-group cycle slips", Limits(yellow=(None, 0))),
    Channel("exec_max_ms_gnc", "F32", "ms", "GNC execution time, max since reset",
            Limits(yellow=(None, 2.0), red=(None, 10.0))),
    Channel("exec_mean_ms_gnc", "F32", "ms", "GNC execution time, mean since reset"),
    Channel("exec_max_ms_hk", "F32", "ms", "housekeeping execution time, max since reset"),
    Channel("exec_mean_ms_hk", "F32", "ms", "housekeeping execution time, mean since reset"),
    Channel("jitter_max_ms", "F32", "ms", "real-time cycle start jitter, max since reset",
            Limits(yellow=(None, 1.0), red=(None, 10.0))),
    Channel("bus_rx_ok", "U32", "", "bus frames received and passed E2E checks"),
    Channel("bus_crc_errors", "U32", "", "bus frames with a bad CRC-8", Limits(yellow=(None, 0))),
    Channel("bus_alive_errors", "U32", "", "bus frames with an unexpected alive counter (lost)",
            Limits(yellow=(None, 0))),
    Channel("bus_repeated", "U32", "", "bus frames repeated (same alive counter)", Limits(yellow=(None, 0))),
    Channel("bus_decode_errors", "U32", "", "bus frames that failed to decode, and datagrams on the bus that are not frames (dropped)", Limits(yellow=(None, 0))),
    Channel("bus_corrupt_bursts", "U32", "", "housekeeping periods with 5 or more frames failing their CRC or "
            "decoding: bus faults (BUS_CORRUPT)", Limits(yellow=(None, 0))),
    Channel("bus_auth_failures", "U32", "", "bus_authentication: frames and authenticators the SecOC layer "
            "refused (forged, replayed, injected or not covered by a valid MAC)", Limits(yellow=(None, 0))),
    Channel("bus_timeouts", "U32", "", "ticks with missing sensor frames", Limits(yellow=(None, 0))),
    Channel("bus_tx_errors", "U32", "", "bus transmit failures", Limits(yellow=(None, 0))),
    Channel("bus_unknown_ids", "U32", "", "bus frames with an identifier not in the ICD (or error/extended/remote frames)",
            Limits(yellow=(None, 0))),
    Channel("bus_stale_syncs", "U32", "", "lockstep SYNC frames whose tick was not after the last one (replayed), ignored",
            Limits(yellow=(None, 0))),
    Channel("bus_unexpected_frames", "U32", "", "lockstep: E2E-good device frames outside every announced tick (replayed, injected or late), not used",
            Limits(yellow=(None, 0))),
    Channel("imu_stale_cycles", "U32", "", "consecutive cycles without a fresh IMU sample"),
    Channel("st_stale_cycles", "U32", "", "consecutive cycles without a fresh star-tracker sample"),
    Channel("tc_accepted", "U32", "", "telecommands accepted"),
    Channel("tc_rejected", "U32", "", "telecommands rejected at acceptance (all reasons)"),
    Channel("tc_completed", "U32", "", "accepted telecommands completed"),
    Channel("tc_failed", "U32", "", "accepted telecommands whose execution failed", Limits(yellow=(None, 0))),
    Channel("tc_invalid_opcode", "U32", "", "telecommands rejected: unknown or unhandled opcode"),
    Channel("tc_validation_errors", "U32", "", "telecommands rejected: argument out of range"),
    Channel("tc_format_errors", "U32", "", "telecommands rejected: malformed packet"),
    Channel("tc_execution_errors", "U32", "", "telecommands failed in execution: handler failed"),
    Channel("tc_last_opcode", "U16", "", "opcode of the last accepted telecommand"),
    # link security (comms.link_security) and uplink loss: never reset by RESET_COUNTERS
    Channel("tc_sec_unauthenticated", "U32", "", "uplink datagrams without a security header / with another SPI",
            Limits(yellow=(None, 0))),
    Channel("tc_sec_bad_mac", "U32", "", "uplink datagrams whose MAC did not verify (forged)",
            Limits(yellow=(None, 0))),
    Channel("tc_sec_replay", "U32", "", "uplink datagrams refused: security SN not above the last accepted",
            Limits(yellow=(None, 0))),
    Channel("tc_sec_outside_window", "U32", "", "uplink datagrams refused: security SN beyond the window",
            Limits(yellow=(None, 0))),
    Channel("tc_sec_resyncs", "U32", "", "SEC_RESYNC commands that moved the anti-replay window"),
    Channel("tc_sec_last_sn", "U32", "", "last accepted uplink security SN (the ground sends above it)"),
    Channel("tc_uplink_dropped", "U32", "", "uplink datagrams the kernel discarded, socket buffer full (SO_RXQ_OVFL)",
            Limits(yellow=(None, 0))),
    Channel("tc_uplink_junk", "U32", "", "uplink datagrams refused unanswered (not authenticated, or malformed "
            "without link security): counted per reason in tc_sec_* and tc_format_errors", Limits(yellow=(None, 0))),
    Channel("tc_uplink_deferred", "U32", "", "cycles whose uplink read stopped at its time budget, datagrams left queued",
            Limits(yellow=(None, 0))),
    Channel("tm_packets_sent", "U32", "", "telemetry packets sent"),
    Channel("tm_send_errors", "U32", "", "telemetry packets that failed to send", Limits(yellow=(None, 0))),
    Channel("events_sent", "U32", "", "events sent"),
    Channel("events_throttled", "U32", "", "events suppressed by throttling"),
    *_fdir_channels(),
    Channel("fdir_trips", "U32", "", "FDIR monitors tripped since reset"),
    *_indexed("wheel_fault", MAX_WHEELS, "U8", "", "wheel fault flags reported by the wheel"),
    *_indexed("wheel_temp_C", MAX_WHEELS, "F32", "degC", "wheel temperature",
              Limits(yellow=(-10.0, 50.0), red=(-20.0, 70.0))),
    *_indexed("wheel_current_A", MAX_WHEELS, "F32", "A", "wheel motor current"),
    Channel("wheels_isolated", "U8", "", "bit mask of wheels removed from allocation"),
    *_indexed("mtq_dipole_cmd_Am2", 3, "F32", "A*m^2", "magnetorquer rod dipole commanded (zero unless a law "
              "sets it)"),
    Channel("h_excess_Nms", "F32", "N*m*s", "momentum management: |wheel momentum - bias| (NaN when off)"),
    Channel("eclipse_state", "ENUM", "", "the Earth's shadow from the onboard ephemeris and orbit (UNKNOWN: no "
            "orbit known)", enum=ECLIPSE_STATES),
    Channel("sunlit_fraction", "F32", "", "share of the Sun's disc seen past the Earth from the onboard ephemeris "
            "and orbit: 1 full Sun, 0 umbra (NaN: no orbit known)"),
    Channel("rss_mb", "F32", "MB", "resident memory of the flight software process"),
]

_TC_ACK_CHANNELS: list[Channel] = [
    Channel("ack_report", "ENUM", "", "verification report (PUS subtypes 1, 2, 7, 8)",
            enum=tuple(name for name, _ in TC_ACK_REPORTS)),
    Channel("ack_request_id", "U32", "", "request id of the telecommand: its first four octets (version, type, "
                                          "secondary header flag, APID, sequence flags, sequence count)"),
    Channel("ack_tc_seq", "U16", "", "sequence count of the telecommand"),
    Channel("ack_opcode", "U16", "", "opcode of the telecommand (0 when it could not be read)"),
    Channel("ack_code", "ENUM", "", "reason code (NONE for success reports)", enum=TC_REASON_CODES),
]

PACKETS: tuple[PacketDef, ...] = (
    PacketDef("GNC", GNC_APID, "GNC rate", "GNC state: estimate, guidance, control, zones, wheels",
              tuple(_GNC_CHANNELS)),
    PacketDef("HK", HK_APID, "1 Hz", "housekeeping: counters, timing, bus E2E, TC, FDIR, wheel health",
              tuple(_HK_CHANNELS)),
    PacketDef("TC_ACK", TC_ACK_APID, "per telecommand",
              "telecommand verification report (PUS service 1): " + TC_VERIFICATION_DOC,
              tuple(_TC_ACK_CHANNELS)),
)

_OPCODE = Arg("opcode", "U16", description="telecommand opcode")
_REASON = Arg("reason", "STRING", description="human-readable detail")
_MODE_ARG = Arg("mode", "ENUM", enum=MODES)

EVENTS: tuple[EventDef, ...] = (
    EventDef("FSW_STARTED", 1, Severity.ACTIVITY_HI, "flight software started, GNC at {gnc_rate_hz} Hz",
             (Arg("gnc_rate_hz", "F32", "Hz"),)),
    EventDef("FSW_STOPPED", 2, Severity.ACTIVITY_HI, "flight software stopped after {cycles} cycles",
             (Arg("cycles", "U32"),)),
    EventDef("FATAL_ERROR", 3, Severity.FATAL, "fatal: {reason}", (_REASON,)),
    EventDef("RT_SCHEDULING", 4, Severity.ACTIVITY_LO, "real-time scheduling: {reason}", (_REASON,)),
    EventDef("CHECK_WORKER_LOST", 6, Severity.WARNING_LO,
             "assumption-check worker ended ({reason}): restart {restarts} of {max_restarts}",
             (_REASON, Arg("restarts", "U8"), Arg("max_restarts", "U8"))),
    EventDef("CHECK_WORKER_DROPPED", 7, Severity.WARNING_HI,
             "assumption-check worker lost {restarts} times: background check dropped, the per-cycle eps bound "
             "still guards the zones", (Arg("restarts", "U8"),)),
    EventDef("RT_SCHEDULING_UNAVAILABLE", 5, Severity.WARNING_LO,
             "real-time scheduling not granted, running best effort: {reason}", (_REASON,)),
    EventDef("MODE_CHANGED", 10, Severity.ACTIVITY_HI, "mode {from_mode} -> {to_mode} ({cause})",
             (Arg("from_mode", "ENUM", enum=MODES), Arg("to_mode", "ENUM", enum=MODES),
              Arg("cause", "ENUM", enum=MODE_REASONS))),
    EventDef("SAFE_PHASE_CHANGED", 11, Severity.ACTIVITY_LO, "SAFE phase -> {phase}",
             (Arg("phase", "ENUM", enum=SAFE_PHASES),)),
    EventDef("DETUMBLE_STARTED", 17, Severity.ACTIVITY_HI, "detumbling with B-dot from {rate_deg_s:.3f} deg/s",
             (Arg("rate_deg_s", "F32", "deg/s", "the gyro's |omega| (NaN: no sample yet)"),)),
    EventDef("DETUMBLE_COMPLETE", 18, Severity.ACTIVITY_HI,
             "detumbled at t = {t_s:.1f} s, {rate_deg_s:.3f} deg/s: SAFE",
             (Arg("t_s", "F64", "s", "onboard time"), Arg("rate_deg_s", "F32", "deg/s", "the gyro's |omega|"))),
    EventDef("TARGET_SET", 12, Severity.ACTIVITY_HI,
             "target {kind} [{c0:.6f}, {c1:.6f}, {c2:.6f}, {c3:.6f}]",
             (Arg("kind", "ENUM", enum=TARGET_KINDS), Arg("c0", "F64"), Arg("c1", "F64"),
              Arg("c2", "F64"), Arg("c3", "F64"))),
    EventDef("TARGET_REJECTED", 13, Severity.WARNING_HI,
             "target rejected: inside zone {zone} ({body}), margin {margin_deg:.3f} deg",
             (Arg("zone", "I8"), Arg("body", "ENUM", enum=ZONE_BODIES), Arg("margin_deg", "F32", "deg"))),
    EventDef("TARGET_REACHED", 14, Severity.ACTIVITY_HI, "target reached, error {error_deg:.4f} deg",
             (Arg("error_deg", "F32", "deg"),)),
    EventDef("GAINS_SET", 15, Severity.ACTIVITY_HI,
             "gains k1={k1} kappa={kappa} eps={eps} rate_limit={rate_limit_deg_s} deg/s",
             (Arg("k1", "F64"), Arg("kappa", "F64"), Arg("eps", "F64"), Arg("rate_limit_deg_s", "F64", "deg/s"))),
    EventDef("COUNTERS_RESET", 16, Severity.ACTIVITY_HI, "counters reset"),
    EventDef("ZONES_MERGED", 20, Severity.WARNING_LO,
             "zones {zone_a} and {zone_b} merged (separation {separation_deg:.2f} deg)",
             (Arg("zone_a", "I8"), Arg("zone_b", "I8"), Arg("separation_deg", "F32", "deg")),
             throttle=5, throttle_window_s=60.0),
    EventDef("ZONES_SPLIT", 21, Severity.ACTIVITY_LO, "zones {zone_a} and {zone_b} separated again",
             (Arg("zone_a", "I8"), Arg("zone_b", "I8")), throttle=5, throttle_window_s=60.0),
    EventDef("ZONE_ARMED", 106, Severity.ACTIVITY_LO,
             "zone {zone} ({body}) armed: the target is a fixed direction and the boresight is clear of it",
             (Arg("zone", "I8"), Arg("body", "ENUM", enum=ZONE_BODIES))),
    EventDef("ZONE_DISARMED", 107, Severity.ACTIVITY_LO,
             "zone {zone} ({body}) disarmed: it guards inertial targets only, and the target is on the Earth",
             (Arg("zone", "I8"), Arg("body", "ENUM", enum=ZONE_BODIES))),
    EventDef("ASSUMPTION_VIOLATED", 22, Severity.WARNING_HI, "law assumption violated: {reason}", (_REASON,),
             throttle=5, throttle_window_s=60.0),
    EventDef("EPS_ADJUSTED", 23, Severity.DIAGNOSTIC, "eps set to {eps:.5f} (max {eps_max:.5f})",
             (Arg("eps", "F32"), Arg("eps_max", "F32")), throttle=5, throttle_window_s=60.0),
    EventDef("KEEP_OUT_MARGIN_LOW", 24, Severity.WARNING_HI,
             "keep-out margin low: zone {zone} ({body}) {margin_deg:.3f} deg",
             (Arg("zone", "I8"), Arg("body", "ENUM", enum=ZONE_BODIES), Arg("margin_deg", "F32", "deg")),
             throttle=5, throttle_window_s=10.0),
    EventDef("KEEP_OUT_VIOLATION", 25, Severity.FATAL,
             "keep-out VIOLATED: zone {zone} ({body}) {margin_deg:.3f} deg",
             (Arg("zone", "I8"), Arg("body", "ENUM", enum=ZONE_BODIES), Arg("margin_deg", "F32", "deg")),
             throttle=5, throttle_window_s=10.0),
    EventDef("PATH_PLANNED", 26, Severity.ACTIVITY_LO,
             "slew path round the zones: {length_deg:.1f} deg, {detour_deg:.1f} deg longer than the great circle, {legs} legs",
             (Arg("length_deg", "F32", "deg"), Arg("detour_deg", "F32", "deg"), Arg("legs", "U8")),
             throttle=5, throttle_window_s=60.0),
    EventDef("GUIDANCE_STALLED", 27, Severity.WARNING_LO,
             "slew stalled {error_deg:.1f} deg from the target for {stalled_s:.0f} s: replanned (detour {detour})",
             (Arg("error_deg", "F32", "deg"), Arg("stalled_s", "F32", "s"), Arg("detour", "BOOL")),
             throttle=5, throttle_window_s=60.0),
    EventDef("FDIR_TRIPPED", 30, Severity.WARNING_HI, "FDIR {monitor} tripped (value {value:.4g}), action {action}",
             (Arg("monitor", "ENUM", enum=FDIR_MONITORS), Arg("action", "ENUM", enum=FDIR_ACTIONS),
              Arg("value", "F32")), throttle=10, throttle_window_s=10.0),
    EventDef("FDIR_CLEARED", 31, Severity.ACTIVITY_LO, "FDIR {monitor} cleared",
             (Arg("monitor", "ENUM", enum=FDIR_MONITORS),), throttle=10, throttle_window_s=10.0),
    EventDef("SENSOR_STALE", 32, Severity.WARNING_LO, "{sensor} stale for {cycles} cycles",
             (Arg("sensor", "ENUM", enum=SENSORS), Arg("cycles", "U32")), throttle=5, throttle_window_s=10.0),
    EventDef("SENSOR_CORRUPT", 33, Severity.WARNING_LO, "{sensor} frames corrupt ({count} so far)",
             (Arg("sensor", "ENUM", enum=SENSORS), Arg("count", "U32")), throttle=5, throttle_window_s=10.0),
    EventDef("ST_BLINDED", 34, Severity.ACTIVITY_LO, "star tracker blinded by {source}, coasting on gyro",
             (Arg("source", "ENUM", enum=BLIND_SOURCES),), throttle=5, throttle_window_s=10.0),
    EventDef("ST_RECOVERED", 35, Severity.ACTIVITY_LO, "star tracker valid again after {outage_s:.1f} s",
             (Arg("outage_s", "F32", "s"),), throttle=5, throttle_window_s=10.0),
    EventDef("INNOVATION_HIGH", 36, Severity.WARNING_HI,
             "star-tracker innovation {innovation_deg:.3f} deg above gate", (Arg("innovation_deg", "F32", "deg"),),
             throttle=5, throttle_window_s=10.0),
    EventDef("ESTIMATOR_RESET", 37, Severity.WARNING_LO, "estimator reset: {reason}", (_REASON,)),
    EventDef("BUS_CORRUPT", 38, Severity.WARNING_LO,
             "bus fault: {count} frames failed their CRC or did not decode in bursts ({bursts} bursts so far)",
             (Arg("count", "U32"), Arg("bursts", "U32"))),
    EventDef("WHEEL_FAULT", 40, Severity.WARNING_HI, "wheel {wheel} fault: {cause} (status flags 0x{fault:02x})",
             (Arg("wheel", "U8"), Arg("fault", "U8"), Arg("cause", "STRING", description="the fault in words")), throttle=5, throttle_window_s=10.0),
    EventDef("WHEEL_SPEED_LIMIT", 41, Severity.WARNING_LO, "wheel {wheel} speed {speed_rad_s:.1f} rad/s at limit",
             (Arg("wheel", "U8"), Arg("speed_rad_s", "F32", "rad/s")), throttle=5, throttle_window_s=10.0),
    EventDef("WHEEL_ISOLATED", 42, Severity.WARNING_HI, "wheel {wheel} removed from allocation",
             (Arg("wheel", "U8"),)),
    EventDef("WHEEL_RESTORED", 49, Severity.WARNING_HI, "wheel {wheel} back in allocation, open loop: {reason}",
             (Arg("wheel", "U8"), _REASON)),
    EventDef("SLEW_LIMITS_REDUCED", 44, Severity.WARNING_LO,
             "slew limits reduced to {rate_limit_deg_s:.3f} deg/s, {accel_deg_s2:.4f} deg/s^2 on {wheels} wheels",
             (Arg("rate_limit_deg_s", "F32", "deg/s"), Arg("accel_deg_s2", "F32", "deg/s^2"), Arg("wheels", "U8"))),
    EventDef("TORQUE_SATURATED", 43, Severity.DIAGNOSTIC, "wheel torque scaled by {scale:.3f}",
             (Arg("scale", "F32"),), throttle=1, throttle_window_s=10.0),
    EventDef("DOOR_CLOSING", 80, Severity.WARNING_HI,
             "aperture door commanded closed: {reason}, zone {zone} ({body}) margin {margin_deg:.2f} deg, "
             "predicted reach {reach_deg:.2f} deg",
             (Arg("reason", "ENUM", enum=DOOR_REASONS), Arg("zone", "I8"), Arg("body", "ENUM", enum=ZONE_BODIES),
              Arg("margin_deg", "F32", "deg"), Arg("reach_deg", "F32", "deg"))),
    EventDef("DOOR_OPENING", 81, Severity.ACTIVITY_HI,
             "aperture door commanded open: every margin >= {margin_deg:.2f} deg for {dwell_s:.1f} s",
             (Arg("margin_deg", "F32", "deg"), Arg("dwell_s", "F32", "s"))),
    EventDef("DOOR_STATE", 82, Severity.ACTIVITY_LO, "aperture door {state} ({position_pct:.1f} %)",
             (Arg("state", "ENUM", enum=DOOR_STATES), Arg("position_pct", "F32", "%"))),
    EventDef("DOOR_FAULT", 83, Severity.WARNING_HI, "aperture door fault: {fault} (door {position_pct:.1f} % open)",
             (Arg("fault", "ENUM", enum=DOOR_FAULTS), Arg("position_pct", "F32", "%")),
             throttle=5, throttle_window_s=10.0),
    EventDef("ECLIPSE_ENTRY", 100, Severity.ACTIVITY_LO,
             "entering the Earth's shadow (sunlit fraction {sunlit_fraction:.3f})",
             (Arg("sunlit_fraction", "F32"),)),
    EventDef("COARSE_ATTITUDE_ON", 102, Severity.WARNING_LO,
             "no star-tracker fix for {coasting_s:.1f} s: the attitude rests on the coarse sensors and the gyro",
             (Arg("coasting_s", "F32", "s", "time since the last fused star-tracker fix"),)),
    EventDef("COARSE_ATTITUDE_OFF", 103, Severity.ACTIVITY_HI,
             "the star tracker's fix is back: {fused:d} coarse directions fused, {rejected:d} gated out meanwhile",
             (Arg("fused", "U32"), Arg("rejected", "U32"))),
    EventDef("COARSE_ATTITUDE_FOUND", 104, Severity.ACTIVITY_HI,
             "attitude found without the star tracker: TRIAD of the Sun and the field, {sun_field_angle_deg:.1f} deg "
             "apart", (Arg("sun_field_angle_deg", "F32", "deg"),)),
    EventDef("FDIR_SAFE_DEFERRED", 105, Severity.WARNING_LO,
             "FDIR {monitor} asked for SAFE during DETUMBLE: deferred (DETUMBLE ends in SAFE)",
             (Arg("monitor", "ENUM", enum=FDIR_MONITORS),)),
    EventDef("ECLIPSE_EXIT", 101, Severity.ACTIVITY_LO,
             "in full Sun again after {duration_s:.0f} s in the Earth's shadow (least sunlit fraction "
             "{least_sunlit_fraction:.3f})",
             (Arg("duration_s", "F32", "s"), Arg("least_sunlit_fraction", "F32"))),
    EventDef("PLUGIN_STARTED", 90, Severity.ACTIVITY_HI, "{kind} plug-in {name} flying under keepout's guard",
             (Arg("kind", "ENUM", enum=PLUGIN_KINDS), Arg("name", "STRING", description="its entry-point name"))),
    EventDef("PLUGIN_STOPPED", 91, Severity.WARNING_HI, "{kind} plug-in {name} stopped: {reason}",
             (Arg("kind", "ENUM", enum=PLUGIN_KINDS), Arg("name", "STRING", description="its entry-point name"),
              _REASON)),
    EventDef("CYCLE_SLIP", 50, Severity.WARNING_LO,
             "{rate_group} cycle slip: started {late_ms:.2f} ms late, ran {exec_time_ms:.2f} ms ({count} total)",
             (Arg("rate_group", "ENUM", enum=RATE_GROUPS), Arg("exec_time_ms", "F32", "ms"), Arg("count", "U32"),
              Arg("late_ms", "F32", "ms")),
             throttle=3, throttle_window_s=10.0),
    EventDef("CMD_DISPATCHED", 60, Severity.COMMAND, "command {command} (opcode {opcode}) dispatched, seq {seq}",
             (_OPCODE, Arg("command", "STRING"), Arg("seq", "U16"))),
    EventDef("CMD_COMPLETED", 61, Severity.COMMAND, "command {command} (opcode {opcode}) completed",
             (_OPCODE, Arg("command", "STRING"))),
    EventDef("CMD_REJECTED", 62, Severity.WARNING_HI, "command opcode {opcode} rejected: {error}: {reason}",
             (_OPCODE, Arg("error", "ENUM", enum=TC_ERRORS), _REASON), throttle=20, throttle_window_s=10.0),
    EventDef("UPLINK_JUNK", 64, Severity.WARNING_LO,
             "uplink junk: {count} datagrams refused unanswered in {window_s:.0f} s ({reasons})",
             (Arg("count", "U32"), Arg("window_s", "F32", "s"), Arg("reasons", "STRING", description="count per reason code"))),
    EventDef("SEC_RESYNCED", 63, Severity.WARNING_LO, "uplink anti-replay window moved to security SN {sn}",
             (Arg("sn", "U32"),)),
    EventDef("EVENTS_THROTTLED", 70, Severity.DIAGNOSTIC, "{count} {event} events throttled",
             (Arg("event", "STRING"), Arg("count", "U32"))),
)

_UNIT_COMPONENT = dict(type="F64", min=-1.0, max=1.0)

COMMANDS: tuple[CommandDef, ...] = (
    CommandDef("NOOP", 0x01, "no operation: proves the uplink (accepted counter, COMMAND event)"),
    CommandDef("RESET_COUNTERS", 0x02, "reset telemetry counters (slips, exec max/mean, bus, TC, FDIR trips)"),
    CommandDef("SET_MODE", 0x03, "change flight mode", (_MODE_ARG,)),
    CommandDef(
        "SET_TARGET", 0x04,
        "set the target: DIRECTION (c0..c2 = unit vector in N, c3 unused), QUATERNION (c0..c3 = q_NB, "
        "scalar first), NADIR (c0..c3 unused) or GROUND (c0..c2 = the point's WGS-84 vertical, a unit vector "
        "in the Earth-fixed frame; c3 = its height above the ellipsoid / 10 km: "
        "comms.telecommand.ground_target_args); NADIR and GROUND are followed every GNC cycle. Rejected with "
        "TARGET_REJECTED if inside a keep-out zone.",
        (Arg("kind", "ENUM", enum=TARGET_KINDS),
         Arg("c0", description="component 0", **_UNIT_COMPONENT),
         Arg("c1", description="component 1", **_UNIT_COMPONENT),
         Arg("c2", description="component 2", **_UNIT_COMPONENT),
         Arg("c3", description="component 3 (QUATERNION only)", default=0.0, **_UNIT_COMPONENT)),
        failure_codes=("TARGET_NOT_UNIT", "TARGET_IN_KEEP_OUT"),
    ),
    CommandDef(
        "SET_GAINS", 0x05, "set law gains; eps = 0 selects the admissible eps automatically",
        (Arg("k1", "F64", "", "law gain k1", min=1e-6, max=100.0),
         Arg("kappa", "F64", "", "star-shaped law gain kappa", min=1e-6, max=100.0),
         Arg("eps", "F64", "", "eps-layer width in d_s units (0: auto)", min=0.0, max=1.0),
         Arg("rate_limit_deg_s", "F64", "deg/s", "body rate command limit", min=1e-3, max=20.0)),
        failure_codes=("GAINS_INADMISSIBLE", "BRAKING_DISTANCE", "RATE_ABOVE_SENSOR_LIMIT", "WHEEL_AUTHORITY"),
    ),
    CommandDef("SEC_RESYNC", 0x10, "move the uplink anti-replay window forward to this command's security "
               "SN (the only command accepted beyond the window; never backwards)"),
)

DICTIONARY = TelemetryDictionary(PACKETS, EVENTS, COMMANDS)


# ---------------------------------------------------------------------------------------------
# Argument encoding shared by events (TM) and telecommands (TC)
# ---------------------------------------------------------------------------------------------
class ArgError(ValueError):
    """An argument value has the wrong type or is out of range (message names the argument)."""


class ArgTruncatedError(ArgError):
    """The encoded arguments end before every declared argument was read."""


def coerce_arg(arg: Arg, value: Any, check_range: bool = True) -> Any:
    """Convert ``value`` to the Python value of ``arg`` (enum -> name str) or raise ArgError.

    ``check_range=False`` keeps the type conversion but skips the declared min/max (used by tests and
    the ground ``--no-check`` option to send deliberately out-of-range telecommands).
    """
    t = arg.type
    if t == "ENUM":
        assert arg.enum is not None
        if isinstance(value, enum.Enum):
            value = value.name
        if isinstance(value, str):
            if value.upper() not in arg.enum:
                raise ArgError(f"{arg.name}: {value!r} not one of {list(arg.enum)}")
            return value.upper()
        if not isinstance(value, bool):
            try:
                index = operator.index(value)  # accepts numpy integers too
            except TypeError:
                index = -1
            if 0 <= index < len(arg.enum):
                return arg.enum[index]
        raise ArgError(f"{arg.name}: {value!r} not one of {list(arg.enum)}")
    if t == "STRING":
        text = str(value)
        if len(text.encode("utf-8", "replace")) > MAX_STRING_LEN:
            text = text.encode("utf-8", "replace")[:MAX_STRING_LEN].decode("utf-8", "ignore")
        return text
    if t == "BOOL":
        if isinstance(value, str):
            low = value.strip().lower()
            if low in ("1", "true", "yes", "on"):
                return True
            if low in ("0", "false", "no", "off"):
                return False
            raise ArgError(f"{arg.name}: {value!r} is not a boolean")
        return bool(value)
    if t in ("F32", "F64"):
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ArgError(f"{arg.name}: {value!r} is not a number") from None
        if check_range:
            _check_range(arg, number)
        return number
    # integers
    try:
        if isinstance(value, float) and not value.is_integer():
            raise ValueError
        number = int(value)
    except (TypeError, ValueError, OverflowError):
        raise ArgError(f"{arg.name}: {value!r} is not an integer") from None
    low, high = _INT_RANGES[t]
    if not low <= number <= high:
        raise ArgError(f"{arg.name}: {number} outside {t} range [{low}, {high}]")
    if check_range:
        _check_range(arg, number)
    return number


def _check_range(arg: Arg, number: float) -> None:
    if math.isnan(number) or math.isinf(number):
        if arg.min is not None or arg.max is not None:
            raise ArgError(f"{arg.name}: {number} is not finite")
        return
    if arg.min is not None and number < arg.min:
        raise ArgError(f"{arg.name}: {number} below minimum {arg.min}")
    if arg.max is not None and number > arg.max:
        raise ArgError(f"{arg.name}: {number} above maximum {arg.max}")


def encode_args(args: Sequence[Arg], values: Mapping[str, Any], check_range: bool = True) -> bytes:
    """Encode ``values`` (by arg name, coerced and range-checked) in declaration order."""
    out = bytearray()
    for arg in args:
        if arg.name in values:
            value = coerce_arg(arg, values[arg.name], check_range)
        elif arg.default is not None:
            value = coerce_arg(arg, arg.default, check_range)
        else:
            raise ArgError(f"missing argument {arg.name!r}")
        out += encode_value(arg.type, value, arg.enum)
    unknown = set(values) - {a.name for a in args}
    if unknown:
        raise ArgError(f"unknown argument(s) {sorted(unknown)}; allowed {[a.name for a in args]}")
    return bytes(out)


def encode_value(type_name: str, value: Any, enum_names: tuple[str, ...] | None = None) -> bytes:
    if type_name == "STRING":
        raw = str(value).encode("utf-8")[:MAX_STRING_LEN]
        return bytes([len(raw)]) + raw
    if type_name == "ENUM":
        assert enum_names is not None
        return struct.pack("!B", enum_names.index(value))
    return struct.pack("!" + _STRUCT_CODES[type_name], value)


def decode_args(args: Sequence[Arg], data: bytes | memoryview, offset: int = 0) -> tuple[dict[str, Any], int]:
    """Decode args from ``data`` starting at ``offset``; returns (values, new offset).

    Raises ArgTruncatedError on truncation, ArgError on an enum index outside the declared names (no range checks: the
    caller validates with ``coerce_arg`` where it must).
    """
    values: dict[str, Any] = {}
    for arg in args:
        if arg.type == "STRING":
            if offset >= len(data):
                raise ArgTruncatedError(f"truncated before string argument {arg.name!r}")
            length = data[offset]
            end = offset + 1 + length
            if end > len(data):
                raise ArgTruncatedError(f"string argument {arg.name!r} truncated")
            values[arg.name] = bytes(data[offset + 1:end]).decode("utf-8", "replace")
            offset = end
            continue
        code = _STRUCT_CODES[arg.type]
        size = struct.calcsize("!" + code)
        if offset + size > len(data):
            raise ArgTruncatedError(f"truncated before argument {arg.name!r}")
        (raw,) = struct.unpack_from("!" + code, data, offset)
        offset += size
        if arg.type == "ENUM":
            assert arg.enum is not None
            if raw >= len(arg.enum):
                raise ArgError(f"{arg.name}: enum index {raw} not in 0..{len(arg.enum) - 1}")
            raw = arg.enum[raw]
        values[arg.name] = raw
    return values, offset


def packet_struct(packet: PacketDef) -> struct.Struct:
    """The struct of a TM packet's channel block (after the secondary header)."""
    return struct.Struct("!" + "".join(_STRUCT_CODES[c.type] for c in packet.channels))


def vector_groups(packet: PacketDef) -> dict[str, list[str]]:
    """Base name -> component channel names for vector/indexed channels (``q_est_NB`` -> 4 names)."""
    groups: dict[str, list[str]] = {}
    for channel in packet.channels:
        base, sep, suffix = channel.name.rpartition("_")
        if sep and (suffix in ("x", "y", "z") or suffix.isdigit()):
            groups.setdefault(base, []).append(channel.name)
    return {base: names for base, names in groups.items() if len(names) > 1}
