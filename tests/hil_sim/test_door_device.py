"""The aperture door as a CAN device: its mechanism (strokes, silence, failures), its frames in the lockstep
tick (DOOR_STATUS counted in SYNC, DOOR_CMD taken on every receive path), and nothing of it without a door."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from fsw.bus import FswBusDriver
from comms.bus import Icd, open_bus
from hil_sim.devices.nodes import (DOOR_CLOSED, DOOR_CLOSING, DOOR_FAULT_CMD_TIMEOUT, DOOR_FAULT_STALLED, DOOR_OPEN,
                             DOOR_OPENING, DoorNode, DoorParams)
from hil_sim.devices.faults import FaultInjector, FaultSpec
from hil_sim.sil.lockstep import Simulator
from hil_sim.world.params import WorldParams
from hil_sim.world.world import World

_channels = itertools.count()
PERIOD = 0.1


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


def _door(icd: Icd, faults=(), **kw) -> DoorNode:
    params = DoorParams(close_time_s=kw.pop("close_time_s", 1.0), open_time_s=kw.pop("open_time_s", 2.0), **kw)
    return DoorNode(icd, params, faults=faults)


def _run(door: DoorNode, t0: float, t1: float, command: bool | None = None) -> list[float]:
    """Advance period by period from t0 to t1 (commanding ``command`` each period when given): positions."""
    out = []
    n = round((t1 - t0) / PERIOD)
    for k in range(n):
        t = t0 + k * PERIOD
        if command is not None:
            door.on_command(command, t)
        door.advance(t, t + PERIOD)
        out.append(door.position)
    return out


def _status(icd: Icd, door: DoorNode, t: float) -> dict:
    row = door.status_row(t)
    return {s: row[icd.column("DOOR_STATUS", s)] for s in icd.spec("DOOR_STATUS").signals}


def test_strokes_take_their_times_linearly(icd: Icd) -> None:
    door = _door(icd, initially_open=True)
    assert door.position == 1.0 and _status(icd, door, 0.0)["state"] == DOOR_OPEN
    closing = _run(door, 0.0, 1.2, command=False)
    # 1 s stroke: 10 % per 0.1 s period, shut at 1.0 s and held there
    assert closing[:3] == pytest.approx([0.9, 0.8, 0.7])
    assert closing[9] == pytest.approx(0.0, abs=1e-12) and closing[-1] == 0.0
    assert _status(icd, door, 1.2)["state"] == DOOR_CLOSED and _status(icd, door, 1.2)["commanded_open"] == 0
    opening = _run(door, 1.2, 3.4, command=True)
    assert opening[4] == pytest.approx(0.25)  # 2 s stroke: 5 % per period
    assert _status(icd, door, 1.7)["state"] in (DOOR_OPENING, DOOR_OPEN)
    assert opening[-1] == 1.0


def test_status_reports_the_motion_and_position(icd: Icd) -> None:
    door = _door(icd, initially_open=True)
    _run(door, 0.0, 0.3, command=False)
    st = _status(icd, door, 0.3)
    assert st["state"] == DOOR_CLOSING and st["position"] == pytest.approx(70.0) and st["fault"] == 0
    frame = icd.encode("DOOR_STATUS", st, 0)
    name, decoded = icd.decode(frame)
    assert name == "DOOR_STATUS" and decoded["position"] == pytest.approx(70.0, abs=0.05)


def test_drive_closes_by_itself_after_a_command_silence(icd: Icd) -> None:
    door = _door(icd, initially_open=True, close_on_silence_s=1.0)
    _run(door, 0.0, 5.0)  # never commanded: holds its launch position
    assert door.position == 1.0 and not door.silenced
    door.on_command(True, 5.0)
    positions = _run(door, 5.0, 7.5)
    # silent after 5.0: still open up to 6.0, then it closes within its 1 s stroke
    assert positions[8] == 1.0 and positions[-1] == 0.0
    st = _status(icd, door, 7.5)
    assert st["fault"] & DOOR_FAULT_CMD_TIMEOUT and st["commanded_open"] == 0
    door.on_command(True, 7.5)  # a valid command again: it obeys
    assert not door.silenced and _run(door, 7.5, 9.6, command=True)[-1] == 1.0


def test_no_silence_timeout_when_disabled(icd: Icd) -> None:
    door = _door(icd, initially_open=True, close_on_silence_s=0.0)
    door.on_command(True, 0.0)
    assert _run(door, 0.0, 10.0)[-1] == 1.0


def test_stuck_open_cannot_close_and_reports_the_stall(icd: Icd) -> None:
    stuck = FaultSpec("door_stuck_open", "DOOR_STATUS", 0.45, 2.0)
    logged = []
    door = _door(icd, faults=[stuck], initially_open=True)
    door._record = lambda t, f, detail: logged.append((t, f.kind))
    positions = _run(door, 0.0, 3.0, command=False)
    # closing until the failure at 0.45 s (the period starting at 0.5 s is the first failed), stuck until 2.0 s
    assert positions[4] == pytest.approx(0.5) and positions[19] == pytest.approx(0.5)
    assert positions[-1] == 0.0
    assert logged == [(0.5, "door_stuck_open")]
    door2 = _door(icd, faults=[stuck], initially_open=True)
    _run(door2, 0.0, 1.0, command=False)
    assert _status(icd, door2, 1.0)["fault"] & DOOR_FAULT_STALLED


def test_stuck_closed_cannot_open_and_slow_takes_longer(icd: Icd) -> None:
    door = _door(icd, faults=[FaultSpec("door_stuck_closed", "DOOR_STATUS", 0.0, 100.0)])
    assert _run(door, 0.0, 5.0, command=True)[-1] == 0.0 and door.stalled
    # a stuck-closed door still closes (the failure blocks only the opening)
    door = _door(icd, faults=[FaultSpec("door_stuck_closed", "DOOR_STATUS", 0.0, 100.0)], initially_open=True)
    assert _run(door, 0.0, 1.5, command=False)[-1] == 0.0
    slow = _door(icd, faults=[FaultSpec("door_slow", "DOOR_STATUS", 0.0, 100.0, delay_s=3.0)], initially_open=True)
    positions = _run(slow, 0.0, 5.0, command=False)
    assert positions[9] == pytest.approx(0.75)  # 1 s stroke + 3 s: 2.5 % per period
    assert positions[38] > 0.0 and positions[-1] == 0.0


def test_injector_checks_door_failures_and_leaves_frames_alone(icd: Icd) -> None:
    with pytest.raises(ValueError, match="door frame"):
        FaultInjector(icd, [FaultSpec("door_stuck_open", "IMU_RATE", 0.0, 1.0)])
    with pytest.raises(ValueError, match="delay_s"):
        FaultInjector(icd, [FaultSpec("door_slow", "DOOR_STATUS", 0.0, 1.0)])
    injector = FaultInjector(icd, [FaultSpec("door_stuck_open", "DOOR_STATUS", 0.0, 10.0)])
    assert injector.passes_through(1.0)  # a mechanism failure: no frame goes the injector's way


def _pair(icd: Icd, door: DoorParams | None, light: bool, faults=()):
    channel = f"virtual:door{next(_channels)}"
    sim_bus, fsw_bus = open_bus(channel, light=light), open_bus(channel, light=light)
    world = World(WorldParams(), seed=5)
    frames: list = []
    sim = Simulator(world, sim_bus, icd, door=door, faults=faults,
                    on_frame=lambda d, t, m: frames.append((d, m.arbitration_id, bytes(m.data))),
                    on_burst=lambda d, t, b, rows: frames.extend(
                        (d, int(b.ids[i]), bytes(b.data[i, :b.lengths[i]])) for i in (rows or range(len(b)))))
    driver = FswBusDriver(fsw_bus, icd, world.n_wheels)
    return sim, driver, frames, (sim_bus, fsw_bus)


def _cycle(driver: FswBusDriver, open_door: bool | None, with_commands: bool = True):
    inputs = driver.collect_tick(0.0)
    assert inputs is not None and inputs.complete
    if open_door is not None:  # in the wheel commands' burst, or a burst of its own before it
        driver.send_frame("DOOR_CMD", {"open": int(open_door), "tick_lsb": inputs.tick & 0xFFFF}, with_commands)
    driver.send_wheel_torques(inputs.tick, np.zeros(driver.n_wheels), cycle_done=True)
    return inputs


@pytest.mark.parametrize("light", [True, False])
def test_tick_carries_door_status_and_the_door_obeys_its_command(icd: Icd, light: bool) -> None:
    sim, driver, frames, buses = _pair(icd, DoorParams(close_time_s=1.0, open_time_s=1.0), light)
    try:
        driver.keep_latest("DOOR_STATUS")
        status_id = icd.spec("DOOR_STATUS").frame_id
        for k in range(25):
            sim.begin_tick()
            inputs = _cycle(driver, open_door=k >= 2, with_commands=light)
            sim.end_tick(wait_s=0.0)
            # SYNC counts the door's status among the frames that follow it, and the tick waits for it
            assert inputs.frames_received == inputs.frames_expected
            row, t = driver.latest("DOOR_STATUS")
            assert t == pytest.approx(inputs.t)
            if k < 2:  # commanded closed: it stays closed; then open within its 1 s stroke
                assert sim.door.position == 0.0
        assert sim.door.position == 1.0 and sim.door.commands_applied == 25
        assert row[icd.column("DOOR_STATUS", "state")] == DOOR_OPEN
        assert sum(1 for d, fid, _ in frames if d == "tx" and fid == status_id) == 25
        assert driver.counters["DOOR_STATUS"]["ok"] == 25 and sim.receiver.counters["DOOR_CMD"]["ok"] == 25
    finally:
        for bus in buses:
            bus.shutdown()


def test_door_failure_on_the_bus_and_in_the_fault_log(icd: Icd) -> None:
    stuck = FaultSpec("door_stuck_closed", "DOOR_STATUS", 0.5, 100.0)
    sim, driver, _, buses = _pair(icd, DoorParams(close_time_s=1.0, open_time_s=1.0), True, faults=[stuck])
    try:
        driver.keep_latest("DOOR_STATUS")
        for _ in range(20):
            sim.begin_tick()
            _cycle(driver, open_door=True)
            sim.end_tick(wait_s=0.0)
        row, _ = driver.latest("DOOR_STATUS")
        # opened half way before the failure, then stalled there
        assert sim.door.position == pytest.approx(0.5)
        assert row[icd.column("DOOR_STATUS", "fault")] == DOOR_FAULT_STALLED
        assert [(e.kind, e.message) for e in sim.injector.log] == [("door_stuck_closed", "DOOR_STATUS")]
    finally:
        for bus in buses:
            bus.shutdown()


def test_without_a_door_nothing_of_it_is_on_the_bus(icd: Icd) -> None:
    sim, driver, frames, buses = _pair(icd, None, True)
    door_ids = {icd.spec("DOOR_CMD").frame_id, icd.spec("DOOR_STATUS").frame_id}
    try:
        for _ in range(5):
            sim.begin_tick()
            _cycle(driver, open_door=None)
            sim.end_tick(wait_s=0.0)
        assert sim.door is None and frames and not any(fid in door_ids for _, fid, _ in frames)
    finally:
        for bus in buses:
            bus.shutdown()
    with pytest.raises(ValueError, match="no door"):
        _pair(icd, None, True, faults=[FaultSpec("door_slow", "DOOR_STATUS", 0.0, 1.0, delay_s=1.0)])
