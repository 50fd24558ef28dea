"""The driver's compiled lockstep tick (comms.bus.kernels.collect_rows) and command encoder (command_rows)
against plain references: a frame-by-frame driver on the receiver's Python path (the rules of
FswBusDriver.collect_tick as they were written before the kernel), and E2ESender.frame with Python's
limits. Random ticks with lost, repeated, corrupted, reordered, stale, foreign and non-data frames, read
in bursts of any size, some ticks' frames arriving early."""
from __future__ import annotations

import math
import random

import can
import numpy as np
import pytest

from comms.bus import E2ESender, Icd
from fsw.bus import FswBusDriver, TickInputs
from comms.bus.burst import FrameBurst
from fsw.bus.driver import ImuSample, StarTrackerSample, WheelStatus
from reference.bus import ReferenceDriver


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


class _BurstBus:
    """A bus that hands out prepared bursts, one per read, and keeps what is sent."""

    def __init__(self) -> None:
        self.bursts: list[FrameBurst] = []
        self.sent: list[tuple[list[int], list[bytes]]] = []

    def recv_burst(self, timeout=0.0):
        return self.bursts.pop(0) if self.bursts else None

    def send_burst(self, burst, timeout=None) -> int:
        self.sent.append((burst.ids.tolist(), [bytes(burst.data[i, :burst.lengths[i]]) for i in range(len(burst))]))
        return len(burst)

    def send(self, msg, timeout=None) -> None:
        self.sent.append(([msg.arbitration_id], [bytes(msg.data)]))


def _view(inputs: TickInputs | None):
    if inputs is None:
        return None
    st = inputs.star_tracker
    return (inputs.tick, inputs.t, inputs.period_s,
            [(s.omega_BN_B.tolist(), s.saturated, s.t) for s in inputs.imu_samples],
            None if st is None else (st.q_NS.tolist(), st.valid, st.blind_source, st.t),
            [None if w is None else tuple(w) for w in inputs.wheels], inputs.frames_expected, inputs.frames_received)


def _stream(icd: Icd, seed: int, n_ticks: int, n_wheels: int) -> list[list]:
    """Per tick the frames (can.Message) a simulator would send, damaged at random."""
    rng = random.Random(seed)
    tx = E2ESender(icd)
    ticks, syncs, carry = [], [], []
    for k in range(1, n_ticks + 1):
        frames = []
        for _ in range(rng.choice([10, 10, 3])):
            frames.append(tx.frame("IMU_RATE", dict(omega_x=rng.uniform(-0.5, 0.5), omega_y=rng.uniform(-0.5, 0.5),
                                                    omega_z=rng.uniform(-0.5, 0.5), saturated=rng.random() < 0.1)))
        seq = k % 16
        frames.append(tx.frame("ST_QUAT_A", dict(q_w=rng.uniform(-1, 1), q_x=rng.uniform(-1, 1), valid=rng.random() < 0.8,
                                                 blind_source=rng.randrange(4), sample_seq=seq)))
        frames.append(tx.frame("ST_QUAT_B", dict(q_y=rng.uniform(-1, 1), q_z=rng.uniform(-1, 1),
                                                 sample_seq=seq if rng.random() < 0.9 else (seq + 1) % 16,
                                                 age_ms=rng.randrange(0, 200))))
        frames += [tx.frame(f"RW{i}_STATUS", dict(speed=rng.uniform(-500, 500), torque=rng.uniform(-0.2, 0.2),
                                                  current=rng.uniform(0, 2), temp=rng.randrange(-20, 60),
                                                  fault=rng.randrange(8) if rng.random() < 0.1 else 0))
                   for i in range(1, 7)]  # RW5/RW6 on the bus too: device frames the driver does not use
        sync = tx.frame("SYNC", dict(tick=k, frames_following=len(frames) - rng.choice([0, 0, 0, 1, 3]),
                                     period_ms=100))
        syncs.append(sync)
        out, frames = carry + [sync], frames
        carry = []
        for f in frames:
            r = rng.random()
            if r < 0.03:
                continue  # lost
            if r < 0.06:
                out.append(f)  # repeated
            elif r < 0.09:
                d = bytearray(f.data)
                d[rng.randrange(len(d))] ^= 1 << rng.randrange(8)
                f = can.Message(arbitration_id=f.arbitration_id, data=d, is_extended_id=False)  # corrupted
            elif r < 0.11 and out:
                out.insert(len(out) - 1, f)  # out of order
                continue
            elif r < 0.13:
                carry.append(f)  # late: comes with the next tick
                continue
            elif r < 0.135:
                out.append(syncs[max(0, len(syncs) - 1 - rng.randrange(3))])  # replayed SYNC (E2E rejects it)
            elif r < 0.14:  # a SYNC of this or an earlier tick with a fresh counter: delivered, stale
                out.append(tx.frame("SYNC", dict(tick=max(0, k - rng.randrange(3)), frames_following=5,
                                                 period_ms=100)))
            elif r < 0.15:
                out.append(can.Message(arbitration_id=0x7FF, data=b"\x00\x01", is_extended_id=False))  # foreign id
            elif r < 0.16:
                out.append(can.Message(arbitration_id=0x20, data=bytes(6), is_extended_id=False))  # own id echoed
            elif r < 0.17:
                out.append(can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=True))
            elif r < 0.175:
                out.append(can.Message(arbitration_id=0, is_error_frame=True))
            elif r < 0.19:
                out.append(can.Message(arbitration_id=f.arbitration_id, data=bytes(f.data)[:-1],
                                       is_extended_id=False))  # wrong length
            out.append(f)
        ticks.append(out)
    return ticks


@pytest.mark.parametrize("seed", range(8))
def test_collect_tick_matches_the_frame_by_frame_reference(icd: Icd, seed: int) -> None:
    rng = random.Random(100 + seed)
    n_wheels = rng.choice([3, 4, 6])
    ticks = _stream(icd, seed, 80, n_wheels)
    bus = _BurstBus()
    driver = FswBusDriver(bus, icd, n_wheels)
    ref = ReferenceDriver(icd, n_wheels)
    k = 0
    while k < len(ticks):
        frames = list(ticks[k])
        if rng.random() < 0.15 and k + 1 < len(ticks):
            frames += ticks[k + 1]  # the next tick's frames are queued already
            ticks[k + 1] = []
        ref.queue += frames
        i = 0
        while i < len(frames):  # bursts of any size, runs of one or two frames included
            size = rng.choice([1, 2, 3, 5, len(frames)])
            bus.bursts.append(FrameBurst.from_messages(frames[i:i + size]))
            i += size
        got, want = driver.collect_tick(0.0), ref.collect_tick()
        if got is not None:  # the arrays the samples are built from, read before the lists
            speeds = got.wheel_speed_rad_s.tolist()
            assert got.imu_omega_BN_B.tolist() == [s[0] for s in want[3]]
            assert [None if s != s else s for s in speeds] == [None if w is None else w[0] for w in want[5]]
        assert _view(got) == (None if want is None else (
            want[0], want[1], want[2], want[3], want[4],
            [None if w is None else w for w in want[5]], want[6], want[7]))
        assert driver.counters == ref.rx.counters
        assert (driver.stale_syncs, driver.unexpected_frames, driver.incomplete_ticks) == \
               (ref.stale, ref.unexpected, ref.incomplete)
        assert driver.last_tick == ref.last_tick
        k += 1
    assert sum(c["ok"] for c in driver.counters.values() if "ok" in c) > 0
    assert driver.counters["_bus"]["unknown_id"] > 0 and driver.incomplete_ticks > 0
    assert driver.stale_syncs > 0 and driver.unexpected_frames > 0


def test_collect_tick_grows_its_gyro_rows(icd: Icd) -> None:
    """More gyro frames in a tick than the driver's rows hold: all of them, in order."""
    tx, bus = E2ESender(icd), _BurstBus()
    driver = FswBusDriver(bus, icd, 4)
    omegas = [0.001 * k for k in range(150)]
    frames = [tx.frame("SYNC", dict(tick=3, frames_following=150, period_ms=100))]
    frames += [tx.frame("IMU_RATE", dict(omega_x=w, omega_y=0.0, omega_z=0.0, saturated=0)) for w in omegas]
    bus.bursts.append(FrameBurst.from_messages(frames))
    inputs = driver.collect_tick(0.0)
    assert inputs.complete and len(inputs.imu_samples) == 150
    np.testing.assert_allclose(inputs.imu_omega_BN_B[:, 0], omegas, atol=1e-5)
    assert [s.omega_BN_B[0] for s in inputs.imu_samples] == inputs.imu_omega_BN_B[:, 0].tolist()


@pytest.mark.parametrize("seed", range(4))
def test_wheel_commands_match_the_frame_by_frame_encoder(icd: Icd, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = [3, 4, 6, 1][seed]
    bus = _BurstBus()
    driver = FswBusDriver(bus, icd, n)
    reference = E2ESender(icd)  # one sender across the calls: its alive counters advance as the driver's
    edge = [math.nan, math.inf, -math.inf, -0.0, 0.0, 1.638, -1.638, 1.6381, 5.0, -5.0, 1e-12, 0.00025, 0.00075]
    for call in range(60):
        tau = rng.uniform(-2.0, 2.0, n)
        for j in range(n):
            if rng.random() < 0.3:
                tau[j] = edge[rng.integers(len(edge))]
        tick = int(rng.integers(0, 1 << 34))
        done = bool(rng.random() < 0.7)
        given = tau if call % 3 == 0 else (tau.tolist() if call % 3 == 1 else tau.astype(np.float32))
        driver.send_wheel_torques(tick, given, cycle_done=done)
        ids, data = bus.sent[-1]
        want_tau = given if call % 3 != 2 else given
        # the reference, on its own sender with the same history
        names = [f"RW{i}_CMD" for i in range(1, n + 1)] + (["CYCLE_DONE"] if done else [])
        assert ids == [icd.spec(nm).frame_id for nm in names]
        want = []
        for i, t in enumerate(want_tau, 1):
            lo, hi = icd.signal_range(f"RW{i}_CMD", "torque_cmd")
            t = float(t)
            t = 0.0 if not math.isfinite(t) else min(max(t, lo), hi)
            want.append(bytes(reference.frame(f"RW{i}_CMD", {"torque_cmd": t, "tick_lsb": tick & 0xFFFF}).data))
        if done:
            want.append(bytes(reference.frame("CYCLE_DONE", {"tick": tick & 0xFFFFFFFF}).data))
        assert data == want
    assert driver.sent == reference.sent


def test_wheel_commands_refuse_what_float_refuses(icd: Icd) -> None:
    driver = FswBusDriver(_BurstBus(), icd, 2)
    with pytest.raises(TypeError):
        driver.send_wheel_torques(1, [0.1, None])
    with pytest.raises(ValueError):
        driver.send_wheel_torques(1, [0.1, 0.2, 0.3])


def test_tick_inputs_keep_their_constructor_and_build_samples_on_demand() -> None:
    imu = ImuSample(np.array([0.1, 0.2, 0.3]), False, 1.0)
    st = StarTrackerSample(np.array([1.0, 0.0, 0.0, 0.0]), True, 0, 0.95)
    wheels = [WheelStatus(1.0, 0.0, 0.1, 20.0, 0, 1.0), None]
    a = TickInputs(10, 1.0, 0.1, imu, st, wheels, [imu], 5, 4)
    assert a.imu_samples == [imu] and not a.complete and a.imu_omega_BN_B.tolist() == [[0.1, 0.2, 0.3]]
    omega = np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.2]])
    b = TickInputs(10, 1.0, 0.1, imu, None, [None], imu_omega_BN_B=omega, imu_saturated=[0.0, 1.0])
    assert [(s.omega_BN_B.tolist(), s.saturated, s.t) for s in b.imu_samples] == \
           [([0.0, 0.0, 0.1], False, 1.0 - 0.1 / 2), ([0.0, 0.0, 0.2], True, 1.0)]
    assert b.imu_samples is b.imu_samples and b.imu_omega_BN_B is omega
    assert TickInputs(1, 0.1, 0.1, None, None, []).imu_samples == []


@pytest.mark.parametrize("seed", range(5))
def test_fresh_arrays_match_the_sample_and_status_objects(seed: int) -> None:
    """fresh_imu_omega_BN_B / fresh_wheel_arrays give what the GNC cycle builds from ``imu_samples`` and
    ``wheels`` (speed NaN and fault -1 for a wheel with no status), and None once those lists are set."""
    rng = np.random.default_rng(seed)
    nw = int(rng.integers(1, 6))
    rows = np.column_stack([rng.normal(0, 300, (nw, 4)), rng.integers(0, 8, nw).astype(float)])
    new = [bool(x) for x in rng.integers(0, 2, nw)]
    if seed == 0:
        new = [True] * nw
    omega = rng.normal(0, 0.1, (int(rng.integers(1, 11)), 3))
    for wheel_rows in (rows, None):
        ti = TickInputs(3, 0.3, 0.1, None, None, None, None, imu_omega_BN_B=omega,
                        imu_saturated=[0.0] * len(omega), wheel_rows=wheel_rows,
                        wheel_new=new if wheel_rows is not None else [False] * nw)
        speeds, faults = ti.fresh_wheel_arrays()
        fresh = ti.fresh_imu_omega_BN_B()
        ref = ti.wheels  # builds the objects: from now on the arrays are not "fresh"
        assert ti.fresh_wheel_arrays() is None
        ref_speeds = np.array([w.speed_rad_s if w is not None else math.nan for w in ref], dtype=float)
        ref_faults = np.array([w.fault if w is not None else -1 for w in ref], dtype=np.int64)
        assert speeds.dtype == np.float64 and faults.dtype == np.int64
        np.testing.assert_array_equal(speeds, ref_speeds)
        np.testing.assert_array_equal(faults, ref_faults)
        ref_samples = np.array([s.omega_BN_B for s in ti.imu_samples if s.valid], dtype=float).reshape(-1, 3)
        assert ti.fresh_imu_omega_BN_B() is None
        np.testing.assert_array_equal(fresh, ref_samples)
    ti.imu_samples = [ImuSample(omega[0], False, 0.3, False)]  # a sample set by hand may be invalid
    assert ti.fresh_imu_omega_BN_B() is None
