"""SecOC-style frame authentication (comms.bus.secoc): only frames whose authenticator's MAC matches, under a
freshness value above the last accepted one, reach the flight software or the simulator. Forged, injected
and replayed frames (of this run or of an earlier one) are counted and dropped; frames injected between a
genuine frame and its authenticator do not void it."""
from __future__ import annotations

import itertools
import secrets
from pathlib import Path

import can
import pytest

from comms.bus import E2ESender, Icd, open_bus
from fsw.bus import FswBusDriver
from comms.bus.icd import IcdError
from comms.bus.secoc import CANDIDATES, SecOCBus, association, authenticator, next_freshness, secure

_channels = itertools.count()
KEY = bytes(range(32))


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


@pytest.fixture
def wire():
    """Four ends of one in-process bus: the simulator's, the flight software's, an attacker's and a listener's
    (which records what crosses the bus)."""
    channel = f"virtual:secoc{next(_channels)}"
    ends = [open_bus(channel) for _ in range(4)]
    yield ends
    for end in ends:
        end.shutdown()


def _status(i: int) -> dict:
    return dict(speed=10.0 * i, torque=0.0, current=0.1, temp=20, fault=0)


def _tick(tx: E2ESender, tick: int) -> list[can.Message]:
    return ([tx.frame("SYNC", dict(tick=tick, frames_following=4, period_ms=100))]
            + [tx.frame(f"RW{i}_STATUS", _status(i)) for i in range(1, 5)])


def _received(bus: can.BusABC) -> list[can.Message]:
    return bus.recv_queued(0.2)


def test_an_authenticated_batch_arrives_unchanged_and_its_authenticator_is_not_handed_up(icd, wire) -> None:
    sim_raw, fsw_raw, _, _ = wire
    sim, fsw = secure(sim_raw, icd, KEY, "SIM"), secure(fsw_raw, icd, KEY, "FSW")
    frames = _tick(E2ESender(icd), 0)
    assert sim.send_batch(frames) == len(frames)
    got = _received(fsw)
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [(m.arbitration_id, bytes(m.data)) for m in frames]
    assert fsw.counters.frames_accepted == 5 and fsw.auth_failures == 0


def test_frames_injected_between_a_frame_and_its_authenticator_do_not_void_it(icd, wire) -> None:
    sim_raw, fsw_raw, attacker, _ = wire
    sim, fsw = secure(sim_raw, icd, KEY, "SIM"), secure(fsw_raw, icd, KEY, "FSW")
    tx = E2ESender(icd)
    genuine = tx.frame("RW2_STATUS", _status(2))
    forged = [tx.frame("RW2_STATUS", _status(9)) for _ in range(CANDIDATES - 1)]  # valid E2E: the CRC stops nobody
    sim_raw.send(genuine)
    for msg in forged:  # land between the frame and its authenticator
        attacker.send(msg)
    sim_raw.send(authenticator(sim.assoc.tx_key, sim.assoc.tx_auth_id, 1, genuine))
    got = _received(fsw)
    assert [bytes(m.data) for m in got] == [bytes(genuine.data)]
    sim._tx_freshness = 1
    more = _tick(tx, 1)
    sim.send_batch(more)
    assert [bytes(m.data) for m in _received(fsw)] == [bytes(m.data) for m in more]
    assert fsw.counters.bad_mac == 0 and fsw.counters.frames_accepted == 6


def test_a_forged_authenticator_releases_nothing(icd, wire) -> None:
    _, fsw_raw, attacker, _ = wire
    fsw = secure(fsw_raw, icd, KEY, "FSW")
    forged = E2ESender(icd).frame("SYNC", dict(tick=50, frames_following=0, period_ms=100))
    attacker.send(forged)
    attacker.send(authenticator(secrets.token_bytes(32), fsw.assoc.rx_auth_id, 1, forged))
    attacker.send(can.Message(arbitration_id=fsw.assoc.rx_auth_id, data=b"\x10\x00", is_extended_id=False))
    assert _received(fsw) == [] and fsw.counters.bad_mac == 2


def test_frames_without_an_authenticator_never_reach_the_receiver(icd, wire) -> None:
    _, fsw_raw, attacker, _ = wire
    fsw = secure(fsw_raw, icd, KEY, "FSW")
    for msg in _tick(E2ESender(icd), 7):
        attacker.send(msg)
    attacker.send(can.Message(arbitration_id=0x7FF, data=b"\x00" * 8, is_extended_id=False))
    assert _received(fsw) == []
    assert fsw.counters.foreign == 1  # an identifier the simulator never sends


def test_a_replayed_batch_is_refused_whether_from_this_run_or_an_earlier_one(icd, wire) -> None:
    sim_raw, fsw_raw, attacker, tap = wire
    sim, fsw = secure(sim_raw, icd, KEY, "SIM"), secure(fsw_raw, icd, KEY, "FSW")
    tx = E2ESender(icd)
    sim.send_batch(_tick(tx, 0))
    assert len(_received(fsw)) == 5
    recorded = _drain(tap)
    assert len(recorded) == 10  # five frames and their authenticators, as a listener on the bus sees them
    for msg in recorded:  # the same batch again, bit for bit
        attacker.send(msg)
    assert _received(fsw) == []
    earlier = secure(attacker, icd, secrets.token_bytes(32), "SIM")  # a recording made under another run's key
    earlier.send_batch(_tick(tx, 5))
    assert _received(fsw) == []
    assert fsw.counters.bad_mac == 10 and fsw.counters.frames_accepted == 5


def _drain(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (msg := bus.recv(0.1)) is not None:
        out.append(msg)
    return out


def test_freshness_is_rebuilt_from_its_low_bits_and_only_ever_moves_forward() -> None:
    assert next_freshness(0, 1) == 1
    assert next_freshness(5, 9) == 9
    assert next_freshness(0x1FFFFF, 0x000000) == 0x200000  # across the wrap of the 21 transmitted bits
    assert next_freshness(0x212345, 0x12345) == 0x412345  # the value already accepted: only a later one fits
    assert next_freshness(0x212345, 0x12344) == 0x412344


def test_lost_batches_do_not_desynchronise_the_receiver(icd, wire) -> None:
    sim_raw, fsw_raw, _, _ = wire
    sim, fsw = secure(sim_raw, icd, KEY, "SIM"), secure(fsw_raw, icd, KEY, "FSW")
    sim._tx_freshness = 1_000_000  # a million frames lost on the way
    sim.send_batch(_tick(E2ESender(icd), 3))
    assert len(_received(fsw)) == 5 and fsw._rx_freshness == 1_000_005


def test_each_direction_has_its_own_key_so_a_frame_cannot_be_reflected(icd, wire) -> None:
    sim_raw, fsw_raw, attacker, _ = wire
    fsw = secure(fsw_raw, icd, KEY, "FSW")
    reflected = SecOCBus(attacker, association(icd, KEY, "FSW"))  # signs as the FSW would, in the SIM's id
    cmd = E2ESender(icd).frame("SYNC", dict(tick=1, frames_following=0, period_ms=100))
    attacker.send(cmd)
    attacker.send(authenticator(reflected.assoc.tx_key, fsw.assoc.rx_auth_id, 1, cmd))
    assert _received(fsw) == [] and fsw.counters.bad_mac == 1


def test_the_flight_software_driver_reads_a_lockstep_tick_through_the_layer(icd, wire) -> None:
    sim_raw, fsw_raw, attacker, _ = wire
    sim, fsw = secure(sim_raw, icd, KEY, "SIM"), secure(fsw_raw, icd, KEY, "FSW")
    drv = FswBusDriver(fsw, icd, n_wheels=4)
    tx = E2ESender(icd)
    for msg in _tick(E2ESender(icd), 90):  # a forged SYNC far ahead with its device frames, unauthenticated
        attacker.send(msg)
    sim.send_batch(_tick(tx, 0))
    inputs = drv.collect_tick(timeout_s=1.0)
    assert inputs.tick == 0 and inputs.complete
    assert [w.speed_rad_s for w in inputs.wheels] == pytest.approx([10, 20, 30, 40], abs=0.05)
    drv.send_wheel_torques(0, [0.01, 0.0, 0.0, -0.01], cycle_done=True)
    got = _received(sim)
    assert {m.arbitration_id for m in got} >= {icd.spec("RW1_CMD").frame_id, icd.spec("CYCLE_DONE").frame_id}


def test_an_icd_whose_authenticator_has_another_layout_is_refused(tmp_path: Path) -> None:
    text = Icd().path.read_text().replace(" SG_ mac : 32|32@1+ (1,0) [0|4294967295] \"\" FSW",
                                          " SG_ mac : 32|24@1+ (1,0) [0|16777215] \"\" FSW", 1)
    bad = tmp_path / "bad.dbc"
    bad.write_text(text)
    with pytest.raises(IcdError, match="SECOC_SIM.*SecOC authenticator"):
        Icd(bad)


def test_authentication_needs_both_authenticator_frames(tmp_path: Path) -> None:
    kept, in_block = [], False
    for line in Icd().path.read_text().splitlines():  # SECOC_FSW goes: its BO_ line, signals and attributes
        in_block = line.startswith("BO_ 1009") or (in_block and line.startswith(" SG_"))
        if not in_block and " 1009 " not in line:
            kept.append(line)
    path = tmp_path / "one.dbc"
    path.write_text("\n".join(kept) + "\n")
    with pytest.raises(ValueError, match="SIM and FSW"):
        association(Icd(path), KEY, "SIM")
