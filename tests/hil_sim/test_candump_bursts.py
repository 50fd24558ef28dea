"""The SIL's bus.candump.log written per burst (CandumpLog.log_burst, the simulator's ``on_burst``) is the
log written per frame (``on_frame`` alone, which takes the simulator off its burst paths): the same lines,
byte for byte, in the same order, with the same time stamps, and the simulator behaves the same."""
from __future__ import annotations

import itertools
from pathlib import Path

import can
import numpy as np
import pytest

from fsw.bus import FswBusDriver
from comms.bus import Icd, open_bus
from comms.bus.burst import FrameBurst
from hil_sim.devices.faults import FaultSpec
from hil_sim.sil.lockstep import RateDampingResponder, Simulator
from hil_sim.world.params import SpacecraftParams, WorldParams
from hil_sim.sil.orchestrator import CandumpLog
from hil_sim.world.world import World

_channels = itertools.count()


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


# ------------------------------------------------------------------------------ the formatter alone
def _array_burst() -> FrameBurst:
    """Plain data frames from arrays (as the simulator's sender makes them); bytes past each length are
    not zero here, so a line that shows them would differ from the message's."""
    ids = np.array([0x010, 0x7FF, 0x123, 0x000, 0x0A5], dtype=np.int64)
    lengths = np.array([8, 0, 3, 1, 8], dtype=np.int64)
    data = np.arange(40, dtype=np.uint8).reshape(5, 8) * 7
    return FrameBurst(ids, data, lengths)


def _odd_messages() -> list[can.Message]:
    """Received frames of every kind: standard data (bytearray, bytes, empty), extended, remote, error,
    FD with 64 bytes, an extended frame with a small id."""
    return [
        can.Message(arbitration_id=0x101, data=bytearray(b"\x01\x02\xab"), is_extended_id=False),
        can.Message(arbitration_id=0x18FF50E5, data=b"\xde\xad\xbe\xef", is_extended_id=True),
        can.Message(arbitration_id=0x102, data=b"", is_extended_id=False),
        can.Message(arbitration_id=0x103, is_remote_frame=True, dlc=4, is_extended_id=False),
        can.Message(arbitration_id=0x20000004, is_error_frame=True, data=bytearray(8)),
        can.Message(arbitration_id=0x104, data=bytes(range(64)), is_fd=True, is_extended_id=False),
        can.Message(arbitration_id=0x105, data=bytes(b"\xff" * 8), is_extended_id=False),
        can.Message(arbitration_id=0x7, data=b"\x10", is_extended_id=True),
    ]


def _logs(tmp_path: Path) -> tuple[CandumpLog, CandumpLog]:
    return CandumpLog(tmp_path / "frames.log", "vcan0"), CandumpLog(tmp_path / "bursts.log", "vcan0")


def _closed(tmp_path: Path, logs: tuple[CandumpLog, CandumpLog]) -> tuple[bytes, bytes]:
    for log in logs:
        log.close()
    return (tmp_path / "frames.log").read_bytes(), (tmp_path / "bursts.log").read_bytes()


@pytest.mark.parametrize("make", [_array_burst, lambda: FrameBurst.from_messages(_odd_messages()),
                                  lambda: FrameBurst.from_messages([]), lambda: _array_burst().tail(2)],
                         ids=["arrays", "messages", "empty", "tail"])
@pytest.mark.parametrize("rows", [None, "first-two", "every-other", "none"])
def test_a_burst_logs_the_lines_of_its_messages(tmp_path: Path, make, rows) -> None:
    burst = make()
    n = len(burst)
    picked = {None: None, "first-two": range(min(2, n)), "every-other": list(range(0, n, 2)), "none": []}[rows]
    frames, bursts = _logs(tmp_path)
    for t_s, direction in ((0.0, "tx"), (0.1, "rx"), (0.1, "rx"), (1234.5678901, "tx")):
        for i in range(n) if picked is None else picked:
            frames(direction, t_s, burst.message(i))
        bursts.log_burst(direction, t_s, burst, picked)
    assert bursts.frames == frames.frames == 4 * (n if picked is None else len(picked))
    a, b = _closed(tmp_path, (frames, bursts))
    assert a == b


def test_per_frame_and_burst_calls_mix_in_one_log(tmp_path: Path) -> None:
    """The time stamp and identifier caches are shared: alternating calls give the per-frame log."""
    burst = FrameBurst.join([_array_burst(), FrameBurst.from_messages(_odd_messages())])
    frames, bursts = _logs(tmp_path)
    for k in range(6):
        t_s = 0.1 * (k // 2)
        for i in range(len(burst)):
            frames("rx", t_s, burst.message(i))
        if k % 2:
            bursts.log_burst("rx", t_s, burst)
        else:
            for i in range(len(burst)):
                bursts("rx", t_s, burst.message(i))
    a, b = _closed(tmp_path, (frames, bursts))
    assert a == b
    lines = a.decode().splitlines()
    # the kinds formatted from their messages are there (extended: 8 digits; FD: 64 bytes)
    assert "(0.000000) vcan0 18FF50E5#DEADBEEF" in lines
    assert "(0.000000) vcan0 00000007#10" in lines
    assert f"(0.000000) vcan0 104#{bytes(range(64)).hex().upper()}" in lines
    assert "(0.000000) vcan0 7FF#" in lines and "(0.000000) vcan0 123#70777E" in lines


# ------------------------------------------------------------------------ the simulator, both ways
def _params() -> WorldParams:
    return WorldParams(spacecraft=SpacecraftParams(omega_BN_B0_rad_s=(0.02, -0.01, 0.015)))


def _odd_frames(icd: Icd, k: int, fd: bool = True) -> list[can.Message]:
    """Frames a third node puts on the bus: the kinds the compiled classifier leaves to the Python path
    (extended, remote, FD), an unknown id, and one with the simulator's own SYNC id (an own echo to it,
    never logged)."""
    sync_id = icd.spec("SYNC").frame_id
    frames = [can.Message(arbitration_id=0x1ABCDE0 + k, data=bytes([k & 0xFF, 1, 2]), is_extended_id=True),
              can.Message(arbitration_id=0x7F0, data=bytes([k & 0xFF]), is_extended_id=False),
              can.Message(arbitration_id=0x7F1, is_remote_frame=True, dlc=2, is_extended_id=False),
              can.Message(arbitration_id=sync_id, data=bytes(8), is_extended_id=False)]
    if fd:
        frames.append(can.Message(arbitration_id=0x7F2, data=bytes(range(12)), is_fd=True, is_extended_id=False))
    return frames


class _Refusing:
    """``bus.send`` that refuses every ``every``-th frame (transmit queue full), counted over the run."""

    def __init__(self, send, every: int) -> None:
        self.send, self.every, self.n = send, every, 0

    def __call__(self, msg: can.Message, timeout: float | None = None) -> None:
        self.n += 1
        if self.n % self.every == 0:
            raise can.CanOperationError("transmit buffer full")
        self.send(msg, timeout)


SCENARIOS = {
    # name: (light buses, sim hears its own frames, odd frames before/after the answer, faults, refuse every,
    #        real time)
    "plain": (False, False, False, (), 0, False),
    "light": (True, False, False, (), 0, False),
    "own-echoes": (False, True, False, (), 0, False),
    "odd-frames": (False, False, True, (), 0, False),
    "light-odd-frames": (True, False, True, (), 0, False),
    "refused-frames": (False, False, False, (), 7, False),
    "faults": (False, False, True, (FaultSpec("drop", "IMU_RATE", 0.3, 0.6), FaultSpec("delay", "RW2_CMD", 0.8, 1.1,
                                                                                       delay_s=0.15),
                                    FaultSpec("duplicate", "CYCLE_DONE", 1.3, 1.5)), 0, False),
    "realtime": (False, False, True, (), 0, True),
    "socketcan": ("socketcan", False, True, (), 0, False),  # (the real bus: classic frames only)
}


def _fly(icd: Icd, tmp_path: Path, name: str, bursts: bool, n_ticks: int = 24):
    light, echoes, odd, faults, refuse, realtime = SCENARIOS[name]
    channel = "socketcan:vcan0" if light == "socketcan" else f"virtual:cb{next(_channels)}"
    if echoes:
        sim_bus = can.Bus(interface="virtual", channel=channel.split(":")[1], receive_own_messages=True)
    else:
        sim_bus = open_bus(channel, light=light is True)
    fsw_bus, odd_bus = open_bus(channel, light=light is True), open_bus(channel, light=light is True)
    if refuse:
        sim_bus.send = _Refusing(sim_bus.send, refuse)
    path = tmp_path / f"{name}-{'bursts' if bursts else 'frames'}.log"
    log = CandumpLog(path, "vcan0")
    per_frame_calls = [0]

    def on_frame(direction: str, t_s: float, msg: can.Message) -> None:
        per_frame_calls[0] += 1
        log(direction, t_s, msg)

    now = [0.0]
    try:
        params = _params()
        world = World(params, seed=7)
        sim = Simulator(world, sim_bus, icd, faults=faults, fault_seed=3, on_frame=on_frame,
                        on_burst=log.log_burst if bursts else None, clock=lambda: now[0])
        driver = FswBusDriver(fsw_bus, icd, world.n_wheels)
        responder = RateDampingResponder(driver, [w.axis_B for w in params.spacecraft.wheels], 5.0)
        for k in range(n_ticks):
            if realtime:
                sim.run_realtime(1, sleep=lambda dt: now.__setitem__(0, now[0] + dt))
            else:
                sim.begin_tick()
            if odd and k % 3 == 0:
                for msg in _odd_frames(icd, k, fd=light != "socketcan"):  # ahead of the answer: before CYCLE_DONE
                    odd_bus.send(msg)
            # (socketcan: the frames are on their way through the kernel; lockstep waits for CYCLE_DONE)
            responder.cycle(1.0 if light == "socketcan" else 0.0)
            if odd and k % 3 == 1:
                for msg in _odd_frames(icd, k, fd=light != "socketcan"):  # after CYCLE_DONE: handled a tick later
                    odd_bus.send(msg)
            if not realtime:
                sim.end_tick(wait_s=2.0 if light == "socketcan" else 0.0)
        log.close()
        return (path.read_bytes(), log.frames, per_frame_calls[0], vars(sim.stats),
                {m: dict(c) for m, c in sim.receiver.counters.items()}, sim.world.truth.q_NB.copy())
    finally:
        for bus in (sim_bus, fsw_bus, odd_bus):
            bus.shutdown()


@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.socketcan) if name == "socketcan" else name
                                  for name in SCENARIOS])
def test_the_simulator_logs_per_burst_what_it_logged_per_frame(icd: Icd, tmp_path: Path, name: str) -> None:
    log_a, n_a, calls_a, stats_a, counters_a, q_a = _fly(icd, tmp_path, name, bursts=False)
    log_b, n_b, calls_b, stats_b, counters_b, q_b = _fly(icd, tmp_path, name, bursts=True)
    assert log_a == log_b and n_a == n_b == log_a.count(b"\n") == calls_a
    assert stats_a == stats_b and counters_a == counters_b
    assert np.array_equal(q_a, q_b)
    light, echoes, odd, faults, refuse, realtime = SCENARIOS[name]
    if faults:
        # the fault injector's windows go frame by frame (on_frame), the rest per burst
        assert 0 < calls_b < calls_a
    elif realtime:
        assert 0 < calls_b < calls_a  # the real-time sensor frames between SYNCs go out as messages
    else:
        assert calls_b == 0  # the burst paths only: no frame became a message for the log
    lines = log_a.decode().splitlines()
    if odd:
        assert any("01ABCDE" in line for line in lines) and any(line.endswith(" 7F1#") for line in lines)
    if refuse:
        assert stats_a["tx_errors"] > 0
    if not realtime:
        assert stats_a["cycle_done"] > 0


def test_on_burst_needs_on_frame(icd: Icd, tmp_path: Path) -> None:
    bus = open_bus(f"virtual:cb{next(_channels)}")
    try:
        log = CandumpLog(tmp_path / "x.log", "vcan0")
        with pytest.raises(ValueError, match="on_burst needs on_frame"):
            Simulator(World(_params(), seed=1), bus, icd, on_burst=log.log_burst)
        log.close()
    finally:
        bus.shutdown()
