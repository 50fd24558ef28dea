"""Bad telemetry reaching the ground: malformed, truncated, unknown-APID and unknown-event packets are
counted by kind, archived and shown, never a crash; good packets after them still decode."""
from __future__ import annotations

import json
import random
import socket
import struct
import time
from pathlib import Path

from rich.console import Console

from comms.dictionary import DICTIONARY, Channel, EventDef, PacketDef, Severity
from fsw.telemetry import TelemetrySender
from comms.telemetry import crc16_ccitt, encode_event_packet, encode_tm_packet
from ground.display import render_tables
from ground.monitor import GroundMonitor


def _recrc(body: bytes) -> bytes:
    """``body`` (a packet without its CRC) with a correct CRC-16 appended."""
    return body + struct.pack("!H", crc16_ccitt(body))


def _bad_packets() -> dict[str, list[bytes]]:
    """Undecodable datagrams by the kind the ground must report, built by hand."""
    good = TelemetrySender(DICTIONARY, port=None, clock=lambda: 1.0).send_channels("HK", {"cycles": 3})
    stranger = PacketDef("STRANGER", 0x7FF, "1 Hz", "not in the dictionary", (Channel("x", "U8", "", "x"),))
    unknown_event = EventDef("GHOST", 999, Severity.DIAGNOSTIC, "boo")
    corrupt = bytearray(good)
    corrupt[20] ^= 0x01
    as_tc = bytearray(good[:-2])
    as_tc[0] |= 0x10  # packet type bit: a TC
    short = bytearray(good[:-6])  # four bytes of payload fewer, the length field and CRC made consistent
    short[4:6] = struct.pack("!H", len(short) + 2 - 7)
    return {
        "TRUNCATED": [b"", b"\x08", good[:9], good[:-3], _recrc(good[:-6])],
        "CRC_MISMATCH": [bytes(corrupt)],
        "UNKNOWN_APID": [encode_tm_packet(stranger, 0, 1.0, [7])],
        "UNKNOWN_EVENT": [encode_event_packet(DICTIONARY, unknown_event, 0, 1.0, {})],
        "MALFORMED": [good + b"\x00", _recrc(bytes(as_tc)), _recrc(bytes(short))],
    }


def test_bad_packets_are_counted_by_kind_archived_and_shown(tmp_path: Path) -> None:
    bad = _bad_packets()
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0, tmp_path)
    telemetry = TelemetrySender(DICTIONARY, "127.0.0.1", monitor.address[1], clock=lambda: 2.0)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for packets in bad.values():
            for raw in packets:
                sender.sendto(raw, monitor.address)
    telemetry.send_channels("GNC", {"cycle": 42})  # a good packet after all that
    expected = sum(len(p) for p in bad.values()) + 1
    deadline = time.monotonic() + 3.0
    while monitor.stats.datagrams < expected and time.monotonic() < deadline:
        monitor.poll(0.05)
    stats = monitor.stats
    assert stats.datagrams == expected and stats.decoded == 1 and monitor.latest["cycle"] == 42
    assert stats.decode_errors_by_kind == {kind: len(packets) for kind, packets in bad.items()}
    console = Console(record=True, width=200)
    console.print(render_tables(monitor))
    screen = console.export_text()
    assert "UNKNOWN_APID 1" in screen and "TRUNCATED 5" in screen and "decode errors" in screen
    monitor.close()
    telemetry.close()
    summary = json.loads((tmp_path / "ground_summary.json").read_text())
    assert summary["decode_errors"] == expected - 1
    assert summary["decode_errors_by_kind"]["UNKNOWN_EVENT"] == 1
    records = [json.loads(line) for line in (tmp_path / "tm_decoded.jsonl").read_text().splitlines()]
    assert [r.get("kind") for r in records if "error" in r].count("CRC_MISMATCH") == 1


def test_random_datagrams_never_crash_the_ground() -> None:
    """Random bytes, and valid packets with random damage re-CRC'd so that the deeper checks (lengths,
    APIDs, event ids, enum indices, strings) see them too."""
    rng = random.Random(1515)
    sender = TelemetrySender(DICTIONARY, port=None, clock=lambda: 3.0)
    seeds = [sender.send_channels("GNC"), sender.send_channels("HK"),
             encode_event_packet(DICTIONARY, DICTIONARY.event("CMD_REJECTED"), 0, 1.0,
                                 {"opcode": 1, "error": "FORMAT", "reason": "x" * 40})]
    monitor = GroundMonitor(DICTIONARY, port=None)
    for _ in range(3000):
        choice = rng.random()
        if choice < 0.3:
            raw = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 300)))
        else:
            body = bytearray(rng.choice(seeds)[:-2])
            for _ in range(rng.randint(1, 4)):
                body[rng.randrange(len(body))] = rng.getrandbits(8)
            if choice < 0.6:
                body = body[:rng.randint(6, len(body))]
            raw = _recrc(bytes(body))
        monitor.process(raw)  # must not raise
    stats = monitor.stats
    assert stats.datagrams == 3000 and stats.decoded + stats.decode_errors == 3000
    assert sum(stats.decode_errors_by_kind.values()) == stats.decode_errors
    assert {"TRUNCATED", "MALFORMED", "UNKNOWN_APID"} <= set(stats.decode_errors_by_kind)
