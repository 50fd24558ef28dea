"""The simulator's tick kernels (hil_sim.devices.kernels) against the Python of the device nodes they replace."""
from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from comms.bus.icd import Icd
from hil_sim.devices import kernels as dk
from hil_sim.devices.nodes import Devices, ImuNode, StarTrackerNode, WheelNode
from hil_sim.world.params import WorldParams
from hil_sim.world.world import World
from reference.bus import reference_rows_due


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_plan_period_matches_sample_due_and_torque_at(icd: Icd, seed: int) -> None:
    rng = np.random.default_rng(seed)
    imu_ref, st_ref = ImuNode(icd, 100.0), StarTrackerNode(icd, 7.0)
    imu, st = ImuNode(icd, 100.0), StarTrackerNode(icd, 7.0)
    wheels = [WheelNode(i, icd, cmd_timeout_s=0.25) for i in range(1, 5)]
    state = np.stack([w.state for w in wheels])
    timeouts = np.array([w.cmd_timeout_s for w in wheels])
    t = 0.0
    for _ in range(200):
        times = t + np.arange(11) * 0.01
        if rng.random() < 0.1:
            times = times + 0.05  # a gap: several periods skipped at once
        for i, w in enumerate(wheels):  # commands now and then; some wheels go silent (timeouts)
            if rng.random() < 0.3 * (i + 1) / 4:
                w.on_command({"torque_cmd": rng.normal(), "tick_lsb": int(rng.integers(256))}, times[0] - 0.01)
        state[:] = np.stack([w.state for w in wheels])
        imu_due, st_due = np.zeros(10, dtype=np.bool_), np.zeros(10, dtype=np.bool_)
        u = np.full((10, 1, 4), np.nan)
        counts = dk.plan_period(times, imu.clock, st.clock, imu_due, st_due, state, timeouts, u)
        ref_imu = [imu_ref._sample_due(tj) for tj in times[1:].tolist()]  # the nodes' Python rule
        ref_st = [st_ref._sample_due(tj) for tj in times[1:].tolist()]
        assert imu_due.tolist() == ref_imu and st_due.tolist() == ref_st
        assert imu.next_due_s == imu_ref.next_due_s and st.next_due_s == st_ref.next_due_s
        assert counts == sum(ref_imu) * 1000 + sum(ref_st)
        ref_u = [[w.torque_at(tj) for w in wheels] for tj in times[:-1].tolist()]
        assert u[:, 0, :].tolist() == ref_u
        t = float(times[-1])


def test_queue_and_take_due_match_the_nodes_frames(icd: Icd) -> None:
    rng = np.random.default_rng(5)
    world = SimpleNamespace(n_wheels=4, imu_period_s=0.01, star_tracker_period_s=0.1)
    devices = Devices.for_world(world, icd)
    ref_imu = ImuNode(icd, 100.0, latency_s=0.003)
    ref_st = StarTrackerNode(icd, 10.0, latency_s=0.05)
    devices.imu.latency_s, devices.star_tracker.latency_s = 0.003, 0.05
    lo, hi = devices._imu_range
    pending: list = []
    t = 0.0
    for k in range(60):
        J = 10
        times = t + np.arange(J + 1) * 0.01
        imu_due = rng.random(J) < 0.8
        st_due = rng.random(J) < 0.2
        gyro = rng.normal(0.0, 0.5 * hi, (J, 1, 3))
        gyro[rng.random((J, 1, 3)) < 0.05] = np.nan
        sat = rng.random((J, 1)) < 0.1
        q = rng.normal(0.0, 0.6, (J, 1, 4))  # components beyond +-1 and negative scalar parts
        valid = rng.random((J, 1)) < 0.5
        blind = rng.integers(0, 4, (J, 1))
        devices._reserve(3 * J)
        counts = dk.queue_samples(times, imu_due, gyro, sat, 0.003, lo, hi, devices.imu._m, st_due, q, valid, blind,
                                  0.05, devices._st_ms, devices._st_cols, devices.star_tracker.seq_state,
                                  devices.q_due, devices.q_m, devices.q_rows, devices.q_ts, devices.q_n)
        assert counts == int(imu_due.sum()) * 1000 + int(st_due.sum())
        for j in range(J):
            if imu_due[j]:
                pending += ref_imu.frames_for(gyro[j, 0].tolist(), bool(sat[j, 0]), float(times[j + 1]))
            if st_due[j]:
                pending += ref_st.frames_for(q[j, 0], bool(valid[j, 0]), int(blind[j, 0]), float(times[j + 1]))
        t_tx = float(times[-1]) + (0.004 if k % 3 == 0 else 0.0)
        idx, rows = devices.rows_due(t_tx)
        ref_idx, ref_rows, pending = reference_rows_due(pending, t_tx)
        assert idx == ref_idx
        np.testing.assert_array_equal(np.array(rows).reshape(len(idx), -1), np.array(ref_rows).reshape(len(idx), -1))
        assert devices.pending_count == len(pending)
        t = float(times[-1])


def test_wheel_status_rows_match_status_row(icd: Icd) -> None:
    rng = np.random.default_rng(9)
    N = 4
    wheels = [WheelNode(i, icd, cmd_timeout_s=0.3) for i in range(1, N + 1)]
    wheels[1].on_command({"torque_cmd": 0.01, "tick_lsb": 3}, 0.0)
    wheels[2].on_command({"torque_cmd": 0.01, "tick_lsb": 3}, 0.95)
    state = np.stack([w.state for w in wheels])
    timeouts = np.array([w.cmd_timeout_s for w in wheels])
    ranges = np.array([icd.signal_range("RW1_STATUS", s) for s in ("speed", "torque", "current", "temp")])
    cols = np.array(wheels[0]._status_cols, dtype=np.int64)
    status_ms = np.array([w.status_m for w in wheels], dtype=np.int64)
    width = icd.table.start.shape[1]
    for _ in range(200):
        X = np.zeros((7 + N, 1))
        X[7:, 0] = rng.normal(0.0, 1.5 * ranges[0, 1], N)
        applied = rng.normal(0.0, 1.5 * ranges[1, 1], (N, 1))
        kt = rng.uniform(0.01, 0.1, (N, 1))
        temp = np.round(rng.uniform(ranges[3, 0] - 20, ranges[3, 1] + 20, (N, 1)) * 2) / 2  # ties at .5
        flags = rng.integers(0, 16, (N, 1))
        idx, rows = np.zeros(N + 2, dtype=np.int64), np.zeros((N + 2, width))
        t_s = 1.0 + rng.random() * 0.5
        n = dk.wheel_status_rows(t_s, X, applied, kt, temp, flags, state, timeouts, status_ms, cols, ranges, idx, rows,
                                 1)
        assert n == N
        for i, w in enumerate(wheels):
            status = SimpleNamespace(speed_rad_s=X[7 + i, 0], torque_Nm=applied[i, 0],
                                     current_A=applied[i, 0] / kt[i, 0], temp_C=temp[i, 0], fault=int(flags[i, 0]))
            assert idx[1 + i] == w.status_m
            assert rows[1 + i].tolist() == w.status_row(status, t_s)


def test_apply_received_matches_on_command(icd: Icd) -> None:
    wheels = [WheelNode(i, icd) for i in range(1, 4)]
    state = np.stack([w.state for w in wheels])
    width = icd.table.start.shape[1]
    cmd_ids = [icd.spec(f"RW{i}_CMD").frame_id for i in range(1, 4)]
    done_id, hb_id = icd.spec("CYCLE_DONE").frame_id, icd.spec("FSW_HEARTBEAT").frame_id
    lookup = np.full(len(icd.table.index_of_id), -1, dtype=np.int64)
    lookup[cmd_ids] = [0, 1, 2]
    torque_col, tick_col = icd.column("RW1_CMD", "torque_cmd"), icd.column("RW1_CMD", "tick_lsb")
    done_col = icd.column("CYCLE_DONE", "tick")
    ids = np.array([cmd_ids[0], cmd_ids[1], hb_id, cmd_ids[2], cmd_ids[0], done_id, cmd_ids[1]], dtype=np.int64)
    status = np.array([0, 4, 0, 1, 0, 0, 0], dtype=np.int64)  # frame 1: a CRC error, not delivered
    values = np.zeros((len(ids), width))
    for i, fid in enumerate(ids):
        values[i, torque_col], values[i, tick_col] = 0.001 * (i + 1), i
    values[5, done_col] = 41.0
    counts = np.zeros(4, dtype=np.int64)
    end = dk.apply_received(status, ids, values, 0, len(ids), lookup, torque_col, tick_col, done_id, done_col, hb_id,
                            2.5, state, counts)
    assert end == 6 and counts.tolist() == [3, 1, 1, 41]  # stops after CYCLE_DONE, its tick handed back
    for i in (0, 3, 4):  # the delivered commands, in order, through the Python path
        w = wheels[lookup[ids[i]]]
        w.on_command({"torque_cmd": values[i, torque_col], "tick_lsb": values[i, tick_col]}, 2.5)
    np.testing.assert_array_equal(state, np.stack([w.state for w in wheels]))


def test_one_call_period_matches_the_three_call_path(icd: Icd) -> None:
    """Devices.step_world's fused call and its three-call path: the same world, the same queued rows."""
    base = WorldParams()
    sc = replace(base.spacecraft, disturbance=replace(base.spacecraft.disturbance, random_std_Nm=1e-6))
    params = replace(base, spacecraft=sc)  # random disturbance: a third normal stream to serve
    worlds = [World(params, seed=4), World(params, seed=4)]
    devs = [Devices.for_world(w, icd) for w in worlds]
    devs[1]._step_fused = lambda *a: False  # the three-call path throughout
    rng = np.random.default_rng(3)
    took = []
    step_fused = devs[0]._step_fused
    devs[0]._step_fused = lambda *a: took.append(step_fused(*a)) or took[-1]
    for k in range(120):
        times = worlds[0].t + np.arange(11) * 0.01
        cmd = rng.normal(0.0, 0.01, worlds[0].n_wheels)
        for d in devs:
            for i, w in enumerate(d.wheels):
                if k % 7 != i:  # a wheel left without command now and then
                    w.on_command({"torque_cmd": float(cmd[i]), "tick_lsb": k & 0xFF}, float(times[0]))
        devs[0].step_world(worlds[0], 0.01, times)
        devs[1].step_world(worlds[1], 0.01, times.copy())
        a, b = worlds[0].batch, worlds[1].batch
        assert a._t == b._t and a._t_last_imu == b._t_last_imu
        for name in ("X", "TEMP", "U_APPLIED", "FLAGS", "AUX", "GYRO_OUT", "ST_Q"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        for name in ("q_due", "q_m", "q_rows", "q_ts", "q_n"):
            np.testing.assert_array_equal(getattr(devs[0], name), getattr(devs[1], name))
        ia, ra = devs[0].rows_due(float(times[-1]))
        ib, rb = devs[1].rows_due(float(times[-1]))
        assert ia == ib and ra == rb
    assert sum(took) > 60 and not all(took)  # both paths taken (the three-call one when a stream refills)
    assert devs[0].imu.samples == devs[1].imu.samples and devs[0].star_tracker.samples == devs[1].star_tracker.samples
    assert math.isfinite(worlds[0].t)


def _random_flight_frames(icd: Icd, rng: np.random.Generator, tick: int, counters: dict) -> list:
    """One tick's frames from a (misbehaving) flight software: wheel commands and heartbeats with good,
    repeated, skipped or old alive counters, corrupted CRCs, wrong lengths, CYCLE_DONE of this tick or
    another one (or none, or twice), unknown ids, the simulator's own ids, extended frames."""
    import can

    table = icd.table
    names = [f"RW{i}_CMD" for i in range(1, 7)] + ["FSW_HEARTBEAT"]
    frames = []
    for name in rng.permutation(names).tolist() + ["CYCLE_DONE"] * int(rng.integers(0, 3)):
        if rng.random() < 0.1:
            continue
        m = icd.message_index[name]
        spec = icd.spec(name)
        signals = {}
        for k, sig in enumerate(spec.signals):
            lo, hi = table.vmin[m, k + 2], table.vmax[m, k + 2]
            signals[sig] = float(rng.uniform(lo, hi)) if spec.signals else 0.0
            if name == "CYCLE_DONE" and sig == "tick":
                signals[sig] = float(abs(tick - int(rng.random() < 0.3)))
            elif table.scale[m, k + 2] == 1.0:
                signals[sig] = float(round(signals[sig]))
        jump = rng.choice([1, 1, 1, 1, 0, 2, 5, 15])
        counters[name] = (counters.get(name, 0) + int(jump)) & 15
        msg = icd.encode(name, signals, counters[name])
        data = bytearray(msg.data)
        r = rng.random()
        if r < 0.05:
            data[1] ^= 0x10  # CRC error
        elif r < 0.08:
            data = data[:-1]  # wrong length
        frames.append(can.Message(arbitration_id=msg.arbitration_id, data=data, is_extended_id=False))
    r = rng.random()
    if r < 0.1:
        frames.insert(int(rng.integers(0, len(frames) + 1)), can.Message(arbitration_id=0x7FE, data=b"\0" * 8,
                                                                        is_extended_id=False))
    elif r < 0.2:
        frames.insert(int(rng.integers(0, len(frames) + 1)),
                      can.Message(arbitration_id=icd.spec("SYNC").frame_id, data=b"\0" * 8, is_extended_id=False))
    elif r < 0.25:
        frames.insert(int(rng.integers(0, len(frames) + 1)), can.Message(arbitration_id=0x123456, data=b"\0" * 8,
                                                                        is_extended_id=True))
    if rng.random() < 0.1:
        frames = frames[:int(rng.integers(0, 3))]  # a frame or two: the receiver's Python path
    return frames


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_receive_commands_matches_the_per_burst_path(icd: Icd, seed: int) -> None:
    """Simulator's compiled receive of a tick's frames (device_kernels.receive_commands) against the
    per-burst path it replaces (classify_until, apply_received, the receiver's Python path): the same E2E
    counters, statistics, sequence state, wheel commands and world, tick by tick."""
    from comms.bus import open_bus
    from comms.bus.burst import FrameBurst
    from comms.bus.transport import send_burst
    from hil_sim.sil.lockstep import Simulator

    rng = np.random.default_rng(seed)
    sims, senders = [], []
    for j in range(2):
        channel = f"virtual:rc{seed}-{j}-{id(rng)}"
        sim_bus, fsw_bus = open_bus(channel), open_bus(channel)
        sims.append(Simulator(World(WorldParams(), seed=1), sim_bus, icd))
        senders.append(fsw_bus)
    fused, reference = sims
    reference._take_burst = lambda burst, t_s, k: setattr(reference, "_rx", reference.receiver.check(burst))
    reference._rc_watch = (np.zeros(0, dtype=np.int64), np.zeros(0))  # timeouts by E2EReceiver.check_timeouts
    counters: dict = {}
    try:
        for tick in range(120):
            frames = _random_flight_frames(icd, rng, tick, counters) if tick % 40 < 30 else []  # silences: timeouts
            done = []
            for sim, bus in zip(sims, senders):
                sim.begin_tick()
                if frames:
                    send_burst(bus, FrameBurst.from_messages(frames))
                done.append(sim.end_tick(wait_s=0.0))
            reference.receiver.check_timeouts(reference.t0_s + (reference.tick - 1) * reference.period_s
                                              + reference.n_sub * reference.dt_s)  # end_tick's _sub_t(n_sub)
            assert done[0] == done[1]
            assert fused.receiver.counters == reference.receiver.counters
            assert fused.stats == reference.stats
            for a, b in zip(fused.receiver.kernel_state[5:], reference.receiver.kernel_state[5:]):
                np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(fused.devices.wheel_state, reference.devices.wheel_state)
            np.testing.assert_array_equal(fused.world.truth.omega_BN_B, reference.world.truth.omega_BN_B)
        assert fused.stats.stale_cycle_done > 0 and fused.stats.cycle_done_timeouts > 0
        assert sum(c["crc_error"] for c in fused.receiver.counters.values() if "crc_error" in c) > 0
        assert fused.receiver.counters["CYCLE_DONE"]["timeout"] > 0
    finally:
        for sim, bus in zip(sims, senders):
            sim.bus.shutdown()
            bus.shutdown()


def test_pack_arrays_views_are_the_arrays_and_the_kernels_read_them() -> None:
    """pack_arrays: each view holds its array's values (shape, dtype, C order) in a shared buffer, and
    view1/2/3 inside a compiled call see the same memory (a write through either shows in the other)."""
    from numba import njit

    from hil_sim.world.world import pack_arrays, view1, view2, view3

    rng = np.random.default_rng(5)
    floats = [rng.normal(size=3), rng.normal(size=(2, 5)), rng.normal(size=(3, 1, 4)), np.zeros((0, 2))]
    ints = [rng.integers(-9, 9, size=(4, 3)), np.arange(7)]
    bools = [rng.random(6) < 0.5, rng.random((2, 3)) < 0.5]
    fbuf, ibuf, bbuf, views = pack_arrays(floats, ints, bools)
    for a, v, buf in zip(floats + ints + bools, views, [fbuf] * 4 + [ibuf] * 2 + [bbuf] * 2):
        assert v.shape == a.shape and v.dtype == a.dtype and v.flags.c_contiguous
        assert v.size == 0 or np.shares_memory(v, buf)
        np.testing.assert_array_equal(v, a)

    @njit
    def read(fbuf, ibuf, bbuf):
        return (view1(fbuf, ibuf, 0).copy(), view2(fbuf, ibuf, 1).copy(), view3(fbuf, ibuf, 2).copy(),
                view2(ibuf, ibuf, 4).copy(), view1(ibuf, ibuf, 5).copy(), view1(bbuf, ibuf, 6).copy(),
                view2(bbuf, ibuf, 7).copy())

    @njit
    def bump(fbuf, ibuf):
        view3(fbuf, ibuf, 2)[2, 0, 3] += 1.0

    for k, got in zip([0, 1, 2, 4, 5, 6, 7], read(fbuf, ibuf, bbuf)):
        np.testing.assert_array_equal(got, views[k])
    before = float(views[2][2, 0, 3])
    bump(fbuf, ibuf)
    assert views[2][2, 0, 3] == before + 1.0
    with pytest.raises(ValueError):
        pack_arrays([np.zeros((1, 1, 1, 1))], [], [])


def test_step_period_matches_step_world_with_the_simulators_times(icd: Icd) -> None:
    """Devices.step_period (the step times made inside the compiled call from t_s) and step_world with
    times t_s + arange(J + 1) * dt_s made in numpy, as the simulator made them: the same world and frames."""
    worlds = [World(WorldParams(), seed=6), World(WorldParams(), seed=6)]
    devs = [Devices.for_world(w, icd) for w in worlds]
    rng = np.random.default_rng(8)
    j_dt = np.arange(11) * 0.01
    t0 = 0.0
    planned = [0, 0]  # the three-call path taken, per side
    for side, d in enumerate(devs):
        def spy(*args, _inner=d._step_planned, _side=side):
            planned[_side] += 1
            return _inner(*args)
        d._step_planned = spy
    for k in range(150):  # long enough for a normal stream to refill (the three-call path on both sides)
        t_k = t0 + k * 0.1
        cmd = rng.normal(0.0, 0.01, worlds[0].n_wheels)
        for d in devs:
            for i, w in enumerate(d.wheels):
                if k % 5 != i:
                    w.on_command({"torque_cmd": float(cmd[i]), "tick_lsb": k & 0xFF}, t_k)
        devs[0].step_period(worlds[0], 0.01, 10, t_k)
        devs[1].step_world(worlds[1], 0.01, t_k + j_dt)
        a, b = worlds[0].batch, worlds[1].batch
        assert a._t == b._t and a._t_last_imu == b._t_last_imu
        for name in ("X", "TEMP", "U_APPLIED", "FLAGS", "AUX", "GYRO_OUT", "GYRO_SAT", "ST_Q"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        ia, ra = devs[0].rows_due(t_k + 0.1)
        ib, rb = devs[1].rows_due(t_k + 0.1)
        assert ia == ib and ra == rb
    assert devs[0].imu.samples == devs[1].imu.samples > 1000
    assert planned[0] >= 1 and planned[1] >= 1, planned


def test_tick_burst_matches_tick_rows_encoded_by_the_sender(icd: Icd) -> None:
    """Devices.tick_burst (rows and encoding in one compiled call) and tick_rows then E2ESender.burst: the
    same frames (ids, bytes, lengths) and the same alive counters, tick after tick; a row out of its DBC
    range goes to the sender's checked path, which names it."""
    worlds = [World(WorldParams(), seed=2), World(WorldParams(), seed=2)]
    devs = [Devices.for_world(w, icd) for w in worlds]
    sync_m = icd.message_index["SYNC"]
    sync_cols = np.array([icd.column("SYNC", s) for s in ("tick", "frames_following", "period_ms")], dtype=np.int64)
    j_dt = np.arange(11) * 0.01
    for k in range(40):
        t_k = k * 0.1
        burst = devs[0].tick_burst(worlds[0], t_k, k, 100, sync_m, sync_cols)
        idx, rows, n = devs[1].tick_rows(worlds[1], t_k, k, 100, sync_m, sync_cols)
        ref = devs[1].sender.burst(idx[:n], rows[:n])
        assert len(burst) == n
        np.testing.assert_array_equal(burst.ids, ref.ids)
        np.testing.assert_array_equal(burst.data, ref.data)
        np.testing.assert_array_equal(burst.lengths, ref.lengths)
        assert burst.data.dtype == ref.data.dtype and burst.lengths.dtype == ref.lengths.dtype
        assert devs[0].sender.counters == devs[1].sender.counters and devs[0].sender.sent == devs[1].sender.sent
        for d, w in zip(devs, worlds):
            d.step_world(w, 0.01, t_k + j_dt)
    devs[0].wheel_state[0, dk.WS_LAST_T] = 3.95
    worlds[0].batch.X[7, 0] = 1e9  # a wheel speed far outside RW1_STATUS.speed: clamped, so still encodable
    worlds[0].batch.TEMP[0, 0] = math.nan  # NaN is not clamped: the codec refuses it, the checked path raises
    with pytest.raises(Exception, match="RW1_STATUS"):
        devs[0].tick_burst(worlds[0], 4.0, 40, 100, sync_m, sync_cols)
