"""Fault injection: each kind is logged and the receiver classifies it as it should; nothing crashes."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from fsw.bus import FswBusDriver
from comms.bus import Icd, open_bus
from hil_sim.devices.faults import FaultInjector, FaultSpec
from hil_sim.sil.lockstep import RateDampingResponder, Simulator
from hil_sim.world.params import SpacecraftParams, WorldParams
from hil_sim.world.world import World

_channels = itertools.count()
T = 0.1  # GNC period


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


@pytest.fixture(scope="module")
def params() -> WorldParams:
    return WorldParams(spacecraft=SpacecraftParams(omega_BN_B0_rad_s=(0.01, 0.0, -0.01)))


def run_with_faults(icd: Icd, params: WorldParams, faults: list, ticks: int = 30):
    """In-process SIL for ``ticks`` with ``faults``; returns (sim, driver, per-tick inputs)."""
    channel = f"virtual:flt{next(_channels)}"
    sim_bus, fsw_bus = open_bus(channel), open_bus(channel)
    try:
        world = World(params, seed=7)
        sim = Simulator(world, sim_bus, icd, gnc_period_s=T, faults=faults)
        driver = FswBusDriver(fsw_bus, icd, world.n_wheels)
        responder = RateDampingResponder(driver, [w.axis_B for w in params.spacecraft.wheels])
        inputs = []
        for _ in range(ticks):
            sim.step_in_process(responder.cycle)
            inputs.append(responder.last_inputs)
        return sim, driver, inputs
    finally:
        sim_bus.shutdown()
        fsw_bus.shutdown()


def window(tick_from: int, tick_to: int) -> dict:
    """Fault window covering ticks [tick_from, tick_to] (frames are published at t_k = k T)."""
    return dict(start_s=tick_from * T - 1e-6, end_s=tick_to * T + 1e-6)


def only(counters: dict, name: str) -> dict:
    return {k: v for k, v in counters[name].items() if v and k != "ok"}


def test_baseline_without_faults_is_clean(icd, params) -> None:
    sim, driver, _ = run_with_faults(icd, params, [], ticks=20)
    assert all(not only(driver.counters, n) for n in driver.counters if n != "_bus")
    assert sim.injector.log == []


def test_drop_one_frame_is_some_lost_a_burst_wrong_sequence_a_long_gap_timeout(icd, params) -> None:
    faults = [FaultSpec("drop", "ST_QUAT_A", **window(10, 10)),
              FaultSpec("drop", "RW1_STATUS", **window(10, 11)),
              FaultSpec("drop", "IMU_RATE", **window(15, 15))]
    sim, driver, inputs = run_with_faults(icd, params, faults)
    assert only(driver.counters, "ST_QUAT_A") == {"ok_some_lost": 1}
    # 2 frames lost: the next one jumps by 3 > max delta 2 (and the gap of 0.3 s is not beyond the timeout)
    assert only(driver.counters, "RW1_STATUS") == {"wrong_sequence": 1}
    # a whole tick of IMU frames (100 ms > its 50 ms timeout): timeout, then a clean restart
    assert only(driver.counters, "IMU_RATE") == {"timeout": 1}
    assert inputs[10].star_tracker is None and inputs[11].star_tracker is not None
    assert inputs[12].wheels[0] is None and inputs[13].wheels[0] is not None
    assert inputs[15].imu is None and inputs[16].imu is not None
    assert [e.kind for e in sim.injector.log].count("drop") == 1 + 2 + 10


def test_delay_makes_an_old_frame_that_is_rejected(icd, params) -> None:
    faults = [FaultSpec("delay", "ST_QUAT_B", delay_s=0.25, **window(10, 10))]
    sim, driver, inputs = run_with_faults(icd, params, faults)
    # tick 11: next B skips one counter value (some lost); tick 13: the delayed one arrives with an old
    # counter (wrong sequence, not used); the fresh B of tick 13 is still in sequence.
    assert only(driver.counters, "ST_QUAT_B") == {"ok_some_lost": 1, "wrong_sequence": 1}
    assert inputs[10].star_tracker is None
    assert inputs[13].star_tracker is not None
    assert [e.kind for e in sim.injector.log] == ["delay"]


def test_duplicate_is_repeated(icd, params) -> None:
    sim, driver, inputs = run_with_faults(icd, params, [FaultSpec("duplicate", "RW2_STATUS", **window(5, 7))])
    assert only(driver.counters, "RW2_STATUS") == {"repeated": 3}
    assert all(i.wheels[1] is not None for i in inputs[1:])  # the original still gets through
    assert len(sim.injector.log) == 3


def test_corrupt_bit_is_crc_error_and_never_reaches_the_application(icd, params) -> None:
    sim, driver, inputs = run_with_faults(icd, params, [FaultSpec("corrupt", "ST_QUAT_A", bit=30, **window(8, 9))])
    assert only(driver.counters, "ST_QUAT_A") == {"crc_error": 2, "wrong_sequence": 1}
    assert inputs[8].star_tracker is None and inputs[9].star_tracker is None
    assert inputs[11].star_tracker is not None


def test_stuck_alive_counter_is_repeated(icd, params) -> None:
    sim, driver, inputs = run_with_faults(icd, params, [FaultSpec("stick_counter", "RW1_STATUS", **window(10, 14))])
    # tick 10 carries the frozen value legitimately (ok); ticks 11..14 repeat it, which by tick 14 is
    # longer than the 0.3 s timeout; tick 15 restarts the sequence.
    assert only(driver.counters, "RW1_STATUS") == {"repeated": 4, "timeout": 1}
    assert inputs[10].wheels[0] is not None
    assert all(inputs[k].wheels[0] is None for k in range(11, 15))
    assert inputs[15].wheels[0] is not None


def test_babbling_node_is_unknown_id_and_real_traffic_survives(icd, params) -> None:
    fault = FaultSpec("babble", "RW3_STATUS", babble_per_tick=200, **window(5, 9))
    sim, driver, inputs = run_with_faults(icd, params, [fault])
    assert driver.counters["_bus"]["unknown_id"] == 5 * 200
    assert all(not only(driver.counters, n) for n in driver.counters if n != "_bus")
    assert all(i.complete for i in inputs)
    assert sim.stats.cycle_done == 30


def test_silent_node_times_out_and_recovers(icd, params) -> None:
    sim, driver, inputs = run_with_faults(icd, params, [FaultSpec("silent", "IMU_RATE", **window(10, 14))])
    assert only(driver.counters, "IMU_RATE") == {"timeout": 1}  # the first frame after it restarts the sequence
    assert all(inputs[k].imu is None for k in range(10, 15))
    assert inputs[16].imu is not None
    assert {e.message for e in sim.injector.log} == {"IMU_RATE"}


def test_faults_on_flight_software_frames(icd, params) -> None:
    """Drop CYCLE_DONE once; silence the flight software so the wheels time out their commands."""
    faults = [FaultSpec("drop", "CYCLE_DONE", **window(5, 5)), FaultSpec("silent", "RW1_CMD", **window(12, 17))]
    sim, driver, inputs = run_with_faults(icd, params, faults)
    assert sim.stats.cycle_done_timeouts == 1 + 6  # FSW node silent over ticks 12..17
    assert sim.receiver.counters["RW1_CMD"]["timeout"] == 1
    assert sim.receiver.counters["CYCLE_DONE"]["ok_some_lost"] == 1
    # commands stop reaching the wheels at t=1.2 s; after 0.3 s they zero and report it
    assert inputs[16].wheels[0].fault & 2
    assert not inputs[25].wheels[0].fault & 2


def test_fault_specs_are_validated(icd) -> None:
    with pytest.raises(ValueError, match="not in the ICD"):
        FaultInjector(icd, [FaultSpec("drop", "NOPE", 0, 1)])
    with pytest.raises(ValueError, match="delay_s"):
        FaultInjector(icd, [FaultSpec("delay", "IMU_RATE", 0, 1)])
    with pytest.raises(ValueError, match="bit in 0..47"):
        FaultInjector(icd, [FaultSpec("corrupt", "CYCLE_DONE", 0, 1, bit=50)])
    with pytest.raises(ValueError, match="allowed"):
        FaultInjector(icd, [FaultSpec("melt", "IMU_RATE", 0, 1)])


def test_mission_bus_fault_entries_are_accepted(icd) -> None:
    from hil_sim.mission.model import BusFault

    fault = BusFault(kind="corrupt", message="IMU_RATE", start_s=1.0, end_s=2.0, bit=17)
    injector = FaultInjector(icd, [fault])
    assert injector.faults[0] == FaultSpec("corrupt", "IMU_RATE", 1.0, 2.0, bit=17)


def test_probability_is_seeded(icd, params) -> None:
    fault = FaultSpec("drop", "IMU_RATE", probability=0.3, **window(3, 12))
    a = run_with_faults(icd, params, [fault], ticks=15)[0].injector.log
    b = run_with_faults(icd, params, [fault], ticks=15)[0].injector.log
    assert a == b and 10 < len(a) < 60


# ------------------------------------------------------------------------------ simulator-side robustness
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@pytest.fixture(scope="module")
def shared_world(params) -> World:
    return World(params, seed=1)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frames=st.lists(st.tuples(st.one_of(st.integers(0, 0x7FF), st.sampled_from([0x20, 0x21, 0x22, 0x23, 0x70])),
                                 st.binary(min_size=0, max_size=8), st.booleans()), min_size=1, max_size=40))
def test_random_frames_never_move_the_wheels(icd, shared_world, frames) -> None:
    """Garbage from the flight-software side: only the simulator's classification counters change."""
    import can

    channel = f"virtual:hypsim{next(_channels)}"
    sim_bus, garbage = open_bus(channel), open_bus(channel)
    try:
        sim = Simulator(shared_world, sim_bus, icd)
        for fid, data, ext in frames:
            garbage.send(can.Message(arbitration_id=fid, data=data, is_extended_id=ext))
        sim.poll(sim.t_s)
    finally:
        sim_bus.shutdown()
        garbage.shutdown()
    counts = sim.receiver.counters
    delivered = sum(c["ok"] + c["ok_some_lost"] for n, c in counts.items() if n != "_bus")
    assert sum(n for c in counts.values() for k, n in c.items() if k != "timeout") == len(frames)
    if delivered == 0:
        assert all(w.last_cmd_t is None for w in sim.devices.wheels)
        assert np.all(sim.devices.wheel_torques(sim.t_s) == 0.0)
        assert sim.stats.cycle_done == 0 and sim.stats.wheel_commands == 0


def test_lost_sync_costs_one_cycle(icd, params) -> None:
    sim, driver, inputs = run_with_faults(icd, params, [FaultSpec("drop", "SYNC", **window(5, 5))], ticks=12)
    assert sim.stats.cycle_done_timeouts == 1 and sim.stats.cycle_done == 11
    assert only(driver.counters, "SYNC") == {"ok_some_lost": 1}
    assert [i.tick for i in inputs] == [0, 1, 2, 3, 4, 4, 6, 7, 8, 9, 10, 11]  # tick 5 never started


def test_a_wheel_fault_fails_the_mechanism_at_its_time_and_leaves_the_frames_alone(icd, params) -> None:
    """wheel_stuck / wheel_no_torque act on the wheel, not on frames: the wheel of RWn_CMD seizes at start_s
    (its speed relative to the body drops to zero, as hil_sim.world.dynamics.seize_wheel does), every frame still
    goes out, the injector's log says when, and a mission may draw it in a campaign like any fault."""
    import dataclasses

    sc = params.spacecraft
    wheels = tuple(dataclasses.replace(w, initial_speed_rad_s=s) for w, s in zip(sc.wheels, (50.0, -40.0, 30.0, -20.0)))
    spinning = dataclasses.replace(params, spacecraft=dataclasses.replace(sc, wheels=wheels))
    faults = [FaultSpec("wheel_stuck", "RW2_CMD", 1.0, 1e5)]
    sim, _, inputs = run_with_faults(icd, spinning, faults, ticks=30)
    assert not sim.injector.faults  # nothing acts on frames
    assert [(e.kind, e.message, e.detail) for e in sim.injector.log] == [("wheel_stuck", "RW2_CMD", "wheel 2 stuck")]
    assert sim.injector.log[0].t_s == pytest.approx(1.0)
    speeds = sim.world.truth.wheel_speeds_rad_s
    assert speeds[1] == 0.0 and abs(speeds[0]) > 10.0 and all(inp.complete for inp in inputs)
    with pytest.raises(ValueError, match="RWn_CMD or RWn_STATUS"):
        Simulator(World(params, seed=1), open_bus(f"virtual:flt{next(_channels)}"), icd, gnc_period_s=T,
                  faults=[FaultSpec("wheel_stuck", "IMU_RATE", 1.0, 2.0)])
