"""CommandDispatcher: decoding, typed errors, counters, events, and a fuzz test that it never crashes."""
from __future__ import annotations

import socket
import struct
import time
from collections.abc import Iterator
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from comms.dictionary import DICTIONARY, MAX_TC_PACKET_LEN, TC_APID, ArgError
from fsw.telecommand import CommandDispatcher
from comms.telecommand import CommandExecutionError, CommandValidationError, encode_command, encode_tc_packet
from fsw.telemetry import TelemetrySender
from comms.telemetry import crc16_ccitt


def tc_packet_by_hand(apid: int, seq: int, payload: bytes, packet_type: int = 1) -> bytes:
    """A TC space packet assembled with struct only (independent of the code under test)."""
    word0 = (packet_type << 12) | apid
    body = struct.pack("!HHH", word0, 0xC000 | seq, len(payload) + 2 - 1) + payload
    return body + struct.pack("!H", crc16_ccitt(body))


class Recorder:
    """Handlers that record their calls; SET_TARGET validates like the flight app would."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, dict[str, Any]]] = []

    def handler(self, name: str):
        def handle(**kwargs: Any) -> None:
            self.calls.append((name, kwargs))
        return handle

    def set_target(self, kind: str, c0: float, c1: float, c2: float, c3: float) -> None:
        if kind == "DIRECTION" and (c0 * c0 + c1 * c1 + c2 * c2) < 0.25:
            raise CommandValidationError("target direction has no usable norm")
        self.calls.append(("SET_TARGET", {"kind": kind, "c": (c0, c1, c2, c3)}))


def make_dispatcher(port: int | None = None) -> tuple[CommandDispatcher, Recorder, TelemetrySender]:
    telemetry = TelemetrySender(DICTIONARY, port=None, clock=lambda: 0.0)
    dispatcher = CommandDispatcher(DICTIONARY, telemetry, port=port)
    recorder = Recorder()
    for name in ("NOOP", "RESET_COUNTERS", "SET_MODE", "SET_GAINS"):
        dispatcher.register(name, recorder.handler(name))
    dispatcher.register("SET_TARGET", recorder.set_target)
    return dispatcher, recorder, telemetry


@pytest.fixture
def setup() -> Iterator[tuple[CommandDispatcher, Recorder, TelemetrySender]]:
    dispatcher, recorder, telemetry = make_dispatcher()
    yield dispatcher, recorder, telemetry
    dispatcher.close()


def test_encoded_command_has_the_ccsds_tc_layout() -> None:
    packet = encode_command(DICTIONARY, "SET_MODE", ["POINTING"], seq_count=42)
    word0, word1, length = struct.unpack("!HHH", packet[:6])
    assert word0 >> 13 == 0 and (word0 >> 12) & 1 == 1 and (word0 >> 11) & 1 == 0
    assert word0 & 0x7FF == TC_APID and word1 & 0x3FFF == 42 and length == len(packet) - 7
    opcode, mode_index = struct.unpack("!HB", packet[6:9])
    assert opcode == DICTIONARY.command("SET_MODE").opcode and mode_index == 1  # POINTING
    assert packet == tc_packet_by_hand(TC_APID, 42, packet[6:-2])


def test_accepted_commands_reach_handlers_with_typed_args(setup) -> None:
    dispatcher, recorder, telemetry = setup
    results = [
        dispatcher.handle_datagram(encode_command(DICTIONARY, "NOOP", seq_count=0)),
        dispatcher.handle_datagram(encode_command(DICTIONARY, "SET_MODE", {"mode": "QUATERNION"}, 1)),
        dispatcher.handle_datagram(encode_command(DICTIONARY, "SET_GAINS", [2.0, 5.0, 0.0, 1.5], 2)),
        dispatcher.handle_datagram(encode_command(DICTIONARY, "SET_TARGET", ["DIRECTION", 0.0, 0.6, 0.8], 3)),
    ]
    assert all(r.accepted for r in results)
    assert recorder.calls == [
        ("NOOP", {}),
        ("SET_MODE", {"mode": "QUATERNION"}),
        ("SET_GAINS", {"k1": 2.0, "kappa": 5.0, "eps": 0.0, "rate_limit_deg_s": 1.5}),
        ("SET_TARGET", {"kind": "DIRECTION", "c": (0.0, 0.6, 0.8, 0.0)}),  # c3 took its default
    ]
    assert dispatcher.counters["accepted"] == 4 and dispatcher.counters["rejected"] == 0
    assert dispatcher.last_opcode == DICTIONARY.command("SET_TARGET").opcode
    command_events = [e for e in telemetry.recent_events if e.severity.value == "COMMAND"]
    assert [e.name for e in command_events] == ["CMD_DISPATCHED", "CMD_COMPLETED"] * 4
    assert command_events[3].args == {"opcode": 3, "command": "SET_MODE"}
    hk = dispatcher.hk_values()
    assert hk["tc_accepted"] == 4 and hk["tc_rejected"] == 0


def _expect(dispatcher: CommandDispatcher, packet: bytes, error: str, match: str = "", code: str = "") -> None:
    """A failure of class ``error`` (reason code ``code``): an execution error fails an accepted command,
    any other error rejects it at acceptance."""
    before = dict(dispatcher.counters)
    result = dispatcher.handle_datagram(packet)
    accepted = error == "EXECUTION"
    assert result.accepted == accepted and not result.completed and result.error == error, result
    assert match in result.reason
    assert not code or result.code == code, result
    counter = "failed" if accepted else "rejected"
    assert dispatcher.counters[counter] == before[counter] + 1
    assert dispatcher.counters[error.lower()] == before[error.lower()] + 1


def test_format_errors(setup) -> None:
    dispatcher, recorder, telemetry = setup
    good = encode_command(DICTIONARY, "SET_GAINS", [2.0, 5.0, 0.1, 1.5])
    corrupt = bytearray(good)
    corrupt[10] ^= 0x40
    _expect(dispatcher, bytes(corrupt), "FORMAT", "CRC", "CRC_MISMATCH")
    _expect(dispatcher, good[:-4], "FORMAT", "length", "LENGTH_MISMATCH")
    _expect(dispatcher, good[:5], "FORMAT", "shorter", "PACKET_TOO_SHORT")
    _expect(dispatcher, good + b"\x00", "FORMAT", "length", "LENGTH_MISMATCH")
    _expect(dispatcher, tc_packet_by_hand(TC_APID, 0, b"\x00\x01" + bytes(MAX_TC_PACKET_LEN)), "FORMAT", "longer",
            "PACKET_TOO_LONG")
    _expect(dispatcher, tc_packet_by_hand(0x123, 0, good[6:-2]), "FORMAT", "APID", "WRONG_APID")
    _expect(dispatcher, tc_packet_by_hand(TC_APID, 0, good[6:-2], packet_type=0), "FORMAT", "expected TC",
            "BAD_HEADER")
    _expect(dispatcher, tc_packet_by_hand(TC_APID, 0, good[6:-2] + b"\x07"), "FORMAT", "after the last",
            "TRAILING_BYTES")
    _expect(dispatcher, tc_packet_by_hand(TC_APID, 0, good[6:-6]), "FORMAT", "truncated", "ARGS_TRUNCATED")
    segmented = bytearray(good[:-2])
    segmented[2] &= 0x3F  # sequence flags 00: continuation segment
    _expect(dispatcher, bytes(segmented) + struct.pack("!H", crc16_ccitt(bytes(segmented))), "FORMAT", "unsegmented")
    assert recorder.calls == []
    # malformed datagrams are junk anyone can send: counted in housekeeping, summarised in one UPLINK_JUNK
    # event a minute at most (the first at once), never a CMD_REJECTED warning each
    assert not [e for e in telemetry.recent_events if e.name == "CMD_REJECTED"]
    junk = [e for e in telemetry.recent_events if e.name == "UPLINK_JUNK"]
    assert len(junk) == 1 and junk[0].args["count"] == 1
    assert dispatcher.hk_values()["tc_format_errors"] == 10 and dispatcher.hk_values()["tc_uplink_junk"] == 10


def test_invalid_opcode_errors(setup) -> None:
    dispatcher, recorder, _ = setup
    _expect(dispatcher, tc_packet_by_hand(TC_APID, 0, b"\x00\x99"), "INVALID_OPCODE", "not in the dictionary",
            "UNKNOWN_OPCODE")
    assert dispatcher.last_result is not None and dispatcher.last_result.opcode == 0x99
    bare = CommandDispatcher(DICTIONARY, port=None)  # knows the dictionary, has no handlers
    _expect(bare, encode_command(DICTIONARY, "NOOP"), "INVALID_OPCODE", "no handler", "NO_HANDLER")


def test_validation_errors(setup) -> None:
    dispatcher, recorder, _ = setup
    _expect(dispatcher, encode_command(DICTIONARY, "SET_GAINS", [0.0, 5.0, 0.1, 1.5], check_range=False),
            "VALIDATION", "k1", "ARG_OUT_OF_RANGE")
    _expect(dispatcher, encode_command(DICTIONARY, "SET_GAINS", [1.0, 5.0, float("nan"), 1.5],
                                       check_range=False), "VALIDATION", "eps", "ARG_OUT_OF_RANGE")
    bad_enum = tc_packet_by_hand(TC_APID, 0, struct.pack("!HB", DICTIONARY.command("SET_MODE").opcode, 9))
    _expect(dispatcher, bad_enum, "VALIDATION", "enum index 9", "BAD_ENUM")
    # A handler's own check (here: a zero-length target direction) is a validation error too.
    _expect(dispatcher, encode_command(DICTIONARY, "SET_TARGET", ["DIRECTION", 0.0, 0.0, 0.0]), "VALIDATION",
            "norm")
    assert recorder.calls == []


def test_execution_errors_never_escape(setup) -> None:
    dispatcher, _, _ = setup
    dispatcher2 = CommandDispatcher(DICTIONARY, port=None)

    def broken(**_: Any) -> None:
        raise ZeroDivisionError("division by zero in handler")

    def refused(**_: Any) -> None:
        raise CommandExecutionError("estimator not converged")

    dispatcher2.register("NOOP", broken)
    dispatcher2.register("RESET_COUNTERS", refused)
    _expect(dispatcher2, encode_command(DICTIONARY, "NOOP"), "EXECUTION", "ZeroDivisionError", "EXECUTION_FAILED")
    _expect(dispatcher2, encode_command(DICTIONARY, "RESET_COUNTERS"), "EXECUTION", "not converged")
    assert dispatcher2.counters["accepted"] == 2 and dispatcher2.counters["completed"] == 0


class CapturingTelemetry(TelemetrySender):
    """Telemetry that keeps every packet it would send."""

    def __init__(self) -> None:
        super().__init__(DICTIONARY, port=None, clock=lambda: 12.5)
        self.sent: list[bytes] = []

    def _transmit(self, raw: bytes) -> None:
        self.sent.append(raw)
        super()._transmit(raw)


def _acks(raw_packets: list[bytes]) -> list[tuple[str, int, int, int, str]]:
    """(report, request id, sequence count, opcode, reason code) of every TC_ACK packet, decoded."""
    from comms.telemetry import decode_tm_packet

    decoded = [decode_tm_packet(DICTIONARY, raw) for raw in raw_packets]
    return [(p.values["ack_report"], p.values["ack_request_id"], p.values["ack_tc_seq"], p.values["ack_opcode"],
             p.values["ack_code"]) for p in decoded if p.packet == "TC_ACK"]


def test_every_telecommand_is_acknowledged_in_telemetry_as_pus_service_1() -> None:
    telemetry = CapturingTelemetry()
    dispatcher = CommandDispatcher(DICTIONARY, telemetry, port=None)
    dispatcher.register("NOOP", lambda: None)

    def broken() -> None:
        raise RuntimeError("wheel driver lost")

    dispatcher.register("RESET_COUNTERS", broken)
    dispatcher.register("SET_GAINS", lambda **_: None)
    noop = encode_command(DICTIONARY, "NOOP", seq_count=7)
    out_of_range = encode_command(DICTIONARY, "SET_GAINS", [1.0, 5.0, 0.1, 90.0], seq_count=8, check_range=False)
    reset = encode_command(DICTIONARY, "RESET_COUNTERS", seq_count=9)
    set_mode = encode_command(DICTIONARY, "SET_MODE", ["SAFE"], seq_count=10)  # in the dictionary, not handled
    for packet in (noop, out_of_range, reset, set_mode, b"\x17\x00"):
        dispatcher.handle_datagram(packet)

    def request_id(packet: bytes) -> int:  # PUS: the first four octets of the command, read independently
        return struct.unpack("!I", packet[:4])[0]

    assert _acks(telemetry.sent) == [
        ("ACCEPTANCE_SUCCESS", request_id(noop), 7, 0x01, "NONE"),
        ("COMPLETION_SUCCESS", request_id(noop), 7, 0x01, "NONE"),
        ("ACCEPTANCE_FAILURE", request_id(out_of_range), 8, 0x05, "ARG_OUT_OF_RANGE"),
        ("ACCEPTANCE_SUCCESS", request_id(reset), 9, 0x02, "NONE"),
        ("COMPLETION_FAILURE", request_id(reset), 9, 0x02, "EXECUTION_FAILED"),
        ("ACCEPTANCE_FAILURE", request_id(set_mode), 10, 0x03, "NO_HANDLER"),
        ("ACCEPTANCE_FAILURE", 0x17000000, 0, 0, "PACKET_TOO_SHORT"),
    ]
    hk = dispatcher.hk_values()
    assert (hk["tc_accepted"], hk["tc_rejected"], hk["tc_completed"], hk["tc_failed"]) == (2, 3, 1, 1)
    # every reason code a command can get is documented in the dictionary, with the command
    documented = DICTIONARY.to_dict()
    codes = {c["name"] for c in documented["tc_verification"]["reason_codes"]}
    for command in documented["commands"]:
        ack = command["acknowledgement"]
        assert set(ack["acceptance_failure_codes"]) | set(ack["completion_failure_codes"]) <= codes
    set_target = next(c for c in documented["commands"] if c["name"] == "SET_TARGET")
    assert "TARGET_IN_KEEP_OUT" in set_target["acknowledgement"]["acceptance_failure_codes"]


def test_sender_side_refuses_bad_args_with_the_name() -> None:
    with pytest.raises(ArgError, match="rate_limit_deg_s.*above maximum"):
        encode_command(DICTIONARY, "SET_GAINS", [1.0, 1.0, 0.1, 90.0])
    with pytest.raises(ArgError, match="takes 1 args"):
        encode_command(DICTIONARY, "SET_MODE", ["SAFE", "NOW"])


def test_double_registration_is_refused(setup) -> None:
    dispatcher, _, _ = setup
    with pytest.raises(ValueError, match="already registered"):
        dispatcher.register("NOOP", lambda: None)


def test_tc_sequence_gaps_are_counted(setup) -> None:
    dispatcher, _, _ = setup
    for seq in (0, 1, 2, 5):
        dispatcher.handle_datagram(encode_command(DICTIONARY, "NOOP", seq_count=seq))
    assert dispatcher.counters["seq_gaps"] == 1


def test_poll_over_a_real_udp_socket_counts_oversized_and_garbage() -> None:
    dispatcher, recorder, _ = make_dispatcher(port=0)
    host, port = dispatcher.address
    assert host == "127.0.0.1"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as uplink:
        uplink.sendto(encode_command(DICTIONARY, "SET_MODE", ["SAFE"]), (host, port))
        uplink.sendto(b"\xff" * 2000, (host, port))
        uplink.sendto(b"", (host, port))
        uplink.sendto(encode_command(DICTIONARY, "NOOP", seq_count=1), (host, port))
    results: list = []
    deadline = time.monotonic() + 2.0
    while len(results) < 4 and time.monotonic() < deadline:
        results += dispatcher.poll(timeout_s=0.1)
    dispatcher.close()
    assert [r.accepted for r in results] == [True, False, False, True]
    assert dispatcher.counters["format"] == 2 and dispatcher.counters["accepted"] == 2
    assert recorder.calls == [("SET_MODE", {"mode": "SAFE"}), ("NOOP", {})]


class _CountingSocket:
    """The dispatcher's socket with its recvmsg calls counted (every other call passes through)."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock
        self.recvs = 0

    def recvmsg(self, *args: Any) -> tuple:
        self.recvs += 1
        return self._sock.recvmsg(*args)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sock, name)


def test_idle_polls_read_nothing_and_every_arrival_is_handled_at_the_next_poll() -> None:
    """Armed (SIGIO on arrival), a poll with nothing new makes no recv() call; each command sent before a
    poll is handled by that poll, none lost, over many rounds; closing restores the signal handler."""
    import signal

    before = signal.getsignal(signal.SIGIO)
    dispatcher, recorder, _ = make_dispatcher(port=0)
    assert dispatcher._armed
    dispatcher.poll()  # the first poll always reads
    counting = _CountingSocket(dispatcher._sock)
    dispatcher._sock = counting
    address = dispatcher.address
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as uplink:
        for _ in range(50):
            assert dispatcher.poll() == []
        assert counting.recvs == 0
        for seq in range(200):
            if seq % 3 == 0:
                assert dispatcher.poll() == []
            for k in range(1 + seq % 2):
                uplink.sendto(encode_command(DICTIONARY, "NOOP", seq_count=2 * seq + k), address)
            results = dispatcher.poll()
            assert len(results) == 1 + seq % 2 and all(r.accepted for r in results), seq
    assert counting.recvs == sum(2 + seq % 2 for seq in range(200))  # each poll after an arrival: + EAGAIN
    assert dispatcher.counters["accepted"] == len(recorder.calls) == sum(1 + seq % 2 for seq in range(200))
    dispatcher._sock = counting._sock
    dispatcher.close()
    assert signal.getsignal(signal.SIGIO) == before


def test_a_replaced_arrival_handler_makes_every_poll_read() -> None:
    """Another SIGIO handler installed after arming: the arrival flag no longer hears arrivals, so a poll
    must read the socket rather than trust it (a command sent then is handled at the next poll)."""
    import signal

    dispatcher, recorder, _ = make_dispatcher(port=0)
    dispatcher.poll()  # the first poll always reads
    assert dispatcher._nothing_arrived()
    previous = signal.signal(signal.SIGIO, lambda signum, frame: None)
    try:
        assert not dispatcher._nothing_arrived()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as uplink:
            uplink.sendto(encode_command(DICTIONARY, "NOOP", seq_count=1), dispatcher.address)
            time.sleep(0.05)
        results = dispatcher.poll()
        assert len(results) == 1 and results[0].accepted and len(recorder.calls) == 1
    finally:
        signal.signal(signal.SIGIO, previous)
        dispatcher.close()


def test_dispatcher_made_outside_the_main_thread_reads_at_every_poll() -> None:
    import threading

    made: list = []
    thread = threading.Thread(target=lambda: made.append(make_dispatcher(port=0)))
    thread.start()
    thread.join()
    dispatcher, recorder, _ = made[0]
    try:
        assert not dispatcher._armed
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as uplink:
            uplink.sendto(encode_command(DICTIONARY, "NOOP"), dispatcher.address)
        deadline = time.monotonic() + 2.0
        while not recorder.calls and time.monotonic() < deadline:
            dispatcher.poll()
        assert recorder.calls == [("NOOP", {})]
    finally:
        dispatcher.close()


# ------------------------------------------------------------------------------------------ fuzzing
_OPCODES = [c.opcode for c in DICTIONARY.commands]


def _valid_packets() -> st.SearchStrategy[bytes]:
    def build(draw_args: tuple[str, list[Any], int]) -> bytes:
        name, args, seq = draw_args
        return encode_command(DICTIONARY, name, args, seq)
    mode = st.sampled_from(["SAFE", "POINTING", "QUATERNION"])
    unit = st.floats(-1.0, 1.0)
    gains = st.tuples(st.floats(0.001, 100.0), st.floats(0.001, 100.0), st.floats(0.0, 1.0), st.floats(0.01, 20.0))
    choice = st.one_of(
        st.tuples(st.just("NOOP"), st.just([]), st.integers(0, 16383)),
        st.tuples(st.just("SET_MODE"), mode.map(lambda m: [m]), st.integers(0, 16383)),
        st.tuples(st.just("SET_GAINS"), gains.map(list), st.integers(0, 16383)),
        st.tuples(st.just("SET_TARGET"), st.tuples(st.sampled_from(["DIRECTION", "QUATERNION"]), unit, unit, unit,
                                                    unit).map(list), st.integers(0, 16383)),
    )
    return choice.map(build)


def _mutations(packet: bytes, data: st.DataObject) -> bytes:
    kind = data.draw(st.sampled_from(["truncate", "flip", "append", "recrc_payload", "opcode", "apid", "raw"]))
    if kind == "truncate":
        return packet[: data.draw(st.integers(0, len(packet) - 1))]
    if kind == "flip":
        out = bytearray(packet)
        out[data.draw(st.integers(0, len(out) - 1))] ^= data.draw(st.integers(1, 255))
        return bytes(out)
    if kind == "append":
        return packet + data.draw(st.binary(min_size=1, max_size=400))
    if kind == "recrc_payload":  # a random payload behind a header that passes the CRC and length checks
        payload = data.draw(st.binary(min_size=2, max_size=80))
        return encode_tc_packet(TC_APID, 0, payload)
    if kind == "opcode":  # real opcode with random (correctly framed) argument bytes: bad types/ranges
        opcode = data.draw(st.sampled_from(_OPCODES + [0, 0xFFFF, 0x06]))
        return encode_tc_packet(TC_APID, 0, struct.pack("!H", opcode) + data.draw(st.binary(max_size=40)))
    if kind == "apid":
        return encode_tc_packet(data.draw(st.integers(0, 2047)), 0, packet[6:-2])
    return data.draw(st.binary(max_size=600))


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_random_packets_only_change_counters(data: st.DataObject) -> None:
    dispatcher, recorder, telemetry = make_dispatcher()
    packets = data.draw(st.lists(_valid_packets(), min_size=1, max_size=4))
    stream = [p if data.draw(st.booleans()) else _mutations(p, data) for p in packets]
    for packet in stream:
        result = dispatcher.handle_datagram(packet)  # must not raise
        assert result.completed == (result.error is None)
    c = dispatcher.counters
    assert c["received"] == len(stream)
    assert c["accepted"] + c["rejected"] == c["received"]
    assert c["completed"] + c["failed"] == c["accepted"]
    assert c["invalid_opcode"] + c["validation"] + c["format"] + c["execution"] == c["rejected"] + c["failed"]
    assert c["acks_sent"] == c["received"] + c["accepted"]  # an acceptance report each, a completion report each accepted
    assert len(recorder.calls) == c["accepted"]  # only accepted commands reached a handler
    assert c["execution"] == 0  # the recording handlers never fail


def test_a_handed_over_socket_takes_the_telecommands_on_the_port_its_parent_reserved() -> None:
    reserved = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    reserved.bind(("127.0.0.1", 0))
    port = reserved.getsockname()[1]
    telemetry = TelemetrySender(DICTIONARY, port=None, clock=lambda: 0.0)
    dispatcher = CommandDispatcher(DICTIONARY, telemetry, port=None, sock=reserved)
    calls: list[dict] = []
    dispatcher.register("NOOP", lambda **kw: calls.append(kw))
    try:
        assert dispatcher.address[1] == port
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.sendto(encode_command(DICTIONARY, "NOOP", seq_count=0), ("127.0.0.1", port))
        deadline = time.monotonic() + 5.0
        while not calls and time.monotonic() < deadline:
            dispatcher.poll(0.1)
        assert calls == [{}] and dispatcher.counters["accepted"] == 1
    finally:
        dispatcher.close()


def test_the_flight_software_refuses_a_handed_over_descriptor_that_is_not_a_bound_udp_socket(tmp_path) -> None:
    from cli.fsw import _inherited_udp_socket

    with open(tmp_path / "not-a-socket", "w") as f, pytest.raises(OSError):
        _inherited_udp_socket(f.fileno())
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as unbound, pytest.raises(OSError, match="not a bound UDP"):
        _inherited_udp_socket(unbound.fileno())
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp:
        tcp.bind(("127.0.0.1", 0))
        with pytest.raises(OSError, match="not a bound UDP"):
            _inherited_udp_socket(tcp.fileno())
        assert tcp.getsockname()[1] > 0  # refused, not taken: the caller's socket is still open
