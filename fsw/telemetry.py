"""Telemetry: CCSDS space packets (built with ``spacepackets``) over UDP, from the dictionary.

``TelemetrySender`` keeps the latest value of every channel, packs a packet definition from the
dictionary when asked (``send_channels``), and sends events (``event``) with per-event throttling.
Each APID has its own 14-bit sequence count, so the ground sees any lost packet as a gap.

The codec (``encode_tm_packet``, ``encode_event_packet``, ``decode_tm_packet``) is shared with the
ground monitor; the wire format is described in ``fsw.dictionary``.
"""
from __future__ import annotations

import collections
import ipaddress
import math
import socket
import struct
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from fastcrc import crc16  # CRC-16/CCITT-FALSE; a dependency of spacepackets (same CRC as ECSS PUS)
from spacepackets.ccsds.spacepacket import (
    CCSDS_HEADER_LEN,
    MAX_SEQ_COUNT,
    PacketType,
    SpacePacket,
    SpacePacketHeader,
)

from fsw.dictionary import (
    CRC_LEN,
    DEFAULT_HOST,
    DEFAULT_TM_PORT,
    DICTIONARY,
    TM_SECONDARY_HEADER,
    ArgError,
    Channel,
    DictionaryError,
    EventDef,
    PacketDef,
    Severity,
    TelemetryDictionary,
    coerce_arg,
    decode_args,
    encode_value,
    packet_struct,
    vector_groups,
)
from fsw.link_security import SecurityAssociation

SEQ_MODULO = MAX_SEQ_COUNT + 1  # 16384


def crc16_ccitt(data: bytes | bytearray) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xorout); check('123456789') = 0x29B1."""
    return crc16.ibm_3740(bytes(data))


class TelemetryDecodeError(ValueError):
    """A received telemetry packet is malformed (message says why; ``kind`` classifies it for the ground's
    counters: one of ``DECODE_ERROR_KINDS``)."""

    def __init__(self, message: str, kind: str = "MALFORMED") -> None:
        super().__init__(message)
        self.kind = kind


# How the ground classifies packets it cannot decode (counted per kind, shown in the monitor).
DECODE_ERROR_KINDS = ("TRUNCATED", "MALFORMED", "CRC_MISMATCH", "UNKNOWN_APID", "UNKNOWN_EVENT")


# ------------------------------------------------------------------------------------- encoding
_HEADERS: dict[tuple[int, int], bytes] = {}


def _tm_header(apid: int, data_len: int) -> bytes:
    """The TM primary header for ``apid`` and ``data_len`` with sequence count 0, built by spacepackets once
    per (APID, length): a packet then only ORs its count into bytes 2-3 (spacepackets' header and packet
    objects cost ~6 us per packet; tests/fsw/test_telemetry.py checks the bytes against it)."""
    header = _HEADERS.get((apid, data_len))
    if header is None:
        header = _HEADERS[(apid, data_len)] = SpacePacketHeader(
            packet_type=PacketType.TM, apid=apid, seq_count=0, data_len=data_len, sec_header_flag=True).pack()
    return header


def _frame(apid: int, seq_count: int, time_s: float, payload: bytes) -> bytes:
    """A TM space packet: primary header, time secondary header, payload, CRC-16."""
    body = bytearray(_tm_header(apid, TM_SECONDARY_HEADER.size + len(payload) + CRC_LEN - 1))
    seq = seq_count % SEQ_MODULO
    body[2] |= seq >> 8
    body[3] |= seq & 0xFF
    body += TM_SECONDARY_HEADER.pack(time_s)
    body += payload
    return bytes(body) + struct.pack("!H", crc16_ccitt(body))


def encode_tm_packet(packet: PacketDef, seq_count: int, time_s: float, values: Sequence[Any]) -> bytes:
    """Encode one packet's channel values (already in wire types, declaration order)."""
    return _frame(packet.apid, seq_count, time_s, packet_struct(packet).pack(*values))


def encode_event_packet(dictionary: TelemetryDictionary, event: EventDef, seq_count: int, time_s: float,
                        args: Mapping[str, Any]) -> bytes:
    """Encode an event (args already coerced by ``coerce_arg``)."""
    payload = bytearray(struct.pack("!HB", event.id, event.severity.code))
    for arg in event.args:
        payload += encode_value(arg.type, args[arg.name], arg.enum)
    return _frame(dictionary.event_apid, seq_count, time_s, bytes(payload))


# ------------------------------------------------------------------------------------- decoding
@dataclass
class DecodedTm:
    """One decoded telemetry packet (a channel packet or an event)."""

    apid: int
    seq_count: int
    time_s: float
    kind: str  # "channels" or "event"
    packet: str  # packet name, or "EVENT"
    values: dict[str, Any] = field(default_factory=dict)  # channels (kind == "channels")
    event: str | None = None
    severity: str | None = None
    args: dict[str, Any] = field(default_factory=dict)
    message: str | None = None

    def to_json_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"apid": self.apid, "seq": self.seq_count, "time_s": _json_float(self.time_s),
                               "kind": self.kind, "packet": self.packet}
        if self.kind == "channels":
            # _json_float of every value without a call per value: the ground archives every packet (74
            # channels, one or two of them NaN in most packets)
            values = self.values
            out["values"] = plain = dict(values)
            for k, v in values.items():
                if isinstance(v, float) and (v != v or v in _INFINITIES):
                    plain[k] = str(v)
        else:
            out.update(event=self.event, severity=self.severity, message=self.message,
                       args={k: _json_float(v) for k, v in self.args.items()})
        return out


_INFINITIES = (math.inf, -math.inf)


def _json_float(value: Any) -> Any:
    """JSON has no NaN/inf: write them as strings so every line stays strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


_PRIMARY_HEADER = struct.Struct("!BBHH")  # CCSDS primary header: version/type/flag/APID, sequence, data length
_TM_TYPE = int(PacketType.TM)


class _ChannelLayout(NamedTuple):
    """What decoding a channel packet needs, worked out once per packet definition."""

    struct: struct.Struct
    names: tuple[str, ...]
    enums: tuple[tuple[int, tuple[str, ...]], ...]  # (position, enum names) of the ENUM channels


_LAYOUTS: dict[int, tuple[PacketDef, _ChannelLayout]] = {}


def _channel_layout(packet: PacketDef) -> _ChannelLayout:
    # The ground decodes ~10 packets per simulated second: building the 73-channel struct and scanning
    # the channel types for every packet was a third of a decode.
    entry = _LAYOUTS.get(id(packet))
    if entry is None or entry[0] is not packet:
        layout = _ChannelLayout(packet_struct(packet), tuple(c.name for c in packet.channels),
                                tuple((i, c.enum) for i, c in enumerate(packet.channels) if c.type == "ENUM"))
        entry = _LAYOUTS[id(packet)] = (packet, layout)
    return entry[1]


def primary_header_fields(raw: bytes) -> tuple[int, int, int, int, int]:
    """(CCSDS version, packet type, APID, sequence count, packet length) of the primary header at the
    start of ``raw`` (at least 6 bytes): what ``SpacePacketHeader.unpack`` reads, with one struct call
    (that object costs ~9 us to build; tests/fsw/test_telemetry.py compares the two)."""
    first, apid_low, psc, data_len = _PRIMARY_HEADER.unpack_from(raw)
    return (first >> 5) & 0b111, (first >> 4) & 1, ((first & 0b111) << 8) | apid_low, psc & 0x3FFF, \
        data_len + CCSDS_HEADER_LEN + 1


def decode_tm_packet(dictionary: TelemetryDictionary, raw: bytes | bytearray | memoryview) -> DecodedTm:
    """Decode a TM space packet with the dictionary; raises TelemetryDecodeError naming the fault."""
    raw = bytes(raw)
    min_len = CCSDS_HEADER_LEN + TM_SECONDARY_HEADER.size + CRC_LEN
    if len(raw) < min_len:
        raise TelemetryDecodeError(f"packet of {len(raw)} bytes shorter than the minimum {min_len}", "TRUNCATED")
    version, packet_type, apid, seq_count, packet_len = primary_header_fields(raw)
    if packet_type != _TM_TYPE:
        raise TelemetryDecodeError("packet type is TC, expected TM")
    if version != 0:
        raise TelemetryDecodeError(f"CCSDS version {version}, expected 0")
    if packet_len != len(raw):
        raise TelemetryDecodeError(f"length field says {packet_len} bytes, datagram has {len(raw)}",
                                   "TRUNCATED" if packet_len > len(raw) else "MALFORMED")
    if crc16_ccitt(raw) != 0:  # CRC over data + its own CRC is zero for this CRC
        raise TelemetryDecodeError("CRC mismatch", "CRC_MISMATCH")
    (time_s,) = TM_SECONDARY_HEADER.unpack_from(raw, CCSDS_HEADER_LEN)
    payload = raw[CCSDS_HEADER_LEN + TM_SECONDARY_HEADER.size:-CRC_LEN]
    if apid == dictionary.event_apid:
        return _decode_event(dictionary, apid, seq_count, time_s, payload)
    packet = dictionary.packet_by_apid(apid)
    if packet is None:
        raise TelemetryDecodeError(f"unknown APID {apid:#x}", "UNKNOWN_APID")
    layout = _channel_layout(packet)
    if len(payload) != layout.struct.size:
        raise TelemetryDecodeError(f"{packet.name}: payload {len(payload)} bytes, dictionary says {layout.struct.size}")
    values = dict(zip(layout.names, layout.struct.unpack(payload)))
    for i, names in layout.enums:
        name = layout.names[i]
        raw_value = values[name]
        values[name] = names[raw_value] if raw_value < len(names) else f"INVALID({raw_value})"
    return DecodedTm(apid, seq_count, time_s, "channels", packet.name, values=values)


def _decode_event(dictionary: TelemetryDictionary, apid: int, seq_count: int, time_s: float,
                  payload: bytes) -> DecodedTm:
    if len(payload) < 3:
        raise TelemetryDecodeError("event payload shorter than id + severity", "TRUNCATED")
    event_id, severity_code = struct.unpack_from("!HB", payload, 0)
    event = dictionary.event_by_id(event_id)
    if event is None:
        raise TelemetryDecodeError(f"unknown event id {event_id}", "UNKNOWN_EVENT")
    try:
        severity = Severity.from_code(severity_code)
        args, end = decode_args(event.args, payload, 3)
    except ArgError as exc:
        raise TelemetryDecodeError(f"event {event.name}: {exc}") from None
    except ValueError as exc:
        raise TelemetryDecodeError(f"event {event.name}: {exc}") from None
    if end != len(payload):
        raise TelemetryDecodeError(f"event {event.name}: {len(payload) - end} unexpected trailing bytes")
    return DecodedTm(apid, seq_count, time_s, "event", "EVENT", event=event.name,
                     severity=severity.value, args=args, message=format_event_message(event, args))


def format_event_message(event: EventDef, args: Mapping[str, Any]) -> str:
    try:
        return event.format.format(**args)
    except (KeyError, ValueError, IndexError, TypeError):  # a bad format must not lose the event
        return f"{event.name} " + " ".join(f"{k}={v}" for k, v in args.items())


# ------------------------------------------------------------------------------------- sender
def _wire_value(channel: Channel, value: Any) -> Any:
    """Convert a channel value to its wire type; integers saturate (telemetry never raises on range)."""
    t = channel.type
    if t in ("F32", "F64"):
        return float(value)
    if t == "BOOL":
        return bool(value)
    if t == "ENUM":
        assert channel.enum is not None
        if isinstance(value, str):
            try:
                return channel.enum.index(value.upper())
            except ValueError:
                raise DictionaryError(f"channel {channel.name}: {value!r} not one of {list(channel.enum)}") from None
        if hasattr(value, "name") and isinstance(getattr(value, "name"), str) and value.name in channel.enum:
            return channel.enum.index(value.name)  # an enum.Enum member with a matching name
        low, high = 0, len(channel.enum) - 1
    else:
        low, high = _INT_LIMITS[t]
    return _saturate(value, low, high)


_F32_MAX = 3.4028234663852886e38


def _f32(value: float) -> float:
    """``value`` as float32 can hold it: beyond the largest float32, +-inf (what IEEE conversion gives),
    instead of struct's OverflowError."""
    return math.copysign(math.inf, value) if math.isfinite(value) and abs(value) > _F32_MAX else value


def _saturate(value: Any, low: int, high: int) -> int:
    number = float(value)
    if math.isnan(number):
        return 0
    return int(min(max(number, low), high))


def _convert(channel: Channel, value: Any) -> Any:
    """Wire value of ``value`` for ``channel``; None is "no value"; a non-number names the channel."""
    if value is None:
        return _default_value(channel)
    try:
        return _wire_value(channel, value)
    except (TypeError, ValueError) as exc:
        raise DictionaryError(f"channel {channel.name} ({channel.type}): cannot use {value!r}: {exc}") from None


_INT_LIMITS = {"U8": (0, 255), "I8": (-128, 127), "U16": (0, 65535), "I16": (-32768, 32767),
               "U32": (0, 2**32 - 1), "I32": (-(2**31), 2**31 - 1)}


def _default_value(channel: Channel) -> Any:
    if channel.no_value is not None:
        return channel.no_value
    if channel.type in ("F32", "F64"):
        return math.nan  # "no value yet" is visible on the ground, never a plausible 0
    if channel.type == "BOOL":
        return False
    return 0


def _saturating(low: int, high: int) -> Callable[[Any], int]:
    return lambda value: _saturate(value, low, high)


def _update_plans(packet: PacketDef, index: dict[str, int],
                  groups: dict[str, list[str]]) -> dict[str, tuple[int, int, Callable[[Any], Any] | None]]:
    """Name -> (first slot, end slot, conversion) for the float, bool and integer channels (the conversion
    ``_wire_value`` makes for that type) and, with conversion None, for the vectors of float channels in
    consecutive slots: ``TelemetrySender.update`` stores those without a call chain per channel."""
    convert: dict[str, Callable[[Any], Any]] = {}
    for c in packet.channels:
        if c.type in ("F32", "F64"):
            convert[c.name] = float
        elif c.type == "BOOL":
            convert[c.name] = bool
        elif c.type in _INT_LIMITS:
            convert[c.name] = _saturating(*_INT_LIMITS[c.type])
    plans: dict[str, tuple[int, int, Callable[[Any], Any] | None]] = {
        name: (slot, slot + 1, convert[name]) for name, slot in index.items() if name in convert}
    for base, members in groups.items():
        slots = [index[m] for m in members]
        if base not in index and all(convert.get(m) is float for m in members) \
                and slots == list(range(slots[0], slots[0] + len(slots))):
            plans[base] = (slots[0], slots[0] + len(slots), None)
    return plans


@dataclass
class RecordedEvent:
    time_s: float
    name: str
    severity: Severity
    args: dict[str, Any]
    message: str


class TelemetrySender:
    """Sends telemetry packets and events as CCSDS space packets over UDP.

    ``host``/``port`` is the ground destination; ``port=None`` records without sending (unit tests,
    replay). The socket binds to ``bind_host`` (loopback when the destination is on loopback, so a
    default flight build never listens on an external interface). A multicast ``host`` (224.0.0.0/4) is
    sent on the interface of ``multicast_interface`` with TTL ``multicast_ttl`` and loopback on, so every
    ground client that joined the group there receives each packet. ``clock`` gives the onboard time in
    seconds stamped into packets when the caller passes no ``time_s`` (lockstep flight code passes
    the simulated time). ``security``: the downlink association (``fsw.link_security``) that signs
    every packet before it is sent (None: plain packets).
    """

    def __init__(self, dictionary: TelemetryDictionary = DICTIONARY, host: str = DEFAULT_HOST,
                 port: int | None = DEFAULT_TM_PORT, *, bind_host: str | None = None,
                 clock: Callable[[], float] = time.monotonic, event_history: int = 512,
                 multicast_interface: str = DEFAULT_HOST, multicast_ttl: int = 0,
                 security: SecurityAssociation | None = None) -> None:
        self.dictionary = dictionary
        self.security = security
        self.destination = (host, port) if port is not None else None
        self.clock = clock
        self._latest: dict[str, list[Any]] = {
            p.name: [_default_value(c) for c in p.channels] for p in dictionary.packets
        }
        self._index: dict[str, dict[str, int]] = {
            p.name: {c.name: i for i, c in enumerate(p.channels)} for p in dictionary.packets
        }
        self._groups = {p.name: vector_groups(p) for p in dictionary.packets}
        self._plans = {p.name: _update_plans(p, self._index[p.name], self._groups[p.name]) for p in dictionary.packets}
        self._structs = {p.name: packet_struct(p) for p in dictionary.packets}
        self._seq: dict[int, int] = collections.defaultdict(int)
        self._throttle_times: dict[str, collections.deque[float]] = {}
        self._throttled_since: dict[str, int] = collections.defaultdict(int)
        self.recent_events: collections.deque[RecordedEvent] = collections.deque(maxlen=event_history)
        self.counters: dict[str, int] = {
            "packets_sent": 0, "bytes_sent": 0, "send_errors": 0, "events_sent": 0, "events_throttled": 0,
        }
        self.events_by_severity: dict[str, int] = {s.value: 0 for s in Severity}
        self._sock: socket.socket | None = None
        if self.destination is not None:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if _is_multicast(host):
                # Fan-out to any number of ground clients: they join the group on ``multicast_interface``.
                # Loop on, so clients on this host receive it; TTL 0 keeps it on this host by default.
                self._sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                      socket.inet_aton(multicast_interface))
                self._sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, multicast_ttl)
                self._sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
                if bind_host is None:
                    bind_host = multicast_interface
            if bind_host is None:
                bind_host = DEFAULT_HOST if _is_loopback(host) else "0.0.0.0"
            self._sock.bind((bind_host, 0))
            self._sock.setblocking(False)

    # ---- channels ----
    def update(self, packet_name: str, values: Mapping[str, Any]) -> None:
        """Store channel values without sending. Vector base names take a sequence (``q_est_NB``);
        ``None`` means "no value" (NaN for floats, 0/False otherwise)."""
        latest = self._packet_values(packet_name)
        plans = self._plans[packet_name]
        for name, value in values.items():
            plan = plans.get(name)
            if plan is not None and value is not None:
                # Fast path for float, bool and integer channels and for float vectors (most of the GNC
                # packet): the conversion _wire_value makes for that type, without the per-channel calls;
                # anything it refuses takes the general path below, which names the channel.
                start, stop, convert = plan
                try:
                    if convert is not None:
                        latest[start] = convert(value)
                        continue
                    tolist = getattr(value, "tolist", None)  # numpy: one call instead of a scalar per element
                    components = [float(c) for c in (tolist() if tolist is not None else value)]
                    if len(components) == stop - start:
                        latest[start:stop] = components
                        continue
                except (TypeError, ValueError):
                    pass
            self._update_one(packet_name, latest, name, value)

    def _update_one(self, packet_name: str, latest: list[Any], name: str, value: Any) -> None:
        index = self._index[packet_name]
        channels = self.dictionary.packet(packet_name).channels
        slot = index.get(name)
        if slot is not None:
            latest[slot] = _convert(channels[slot], value)
            return
        members = self._groups[packet_name].get(name)
        if members is None:
            raise DictionaryError(f"packet {packet_name} has no channel or vector {name!r}")
        if value is None:  # "no value" (e.g. no target attitude outside QUATERNION mode)
            for member in members:
                latest[index[member]] = _default_value(channels[index[member]])
            return
        components = list(value)
        if len(components) > len(members):
            raise DictionaryError(f"{packet_name}.{name}: {len(components)} values for {len(members)} channels")
        for member, component in zip(members, components):
            slot = index[member]
            latest[slot] = _convert(channels[slot], component)

    def send_channels(self, packet_name: str, values: Mapping[str, Any] | None = None,
                      time_s: float | None = None) -> bytes:
        """Update ``values`` and send the whole packet; channels not given keep their last value.

        Unknown names raise ``DictionaryError`` (a programming error); numeric values never raise:
        integers saturate at their type's range, F32 values beyond float32 become +-inf. Returns the
        packet bytes.
        """
        if values:
            self.update(packet_name, values)
        packet = self.dictionary.packet(packet_name)
        latest = self._latest[packet_name]
        try:
            payload = self._structs[packet_name].pack(*latest)
        except OverflowError:  # an F32 channel beyond float32 (found by bench/fuzz.py): saturate, then pack
            for i, channel in enumerate(packet.channels):
                if channel.type == "F32":
                    latest[i] = _f32(latest[i])
            payload = self._structs[packet_name].pack(*latest)
        raw = _frame(packet.apid, self._next_seq(packet.apid), self._time(time_s), payload)
        return self._transmit(raw)

    def latest(self, packet_name: str) -> dict[str, Any]:
        """The values the next packet would carry (wire types: enums as indices)."""
        packet = self.dictionary.packet(packet_name)
        return {c.name: v for c, v in zip(packet.channels, self._latest[packet_name])}

    # ---- events ----
    def event(self, name: str, /, time_s: float | None = None, **args: Any) -> bool:
        """Send event ``name`` with typed ``args``; returns False if throttled.

        An unknown event name or a missing/mistyped arg raises (programming errors caught by tests).
        """
        event = self.dictionary.event(name)
        coerced = self._coerce_event_args(event, args)
        now = self._time(time_s)
        if not self._throttle_allows(event, now):
            self.counters["events_throttled"] += 1
            self._throttled_since[event.name] += 1
            return False
        suppressed = self._throttled_since.pop(event.name, 0)
        if suppressed:
            summary = self.dictionary.event("EVENTS_THROTTLED")
            self._emit(summary, {"event": event.name, "count": suppressed}, now)
        self._emit(event, coerced, now)
        return True

    def _coerce_event_args(self, event: EventDef, args: Mapping[str, Any]) -> dict[str, Any]:
        unknown = set(args) - {a.name for a in event.args}
        if unknown:
            raise DictionaryError(f"event {event.name}: unknown args {sorted(unknown)}; "
                                  f"declared {[a.name for a in event.args]}")
        coerced = {}
        for arg in event.args:
            if arg.name not in args:
                raise DictionaryError(f"event {event.name}: missing arg {arg.name!r}")
            value = coerce_arg(arg, args[arg.name], check_range=False)
            if arg.type == "F32":
                value = _f32(value)
            if arg.type in _INT_LIMITS:
                low, high = _INT_LIMITS[arg.type]
                value = min(max(value, low), high)
            coerced[arg.name] = value
        return coerced

    def _throttle_allows(self, event: EventDef, now: float) -> bool:
        if event.throttle is None:
            return True
        times = self._throttle_times.setdefault(event.name, collections.deque())
        while times and now - times[0] >= event.throttle_window_s:
            times.popleft()
        if len(times) >= event.throttle:
            return False
        times.append(now)
        return True

    def _emit(self, event: EventDef, args: dict[str, Any], now: float) -> None:
        raw = encode_event_packet(self.dictionary, event, self._next_seq(self.dictionary.event_apid), now, args)
        self.recent_events.append(RecordedEvent(now, event.name, event.severity, args,
                                                format_event_message(event, args)))
        self.counters["events_sent"] += 1
        self.events_by_severity[event.severity.value] += 1
        self._transmit(raw)

    # ---- plumbing ----
    def _packet_values(self, packet_name: str) -> list[Any]:
        try:
            return self._latest[packet_name]
        except KeyError:
            self.dictionary.packet(packet_name)  # raises with the known names
            raise

    def _time(self, time_s: float | None) -> float:
        return float(self.clock() if time_s is None else time_s)

    def _next_seq(self, apid: int) -> int:
        seq = self._seq[apid]
        self._seq[apid] = (seq + 1) % SEQ_MODULO
        return seq

    def sequence_count(self, apid: int) -> int:
        """The sequence count the next packet on ``apid`` will carry."""
        return self._seq[apid]

    def _transmit(self, raw: bytes) -> bytes:
        """Sign (with a security association) and send one packet; returns the bytes sent."""
        if self.security is not None:
            raw = self.security.protect(raw)
        if self._sock is None or self.destination is None:
            self.counters["packets_sent"] += 1
            self.counters["bytes_sent"] += len(raw)
            return raw
        try:
            self._sock.sendto(raw, self.destination)
        except OSError:
            # A full socket buffer or an unreachable ground must not stop the flight software; the
            # ground sees the gap in the sequence count, and the count shows in housekeeping.
            self.counters["send_errors"] += 1
            return raw
        self.counters["packets_sent"] += 1
        self.counters["bytes_sent"] += len(raw)
        return raw

    def reset_counters(self) -> None:
        for key in self.counters:
            self.counters[key] = 0

    @property
    def local_address(self) -> tuple[str, int] | None:
        return self._sock.getsockname() if self._sock is not None else None

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> "TelemetrySender":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _is_loopback(host: str) -> bool:
    return host.startswith("127.") or host in ("localhost", "::1")


def _is_multicast(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_multicast
    except ValueError:  # a host name: never a group
        return False
