"""E2E protection: CRC-8 SAE J1850 against published check values, receiver classification."""
from __future__ import annotations

import can
import pytest

from comms.bus.crc import crc8_sae_j1850, e2e_crc
from comms.bus.e2e import (BAD_LENGTH, BUS_KEY, CRC_ERROR, OK, OK_SOME_LOST, OUT_OF_RANGE, REPEATED, TIMEOUT,
                         UNKNOWN_ID, WRONG_SEQUENCE, E2EReceiver)
from comms.bus.icd import E2ESender, Icd


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


# AUTOSAR SWS CRC Library, CRC8 (SAE J1850) check table, and the reveng catalogue check value.
@pytest.mark.parametrize("data,expected", [
    ("00000000", 0x59), ("F20183", 0x37), ("0FAA0055", 0x79), ("00FF5511", 0xB8),
    ("332255AABBCCDDEEFF", 0xCB), ("926B55", 0x8C), ("FFFFFFFF", 0x74),
    ("313233343536373839", 0x4B),
])
def test_crc8_sae_j1850_matches_published_values(data: str, expected: int) -> None:
    assert crc8_sae_j1850(bytes.fromhex(data)) == expected


def test_crc_can_be_computed_in_pieces() -> None:
    whole = crc8_sae_j1850(b"123456789")
    reg = crc8_sae_j1850(b"1234", final_xor=False)
    assert crc8_sae_j1850(b"56789", crc=reg) == whole


def test_e2e_crc_covers_data_id_low_byte_first() -> None:
    payload = bytes.fromhex("0102030405")
    assert e2e_crc(0x1234, payload) == crc8_sae_j1850(bytes([0x34, 0x12]) + payload)
    assert e2e_crc(0x1234, payload) != e2e_crc(0x1235, payload)


def _receiver(icd: Icd) -> E2EReceiver:
    return E2EReceiver(icd, ignore_ids=icd.ids_sent_by("FSW"))


IMU = dict(omega_x=0.01, omega_y=-0.02, omega_z=0.003, saturated=0)


def test_counter_sequence_classification(icd: Icd) -> None:
    rx = _receiver(icd)
    frames = [icd.encode("IMU_RATE", IMU, c) for c in (5, 6, 6, 8, 12, 13, 11, 14)]
    statuses = [rx.classify(f, 0.0).status for f in frames]
    # 5 first -> ok, 6 -> ok, 6 again -> repeated, 8 (one lost, max delta 2) -> ok_some_lost,
    # 12 (jump of 4) -> wrong_sequence, 13 -> ok (resynchronised), 11 (backwards: an old, delayed frame)
    # -> wrong_sequence without disturbing the reference, so 14 -> ok
    assert statuses == [OK, OK, REPEATED, OK_SOME_LOST, WRONG_SEQUENCE, OK, WRONG_SEQUENCE, OK]
    c = rx.counters["IMU_RATE"]
    assert (c[OK], c[REPEATED], c[OK_SOME_LOST], c[WRONG_SEQUENCE]) == (4, 1, 1, 2)


def test_counter_wraps_modulo_16(icd: Icd) -> None:
    rx = _receiver(icd)
    statuses = [rx.classify(icd.encode("IMU_RATE", IMU, c % 16), 0.0).status for c in range(14, 20)]
    assert statuses == [OK] * 6


def test_only_delivered_frames_carry_signals(icd: Icd) -> None:
    rx = _receiver(icd)
    ok = rx.classify(icd.encode("IMU_RATE", IMU, 1), 0.0)
    rep = rx.classify(icd.encode("IMU_RATE", IMU, 1), 0.0)
    assert ok.delivered and ok.signals["omega_y"] == pytest.approx(-0.02, abs=5e-6)
    assert not rep.delivered and rep.signals is None


@pytest.mark.parametrize("name", ["SYNC", "IMU_RATE", "ST_QUAT_A", "ST_QUAT_B", "RW1_STATUS"])
def test_every_single_bit_flip_is_a_crc_error(icd: Icd, name: str) -> None:
    sender = E2ESender(icd)
    values = {
        "SYNC": dict(tick=123456, frames_following=17, period_ms=100),
        "IMU_RATE": IMU,
        "ST_QUAT_A": dict(q_w=0.5, q_x=-0.5, valid=1, blind_source=2, sample_seq=9),
        "ST_QUAT_B": dict(q_y=0.5, q_z=0.5, sample_seq=9, age_ms=40),
        "RW1_STATUS": dict(speed=100.0, torque=0.01, current=0.3, temp=25, fault=0),
    }[name]
    good = sender.frame(name, values)
    for bit in range(8 * len(good.data)):
        rx = _receiver(icd)
        data = bytearray(good.data)
        data[bit // 8] ^= 1 << (bit % 8)
        bad = can.Message(arbitration_id=good.arbitration_id, data=bytes(data), is_extended_id=False)
        assert rx.classify(bad, 0.0).status == CRC_ERROR, f"bit {bit} flip not detected"
        assert rx.counters[name][CRC_ERROR] == 1


def test_frame_under_wrong_id_fails_crc(icd: Icd) -> None:
    """Same layout, different data id: RW2_STATUS bytes sent as RW1_STATUS must not be accepted."""
    rx = _receiver(icd)
    frame = icd.encode("RW2_STATUS", dict(speed=1.0, torque=0.0, current=0.0, temp=20, fault=0), 0)
    moved = can.Message(arbitration_id=icd.spec("RW1_STATUS").frame_id, data=frame.data, is_extended_id=False)
    assert rx.classify(moved, 0.0).status == CRC_ERROR


def test_bad_length_unknown_id_and_out_of_range(icd: Icd) -> None:
    rx = _receiver(icd)
    frame = icd.encode("IMU_RATE", IMU, 0)
    short = can.Message(arbitration_id=frame.arbitration_id, data=frame.data[:7], is_extended_id=False)
    assert rx.classify(short, 0.0).status == BAD_LENGTH
    assert rx.classify(can.Message(arbitration_id=0x7FF, data=b"\x00" * 8, is_extended_id=False), 0.0).status \
        == UNKNOWN_ID
    assert rx.classify(can.Message(arbitration_id=0x40, data=b"\x00" * 8, is_extended_id=True), 0.0).status \
        == UNKNOWN_ID
    # A SYNC with period_ms = 0 (DBC range 1..4095) but a correct CRC: a sender bug, rejected.
    spec = icd.spec("SYNC")
    payload = spec.db_message.encode(dict(E2E_CRC=0, E2E_Counter=0, tick=1, frames_following=0, period_ms=0),
                                     strict=False)
    data = spec.db_message.encode(dict(E2E_CRC=e2e_crc(spec.data_id, payload[1:]), E2E_Counter=0, tick=1,
                                       frames_following=0, period_ms=0), strict=False)
    bad = can.Message(arbitration_id=spec.frame_id, data=data, is_extended_id=False)
    assert rx.classify(bad, 0.0).status == OUT_OF_RANGE
    assert rx.counters["IMU_RATE"][BAD_LENGTH] == 1
    assert rx.counters[BUS_KEY][UNKNOWN_ID] == 2
    assert rx.counters["SYNC"][OUT_OF_RANGE] == 1


def test_own_echo_is_ignored(icd: Icd) -> None:
    rx = _receiver(icd)
    assert rx.classify(icd.encode("CYCLE_DONE", dict(tick=3), 0), 0.0) is None
    assert rx.counters[BUS_KEY]["own_echo"] == 1
    assert "CYCLE_DONE" not in rx.counters


def test_timeout_counted_once_per_silence_and_rearmed(icd: Icd) -> None:
    rx = _receiver(icd)
    timeout = icd.spec("IMU_RATE").timeout_s
    rx.classify(icd.encode("IMU_RATE", IMU, 0), 1.0)
    assert "IMU_RATE" not in rx.check_timeouts(1.0 + timeout)
    assert "IMU_RATE" in rx.check_timeouts(1.0 + timeout + 0.001)
    rx.check_timeouts(5.0)
    assert rx.counters["IMU_RATE"][TIMEOUT] == 1
    rx.classify(icd.encode("IMU_RATE", IMU, 1), 5.0)
    assert "IMU_RATE" not in rx.check_timeouts(5.0)
    rx.check_timeouts(10.0)
    assert rx.counters["IMU_RATE"][TIMEOUT] == 2


def test_first_frame_after_a_timeout_restarts_the_sequence(icd: Icd) -> None:
    rx = _receiver(icd)
    assert rx.classify(icd.encode("SYNC", dict(tick=1, frames_following=0, period_ms=100), 3), 0.0).status == OK
    rx.check_timeouts(10.0)
    # counter 9 after 3 would be a wrong sequence, but the link was declared lost: fresh start
    assert rx.classify(icd.encode("SYNC", dict(tick=2, frames_following=0, period_ms=100), 9), 10.0).status == OK
    assert rx.classify(icd.encode("SYNC", dict(tick=3, frames_following=0, period_ms=100), 10), 10.0).status == OK
    assert rx.counters["SYNC"][TIMEOUT] == 1
