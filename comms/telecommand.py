"""The telecommand codec: CCSDS TC space packets from and to the dictionary's commands.

``encode_command`` builds a packet (primary header, opcode, arguments checked against their types and
ranges, CRC-16); ``decode_command`` reads one back and raises one of the typed errors whose class the
flight software counts: ``InvalidOpcodeError`` (INVALID_OPCODE), ``CommandValidationError``
(VALIDATION), ``CommandFormatError`` (FORMAT), ``CommandExecutionError`` (EXECUTION),
``CommandSecurityError`` (SECURITY), each with a reason code of ``comms.dictionary.TC_REASON_CODES``.
The ground encodes with it and the flight software's dispatcher (``fsw.telecommand``) decodes with it.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from spacepackets.ccsds.spacepacket import (
    CCSDS_HEADER_LEN,
    MAX_SEQ_COUNT,
    PacketType,
    SequenceFlags,
    SpacePacket,
    SpacePacketHeader,
)

from comms.dictionary import (
    CRC_LEN,
    MAX_TC_PACKET_LEN,
    ArgError,
    ArgTruncatedError,
    CommandDef,
    TC_REASON_CLASS,
    TelemetryDictionary,
    coerce_arg,
    decode_args,
    encode_args,
)
from comms.telemetry import crc16_ccitt


OPCODE = struct.Struct("!H")
MIN_TC_PACKET_LEN = CCSDS_HEADER_LEN + OPCODE.size + CRC_LEN

INVALID_OPCODE = "INVALID_OPCODE"
VALIDATION = "VALIDATION"
FORMAT = "FORMAT"
EXECUTION = "EXECUTION"
SECURITY = "SECURITY"



class CommandError(Exception):
    """Base of the typed telecommand errors.

    ``code`` is the reason code reported in the acknowledgement (a name of ``TC_REASON_CODES``); ``kind``,
    the error class counted in housekeeping, follows from it (INVALID_OPCODE, VALIDATION, FORMAT, EXECUTION).
    """

    default_code = "EXECUTION_FAILED"

    def __init__(self, message: str, code: str | None = None) -> None:
        super().__init__(message)
        self.code = code or self.default_code
        if self.code not in TC_REASON_CLASS or not TC_REASON_CLASS[self.code]:
            raise ValueError(f"{self.code!r} is not a failure code of TC_REASON_CODES")

    @property
    def kind(self) -> str:
        return TC_REASON_CLASS[self.code]


class InvalidOpcodeError(CommandError):
    default_code = "UNKNOWN_OPCODE"


class CommandValidationError(CommandError):
    """Arguments are well formed but not acceptable (out of range, target inside a zone, ...).

    Raised by a handler, it rejects the command at acceptance: the handler must raise it before it changes
    anything on board."""

    default_code = "ARG_OUT_OF_RANGE"


class CommandFormatError(CommandError):
    """The packet is malformed: length, header, APID, CRC or argument encoding."""

    default_code = "BAD_HEADER"


class CommandExecutionError(CommandError):
    """The handler failed while executing an accepted command (a completion failure)."""

    default_code = "EXECUTION_FAILED"


class CommandSecurityError(CommandError):
    """The link refused the datagram: unauthenticated, bad MAC, replayed or outside the SN window
    (codes of the SECURITY class; a link-level CRC failure is CRC_MISMATCH, class FORMAT).
    ``acknowledge``: whether the refusal is reported in a TC_ACK (only for authenticated packets)."""

    default_code = "BAD_MAC"

    def __init__(self, message: str, code: str | None = None, acknowledge: bool = True) -> None:
        super().__init__(message, code)
        self.acknowledge = acknowledge


@dataclass(frozen=True)
class CommandResult:
    """The outcome of one datagram, as reported in its acknowledgements.

    ``accepted``: passed every check (acceptance success); ``completed``: also executed (completion success).
    ``error`` is the error class and ``code`` the reason code of a failure (None / "NONE" on success).
    """

    accepted: bool
    error: str | None  # None when completed, else INVALID_OPCODE / VALIDATION / FORMAT / EXECUTION
    opcode: int | None
    name: str | None
    seq_count: int | None
    reason: str
    args: Mapping[str, Any] | None = None
    code: str = "NONE"
    request_id: int = 0

    @property
    def completed(self) -> bool:
        return self.accepted and self.error is None


# --------------------------------------------------------------------------------------- codec
def encode_command(dictionary: TelemetryDictionary, command: str | int,
                   args: Mapping[str, Any] | Sequence[Any] = (), seq_count: int = 0,
                   check_range: bool = True) -> bytes:
    """Build a TC space packet; ``args`` by name or positionally (trailing args with defaults may be left out).

    Raises ``ArgError`` (names the argument) for a value the dictionary does not allow, unless
    ``check_range=False`` (only the type must fit: lets tests send out-of-range commands).
    """
    definition = dictionary.command(command)
    if not isinstance(args, Mapping):
        args = list(args)
        if len(args) > len(definition.args):
            raise ArgError(f"{definition.name} takes {len(definition.args)} args "
                           f"({[a.name for a in definition.args]}), got {len(args)}")
        args = {a.name: v for a, v in zip(definition.args, args)}
    payload = OPCODE.pack(definition.opcode) + encode_args(definition.args, args, check_range)
    return encode_tc_packet(dictionary.tc_apid, seq_count, payload)


def encode_tc_packet(apid: int, seq_count: int, payload: bytes) -> bytes:
    """A TC space packet around ``payload`` (opcode + args) with a trailing CRC-16/CCITT-FALSE."""
    header = SpacePacketHeader(packet_type=PacketType.TC, apid=apid, seq_count=seq_count % (MAX_SEQ_COUNT + 1),
                               data_len=len(payload) + CRC_LEN - 1)
    body = SpacePacket(header, sec_header=None, user_data=payload).pack()
    return bytes(body) + struct.pack("!H", crc16_ccitt(body))


def decode_command(dictionary: TelemetryDictionary, data: bytes) -> tuple[CommandDef, dict[str, Any], int]:
    """Check and decode a TC packet: returns (command, validated args, seq count).

    Raises ``CommandFormatError``, ``InvalidOpcodeError`` or ``CommandValidationError``.
    """
    if len(data) < MIN_TC_PACKET_LEN:
        raise CommandFormatError(f"packet of {len(data)} bytes shorter than the minimum {MIN_TC_PACKET_LEN}",
                                 "PACKET_TOO_SHORT")
    if len(data) > MAX_TC_PACKET_LEN:
        raise CommandFormatError(f"packet of {len(data)} bytes longer than the maximum {MAX_TC_PACKET_LEN}",
                                 "PACKET_TOO_LONG")
    header = SpacePacketHeader.unpack(data)
    if header.ccsds_version != 0:
        raise CommandFormatError(f"CCSDS version {header.ccsds_version}, expected 0")
    if header.packet_type != PacketType.TC:
        raise CommandFormatError("packet type is TM, expected TC")
    if header.seq_flags != SequenceFlags.UNSEGMENTED:
        raise CommandFormatError(f"sequence flags {int(header.seq_flags):#04b}; keepout TCs are unsegmented")
    if header.sec_header_flag:
        raise CommandFormatError("secondary header flag set; keepout TCs carry none")
    if header.apid != dictionary.tc_apid:
        raise CommandFormatError(f"APID {header.apid:#x} is not the telecommand APID {dictionary.tc_apid:#x}",
                                 "WRONG_APID")
    if header.packet_len != len(data):
        raise CommandFormatError(f"length field says {header.packet_len} bytes, datagram has {len(data)}",
                                 "LENGTH_MISMATCH")
    if crc16_ccitt(data) != 0:
        raise CommandFormatError("CRC mismatch", "CRC_MISMATCH")
    payload = data[CCSDS_HEADER_LEN:-CRC_LEN]
    (opcode,) = OPCODE.unpack_from(payload, 0)
    definition = dictionary.command_by_opcode(opcode)
    if definition is None:
        raise InvalidOpcodeError(f"opcode {opcode:#06x} not in the dictionary")
    try:
        raw_args, end = decode_args(definition.args, payload, OPCODE.size)
    except ArgTruncatedError as exc:
        raise CommandFormatError(f"{definition.name}: {exc}", "ARGS_TRUNCATED") from None
    except ArgError as exc:  # an enum index outside the declared names
        raise CommandValidationError(f"{definition.name}: {exc}", "BAD_ENUM") from None
    if end != len(payload):
        raise CommandFormatError(f"{definition.name}: {len(payload) - end} bytes after the last argument",
                                 "TRAILING_BYTES")
    try:
        args = {arg.name: coerce_arg(arg, raw_args[arg.name]) for arg in definition.args}
    except ArgError as exc:
        raise CommandValidationError(f"{definition.name}: {exc}", "ARG_OUT_OF_RANGE") from None
    return definition, args, header.seq_count


# ------------------------------------------------------------------ SET_TARGET on the Earth
GROUND_HEIGHT_UNIT_M = 10000.0
"""SET_TARGET GROUND carries the height above the WGS-84 ellipsoid in c3 in units of 10 km, so that every
component stays within the command's +-1 range (-500 m .. 9 km: -0.05 .. 0.9)."""


def ground_target_args(latitude_deg: float, longitude_deg: float, altitude_m: float = 0.0) -> dict[str, Any]:
    """SET_TARGET's arguments for a WGS-84 ground point: kind GROUND, c0..c2 its geodetic vertical (the
    unit normal to the ellipsoid) in the Earth-fixed frame, c3 its height / GROUND_HEIGHT_UNIT_M."""
    lat, lon = math.radians(latitude_deg), math.radians(longitude_deg)
    return {"kind": "GROUND", "c0": math.cos(lat) * math.cos(lon), "c1": math.cos(lat) * math.sin(lon),
            "c2": math.sin(lat), "c3": altitude_m / GROUND_HEIGHT_UNIT_M}


def ground_target_of(c0: float, c1: float, c2: float, c3: float) -> tuple[float, float, float]:
    """(latitude [deg], longitude [deg], height [m]) of SET_TARGET GROUND's arguments (`ground_target_args`);
    raises ``CommandValidationError`` (TARGET_NOT_UNIT) when c0..c2 is not a unit vector."""
    n = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    if not math.isfinite(n) or abs(n - 1.0) > 1e-3:
        raise CommandValidationError(f"SET_TARGET: GROUND vertical must be a unit vector (norm {n:.6f})",
                                     "TARGET_NOT_UNIT")
    lat = math.degrees(math.asin(max(-1.0, min(1.0, c2 / n))))
    return lat, math.degrees(math.atan2(c1, c0)), c3 * GROUND_HEIGHT_UNIT_M
