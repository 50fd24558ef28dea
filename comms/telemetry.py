"""The telemetry packet codec: CCSDS space packets (built with ``spacepackets``) from the dictionary.

``encode_tm_packet`` / ``encode_event_packet`` build a packet (primary header, onboard-time secondary
header, the packet's channels or the event's arguments, CRC-16); ``decode_tm_packet`` reads one back
and says what is wrong with a bad one (``TelemetryDecodeError``). The flight software's sender
(``fsw.telemetry.TelemetrySender``), the ground monitor and the web ground all use it; the wire format
is described in ``comms.dictionary``.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from fastcrc import crc16  # CRC-16/CCITT-FALSE; a dependency of spacepackets (same CRC as ECSS PUS)
from spacepackets.ccsds.spacepacket import (
    CCSDS_HEADER_LEN,
    MAX_SEQ_COUNT,
    PacketType,
    SpacePacketHeader,
)

from comms.dictionary import (
    CRC_LEN,
    TM_SECONDARY_HEADER,
    ArgError,
    EventDef,
    PacketDef,
    Severity,
    TelemetryDictionary,
    decode_args,
    encode_value,
    packet_struct,
)

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


def frame_tm_packet(apid: int, seq_count: int, time_s: float, payload: bytes) -> bytes:
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
    return frame_tm_packet(packet.apid, seq_count, time_s, packet_struct(packet).pack(*values))


def encode_event_packet(dictionary: TelemetryDictionary, event: EventDef, seq_count: int, time_s: float,
                        args: Mapping[str, Any]) -> bytes:
    """Encode an event (args already coerced by ``coerce_arg``)."""
    payload = bytearray(struct.pack("!HB", event.id, event.severity.code))
    for arg in event.args:
        payload += encode_value(arg.type, args[arg.name], arg.enum)
    return frame_tm_packet(dictionary.event_apid, seq_count, time_s, bytes(payload))


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
