"""Ground monitor: archive completeness, sequence gaps, live table, CLI send, TC round trip."""
from __future__ import annotations

import json
import multiprocessing
import socket
import threading
import time
from pathlib import Path

import numpy as np
import yaml
from rich.console import Console

from keepout_config import config_path
from comms.dictionary import DICTIONARY, GNC_APID, HK_APID, LimitState
from ground.archive import (
    DECODED_ARCHIVE,
    EVENTS_ARCHIVE,
    LIMITS_ARCHIVE,
    RAW_ARCHIVE,
    SUMMARY_FILE,
    read_channels,
    read_events,
    read_raw_archive,
)
from cli.ground import main
from ground.display import limit_state, render_tables
from ground.monitor import GroundMonitor, run_ground_monitor
from comms.link_security import SPI_TM, SecurityAssociation, downlink_receiver, uplink_receiver, write_key_file
from fsw.telecommand import CommandDispatcher
from fsw.telemetry import TelemetrySender
from comms.telemetry import encode_tm_packet

RESYNC = DICTIONARY.command("SEC_RESYNC").opcode


def _gnc_values(cycle: int) -> list:
    packet = DICTIONARY.packet("GNC")
    values = []
    for channel in packet.channels:
        if channel.name == "cycle":
            values.append(cycle)
        elif channel.type in ("F32", "F64"):
            values.append(0.5)
        elif channel.type == "BOOL":
            values.append(True)
        else:
            values.append(0)
    return values


def _receive(monitor: GroundMonitor, count: int, timeout_s: float = 3.0) -> None:
    deadline = time.monotonic() + timeout_s
    while monitor.stats.datagrams < count and time.monotonic() < deadline:
        monitor.poll(0.05)
    assert monitor.stats.datagrams == count


def test_skipped_sequence_count_is_detected_and_every_packet_archived(tmp_path: Path) -> None:
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0, tmp_path)
    packet = DICTIONARY.packet("GNC")
    seqs = [0, 1, 2, 5, 6]  # 3 and 4 "lost on the link"
    datagrams = [encode_tm_packet(packet, s, 10.0 + s, _gnc_values(s)) for s in seqs]
    datagrams.insert(2, b"\x01\x02garbage that is not a space packet")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as link:
        for raw in datagrams:
            link.sendto(raw, monitor.address)
    _receive(monitor, len(datagrams))
    monitor.close()

    stats = monitor.stats
    assert stats.decode_errors == 1 and stats.decoded == 5
    assert [(g.apid, g.expected, g.received, g.missing) for g in stats.gaps] == [(GNC_APID, 3, 5, 2)]
    assert stats.missing == 2
    archived = [raw for _, raw in read_raw_archive(tmp_path / RAW_ARCHIVE)]
    assert archived == datagrams, "the raw archive holds every datagram, undecodable ones included"
    lines = [json.loads(line) for line in (tmp_path / DECODED_ARCHIVE).read_text().splitlines()]
    assert len(lines) == 6 and "error" in lines[2]
    assert [line["seq"] for line in lines if "seq" in line] == seqs
    assert lines[4]["gap_missing"] == 2 and lines[4]["values"]["cycle"] == 5
    summary = json.loads((tmp_path / SUMMARY_FILE).read_text())
    assert summary["missing_packets"] == 2 and summary["per_apid"][f"{GNC_APID:#05x}"]["gaps"] == 1


def test_rollover_is_not_a_gap_and_a_restart_is_not_16000_lost() -> None:
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0)
    packet = DICTIONARY.packet("HK")
    values = [0] * len(packet.channels)
    for seq in (16382, 16383, 0, 1, 0, 1):  # wrap, then the flight software restarts
        monitor.process(encode_tm_packet(packet, seq, 0.0, values))
    monitor.close()
    stats = monitor.stats.per_apid[HK_APID]
    assert stats.missing == 0 and stats.gaps == 0 and stats.duplicates_or_restarts == 1


def test_sender_to_monitor_end_to_end_with_events(tmp_path: Path) -> None:
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0, tmp_path)
    tm = TelemetrySender(DICTIONARY, "127.0.0.1", monitor.address[1], clock=lambda: 5.0)
    for cycle in range(20):
        tm.send_channels("GNC", {"cycle": cycle, "margin_min_deg": 1.0, "mode": "POINTING"})
    tm.event("KEEP_OUT_MARGIN_LOW", zone=1, body="MOON", margin_deg=1.0)
    tm.close()
    _receive(monitor, 21)
    assert monitor.stats.missing == 0
    assert monitor.latest["cycle"] == 19 and monitor.latest["mode"] == "POINTING"
    assert monitor.events[-1].event == "KEEP_OUT_MARGIN_LOW" and monitor.events[-1].severity == "WARNING_HI"
    assert limit_state(DICTIONARY, "margin_min_deg", monitor.latest["margin_min_deg"]) is LimitState.YELLOW
    console = Console(record=True, width=140)
    console.print(render_tables(monitor))
    screen = console.export_text()
    assert "margin_min_deg" in screen and "YELLOW" in screen and "keep-out margin low: zone 1 (MOON)" in screen
    monitor.close()
    events = [json.loads(line) for line in (tmp_path / EVENTS_ARCHIVE).read_text().splitlines()]
    assert [e["event"] for e in events] == ["KEEP_OUT_MARGIN_LOW"]


def test_tc_round_trip_ground_send_to_dispatcher_and_command_event_back(tmp_path: Path) -> None:
    key = write_key_file(tmp_path / "link.key")
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0, security=downlink_receiver(key))
    telemetry = TelemetrySender(DICTIONARY, "127.0.0.1", monitor.address[1], security=SecurityAssociation(key, SPI_TM))
    dispatcher = CommandDispatcher(DICTIONARY, telemetry, "127.0.0.1", 0,
                                   security=uplink_receiver(key, resync_opcode=RESYNC))
    modes: list[str] = []
    dispatcher.register("SET_MODE", lambda mode: modes.append(mode))
    tc_port = dispatcher.address[1]

    json_dictionary = str(Path(__file__).resolve().parents[2] / "config" / "telemetry_dictionary.json")
    assert main(["ground", "--dictionary", json_dictionary, "send", "SET_MODE", "POINTING",
                 "--port", str(tc_port), "--no-wait", "--key-file", str(tmp_path / "link.key")]) == 0
    results = []
    deadline = time.monotonic() + 3.0
    while not results and time.monotonic() < deadline:
        results = dispatcher.poll(timeout_s=0.1)
    assert [r.accepted for r in results] == [True]
    assert modes == ["POINTING"]
    assert dispatcher.counters["accepted"] == 1 and dispatcher.hk_values()["tc_accepted"] == 1
    _receive(monitor, 4)  # CMD_DISPATCHED, acceptance report, CMD_COMPLETED, completion report
    assert monitor.stats.decoded == 4 and monitor.stats.forged == 0  # all signed, all verified
    assert [(e.event, e.severity) for e in monitor.events] == [("CMD_DISPATCHED", "COMMAND"),
                                                               ("CMD_COMPLETED", "COMMAND")]
    assert monitor.events[-1].args["command"] == "SET_MODE"
    dispatcher.close()
    telemetry.close()
    monitor.close()


def test_cli_send_rejects_bad_arguments_with_a_clear_message(tmp_path: Path, capsys) -> None:
    write_key_file(tmp_path / "k")
    assert main(["ground", "send", "SET_MODE", "SPIN", "--port", "9", "--key-file", str(tmp_path / "k")]) == 2
    assert "mode: 'SPIN' not one of" in capsys.readouterr().err
    assert main(["ground", "send", "WARP", "--port", "9"]) == 2
    assert "unknown command" in capsys.readouterr().err
    assert main(["ground", "send", "NOOP", "--port", "9"]) == 2  # nothing is sent unsigned
    assert "no link key" in capsys.readouterr().err


def test_monitor_runs_until_stop_event_in_a_thread(tmp_path: Path) -> None:
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0, tmp_path)
    stop = threading.Event()
    thread = threading.Thread(target=monitor.run, kwargs={"stop_event": stop})
    thread.start()
    tm = TelemetrySender(DICTIONARY, "127.0.0.1", monitor.address[1])
    for _ in range(5):
        tm.send_channels("HK", {"cycles": 1})
    time.sleep(0.3)
    stop.set()
    thread.join(timeout=5.0)
    tm.close()
    assert not thread.is_alive()
    assert json.loads((tmp_path / SUMMARY_FILE).read_text())["datagrams"] == 5


def test_run_ground_monitor_as_a_separate_process_on_an_ephemeral_port(tmp_path: Path) -> None:
    ctx = multiprocessing.get_context("spawn")
    ready, stop, port_queue = ctx.Event(), ctx.Event(), ctx.Queue()
    process = ctx.Process(target=run_ground_monitor,
                          kwargs={"archive_dir": str(tmp_path), "port": 0, "stop_event": stop, "ready": ready,
                                  "port_queue": port_queue, "duration_s": 30.0, "write_decoded": False})
    process.start()
    try:
        assert ready.wait(20.0)
        port = port_queue.get(timeout=5.0)
        tm = TelemetrySender(DICTIONARY, "127.0.0.1", port)
        for cycle in range(10):
            tm.send_channels("GNC", {"cycle": cycle, "pointing_error_deg": 10.0 - cycle})
        tm.event("TARGET_REACHED", error_deg=0.01)
        tm.close()
        time.sleep(0.3)
        stop.set()
        process.join(timeout=10.0)
    finally:
        if process.is_alive():
            process.kill()
    assert process.exitcode == 0
    assert len(list(read_raw_archive(tmp_path / RAW_ARCHIVE))) == 11
    assert not (tmp_path / DECODED_ARCHIVE).exists()  # raw + events only, as asked
    assert json.loads((tmp_path / SUMMARY_FILE).read_text())["missing_packets"] == 0
    # The SIL reads channel time series and events back from the raw archive.
    series = read_channels(tmp_path, "GNC")
    assert list(series["cycle"]) == list(range(10)) and list(series["seq"]) == list(range(10))
    assert series["pointing_error_deg"][-1] == 1.0 and series["mode"][0] == "SAFE"
    assert [e["event"] for e in read_events(tmp_path)] == ["TARGET_REACHED"]
    # `keepout ground decode` rebuilds the decoded JSONL from the raw archive.
    assert main(["ground", "decode", str(tmp_path)]) == 0
    lines = (tmp_path / DECODED_ARCHIVE).read_text().splitlines()
    assert len(lines) == 11 and json.loads(lines[-1])["event"] == "TARGET_REACHED"


def test_cli_monitor_with_duration(tmp_path: Path, capsys) -> None:
    write_key_file(tmp_path / "link.key")
    assert main(["ground", "--port", "0", "--duration", "0.3", "--no-live", "--archive", str(tmp_path),
                 "--key-file", str(tmp_path / "link.key")]) == 0
    assert "received 0 packets" in capsys.readouterr().out
    assert (tmp_path / SUMMARY_FILE).exists()


def test_send_takes_the_telecommand_address_and_key_from_the_mission_config(tmp_path: Path) -> None:
    key = write_key_file(tmp_path / "link.key")
    dispatcher = CommandDispatcher(DICTIONARY, None, "127.0.0.1", 0, security=uplink_receiver(key))
    calls: list[str] = []
    dispatcher.register("NOOP", lambda: calls.append("NOOP"))
    mission = tmp_path / "mission.yaml"  # a whole mission: the ground reads it with the one mission reader
    data = yaml.safe_load(config_path("missions/demo-pointing.yaml").read_text())
    data["flight_software"]["tmtc"] = {"telecommand_bind_host": "127.0.0.1", "telecommand_port": dispatcher.address[1],
                                       "security": {"key_file": "link.key"}}
    mission.write_text(yaml.safe_dump(data))
    assert main(["ground", "--config", str(mission), "send", "NOOP", "--no-wait"]) == 0
    deadline = time.monotonic() + 3.0
    while not calls and time.monotonic() < deadline:
        dispatcher.poll(timeout_s=0.1)
    dispatcher.close()
    assert calls == ["NOOP"] and dispatcher.counters["accepted"] == 1


def test_bad_mission_config_is_reported_not_raised(tmp_path: Path, capsys) -> None:
    mission = tmp_path / "mission.yaml"
    mission.write_text("flight_software:\n  tmtc:\n    telecommand_port: -5\n")
    assert main(["ground", "--config", str(mission), "send", "NOOP"]) == 2
    assert "telecommand_port" in capsys.readouterr().err


def test_limit_transitions_are_logged_and_summarised(tmp_path: Path) -> None:
    monitor = GroundMonitor(DICTIONARY, port=None, archive_dir=tmp_path)
    tm = TelemetrySender(DICTIONARY, port=None)
    margins = [5.0, 1.5, -0.2, 0.5, 3.0, float("nan"), 4.0]
    for i, margin in enumerate(margins):
        monitor.process(tm.send_channels("GNC", {"margin_min_deg": margin}, time_s=float(i)), float(i))
    monitor.close()
    transitions = [json.loads(line) for line in (tmp_path / LIMITS_ARCHIVE).read_text().splitlines()
                   if json.loads(line)["channel"] == "margin_min_deg"]
    # 5.0 GREEN -> 1.5 YELLOW -> -0.2 RED -> 0.5 YELLOW -> 3.0 GREEN; NaN skipped; 4.0 stays GREEN
    assert [(t["from"], t["to"], t["time_s"]) for t in transitions] == [
        ("GREEN", "YELLOW", 1.0), ("YELLOW", "RED", 2.0), ("RED", "YELLOW", 3.0), ("YELLOW", "GREEN", 4.0)]
    summary = json.loads((tmp_path / SUMMARY_FILE).read_text())["limits"]["margin_min_deg"]
    assert summary["to_red"] == 1 and summary["to_yellow"] == 2 and summary["first_red_time_s"] == 2.0
    assert summary["min"] == float(np.float32(-0.2)) and summary["max"] == 5.0 and summary["state"] == "GREEN"


def test_live_display_renders_during_run(capsys) -> None:
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0)
    tm = TelemetrySender(DICTIONARY, "127.0.0.1", monitor.address[1])
    tm.send_channels("GNC", {"mode": "QUATERNION", "att_error_deg": 12.5})
    tm.event("TARGET_REACHED", error_deg=0.02)
    tm.close()
    monitor.run(duration_s=0.4, live=True, refresh_s=0.05)
    out = capsys.readouterr().out
    assert "keepout telemetry" in out and "QUATERNION" in out and "TARGET_REACHED" in out


def test_limit_states_follow_the_dictionary_limits_at_and_around_every_bound() -> None:
    """The monitor's green-band shortcut gives the states Limits.check gives, bounds included."""
    import math

    monitor = GroundMonitor(DICTIONARY, port=None)
    tm = TelemetrySender(DICTIONARY, port=None)
    for packet in ("GNC", "HK"):
        limited = [c for c in DICTIONARY.packet(packet).channels
                   if c.limits is not None and c.type not in ("BOOL", "ENUM")]
        assert limited
        for channel in limited:
            limits = channel.limits
            bounds = [b for b in (*limits.yellow, *limits.red) if b is not None]
            probes = [v for b in bounds for v in (b, math.nextafter(b, -math.inf), math.nextafter(b, math.inf))]
            probes += [0.0, 1e9, -1e9, float("nan")] + probes[::-1]
            expected, state = [], "GREEN"
            for i, value in enumerate(probes):
                sent = tm.send_channels(packet, {channel.name: value}, time_s=float(i))
                wire = monitor.process(sent, 0.0).values[channel.name]
                if wire == wire:
                    new = limits.check(wire).value
                    if new != state:
                        expected.append((state, new))
                    state = new
            stats = monitor.stats.limits[channel.name]
            assert stats.state == state, channel.name
            assert stats.to_red == sum(1 for _, to in expected if to == "RED"), channel.name
            assert stats.to_yellow == sum(1 for _, to in expected if to == "YELLOW"), channel.name
