"""Telemetry the ground can trust: only packets with the mission key's MAC and a fresh security sequence
number are archived; forged, unauthenticated and replayed packets are counted, shown and quarantined."""
from __future__ import annotations

import json
import socket
import time
from pathlib import Path

from comms.dictionary import DICTIONARY
from comms.link_security import SPI_TM, SecurityAssociation, downlink_receiver, write_key_file
from fsw.telemetry import TelemetrySender
from ground.archive import EVENTS_ARCHIVE, RAW_ARCHIVE, REJECTED_ARCHIVE, SUMMARY_FILE, read_events, read_raw_archive
from ground.display import render_tables
from ground.monitor import GroundMonitor


def test_forged_unauthenticated_and_replayed_events_are_never_archived_as_genuine(tmp_path: Path) -> None:
    key = write_key_file(tmp_path / "link.key")
    archive = tmp_path / "ground"
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0, archive, security=downlink_receiver(key))
    flight = TelemetrySender(DICTIONARY, "127.0.0.1", monitor.address[1], security=SecurityAssociation(key, SPI_TM))
    # The attacker knows the dictionary (it is public) but not the key.
    plain = TelemetrySender(DICTIONARY, port=None)  # valid CCSDS + CRC, no MAC: what forged the old verdicts
    wrong_key = TelemetrySender(DICTIONARY, port=None, security=SecurityAssociation(bytes(32), SPI_TM))
    genuine = [flight.send_channels("HK", {"cycles": 10}),
               flight.event("TARGET_REACHED", error_deg=0.01) and flight.recent_events[-1]]
    forgeries = [plain.send_channels("HK", {"cycles": 99}),
                 _event_bytes(plain, "FATAL_ERROR", reason="forged"),
                 _event_bytes(wrong_key, "FDIR_TRIPPED", monitor="WHEEL_FAULT", action="ENTER_SAFE", value=1.0),
                 flight.send_channels("HK", {"cycles": 11})]  # genuine: sent, then replayed below
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as attacker:
        for raw in forgeries[:3]:
            attacker.sendto(raw, monitor.address)
        time.sleep(0.05)
        attacker.sendto(forgeries[3], monitor.address)  # the replay of a genuine packet (already received)
    deadline = time.monotonic() + 3.0
    while monitor.stats.datagrams < 7 and time.monotonic() < deadline:
        monitor.poll(0.05)
    assert genuine[1].name == "TARGET_REACHED"
    assert monitor.stats.datagrams == 7
    assert monitor.stats.rejected == {"unauthenticated": 2, "bad_mac": 1, "replay": 1}
    assert monitor.latest["cycles"] == 11  # the forged 99 never reached the displayed values
    table = _text(render_tables(monitor))
    assert "unauthenticated 2" in table and "bad_mac 1" in table
    monitor.close()
    flight.close()
    # the archive the run is judged on holds the genuine packets only
    assert [e["event"] for e in read_events(archive)] == ["TARGET_REACHED"]
    assert [json.loads(line)["event"] for line in (archive / EVENTS_ARCHIVE).read_text().splitlines()] == \
        ["TARGET_REACHED"]
    assert len(list(read_raw_archive(archive / RAW_ARCHIVE))) == 3
    assert len(list(read_raw_archive(archive / REJECTED_ARCHIVE))) == 4  # kept apart, as received
    summary = json.loads((archive / SUMMARY_FILE).read_text())
    assert summary["rejected_by_link_security"] == 4
    assert summary["rejected_by_reason"] == {"bad_mac": 1, "replay": 1, "unauthenticated": 2}


def _event_bytes(sender: TelemetrySender, name: str, **args) -> bytes:
    """The bytes ``sender`` puts on the wire for one event (it has no socket: capture what it sends)."""
    sent: list[bytes] = []
    original = sender._transmit
    sender._transmit = lambda raw: sent.append(original(raw)) or sent[-1]  # type: ignore[method-assign]
    sender.event(name, **args)
    sender._transmit = original  # type: ignore[method-assign]
    return sent[-1]


def _text(renderable) -> str:
    from rich.console import Console

    console = Console(width=200, record=True)
    console.print(renderable)
    return console.export_text()
