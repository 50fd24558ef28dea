"""Lockstep SIL over the bus: in-process stepping, determinism, timeouts, real time, two runs side by side."""
from __future__ import annotations

import itertools
import os
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from fsw.bus import FswBusDriver
from comms.bus import Icd, open_bus
from comms.bus.transport import random_udp_endpoint
from hil_sim.sil.lockstep import RateDampingResponder, Simulator
from hil_sim.world.params import SpacecraftParams, WorldParams
from hil_sim.world.world import World

ROOT = Path(__file__).resolve().parents[2]
_channels = itertools.count()
OMEGA0 = (0.02, -0.01, 0.015)


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


def _params() -> WorldParams:
    return WorldParams(spacecraft=SpacecraftParams(omega_BN_B0_rad_s=OMEGA0))


def _in_process_pair(icd: Icd, seed: int = 3, **sim_kwargs):
    channel = f"virtual:ls{next(_channels)}"
    sim_bus, fsw_bus = open_bus(channel), open_bus(channel)
    params = _params()
    world = World(params, seed=seed)
    sim = Simulator(world, sim_bus, icd, **sim_kwargs)
    driver = FswBusDriver(fsw_bus, icd, world.n_wheels)
    responder = RateDampingResponder(driver, [w.axis_B for w in params.spacecraft.wheels], 5.0)
    return sim, driver, responder, (sim_bus, fsw_bus)


def _close(buses) -> None:
    for bus in buses:
        bus.shutdown()


@contextmanager
def _fake_clock_sim(icd: Icd, tag: str, **sim_kwargs):
    """A real-time Simulator (10 Hz GNC, 100 Hz dynamics) on a fresh virtual channel whose clock reads
    ``now[0]``, which the test's fake sleep moves on; yields (sim, world, the channel's other bus, now) and
    shuts both buses down."""
    channel = f"virtual:{tag}{next(_channels)}"
    sim_bus, peer_bus = open_bus(channel), open_bus(channel)
    try:
        world = World(_params(), seed=1)
        now = [0.0]
        sim = Simulator(world, sim_bus, icd, gnc_period_s=0.1, dynamics_dt_s=0.01, clock=lambda: now[0],
                        **sim_kwargs)
        yield sim, world, peer_bus, now
    finally:
        _close((sim_bus, peer_bus))


def test_in_process_closed_loop_damps_the_rate(icd: Icd) -> None:
    sim, driver, responder, buses = _in_process_pair(icd)
    try:
        for _ in range(100):
            assert sim.step_in_process(responder.cycle)
            inputs = responder.last_inputs
            assert inputs.complete and inputs.frames_received == inputs.frames_expected
        world = sim.world
        assert world.t == pytest.approx(10.0)
        assert np.linalg.norm(world.truth.omega_BN_B) < 0.1 * np.linalg.norm(OMEGA0)
        assert sim.stats.cycle_done == 100 and sim.stats.cycle_done_timeouts == 0
        assert sim.stats.wheel_commands == 100 * world.n_wheels
        # 100 Hz IMU at 10 Hz GNC: 10 samples per tick once running; nothing but ok on either side
        assert len(responder.last_inputs.imu_samples) == 10
        bad = {c: n for name, counts in driver.counters.items() for c, n in counts.items()
               if c not in ("ok",) and n}
        assert bad == {}
        assert all(n == 0 for c, n in sim.receiver.counters["CYCLE_DONE"].items() if c != "ok")
    finally:
        _close(buses)


def test_lockstep_is_deterministic(icd: Icd) -> None:
    def run() -> tuple[list, np.ndarray]:
        log: list = []
        sim, _, responder, buses = _in_process_pair(icd, seed=11,
                                                    on_frame=lambda d, t, m: log.append((d, t, m.arbitration_id,
                                                                                         bytes(m.data))))
        try:
            for _ in range(30):
                sim.step_in_process(responder.cycle)
            return log, sim.world.truth.q_NB
        finally:
            _close(buses)

    log_a, q_a = run()
    log_b, q_b = run()
    assert len(log_a) > 30 * 15
    assert log_a == log_b
    assert np.array_equal(q_a, q_b)


def test_missing_cycle_done_is_counted_and_the_world_steps_with_held_then_zero_torque(icd: Icd) -> None:
    sim, driver, responder, buses = _in_process_pair(icd)
    try:
        for _ in range(5):
            sim.step_in_process(responder.cycle)
        held = sim.devices.wheel_torques(sim.t_s).copy()
        assert np.any(held != 0)
        t_before = sim.world.t
        for _ in range(5):  # the flight software stops answering
            sim.begin_tick()
            assert sim.end_tick(wait_s=0.01) is False
        assert sim.stats.cycle_done_timeouts == 5
        assert sim.world.t == pytest.approx(t_before + 0.5)
        # command timeout 0.3 s: torque held for 3 periods, then zero, and the status says why
        assert np.all(sim.devices.wheel_torques(sim.t_s) == 0.0)
        sim.begin_tick()
        ticks = list(iter(lambda: driver.collect_tick(0.0), None))  # the backlog, oldest first
        assert [i.tick for i in ticks] == list(range(5, 11))
        inputs = ticks[-1]
        assert all(w.fault & 2 for w in inputs.wheels)
        assert all(w.torque_Nm == 0.0 for w in inputs.wheels)
    finally:
        _close(buses)


def test_realtime_never_waits_for_the_flight_software(icd: Icd) -> None:
    sim, _, _, buses = _in_process_pair(icd, gnc_period_s=0.02, dynamics_dt_s=0.01)
    try:
        start = time.monotonic()
        sim.run_realtime(10)
        elapsed = time.monotonic() - start
        assert sim.stats.ticks == 10 and sim.stats.cycle_done_late == 10
        # paced by the clock (10 x 20 ms); waiting for the silent FSW would take 10 x 2 s
        assert 0.18 <= elapsed < 5.0
        assert sim.world.t == pytest.approx(0.2)
    finally:
        _close(buses)


def test_realtime_applies_late_commands_when_they_arrive(icd: Icd) -> None:
    """Fake clock: a command that arrives mid-period is applied from the dynamics step it arrived in."""
    with _fake_clock_sim(icd, "rt") as (sim, world, fsw_bus, now):
        driver = FswBusDriver(fsw_bus, icd, world.n_wheels)
        sent = []

        def fake_sleep(dt: float) -> None:
            now[0] += dt
            # The flight software answers tick 0 only after 45 ms of wall time.
            if not sent and now[0] >= 0.045:
                driver.collect_tick(0.0)
                driver.send_wheel_torques(0, [0.01] * world.n_wheels)
                driver.send_cycle_done(0)
                sent.append(now[0])

        applied = []
        real_step = world.step
        world.step = lambda dt, u: (applied.append(np.array(u)), real_step(dt, u))[1]
        sim.run_realtime(1, sleep=fake_sleep)
        first_nonzero = next(j for j, u in enumerate(applied) if np.any(u != 0))
        assert first_nonzero == 5  # steps 0..4 ran before the command arrived (at 45-50 ms)
        assert sim.stats.cycle_done_late == 0


def _free_running_flight_software(driver: FswBusDriver, now: list, first_cycle_s: float, late: set[int]):
    """A fake sleep for the simulator that also runs a flight software on its own clock: cycle j at
    first_cycle_s + j T, each answering the newest SYNC it has seen; cycles in ``late`` start 8 ms late (a
    busy host)."""
    cycle = [0]

    def sleep(dt: float) -> None:
        end = now[0] + dt
        while True:
            start = first_cycle_s + cycle[0] * 0.1 + (0.008 if cycle[0] in late else 0.0)
            if start > end:
                break
            now[0] = max(now[0], start)
            driver.collect_latest()
            driver.send_wheel_torques(cycle[0], [0.0] * driver.n_wheels)
            driver.send_cycle_done(cycle[0])  # in real time: answers the newest SYNC seen
            cycle[0] += 1
        now[0] = end

    return sleep


@pytest.mark.parametrize("lock", [False, True])
def test_realtime_puts_the_flight_softwares_cycle_mid_tick(icd: Icd, monkeypatch, lock: bool) -> None:
    """Two free-running schedules keep their start phase. A flight software started just before the
    simulator answers each tick a few ms before the next one begins, so any delay on the host makes the
    answer late. The simulator measures where the answers fall and delays its schedule once so the flight
    software's cycle sits PHASE_LOCK_TARGET into each tick: then the same delays cost nothing."""
    import hil_sim.sil.lockstep as lockstep

    if not lock:
        monkeypatch.setattr(lockstep.Simulator, "_lock_phase", lambda self: setattr(self, "_phase_locked", True))
    with _fake_clock_sim(icd, "rtphase") as (sim, world, fsw_bus, now):
        driver = FswBusDriver(fsw_bus, icd, world.n_wheels, clock=lambda: now[0])
        late = set(range(8, 40, 4))  # every fourth cycle after the lock, 8 ms late
        sleep = _free_running_flight_software(driver, now, first_cycle_s=0.097, late=late)
        for _ in range(40):
            sim.run_realtime(1, sleep=sleep)
        if lock:
            # the answers came 97 ms into each tick (seen at the next dynamics step, 10 ms apart): the schedule
            # moved once by 97 - 50 ms, to within a step
            assert sim.rt_phase_shift_s == pytest.approx(0.097 - lockstep.PHASE_LOCK_TARGET * 0.1, abs=0.0101)
            assert sim.stats.cycle_done_late == 0
        else:
            assert sim.stats.cycle_done_late >= len(late) - 1


# ------------------------------------------------------------------------------ multi-process lockstep
def _start_responder(spec: str, n_wheels: int, ticks: int) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "cli", "bus", "respond", "--bus", spec, "--wheels", str(n_wheels),
                             "--ticks", str(ticks), "--idle-timeout", "30"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    line = proc.stdout.readline()
    assert line.strip() == "READY", proc.stderr.read()
    return proc


def _run_side_by_side(icd: Icd, specs: list[str], ticks: int = 40) -> None:
    """Two SIL runs at once, each: its own bus, world, simulator and responder process."""
    procs, sims, buses = [], [], []
    try:
        worlds = [World(_params(), seed=20 + i) for i in range(len(specs))]
        for spec, world in zip(specs, worlds):
            procs.append(_start_responder(spec, world.n_wheels, ticks))
        for spec, world in zip(specs, worlds):
            bus = open_bus(spec)
            buses.append(bus)
            sims.append(Simulator(world, bus, icd, cycle_done_timeout_s=2.0))
        time.sleep(0.2)  # let the responders' sockets settle
        threads = [threading.Thread(target=s.run_lockstep, args=(ticks,)) for s in sims]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=300)
        for sim in sims:
            assert sim.stats.ticks == ticks
            assert sim.stats.cycle_done == ticks and sim.stats.cycle_done_timeouts == 0
            assert sim.stats.stale_cycle_done == 0  # a foreign CYCLE_DONE would show here
            counts = sim.receiver.counters
            assert counts["_bus"]["unknown_id"] == 0
            for name in ("CYCLE_DONE", "RW1_CMD"):
                assert counts[name]["ok"] == ticks, (name, counts[name])
                assert sum(counts[name].values()) == ticks, (name, counts[name])
        for proc in procs:
            out, err = proc.communicate(timeout=20)
            assert f"cycles {ticks}" in out, err
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
        for bus in buses:
            bus.shutdown()


def test_two_lockstep_runs_side_by_side_on_udp_multicast(icd: Icd) -> None:
    specs = []
    for run in ("side-a", "side-b"):
        group, port = random_udp_endpoint()
        specs.append(f"udp_multicast:{group}:{port}")
    _run_side_by_side(icd, specs)


@pytest.mark.socketcan
def test_two_lockstep_runs_side_by_side_on_vcan0_and_vcan1(icd: Icd) -> None:
    _run_side_by_side(icd, ["socketcan:vcan0", "socketcan:vcan1"])


@pytest.fixture
def socketcan_pair(icd: Icd):
    """Simulator and the real FswBusDriver (in a rate-damping responder) on two sockets of vcan0."""
    sim_bus, fsw_bus = open_bus("socketcan:vcan0"), open_bus("socketcan:vcan0")
    try:
        params = _params()
        world = World(params, seed=5)
        sim = Simulator(world, sim_bus, icd)
        driver = FswBusDriver(fsw_bus, icd, world.n_wheels)
        yield sim, RateDampingResponder(driver, [w.axis_B for w in params.spacecraft.wheels], 5.0)
    finally:
        sim_bus.shutdown()
        fsw_bus.shutdown()


@pytest.mark.socketcan
def test_lockstep_over_socketcan_with_in_process_fsw_thread(socketcan_pair) -> None:
    """Flight side in a thread, simulator waiting for each CYCLE_DONE."""
    sim, responder = socketcan_pair
    fsw = threading.Thread(target=lambda: [responder.cycle(2.0) for _ in range(50)])
    fsw.start()
    sim.run_lockstep(50)
    fsw.join(timeout=30)
    assert sim.stats.cycle_done == 50 and sim.stats.cycle_done_timeouts == 0
    assert responder.driver.counters["IMU_RATE"]["ok"] >= 490
    assert np.linalg.norm(sim.world.truth.omega_BN_B) < np.linalg.norm(OMEGA0)


@pytest.mark.socketcan
def test_in_process_ticks_over_socketcan_read_what_is_queued(socketcan_pair) -> None:
    """end_tick(wait_s=0) over socketcan (whose lockstep waits use the CYCLE_DONE doorbell) still takes
    the frames already queued: every tick's CYCLE_DONE and wheel commands, none counted as a timeout."""
    sim, responder = socketcan_pair
    for _ in range(20):
        sim.begin_tick()
        assert responder.cycle(1.0)
        deadline = time.monotonic() + 1.0  # the frames are on their way through the kernel
        while not sim.bus.wait_for(0.0) and time.monotonic() < deadline:
            time.sleep(0.001)
        assert sim.end_tick(wait_s=0.0)
    assert sim.stats.cycle_done == 20 and sim.stats.cycle_done_timeouts == 0
    assert sim.stats.wheel_commands == 20 * sim.n_wheels


def test_realtime_sensor_frames_go_out_at_their_own_rate(icd: Icd) -> None:
    """Between SYNCs the IMU frames are spread over the period (fake clock), not sent in a burst."""
    log: list = []

    def on_frame(direction: str, t: float, msg) -> None:
        if direction == "tx":
            log.append((t, msg.arbitration_id))

    with _fake_clock_sim(icd, "rtimu", on_frame=on_frame) as (sim, _world, _rx_bus, now):
        sim.run_realtime(3, sleep=lambda dt: now.__setitem__(0, now[0] + dt))
        imu_id = icd.spec("IMU_RATE").frame_id
        imu_times = sorted({round(t, 6) for t, fid in log if fid == imu_id})
        # one IMU frame every 10 ms of simulated (= wall) time, from the first tick on
        assert imu_times[:25] == pytest.approx([0.01 * k for k in range(25)])
        sync_times = [t for t, fid in log if fid == icd.spec("SYNC").frame_id]
        assert sync_times == pytest.approx([0.0, 0.1, 0.2])


def test_simulator_rejects_inconsistent_periods_and_phase_misuse(icd: Icd) -> None:
    bus = open_bus(f"virtual:bad{next(_channels)}")
    try:
        world = World(_params(), seed=1)
        with pytest.raises(ValueError, match="whole multiple"):
            Simulator(world, bus, icd, gnc_period_s=0.105, dynamics_dt_s=0.01)
        with pytest.raises(ValueError, match="period_ms"):
            Simulator(world, bus, icd, gnc_period_s=5.0, dynamics_dt_s=0.01)
        sim = Simulator(world, bus, icd)
        with pytest.raises(RuntimeError, match="without begin_tick"):
            sim.end_tick(0.0)
        sim.begin_tick()
        with pytest.raises(RuntimeError, match="twice"):
            sim.begin_tick()
    finally:
        bus.shutdown()


def test_one_call_period_gives_the_frames_and_state_of_the_step_loop(icd: Icd) -> None:
    """Unpaced ticks step the world and sample the sensors in one compiled call per period; the paced
    (real-time) loop does it step by step: the same frames, bit for bit, and the same world."""
    results = []
    for paced in (None, lambda j: None):
        sim, driver, _, buses = _in_process_pair(icd, seed=11)
        try:
            sent = []
            sim.on_frame = lambda d, t, m: sent.append((d, t, m.arbitration_id, bytes(m.data))) if d == "tx" else None
            for k in range(25):
                sim.begin_tick()
                inputs = driver.collect_tick(0.0)
                driver.send_wheel_torques(inputs.tick, [0.002 * (k % 5) - 0.004] * sim.n_wheels)
                driver.send_cycle_done(inputs.tick)
                sim._receive_until_done(sim.tick, 0.0)
                sim._advance_period(paced=paced)
            results.append((sent, sim.world.truth, sim.world.t))
        finally:
            _close(buses)
    (a, ta, t_a), (b, tb, t_b) = results
    assert len(a) > 25 * 10 and a == b and t_a == t_b
    for x, y in zip(ta, tb):
        np.testing.assert_array_equal(x, y)
