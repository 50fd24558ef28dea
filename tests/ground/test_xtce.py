"""XTCE export: valid against the XTCE 1.2 schema, and enough on its own to decode keepout's packets.

The decoder here knows nothing of keepout: it walks the XTCE containers (entries, base containers and
their restriction criteria) and parameter types (encodings, enumerations, dynamic string sizes) as a
generic XTCE ground system would, and its values are compared with the project's own decoder on packets
recorded from a real UDP socket.
"""
from __future__ import annotations

import math
import random
import socket
import struct
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import xmlschema

from comms.dictionary import DICTIONARY
from fsw.telecommand import CommandDispatcher
from comms.telecommand import encode_command
from fsw.telemetry import TelemetrySender
from comms.telemetry import decode_tm_packet
from cli.ground import main
from ground.xtce import to_xtce

XSD = Path(__file__).resolve().parents[1] / "data" / "xtce" / "SpaceSystemV1.2.xsd"
NS = "{http://www.omg.org/spec/XTCE/20180204}"


@pytest.fixture(scope="module")
def xtce_text(tmp_path_factory: pytest.TempPathFactory) -> str:
    """What `keepout ground xtce --out FILE` writes."""
    out = tmp_path_factory.mktemp("xtce") / "keepout.xtce.xml"
    assert main(["ground", "xtce", "--out", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    assert text == to_xtce()
    return text


def test_export_validates_against_the_xtce_1_2_schema(xtce_text: str) -> None:
    schema = xmlschema.XMLSchema(str(XSD))
    errors = list(schema.iter_errors(xtce_text))
    assert errors == [], errors[:3]
    # and the schema is not a rubber stamp: a misplaced element is refused
    broken = xtce_text.replace("<UnitSet />", "<Unitset />", 1)
    assert list(schema.iter_errors(broken))


class XtceDecoder:
    """A generic XTCE telemetry decoder (big-endian, bit-packed), independent of keepout's code."""

    def __init__(self, text: str) -> None:
        root = ET.fromstring(text)
        tm = root.find(f"{NS}TelemetryMetaData")
        self.types = {t.get("name"): t for t in tm.find(f"{NS}ParameterTypeSet")}
        self.parameters = {p.get("name"): p.get("parameterTypeRef") for p in tm.find(f"{NS}ParameterSet")}
        self.containers = {c.get("name"): c for c in tm.find(f"{NS}ContainerSet")}
        self.children: dict[str, list[tuple[str, list[tuple[str, str]]]]] = {}
        self.root = None
        for name, container in self.containers.items():
            base = container.find(f"{NS}BaseContainer")
            if base is None:
                self.root = name
                continue
            criteria = [(c.get("parameterRef"), c.get("value")) for c in base.iter(f"{NS}Comparison")]
            self.children.setdefault(base.get("containerRef"), []).append((name, criteria))

    def decode(self, raw: bytes) -> tuple[str, dict[str, Any], int]:
        """(most derived container, parameter values, bits consumed)."""
        values: dict[str, Any] = {}
        raws: dict[str, int] = {}
        position = 0
        name = self.root
        while True:
            for entry in self.containers[name].find(f"{NS}EntryList"):
                ref = entry.get("parameterRef")
                values[ref], raws[ref], position = self._read(ref, raw, position, raws)
            matches = [child for child, criteria in self.children.get(name, [])
                       if all(raws.get(p) == int(v) for p, v in criteria)]
            if not matches:
                return name, values, position
            assert len(matches) == 1, matches
            name = matches[0]

    def _read(self, parameter: str, raw: bytes, position: int, raws: dict[str, int]) -> tuple[Any, int, int]:
        ptype = self.types[self.parameters[parameter]]
        kind = ptype.tag.removeprefix(NS)
        if kind == "StringParameterType":
            dynamic = ptype.find(f"{NS}StringDataEncoding/{NS}Variable/{NS}DynamicValue")
            length_ref = dynamic.find(f"{NS}ParameterInstanceRef").get("parameterRef")
            slope = float(dynamic.find(f"{NS}LinearAdjustment").get("slope", "1"))
            size = int(raws[length_ref] * slope)
            assert position % 8 == 0 and size % 8 == 0
            text = raw[position // 8:(position + size) // 8].decode("utf-8")
            return text, 0, position + size
        if kind == "FloatParameterType":
            bits = int(ptype.find(f"{NS}FloatDataEncoding").get("sizeInBits"))
            assert position % 8 == 0
            value = struct.unpack(">f" if bits == 32 else ">d", raw[position // 8:(position + bits) // 8])[0]
            return value, 0, position + bits
        encoding = ptype.find(f"{NS}IntegerDataEncoding")
        bits = int(encoding.get("sizeInBits"))
        total = len(raw) * 8
        number = (int.from_bytes(raw, "big") >> (total - position - bits)) & ((1 << bits) - 1)
        if encoding.get("encoding") == "twosComplement" and number >= 1 << (bits - 1):
            number -= 1 << bits
        if kind == "EnumeratedParameterType":
            labels = {int(e.get("value")): e.get("label") for e in ptype.iter(f"{NS}Enumeration")}
            return labels[number], number, position + bits
        if kind == "BooleanParameterType":
            return bool(number), number, position + bits
        return number, number, position + bits


def _random_value(channel, rng: random.Random) -> Any:
    if channel.type == "ENUM":
        return rng.choice(channel.enum)
    if channel.type == "BOOL":
        return rng.random() < 0.5
    if channel.type.startswith("F"):
        return rng.uniform(-1000.0, 1000.0)
    low, high = {"U8": (0, 255), "I8": (-128, 127), "U16": (0, 65535), "I16": (-32768, 32767),
                 "U32": (0, 2**32 - 1), "I32": (-(2**31), 2**31 - 1)}[channel.type]
    return rng.randint(low, high)


@pytest.fixture(scope="module")
def recorded() -> list[bytes]:
    """Telemetry of every kind (GNC, HK, events with strings, TC acknowledgements) from the flight
    software's sender and dispatcher, recorded from a real UDP socket."""
    rng = random.Random(15)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as ground:
        ground.bind(("127.0.0.1", 0))
        ground.settimeout(2.0)
        telemetry = TelemetrySender(DICTIONARY, "127.0.0.1", ground.getsockname()[1], clock=lambda: 1234.5)
        for packet_name in ("GNC", "HK"):
            telemetry.send_channels(packet_name, {c.name: _random_value(c, rng)
                                                  for c in DICTIONARY.packet(packet_name).channels})
        telemetry.event("KEEP_OUT_MARGIN_LOW", zone=2, body="MOON", margin_deg=1.25)
        dispatcher = CommandDispatcher(DICTIONARY, telemetry, port=None)
        dispatcher.register("SET_MODE", lambda mode: None)
        dispatcher.handle_datagram(encode_command(DICTIONARY, "SET_MODE", ["POINTING"], seq_count=41))
        dispatcher.handle_datagram(encode_command(DICTIONARY, "SET_GAINS", [0.0, 1.0, 0.1, 1.0], seq_count=42,
                                                  check_range=False))
        sent = telemetry.counters["packets_sent"]
        packets = [ground.recv(65536) for _ in range(sent)]
        telemetry.close()
    return packets


def test_a_recorded_packet_decodes_by_its_xtce_description_alone(xtce_text: str, recorded: list[bytes]) -> None:
    decoder = XtceDecoder(xtce_text)
    seen = set()
    for raw in recorded:
        reference = decode_tm_packet(DICTIONARY, raw)  # the project's decoder
        container, values, bits = decoder.decode(raw)
        assert bits == len(raw) * 8, f"{container}: XTCE describes {bits} bits of a {len(raw) * 8}-bit packet"
        assert values["ccsds_apid"] == reference.apid and values["ccsds_seq_count"] == reference.seq_count
        assert values["time_s"] == reference.time_s == 1234.5
        assert values["packet_crc"] == struct.unpack(">H", raw[-2:])[0]
        if reference.kind == "event":
            assert container == f"EVENT_{reference.event}"
            assert values["event_severity"] == reference.severity
            expected = {f"{reference.event}_{k}": v for k, v in reference.args.items()}
        else:
            assert container == reference.packet
            expected = reference.values
        for name, value in expected.items():
            if isinstance(value, float) and math.isnan(value):
                assert math.isnan(values[name]), name
            else:
                assert values[name] == value, name
        seen.add(container)
    assert {"GNC", "HK", "TC_ACK", "EVENT_KEEP_OUT_MARGIN_LOW", "EVENT_CMD_DISPATCHED",
            "EVENT_CMD_REJECTED"} <= seen


def test_telecommands_encode_from_their_xtce_description(xtce_text: str) -> None:
    """Build SET_TARGET's bytes from the meta-command alone (fixed header fields, opcode assignment, typed
    arguments), fill in what a ground system's CCSDS post-processor fills (sequence count, length, CRC),
    and compare with the project's encoder."""
    from comms.telemetry import crc16_ccitt

    root = ET.fromstring(xtce_text)
    cmd_meta = root.find(f"{NS}CommandMetaData")
    arg_types = {t.get("name"): t for t in cmd_meta.find(f"{NS}ArgumentTypeSet")}
    commands = {c.get("name"): c for c in cmd_meta.find(f"{NS}MetaCommandSet")}
    given = {"kind": "QUATERNION", "c0": 0.5, "c1": -0.5, "c2": 0.5, "c3": 0.5}

    def encode(command: ET.Element, assigned: dict[str, str]) -> list[tuple[int, int]]:
        fields: list[tuple[int, int]] = []
        base = command.find(f"{NS}BaseMetaCommand")
        if base is not None:
            for a in base.iter(f"{NS}ArgumentAssignment"):
                assigned[a.get("argumentName")] = a.get("argumentValue")
            fields += encode(commands[base.get("metaCommandRef")], assigned)
        arg_type_of = {a.get("name"): a.get("argumentTypeRef") for a in command.iter(f"{NS}Argument")}
        for entry in command.find(f"{NS}CommandContainer/{NS}EntryList"):
            if entry.tag == f"{NS}FixedValueEntry":
                fields.append((int(entry.get("binaryValue"), 16), int(entry.get("sizeInBits"))))
                continue
            name = entry.get("argumentRef")
            atype = arg_types[arg_type_of[name]]
            value = assigned.get(name, given.get(name))
            if atype.tag == f"{NS}FloatArgumentType":
                bits = int(atype.find(f"{NS}FloatDataEncoding").get("sizeInBits"))
                fields.append((int.from_bytes(struct.pack(">d" if bits == 64 else ">f", float(value)), "big"), bits))
            elif atype.tag == f"{NS}EnumeratedArgumentType":
                index = next(int(e.get("value")) for e in atype.iter(f"{NS}Enumeration") if e.get("label") == value)
                fields.append((index, int(atype.find(f"{NS}IntegerDataEncoding").get("sizeInBits"))))
            else:
                fields.append((int(value), int(atype.find(f"{NS}IntegerDataEncoding").get("sizeInBits"))))
        return fields

    number, total = 0, 0
    for value, bits in encode(commands["SET_TARGET"], {}):
        number, total = (number << bits) | value, total + bits
    packet = bytearray(number.to_bytes(total // 8, "big"))
    packet[2:4] = (int.from_bytes(packet[2:4], "big") | 7).to_bytes(2, "big")  # sequence count 7
    packet[4:6] = (len(packet) - 7).to_bytes(2, "big")
    packet[-2:] = crc16_ccitt(bytes(packet[:-2])).to_bytes(2, "big")
    assert bytes(packet) == encode_command(DICTIONARY, "SET_TARGET", given, seq_count=7)
