"""FswBusDriver over the in-process virtual bus, and robustness of the receive path (hypothesis)."""
from __future__ import annotations

import itertools

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from comms.bus import E2ESender, Icd, open_bus
from fsw.bus import FswBusDriver
from comms.bus.e2e import BUS_KEY, E2EReceiver

_channels = itertools.count()


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


@pytest.fixture
def buses():
    channel = f"virtual:drv{next(_channels)}"
    sim, fsw = open_bus(channel), open_bus(channel)
    yield sim, fsw
    sim.shutdown()
    fsw.shutdown()


IMU = dict(omega_x=0.01, omega_y=-0.02, omega_z=0.003, saturated=0)


def _status(i: int) -> dict:
    return dict(speed=10.0 * i, torque=0.001 * i, current=0.1 * i, temp=20 + i, fault=0)


def test_collect_tick_assembles_inputs_with_sim_times(icd: Icd, buses) -> None:
    sim, fsw = buses
    tx = E2ESender(icd)
    drv = FswBusDriver(fsw, icd, n_wheels=4)
    frames = [tx.frame("IMU_RATE", dict(IMU, omega_x=0.001 * k)) for k in range(10)]
    frames += [tx.frame("ST_QUAT_A", dict(q_w=0.5, q_x=0.5, valid=1, blind_source=0, sample_seq=7)),
               tx.frame("ST_QUAT_B", dict(q_y=0.5, q_z=-0.5, sample_seq=7, age_ms=30))]
    frames += [tx.frame(f"RW{i}_STATUS", _status(i)) for i in range(1, 5)]
    sim.send(tx.frame("SYNC", dict(tick=42, frames_following=len(frames), period_ms=100)))
    for f in frames:
        sim.send(f)
    inputs = drv.collect_tick(timeout_s=1.0)
    assert inputs.tick == 42 and inputs.t == pytest.approx(4.2) and inputs.complete
    assert len(inputs.imu_samples) == 10
    assert inputs.imu.omega_BN_B[0] == pytest.approx(0.009, abs=1e-5)
    assert inputs.imu.t == pytest.approx(4.2)
    assert inputs.imu_samples[0].t == pytest.approx(4.2 - 0.09)
    np.testing.assert_allclose(inputs.star_tracker.q_NS, [0.5, 0.5, 0.5, -0.5], atol=2e-6)
    assert inputs.star_tracker.t == pytest.approx(4.2 - 0.030)
    assert [w.speed_rad_s for w in inputs.wheels] == pytest.approx([10, 20, 30, 40], abs=0.02)
    assert inputs.wheels[2].temp_C == 23


def test_missing_frames_end_the_tick_at_the_timeout(icd: Icd, buses) -> None:
    sim, fsw = buses
    tx = E2ESender(icd)
    drv = FswBusDriver(fsw, icd, n_wheels=3)
    sim.send(tx.frame("SYNC", dict(tick=1, frames_following=3, period_ms=100)))
    sim.send(tx.frame("IMU_RATE", IMU))
    inputs = drv.collect_tick(timeout_s=0.05)
    assert inputs.frames_received == 1 and not inputs.complete
    assert inputs.star_tracker is None and inputs.wheels == [None, None, None]
    assert drv.incomplete_ticks == 1
    assert drv.collect_tick(timeout_s=0.02) is None  # no SYNC: nothing


def test_star_tracker_halves_of_different_samples_are_not_combined(icd: Icd, buses) -> None:
    sim, fsw = buses
    tx = E2ESender(icd)
    drv = FswBusDriver(fsw, icd, n_wheels=3)
    sim.send(tx.frame("SYNC", dict(tick=1, frames_following=2, period_ms=100)))
    sim.send(tx.frame("ST_QUAT_A", dict(q_w=1, q_x=0, valid=1, blind_source=0, sample_seq=3)))
    sim.send(tx.frame("ST_QUAT_B", dict(q_y=0, q_z=0, sample_seq=4, age_ms=0)))
    assert drv.collect_tick(timeout_s=0.5).star_tracker is None


def test_collect_latest_reports_ages_on_the_driver_clock(icd: Icd, buses) -> None:
    sim, fsw = buses
    tx = E2ESender(icd)
    now = [100.0]
    drv = FswBusDriver(fsw, icd, n_wheels=3, clock=lambda: now[0])
    sim.send(tx.frame("IMU_RATE", IMU))
    latest = drv.collect_latest()
    assert latest.imu_age_s == 0.0 and latest.star_tracker is None
    now[0] = 100.25
    latest = drv.collect_latest()
    assert latest.imu_age_s == pytest.approx(0.25)
    assert latest.imu.omega_BN_B[1] == pytest.approx(-0.02, abs=1e-5)


def test_commands_are_limited_to_the_icd_range_and_decodable(icd: Icd, buses) -> None:
    sim, fsw = buses
    drv = FswBusDriver(fsw, icd, n_wheels=3)
    drv.send_wheel_torques(70000, [0.05, -5.0, float("nan")])
    drv.send_cycle_done(70000)
    drv.send_heartbeat(1, 99)
    rx = E2EReceiver(icd, ignore_ids=icd.ids_sent_by("SIM", "IMU", "STR"))
    got = [rx.classify(sim.recv(timeout=0.5), 0.0) for _ in range(5)]
    assert [g.name for g in got] == ["RW1_CMD", "RW2_CMD", "RW3_CMD", "CYCLE_DONE", "FSW_HEARTBEAT"]
    assert all(g.delivered for g in got)
    assert got[0].signals["torque_cmd"] == pytest.approx(0.05, abs=5e-5)
    assert got[1].signals["torque_cmd"] == pytest.approx(icd.signal_range("RW2_CMD", "torque_cmd")[0])
    assert got[2].signals["torque_cmd"] == 0.0
    assert got[0].signals["tick_lsb"] == 70000 & 0xFFFF
    assert got[3].signals["tick"] == 70000
    with pytest.raises(ValueError, match="expected 3 torques"):
        drv.send_wheel_torques(1, [0.0, 0.0])


def test_driver_rejects_impossible_wheel_count(icd: Icd, buses) -> None:
    with pytest.raises(ValueError, match="1..6"):
        FswBusDriver(buses[1], icd, n_wheels=7)


# ------------------------------------------------------------------------------------------ robustness
_frame = st.builds(
    lambda fid, data, ext, rtr: (fid, data, ext, rtr),
    st.one_of(st.integers(0, 0x7FF), st.sampled_from([0x10, 0x40, 0x50, 0x51, 0x60, 0x61, 0x62])),
    st.binary(min_size=0, max_size=8),
    st.booleans(),
    st.booleans(),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frames=st.lists(_frame, min_size=1, max_size=60))
def test_random_frames_only_touch_classification_counters(icd: Icd, frames) -> None:
    """Random ids/lengths/payloads: no exception, no sample reaches the application, counters add up.

    A random 8-byte payload passes the CRC with probability 1/256; such frames are legitimately
    delivered, so application state may only change for frames the receiver itself classified ok.
    """
    channel = f"virtual:hyp{next(_channels)}"
    sim, fsw = open_bus(channel), open_bus(channel)
    try:
        drv = FswBusDriver(fsw, icd, n_wheels=4)
        for fid, data, ext, rtr in frames:
            msg = can.Message(arbitration_id=fid, data=b"" if rtr else data, is_extended_id=ext,
                              is_remote_frame=rtr, dlc=len(data))
            sim.send(msg)
        latest = drv.collect_latest()
        counts = drv.counters
        total = sum(n for c in counts.values() for cls, n in c.items() if cls != "timeout")
        assert total == len(frames)
        delivered = sum(c["ok"] + c["ok_some_lost"] for n, c in counts.items() if n != BUS_KEY)
        if delivered == 0:
            assert latest.imu is None and latest.star_tracker is None
            assert latest.wheels == [None] * 4
    finally:
        sim.shutdown()
        fsw.shutdown()


def test_transmit_errors_are_counted_not_raised(icd: Icd, buses) -> None:
    class RefusingBus:
        def send(self, msg, timeout=None):
            raise can.CanOperationError("Transmit buffer full")

        def recv(self, timeout=None):
            return None

    drv = FswBusDriver(RefusingBus(), icd, n_wheels=3)
    drv.send_wheel_torques(1, [0.0, 0.0, 0.0])
    drv.send_cycle_done(1)
    assert drv.tx_errors == 4


def test_realtime_cycle_done_answers_the_newest_sync_and_a_late_cycle_still_counts() -> None:
    """Real time, the flight software (its own clock) and the simulator (SYNC paced on the clock) in two
    threads on a virtual bus: the driver answers each SYNC with CYCLE_DONE(k), so cycles that keep up
    are not counted late; a cycle that overruns is."""
    import threading
    import time

    from closed_loop_kit import BusLoop, fsw_config_for

    from hil_sim.world.params import WorldParams
    from hil_sim.world.world import World

    wp = WorldParams()
    cfg = fsw_config_for(wp, initial_mode="SAFE", law={"assumption_check": "off"})
    loop = BusLoop(cfg, World(wp, seed=0))
    try:
        period = cfg.gnc_period_s

        def run(n_ticks: int, overrun_at: int | None = None) -> tuple[int, int]:
            before_late, before_done = loop.sim.stats.cycle_done_late, loop.sim.stats.cycle_done
            before_ticks = loop.sim.stats.ticks
            fsw = threading.Thread(target=loop.fsw.run_realtime, kwargs={"duration_s": (n_ticks + 3) * period})
            cycles = loop.fsw.cycle
            fsw.start()
            # SYNCs start half a period after a flight-software cycle, so each cycle falls mid-tick: with
            # the two clocks in phase, a cycle just before SYNC(k+1) answers SYNC(k) a moment too late
            # (the phase of a real system is arbitrary; this test is about what the counter means)
            deadline = time.monotonic() + 10.0
            while loop.fsw.cycle == cycles and time.monotonic() < deadline:
                time.sleep(0.001)
            time.sleep(0.5 * period)

            def on_tick(sim) -> None:
                if overrun_at is not None and sim.stats.ticks == before_ticks + overrun_at:
                    loop.fsw.inject_overrun_s = 2.5 * period

            loop.sim.run_realtime(n_ticks, on_tick=on_tick)
            loop.fsw.stop()
            fsw.join(timeout=10.0)
            return loop.sim.stats.cycle_done_late - before_late, loop.sim.stats.cycle_done - before_done

        late, done = run(20)
        assert done >= 19 and late <= 1, (late, done)  # before the fix: late == 20, done == 0
        late, done = run(20, overrun_at=10)
        # the overrunning cycle's tick and the ones it covered (2-4); on a loaded host the threads' own
        # scheduling delays add a few (7 seen at load 4.8 on 2 cores); the defect this guards is all 20
        assert 2 <= late <= 10, late
    finally:
        loop.close()


def test_commands_and_cycle_done_go_as_one_burst_and_a_refused_frame_is_counted(icd: Icd, buses) -> None:
    """Wheel commands and CYCLE_DONE leave in one send_batch; when the bus refuses one frame of the burst,
    that frame is counted as a transmit error and the frames after it are still sent."""
    sim, fsw = buses
    calls: list[list[str]] = []

    class RefusesSecond:
        def send_batch(self, msgs, timeout):
            calls.append([icd.db.get_message_by_frame_id(m.arbitration_id).name for m in msgs])
            if len(calls) == 1:
                fsw.send(msgs[0], timeout)
                return 1  # frame [1] refused
            for m in msgs:
                fsw.send(m, timeout)
            return len(msgs)

    drv = FswBusDriver(fsw, icd, n_wheels=3)
    drv.bus = RefusesSecond()
    drv.send_wheel_torques(7, [0.01, 0.02, 0.03], cycle_done=True)
    assert calls == [["RW1_CMD", "RW2_CMD", "RW3_CMD", "CYCLE_DONE"], ["RW3_CMD", "CYCLE_DONE"]]
    assert drv.tx_errors == 1
    rx = E2EReceiver(icd, ignore_ids=icd.ids_sent_by("SIM", "IMU", "STR"))
    got = [rx.classify(sim.recv(timeout=0.5), 0.0).name for _ in range(3)]
    assert got == ["RW1_CMD", "RW3_CMD", "CYCLE_DONE"]


class _ChunkedBus:
    """A bus handing out queued frames ``chunk`` at a time (then once 'empty'), as frames trickle in over
    a real transport; sends are dropped."""

    def __init__(self, msgs: list, chunk: int) -> None:
        self.msgs, self.chunk, self.n, self.gap = list(msgs), chunk, 0, False

    def recv(self, timeout=None):
        if self.gap or not self.msgs:
            self.gap = False
            return None
        self.n += 1
        self.gap = self.n % self.chunk == 0
        return self.msgs.pop(0)

    def send(self, msg, timeout=None) -> None:
        pass


def test_ticks_are_the_same_however_the_frames_arrive_in_chunks(icd: Icd) -> None:
    """The driver classifies what it has read in compiled runs, a frame or two in Python: chunking must
    not change a tick's inputs (order of the gyro samples included), nor the counters."""
    sender, rng = E2ESender(icd), np.random.default_rng(5)
    msgs = []
    for tick in range(1, 5):
        msgs.append(sender.frame("SYNC", {"tick": tick, "frames_following": 16, "period_ms": 100}))
        for _ in range(10):
            w = rng.uniform(-0.5, 0.5, 3)
            msgs.append(sender.frame("IMU_RATE", dict(omega_x=w[0], omega_y=w[1], omega_z=w[2], saturated=0)))
        seq = tick % 16
        msgs.append(sender.frame("ST_QUAT_A", dict(q_w=1.0, q_x=0.0, valid=1, blind_source=0, sample_seq=seq)))
        msgs.append(sender.frame("ST_QUAT_B", dict(q_y=0.0, q_z=0.0, sample_seq=seq, age_ms=50)))
        msgs += [sender.frame(f"RW{i}_STATUS", _status(i)) for i in range(1, 5)]
    msgs[5] = can.Message(arbitration_id=0x7FF, data=b"\x00", is_extended_id=False)  # a foreign frame mid-tick
    results = []
    for chunk in (1, 2, 3, 7, 1000):
        driver = FswBusDriver(_ChunkedBus(msgs, chunk), icd, 4)
        ticks = [driver.collect_tick(0.5) for _ in range(4)]
        results.append(([(t.tick, [(s.omega_BN_B.tolist(), s.t) for s in t.imu_samples], t.wheels,
                          t.star_tracker.q_NS.tolist(), t.frames_received) for t in ticks], driver.counters))
    assert results[0][0][0][4] == 15  # the foreign frame took an IMU frame's place: one fewer received
    for other in results[1:]:
        assert other == results[0]
