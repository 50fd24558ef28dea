"""TelemetrySender over real UDP sockets on loopback; packet layout checked by an independent parser."""
from __future__ import annotations

import math
import socket
import struct
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from comms.dictionary import DICTIONARY, EVENT_APID, GNC_APID, HK_APID, DictionaryError
from comms.telemetry import SEQ_MODULO, TelemetryDecodeError, crc16_ccitt, decode_tm_packet, encode_event_packet
from fsw.telemetry import TelemetrySender


def crc16_ccitt_bitwise(data: bytes) -> int:
    """Textbook CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), written independently of the code under test."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def parse_primary_header(raw: bytes) -> dict[str, int]:
    """CCSDS 133.0-B-2 primary header, parsed by hand."""
    word0, word1, length = struct.unpack("!HHH", raw[:6])
    return {"version": word0 >> 13, "type": (word0 >> 12) & 1, "sec_hdr": (word0 >> 11) & 1,
            "apid": word0 & 0x7FF, "seq_flags": word1 >> 14, "seq": word1 & 0x3FFF, "data_len": length}


@pytest.fixture
def receiver() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)
    yield sock
    sock.close()


@pytest.fixture
def sender(receiver: socket.socket) -> Iterator[TelemetrySender]:
    tm = TelemetrySender(DICTIONARY, "127.0.0.1", receiver.getsockname()[1], clock=lambda: 123.25)
    yield tm
    tm.close()


def test_crc_matches_the_standard_check_value_and_a_bitwise_reference() -> None:
    assert crc16_ccitt(b"123456789") == 0x29B1  # catalogue check value of CRC-16/CCITT-FALSE
    payload = bytes(range(256)) * 3
    assert crc16_ccitt(payload) == crc16_ccitt_bitwise(payload)


def test_gnc_packet_over_udp_has_a_valid_ccsds_layout(sender: TelemetrySender, receiver: socket.socket) -> None:
    q = np.array([0.5, 0.5, -0.5, 0.5])
    sent = sender.send_channels("GNC", {"mode": "POINTING", "q_est_NB": q, "margin_min_deg": 4.25,
                                        "wheel_speed_rad_s": [10.0, -20.0, 30.0, -40.0], "cycle": 77,
                                        "st_blind_source": "MOON", "st_valid": False, "active_zone": -1})
    raw = receiver.recv(65536)
    assert raw == sent
    hdr = parse_primary_header(raw)
    assert hdr == {"version": 0, "type": 0, "sec_hdr": 1, "apid": GNC_APID, "seq_flags": 0b11, "seq": 0,
                   "data_len": len(raw) - 7}
    assert struct.unpack("!H", raw[-2:])[0] == crc16_ccitt_bitwise(raw[:-2])
    assert struct.unpack("!d", raw[6:14])[0] == 123.25
    decoded = decode_tm_packet(DICTIONARY, raw)
    assert decoded.packet == "GNC" and decoded.time_s == 123.25
    v = decoded.values
    assert [v[f"q_est_NB_{i}"] for i in range(4)] == list(q)
    assert v["mode"] == "POINTING" and v["st_blind_source"] == "MOON" and v["st_valid"] is False
    assert v["cycle"] == 77 and v["active_zone"] == -1 and v["margin_min_deg"] == 4.25
    assert v["wheel_speed_rad_s_1"] == -20.0
    assert math.isnan(v["wheel_speed_rad_s_4"]), "channels never set are NaN, not a plausible 0"


def test_sequence_counts_are_per_apid(sender: TelemetrySender, receiver: socket.socket) -> None:
    sender.send_channels("GNC", {"cycle": 1})
    sender.send_channels("HK", {"cycles": 1})
    sender.event("COUNTERS_RESET")
    sender.send_channels("GNC", {"cycle": 2})
    sender.event("COUNTERS_RESET")
    sender.send_channels("GNC", {"cycle": 3})
    seen = [parse_primary_header(receiver.recv(65536)) for _ in range(6)]
    by_apid: dict[int, list[int]] = {}
    for hdr in seen:
        by_apid.setdefault(hdr["apid"], []).append(hdr["seq"])
    assert by_apid == {GNC_APID: [0, 1, 2], HK_APID: [0], EVENT_APID: [0, 1]}
    assert sender.counters["packets_sent"] == 6 and sender.counters["events_sent"] == 2


def test_sequence_count_rolls_over_at_14_bits() -> None:
    tm = TelemetrySender(DICTIONARY, port=None, clock=lambda: 0.0)
    seqs = [parse_primary_header(tm.send_channels("HK"))["seq"] for _ in range(SEQ_MODULO + 2)]
    assert seqs[SEQ_MODULO - 1] == SEQ_MODULO - 1 and seqs[SEQ_MODULO] == 0 and seqs[-1] == 1


def test_partial_updates_keep_the_last_values(sender: TelemetrySender, receiver: socket.socket) -> None:
    sender.send_channels("GNC", {"eps": 0.125, "kappa": 3.0})
    sender.send_channels("GNC", {"kappa": 4.0})
    receiver.recv(65536)
    values = decode_tm_packet(DICTIONARY, receiver.recv(65536)).values
    assert values["eps"] == 0.125 and values["kappa"] == 4.0


def test_integers_saturate_and_floats_round_to_their_type() -> None:
    tm = TelemetrySender(DICTIONARY, port=None)
    values = decode_tm_packet(DICTIONARY, tm.send_channels(
        "GNC", {"cycle": 2**40, "active_zone": 300, "zone_count": -4, "eps": 0.1})).values
    assert values["cycle"] == 2**32 - 1 and values["active_zone"] == 127 and values["zone_count"] == 0
    values = decode_tm_packet(DICTIONARY, tm.send_channels(
        "GNC", {"cycle": float("inf"), "mode": float("nan"), "safe_phase": 99})).values
    assert values["cycle"] == 2**32 - 1 and values["mode"] == "SAFE" and values["safe_phase"] == "SUN_POINTING"
    assert values["eps"] == float(np.float32(0.1))


def test_programming_errors_are_loud() -> None:
    tm = TelemetrySender(DICTIONARY, port=None)
    with pytest.raises(DictionaryError, match="no channel"):
        tm.send_channels("GNC", {"not_a_channel": 1.0})
    with pytest.raises(DictionaryError, match="no channel"):
        tm.send_channels("GNC", {"cycles": 1})  # an HK channel in the GNC packet
    with pytest.raises(DictionaryError, match="7 values for 6"):
        tm.send_channels("GNC", {"wheel_speed_rad_s": np.zeros(7)})
    with pytest.raises(DictionaryError, match="channel eps .*'fast'"):
        tm.send_channels("GNC", {"eps": "fast"})
    with pytest.raises(DictionaryError, match="not one of"):
        tm.send_channels("GNC", {"mode": "SPIN"})
    with pytest.raises(DictionaryError, match="unknown packet"):
        tm.send_channels("FAST", {})
    with pytest.raises(DictionaryError, match="missing arg"):
        tm.event("MODE_CHANGED", from_mode="SAFE")
    with pytest.raises(DictionaryError, match="unknown event"):
        tm.event("EXPLODED")


def test_event_packet_carries_id_severity_and_typed_args(sender: TelemetrySender,
                                                         receiver: socket.socket) -> None:
    assert sender.event("MODE_CHANGED", from_mode="SAFE", to_mode=np.int64(1), cause="FDIR")
    raw = receiver.recv(65536)
    hdr = parse_primary_header(raw)
    assert hdr["apid"] == EVENT_APID and hdr["type"] == 0
    event_id, severity = struct.unpack("!HB", raw[14:17])
    assert event_id == DICTIONARY.event("MODE_CHANGED").id and severity == 4  # ACTIVITY_HI
    decoded = decode_tm_packet(DICTIONARY, raw)
    assert decoded.event == "MODE_CHANGED" and decoded.severity == "ACTIVITY_HI"
    assert decoded.args == {"from_mode": "SAFE", "to_mode": "POINTING", "cause": "FDIR"}
    assert decoded.message == "mode SAFE -> POINTING (FDIR)"
    assert sender.recent_events[-1].message == decoded.message


def test_events_are_throttled_per_window_and_the_suppression_is_reported() -> None:
    tm = TelemetrySender(DICTIONARY, port=None)
    throttle = DICTIONARY.event("CYCLE_SLIP").throttle
    assert throttle == 3
    sent = [tm.event("CYCLE_SLIP", time_s=0.1 * i, rate_group="GNC", exec_time_ms=150.0, count=i, late_ms=0.0)
            for i in range(8)]
    assert sent == [True] * 3 + [False] * 5
    assert tm.counters["events_throttled"] == 5
    assert tm.event("CYCLE_SLIP", time_s=10.5, rate_group="GNC", exec_time_ms=150.0, count=9, late_ms=0.0)
    names = [e.name for e in tm.recent_events]
    assert names[-2:] == ["EVENTS_THROTTLED", "CYCLE_SLIP"]
    assert tm.recent_events[-2].args == {"event": "CYCLE_SLIP", "count": 5}
    # An unthrottled event is never suppressed.
    assert all(tm.event("COUNTERS_RESET", time_s=11.0) for _ in range(20))


def test_decoder_rejects_damaged_packets() -> None:
    tm = TelemetrySender(DICTIONARY, port=None)
    raw = bytearray(tm.send_channels("HK", {"cycles": 5}))
    flipped = bytearray(raw)
    flipped[20] ^= 0x01
    with pytest.raises(TelemetryDecodeError, match="CRC"):
        decode_tm_packet(DICTIONARY, flipped)
    with pytest.raises(TelemetryDecodeError, match="length"):
        decode_tm_packet(DICTIONARY, raw[:-3])
    with pytest.raises(TelemetryDecodeError, match="shorter"):
        decode_tm_packet(DICTIONARY, raw[:5])
    wrong_apid = bytearray(raw)
    wrong_apid[1] = 0x7E
    wrong_apid[-2:] = struct.pack("!H", crc16_ccitt_bitwise(bytes(wrong_apid[:-2])))
    with pytest.raises(TelemetryDecodeError, match="unknown APID"):
        decode_tm_packet(DICTIONARY, wrong_apid)


def test_sockets_bind_to_loopback_by_default(sender: TelemetrySender) -> None:
    assert sender.local_address is not None and sender.local_address[0] == "127.0.0.1"


def test_send_errors_are_counted_not_raised() -> None:
    tm = TelemetrySender(DICTIONARY, "127.0.0.1", 9)
    tm._sock.close()  # simulate a dead socket: sendto raises OSError
    tm.send_channels("HK", {"cycles": 1})
    assert tm.counters["send_errors"] == 1 and tm.counters["packets_sent"] == 0


def test_none_means_no_value() -> None:
    tm = TelemetrySender(DICTIONARY, port=None)
    tm.update("GNC", {"q_target_NB": [1.0, 0.0, 0.0, 0.0], "eps": 0.2, "active_zone": 3})
    values = decode_tm_packet(DICTIONARY, tm.send_channels(
        "GNC", {"q_target_NB": None, "eps": None, "active_zone": None})).values
    assert all(math.isnan(values[f"q_target_NB_{i}"]) for i in range(4))
    assert math.isnan(values["eps"]) and values["active_zone"] == -1  # the dictionary's "no zone"
    assert values["zone_count"] == 0


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_decoder_and_ground_survive_any_datagram(data: st.DataObject) -> None:
    from ground.monitor import GroundMonitor

    tm = TelemetrySender(DICTIONARY, port=None, clock=lambda: 1.0)
    reason = "x" * data.draw(st.integers(0, 200))
    event = encode_event_packet(DICTIONARY, DICTIONARY.event("CMD_REJECTED"), 0, 1.0,
                                {"opcode": 3, "error": "FORMAT", "reason": reason[:120]})
    valid = [tm.send_channels("GNC", {"cycle": 1}), tm.send_channels("HK"), event]
    raw = bytearray(data.draw(st.sampled_from(valid)))
    kind = data.draw(st.sampled_from(["truncate", "flip", "append", "random", "resync"]))
    if kind == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif kind == "flip":
        raw[data.draw(st.integers(0, len(raw) - 1))] ^= data.draw(st.integers(1, 255))
    elif kind == "append":
        raw += data.draw(st.binary(min_size=1, max_size=64))
    elif kind == "random":
        raw = bytearray(data.draw(st.binary(max_size=400)))
    else:  # damage inside, then fix length and CRC so only the payload decoder can notice
        raw[data.draw(st.integers(6, len(raw) - 3))] = data.draw(st.integers(0, 255))
        raw[-2:] = struct.pack("!H", crc16_ccitt(bytes(raw[:-2])))
    try:
        decode_tm_packet(DICTIONARY, bytes(raw))
    except TelemetryDecodeError:
        pass
    monitor = GroundMonitor(DICTIONARY, port=None)
    monitor.process(bytes(raw), 0.0)
    assert monitor.stats.datagrams == 1 and monitor.stats.decoded + monitor.stats.decode_errors == 1


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=6, max_size=12))
def test_primary_header_fields_read_as_spacepackets_reads_them(raw: bytes) -> None:
    from spacepackets.ccsds.spacepacket import SpacePacketHeader

    from comms.telemetry import primary_header_fields

    header = SpacePacketHeader.unpack(raw)
    assert primary_header_fields(raw) == (header.ccsds_version, int(header.packet_type), header.apid,
                                          header.seq_count, header.packet_len)


_CHANNEL_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-2**40, 2**40), st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["SAFE", "POINTING", "x", "1.5"]))
_VECTOR_VALUES = st.one_of(
    _CHANNEL_VALUES,
    st.lists(st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True), st.integers(-9, 9)), max_size=7),
    st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=7).map(np.array),
    st.lists(st.integers(-9, 9), min_size=1, max_size=7).map(lambda v: np.array(v, dtype=np.int32)))


def _update_channel_by_channel(tm: TelemetrySender, packet: str, values: dict) -> tuple | None:
    """The general path (one conversion call per channel) for every name; the error if it raises."""
    try:
        for name, value in values.items():
            tm._update_one(packet, tm._latest[packet], name, value)
    except Exception as exc:  # noqa: BLE001 - compared with what the fast path raises
        return type(exc), str(exc)
    return None


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_update_fast_paths_store_what_the_general_path_stores(data: st.DataObject) -> None:
    packet = data.draw(st.sampled_from(["GNC", "HK"]))
    tm = TelemetrySender(DICTIONARY, port=None)
    names = [c.name for c in DICTIONARY.packet(packet).channels] + list(tm._groups[packet])
    chosen = data.draw(st.lists(st.sampled_from(names), min_size=1, max_size=8, unique=True))
    values = {n: data.draw(_VECTOR_VALUES if n in tm._groups[packet] else _CHANNEL_VALUES) for n in chosen}
    reference = TelemetrySender(DICTIONARY, port=None)
    expected_error = _update_channel_by_channel(reference, packet, values)
    try:
        tm.update(packet, values)
        error = None
    except Exception as exc:  # noqa: BLE001
        error = type(exc), str(exc)
    assert error == expected_error
    if error is None:
        got, want = tm.latest(packet), reference.latest(packet)
        assert got.keys() == want.keys()
        for name in got:  # NaN == NaN here; same value and the same wire type
            assert type(got[name]) is type(want[name]), name
            assert got[name] == want[name] or (got[name] != got[name] and want[name] != want[name]), name
    assert any(plan[2] is None for plan in tm._plans["GNC"].values())  # the vector fast path exists


@settings(max_examples=200, deadline=None)
@given(apid=st.integers(0, 0x7FF), seq=st.integers(0, 3 * SEQ_MODULO), time_s=st.floats(allow_nan=False),
       payload=st.binary(max_size=300))
def test_tm_packets_are_the_bytes_spacepackets_builds(apid: int, seq: int, time_s: float, payload: bytes) -> None:
    from spacepackets.ccsds.spacepacket import PacketType, SpacePacket, SpacePacketHeader

    from comms.dictionary import TM_SECONDARY_HEADER
    from comms.telemetry import frame_tm_packet

    sec = TM_SECONDARY_HEADER.pack(time_s)
    header = SpacePacketHeader(packet_type=PacketType.TM, apid=apid, seq_count=seq % SEQ_MODULO,
                               data_len=len(sec) + len(payload) + 1, sec_header_flag=True)
    body = SpacePacket(header, sec_header=sec, user_data=payload).pack()
    assert frame_tm_packet(apid, seq, time_s, payload) == bytes(body) + struct.pack("!H", crc16_ccitt_bitwise(bytes(body)))


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.text(min_size=1, max_size=8),
                       st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-2**70, 2**70),
                                 st.booleans(), st.text(max_size=8)), max_size=80),
       st.floats(allow_nan=True, allow_infinity=True))
def test_channel_record_is_json_float_of_every_value(values: dict, time_s: float) -> None:
    """to_json_dict rewrites exactly the non-finite floats as strings, as _json_float of each value does."""
    import json

    from comms.telemetry import DecodedTm, _json_float

    packet = DecodedTm(GNC_APID, 7, time_s, "channels", "GNC", dict(values))
    record = packet.to_json_dict()
    assert record["values"] == {k: _json_float(v) for k, v in values.items()} or \
        json.dumps(record["values"]) == json.dumps({k: _json_float(v) for k, v in values.items()})
    assert list(record["values"]) == list(values)
    assert json.dumps(record, allow_nan=False)  # strict JSON: every NaN/inf became a string
    assert packet.values == values  # the packet's own values are not touched
