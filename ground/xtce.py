"""XTCE 1.2 export of the keepout dictionary, so a Yamcs (or any XTCE) ground system decodes keepout's packets.

``keepout ground xtce [--out FILE]`` writes one ``SpaceSystem`` generated from the flight dictionary (the
same source the flight software and ``ground`` decode with, so the two cannot drift):

- telemetry: one parameter type per channel (its unit, its encoding, its yellow/red limits as the
  WarningRange/CriticalRange of a static alarm); an abstract ``CCSDS_Packet`` container for the primary
  header, an abstract ``keepout_TM`` one for the time secondary header, one container per telemetry packet
  restricted to its APID, and an abstract ``EVENT`` container (event id, severity) with one container per
  event restricted to its id. Every packet ends with the ``packet_crc`` parameter (CRC-16/CCITT-FALSE over
  everything before it; Yamcs checks it with the packet preprocessor's ``CRC-16-CCIIT`` error detection).
- telecommands: an abstract ``keepout_TC`` meta-command whose container holds the primary header as fixed
  values (the sequence count and packet length are filled by the ground system's CCSDS post-processor,
  as Yamcs' ``CcsdsPacketPostprocessor`` does) and the opcode; one meta-command per telecommand, assigning
  its opcode, with its arguments (types, units, ranges, defaults), then a 16-bit CRC placeholder.

Strings (event arguments) are a length octet then UTF-8 bytes: an ``<name>_len`` parameter followed by the
string, whose size is that length times 8 bits (a DynamicValue with a LinearAdjustment).
"""
from __future__ import annotations

import datetime as dt
import xml.etree.ElementTree as ET
from pathlib import Path

from comms.dictionary import (
    DICTIONARY,
    MAX_STRING_LEN,
    TC_ACK_REPORTS,
    TC_VERIFICATION_DOC,
    Arg,
    Limits,
    Severity,
    TelemetryDictionary,
)

XTCE_NS = "http://www.omg.org/spec/XTCE/20180204"
SPACE_SYSTEM = "keepout"
ROOT_CONTAINER = "CCSDS_Packet"
TM_CONTAINER = "keepout_TM"
EVENT_CONTAINER = "EVENT"
TC_META_COMMAND = "keepout_TC"
CRC_PARAMETER = "packet_crc"

# (name, size in bits) of the CCSDS 133.0-B-2 primary header, in order.
PRIMARY_HEADER = (("ccsds_version", 3), ("ccsds_type", 1), ("ccsds_sec_hdr_flag", 1), ("ccsds_apid", 11),
                  ("ccsds_seq_flags", 2), ("ccsds_seq_count", 14), ("ccsds_packet_length", 16))
_INT_BITS = {"U8": (8, False), "I8": (8, True), "U16": (16, False), "I16": (16, True), "U32": (32, False),
             "I32": (32, True)}
_FLOAT_BITS = {"F32": 32, "F64": 64}


def _el(parent: ET.Element, tag: str, text: str | None = None, **attrs: object) -> ET.Element:
    element = ET.SubElement(parent, tag, {k.rstrip("_"): str(v) for k, v in attrs.items() if v is not None})
    if text is not None:
        element.text = text
    return element


def _describe(element: ET.Element, text: str) -> None:
    """A one-line text as ``shortDescription``, a longer one as the ``LongDescription`` element (first child)."""
    if len(text) <= 120:
        if text:
            element.set("shortDescription", text)
        return
    long = ET.Element("LongDescription")
    long.text = text
    element.insert(0, long)


def _number(value: float) -> str:
    return repr(float(value))


# ------------------------------------------------------------------------------------------ data types
def _data_type(parent: ET.Element, kind: str, name: str, type_name: str, unit: str = "",
               enum_names: tuple[str, ...] | None = None, limits: Limits | None = None,
               valid: tuple[float | None, float | None] = (None, None), description: str = "") -> None:
    """One parameter type (``kind`` = "Parameter") or argument type (``kind`` = "Argument")."""
    if type_name == "ENUM":
        element = _el(parent, f"Enumerated{kind}Type", name=name)
    elif type_name == "BOOL":
        element = _el(parent, f"Boolean{kind}Type", name=name)
    elif type_name == "STRING":
        element = _el(parent, f"String{kind}Type", name=name)
    elif type_name in _FLOAT_BITS:
        element = _el(parent, f"Float{kind}Type", name=name, sizeInBits=_FLOAT_BITS[type_name])
    else:
        bits, signed = _INT_BITS[type_name]
        element = _el(parent, f"Integer{kind}Type", name=name, signed=str(signed).lower(), sizeInBits=bits)
    _describe(element, description)
    units = _el(element, "UnitSet")
    if unit:
        _el(units, "Unit", unit)
    if type_name in ("ENUM", "BOOL"):
        _el(element, "IntegerDataEncoding", sizeInBits=8, encoding="unsigned")
    elif type_name == "STRING":
        encoding = _el(element, "StringDataEncoding", encoding="UTF-8")
        variable = _el(encoding, "Variable", maxSizeInBits=8 * MAX_STRING_LEN)
        dynamic = _el(variable, "DynamicValue")
        _el(dynamic, f"{'Argument' if kind == 'Argument' else 'Parameter'}InstanceRef",
            **{"argumentRef" if kind == "Argument" else "parameterRef": f"{name.removesuffix('_Type')}_len"})
        _el(dynamic, "LinearAdjustment", slope=8)
    elif type_name in _FLOAT_BITS:
        _el(element, "FloatDataEncoding", sizeInBits=_FLOAT_BITS[type_name], encoding="IEEE754_1985")
    else:
        bits, signed = _INT_BITS[type_name]
        _el(element, "IntegerDataEncoding", sizeInBits=bits, encoding="twosComplement" if signed else "unsigned")
    if type_name == "ENUM":
        assert enum_names is not None
        listing = _el(element, "EnumerationList")
        for index, label in enumerate(enum_names):
            _el(listing, "Enumeration", value=index, label=label)
    if limits is not None and type_name not in ("ENUM", "BOOL", "STRING") and kind == "Parameter":
        _alarm(element, limits)
    if kind == "Argument" and (valid[0] is not None or valid[1] is not None) and type_name not in ("ENUM", "BOOL"):
        ranges = _el(element, "ValidRangeSet")
        _el(ranges, "ValidRange", minInclusive=None if valid[0] is None else _number(valid[0]),
            maxInclusive=None if valid[1] is None else _number(valid[1]))


def _alarm(element: ET.Element, limits: Limits) -> None:
    """Dictionary limits as a static alarm: outside yellow is a warning, outside red is critical."""
    alarm = _el(element, "DefaultAlarm")
    ranges = _el(alarm, "StaticAlarmRanges")
    for tag, (low, high) in (("WarningRange", limits.yellow), ("CriticalRange", limits.red)):
        if low is None and high is None:
            continue
        _el(ranges, tag, minInclusive=None if low is None else _number(low),
            maxInclusive=None if high is None else _number(high))


# ------------------------------------------------------------------------------------------ telemetry
def _telemetry(space: ET.Element, dictionary: TelemetryDictionary) -> None:
    meta = _el(space, "TelemetryMetaData")
    types = _el(meta, "ParameterTypeSet")
    parameters = _el(meta, "ParameterSet")
    containers = _el(meta, "ContainerSet")

    def parameter(name: str, type_name: str, unit: str = "", description: str = "",
                  enum_names: tuple[str, ...] | None = None, limits: Limits | None = None) -> None:
        if type_name == "STRING":  # its length octet first
            parameter(f"{name}_len", "U8", description=f"length of {name} in bytes")
        _data_type(types, "Parameter", f"{name}_Type", type_name, unit, enum_names, limits)
        _describe(_el(parameters, "Parameter", name=name, parameterTypeRef=f"{name}_Type"), description)

    def header_field(name: str, bits: int) -> None:
        element = _el(types, "IntegerParameterType", name=f"{name}_Type", signed="false", sizeInBits=bits)
        _el(element, "UnitSet")
        _el(element, "IntegerDataEncoding", sizeInBits=bits, encoding="unsigned")
        _el(parameters, "Parameter", name=name, parameterTypeRef=f"{name}_Type")

    for name, bits in PRIMARY_HEADER:
        header_field(name, bits)
    parameter("time_s", "F64", "s", "onboard time (TM secondary header)")
    parameter(CRC_PARAMETER, "U16", description="CRC-16/CCITT-FALSE over the packet before it")

    def container(name: str, entries: list[str], base: str | None = None, restriction: tuple[str, int] | None = None,
                  abstract: bool = False, description: str = "") -> None:
        element = _el(containers, "SequenceContainer", name=name, abstract="true" if abstract else None)
        _describe(element, description)
        entry_list = _el(element, "EntryList")
        for entry in entries:
            _el(entry_list, "ParameterRefEntry", parameterRef=entry)
        if base is not None:
            base_element = _el(element, "BaseContainer", containerRef=base)
            if restriction is not None:
                criteria = _el(base_element, "RestrictionCriteria")
                _el(criteria, "Comparison", parameterRef=restriction[0], value=restriction[1])

    container(ROOT_CONTAINER, [n for n, _ in PRIMARY_HEADER], abstract=True,
              description="CCSDS 133.0-B-2 space packet primary header")
    container(TM_CONTAINER, ["time_s"], ROOT_CONTAINER, ("ccsds_type", 0), abstract=True,
              description="keepout telemetry: time secondary header")
    for packet in dictionary.packets:
        for channel in packet.channels:
            parameter(channel.name, channel.type, channel.unit, channel.description, channel.enum, channel.limits)
        description = packet.description if packet.name != "TC_ACK" else TC_VERIFICATION_DOC
        container(packet.name, [c.name for c in packet.channels] + [CRC_PARAMETER], TM_CONTAINER,
                  ("ccsds_apid", packet.apid), description=f"{description} ({packet.rate})")

    parameter("event_id", "U16", description="event id")
    parameter("event_severity", "ENUM", description="event severity", enum_names=tuple(s.value for s in Severity))
    container(EVENT_CONTAINER, ["event_id", "event_severity"], TM_CONTAINER, ("ccsds_apid", dictionary.event_apid),
              abstract=True, description="events: id, severity, then the event's arguments")
    for event in dictionary.events:
        entries = []
        for arg in event.args:
            name = f"{event.name}_{arg.name}"
            parameter(name, arg.type, arg.unit, arg.description, arg.enum)
            entries += [f"{name}_len", name] if arg.type == "STRING" else [name]
        container(f"EVENT_{event.name}", entries + [CRC_PARAMETER], EVENT_CONTAINER, ("event_id", event.id),
                  description=f"{event.severity.value}: {event.format}")


# ------------------------------------------------------------------------------------------ telecommands
def _commands(space: ET.Element, dictionary: TelemetryDictionary) -> None:
    meta = _el(space, "CommandMetaData")
    types = _el(meta, "ArgumentTypeSet")
    commands = _el(meta, "MetaCommandSet")
    _data_type(types, "Argument", "opcode_Type", "U16", description="telecommand opcode")

    base = _el(commands, "MetaCommand", name=TC_META_COMMAND, abstract="true")
    _describe(base, "keepout telecommand: CCSDS TC packet, no secondary header, opcode, arguments, CRC-16")
    _el(_el(base, "ArgumentList"), "Argument", name="opcode", argumentTypeRef="opcode_Type")
    container = _el(base, "CommandContainer", name=f"{TC_META_COMMAND}_Container")
    entries = _el(container, "EntryList")
    fixed = {"ccsds_version": 0, "ccsds_type": 1, "ccsds_sec_hdr_flag": 0, "ccsds_apid": dictionary.tc_apid,
             "ccsds_seq_flags": 3, "ccsds_seq_count": 0, "ccsds_packet_length": 0}
    for name, bits in PRIMARY_HEADER:
        _el(entries, "FixedValueEntry", name=name, binaryValue=f"{fixed[name]:0{(bits + 7) // 8 * 2}x}",
            sizeInBits=bits)
    _el(entries, "ArgumentRefEntry", argumentRef="opcode")

    for command in dictionary.commands:
        element = _el(commands, "MetaCommand", name=command.name)
        ack = command.acknowledgement
        _describe(element, f"{command.description}. Acknowledged by TC_ACK packets: ACCEPTANCE_FAILURE codes "
                           f"{', '.join(ack['acceptance_failure_codes'])}; COMPLETION_FAILURE codes "
                           f"{', '.join(ack['completion_failure_codes'])}.")
        assignment = _el(_el(_el(element, "BaseMetaCommand", metaCommandRef=TC_META_COMMAND),
                             "ArgumentAssignmentList"), "ArgumentAssignment")
        assignment.set("argumentName", "opcode")
        assignment.set("argumentValue", str(command.opcode))
        if command.args:
            arguments = _el(element, "ArgumentList")
            for arg in command.args:
                type_name = f"{command.name}_{arg.name}_Type"
                _data_type(types, "Argument", type_name, arg.type, arg.unit, arg.enum, valid=(arg.min, arg.max),
                           description=arg.description)
                _describe(_el(arguments, "Argument", name=arg.name, argumentTypeRef=type_name,
                              initialValue=_initial(arg)), arg.description)
        container = _el(element, "CommandContainer", name=f"{command.name}_Container")
        entries = _el(container, "EntryList")
        for arg in command.args:
            _el(entries, "ArgumentRefEntry", argumentRef=arg.name)
        _el(entries, "FixedValueEntry", name="crc_placeholder", binaryValue="0000", sizeInBits=16)
        _el(container, "BaseContainer", containerRef=f"{TC_META_COMMAND}_Container")


def _initial(arg: Arg) -> str | None:
    if arg.default is None:
        return None
    return _number(arg.default) if arg.type in _FLOAT_BITS else str(arg.default)


# ------------------------------------------------------------------------------------------ document
def to_xtce(dictionary: TelemetryDictionary = DICTIONARY) -> str:
    """The XTCE 1.2 document (a string) describing every packet and telecommand of ``dictionary``."""
    space = ET.Element("SpaceSystem", {"xmlns": XTCE_NS, "name": SPACE_SYSTEM})
    space.set("shortDescription", "keepout attitude GNC: telemetry, events, TC verification and telecommands")
    header = _el(space, "Header", version=dictionary.version, validationStatus="Working",
                 date=dt.date.today().isoformat())
    notes = _el(header, "NoteSet")
    _el(notes, "Note", "Generated from the keepout telemetry dictionary (comms/dictionary.py) by `keepout ground "
                       "xtce`. Byte order big-endian. Every packet ends with a CRC-16/CCITT-FALSE (poly 0x1021, "
                       "init 0xFFFF) over everything before it. Telecommand verification reports: "
                       + ", ".join(f"{name} (PUS subtype {subtype})" for name, subtype in TC_ACK_REPORTS) + ".")
    _telemetry(space, dictionary)
    _commands(space, dictionary)
    ET.indent(space)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(space, encoding="unicode") + "\n"


def write_xtce(path: str | Path, dictionary: TelemetryDictionary = DICTIONARY) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(to_xtce(dictionary), encoding="utf-8")
    return path

