"""Fuzzing (hypothesis) of the four entry points that take outside input: the telecommand dispatcher,
the bus receiver, the ground's telemetry decoder and the mission loader. None may raise, whatever the
input; the bench (bench/fuzz.py) feeds the same targets millions of inputs."""
from __future__ import annotations

import random

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fuzz_kit import CanTarget, MissionTarget, TcTarget, TmTarget

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                            HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def tc() -> TcTarget:
    target = TcTarget()
    yield target
    target.close()


@pytest.fixture(scope="module")
def tm() -> TmTarget:
    target = TmTarget()
    yield target
    target.close()


@pytest.fixture(scope="module")
def bus() -> CanTarget:
    target = CanTarget()
    yield target
    target.close()


@pytest.fixture(scope="module")
def missions(tmp_path_factory) -> MissionTarget:
    return MissionTarget(tmp_path_factory.mktemp("fuzz-missions"))


@SETTINGS
@given(data=st.binary(max_size=400))
def test_dispatcher_survives_any_datagram(tc: TcTarget, data: bytes) -> None:
    tc.feed(data)


@SETTINGS
@given(seed=st.integers(0, 2**64 - 1), n=st.integers(1, 30))
def test_dispatcher_survives_signed_replayed_and_mutated_commands(tc: TcTarget, seed: int, n: int) -> None:
    rng = random.Random(seed)  # a seed, not st.randoms(): the generators' draws depend on the target's state
    for _ in range(n):
        tc.feed(tc.generate(rng))


def test_the_dispatcher_fuzz_reaches_the_handlers(tc: TcTarget) -> None:
    """The generated commands get past the link and the decoder often enough to exercise the handlers
    (a fuzzer stopped at the MAC would prove little)."""
    rng = random.Random(7)
    for _ in range(3000):
        tc.feed(tc.generate(rng))
    outcomes = tc.outcomes
    assert outcomes["COMPLETED"] > 100 and outcomes["ARG_OUT_OF_RANGE"] > 10 and outcomes["REPLAY"] > 10
    assert outcomes["BAD_MAC"] + outcomes["UNAUTHENTICATED"] > 100 and outcomes["CRC_MISMATCH"] > 100


@SETTINGS
@given(data=st.binary(max_size=800))
def test_ground_decoder_survives_any_datagram(tm: TmTarget, data: bytes) -> None:
    tm.feed(data)


@SETTINGS
@given(seed=st.integers(0, 2**64 - 1), n=st.integers(1, 30))
def test_ground_decoder_survives_forged_signed_and_mutated_packets(tm: TmTarget, seed: int, n: int) -> None:
    rng = random.Random(seed)
    for _ in range(n):
        tm.feed(tm.generate(rng))


@SETTINGS
@given(frame_id=st.integers(0, 2**29 - 1), data=st.binary(max_size=8), extended=st.booleans(),
       remote=st.booleans(), error=st.booleans())
def test_bus_receiver_survives_any_frame(bus: CanTarget, frame_id: int, data: bytes, extended: bool,
                                         remote: bool, error: bool) -> None:
    if not extended:
        frame_id &= 0x7FF
    bus.feed(can.Message(arbitration_id=frame_id, data=data, is_extended_id=extended, is_remote_frame=remote,
                         is_error_frame=error))


@SETTINGS
@given(seed=st.integers(0, 2**64 - 1), n=st.integers(1, 60))
def test_bus_receiver_survives_sync_storms_and_mutated_frames(bus: CanTarget, seed: int, n: int) -> None:
    rng = random.Random(seed)
    for _ in range(n):
        bus.feed(bus.generate(rng))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**64 - 1))
def test_mission_loader_refuses_hostile_files_with_config_error_only(missions: MissionTarget, seed: int) -> None:
    missions.feed(missions.generate(random.Random(seed)))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(text=st.text(max_size=300))
def test_mission_loader_survives_any_text(missions: MissionTarget, text: str) -> None:
    missions.feed(text.encode("utf-8", "surrogatepass"))


def test_found_by_fuzzing_f32_telemetry_beyond_float32_saturates_instead_of_raising() -> None:
    """A diverging value (1e300) in an F32 channel or event argument raised OverflowError out of the
    flight software's telemetry sender (a GNC cycle would have died on it); it is sent as +-inf."""
    import math

    from comms.dictionary import DICTIONARY
    from fsw.telemetry import TelemetrySender
    from comms.telemetry import decode_tm_packet

    f32 = next(c.name for c in DICTIONARY.packet("GNC").channels if c.type == "F32")
    sender = TelemetrySender(DICTIONARY, port=None)
    packet = decode_tm_packet(DICTIONARY, sender.send_channels("GNC", {f32: -1e300}))
    assert packet.values[f32] == -math.inf
    sent = []
    sender._transmit = lambda raw: sent.append(raw) or raw
    assert sender.event("FDIR_TRIPPED", monitor="WHEEL_SPEED", action="ENTER_SAFE", value=1e300)
    assert decode_tm_packet(DICTIONARY, sent[-1]).args["value"] == math.inf
