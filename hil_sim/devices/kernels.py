"""Compiled kernels of the simulator side of a GNC tick (``hil_sim.devices.nodes``, ``hil_sim.sil.lockstep``).

Each kernel does, on arrays, what the Python of the device nodes does frame by frame or wheel by wheel
(``ImuNode.frames_for``, ``StarTrackerNode.frames_for``, ``WheelNode.status_row``, ``_SampledNode.due_flags``,
``WheelNode.torque_at``, ``Devices.rows_due``, ``Simulator._on_delivered``), with the same arithmetic in the
same order (no fastmath), so the frames are bit for bit those of the Python path; tests/hil_sim/
test_device_kernels.py checks them against it. Python's per-call cost is the budget of a fast-mode tick
(~0.1 ms of it was these per-frame calls), hence a handful of compiled calls per tick instead.

The pending-frame queue (frames sampled, not yet due) is held as arrays: ``Q_DUE`` (C,) due time,
``Q_M`` (C,) message index, ``Q_ROWS`` (C, width) value row, ``Q_TS`` (C,) the sample time of a row whose
``age_ms`` is set at transmission (ST_QUAT_B), else NaN; ``Q_N[0]`` is the number queued (in queue order).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from comms.bus.burst import MAX_DLC
from comms.bus.icd import WHEEL_FAULT_CMD_TIMEOUT, WHEEL_FAULT_DRIVE, WHEEL_FAULT_OVERSPEED
from comms.bus.kernels import FALLBACK_CODE, OK_SOME_LOST_CODE, S_NTALLY, classify_counted, encode_range
from hil_sim.world import world as wd
from hil_sim.world.dynamics import FAULT_NO_TORQUE, FAULT_SPEED_LIMIT, FAULT_STUCK, W_KT
from hil_sim.world.world import _world_period_kernel, view1, view2, view3

# A time within this of a due time counts as reached (the nodes' Python rules use the same)
DUE_EPS_S = 1e-9
# WHEEL_STATE columns: held torque command, time of the last command (NaN: none yet), commands applied,
# tick_lsb of the last command (NaN: none yet)
WS_CMD, WS_LAST_T, WS_APPLIED, WS_TICK = 0, 1, 2, 3


@njit(cache=True)
def due_flags_kernel(times_s, next_due, period, out, offset):
    """``_SampledNode.due_flags``: out[offset + j] for each time; returns the new next due time."""
    nxt = next_due
    for j in range(times_s.shape[0]):
        t_s = times_s[j]
        if t_s + DUE_EPS_S < nxt:
            out[offset + j] = False
        else:
            k = math.floor((t_s - nxt + DUE_EPS_S) / period) + 1
            if k < 1:
                k = 1
            nxt += period * k
            out[offset + j] = True
    return nxt


@njit(cache=True)
def plan_period(times_s, imu_clock, st_clock, imu_due, st_due, wheel_state, timeout_s, u_seq):
    """Before one world period: the sensors' due flags at times_s[1:] (``due_flags``; each clock = [next due,
    period], the next due time advanced in place) and the wheel commands u_seq[j, 0, i] =
    ``torque_at(times_s[j])`` of each wheel (0 before its first command and after its timeout_s[i]).
    Returns the number of IMU samples due * 1000 + star-tracker samples due."""
    J = times_s.shape[0] - 1
    imu_clock[0] = due_flags_kernel(times_s[1:], imu_clock[0], imu_clock[1], imu_due, 0)
    st_clock[0] = due_flags_kernel(times_s[1:], st_clock[0], st_clock[1], st_due, 0)
    for j in range(J):
        t = times_s[j]
        for i in range(wheel_state.shape[0]):
            last = wheel_state[i, WS_LAST_T]
            if math.isnan(last) or t - last > timeout_s[i] + DUE_EPS_S:
                u_seq[j, 0, i] = 0.0
            else:
                u_seq[j, 0, i] = wheel_state[i, WS_CMD]
    n_imu = 0
    n_st = 0
    for j in range(J):
        if imu_due[j]:
            n_imu += 1
        if st_due[j]:
            n_st += 1
    return n_imu * 1000 + n_st


@njit(cache=True)
def queue_samples(times_s, imu_due, gyro, sat, imu_lat, imu_lo, imu_hi, imu_m, st_due, q, valid, blind, st_lat,
                  st_ms, st_cols, st_seq, Q_DUE, Q_M, Q_ROWS, Q_TS, Q_N):
    """After one world period: the IMU_RATE row of each gyro sample (``ImuNode.frames_for``) and the
    ST_QUAT_A/B rows of each star-tracker sample (``StarTrackerNode.frames_for``) taken at times_s[j + 1],
    appended to the queue in sample order. gyro (J, 1, 3), sat (J, 1), q (J, 1, 4), valid/blind (J, 1);
    st_ms = (A, B message index); st_cols = A's (q_w, q_x, valid, blind_source, sample_seq), B's (q_y, q_z,
    sample_seq); st_seq[0]: the next sample_seq. The caller leaves room for 3 rows per step.
    Returns (IMU samples, star-tracker samples) as imu * 1000 + st."""
    n = Q_N[0]
    width = Q_ROWS.shape[1]
    n_imu = 0
    n_st = 0
    for j in range(times_s.shape[0] - 1):
        t_s = times_s[j + 1]
        if imu_due[j]:
            saturated = sat[j, 0]
            w0, w1, w2 = gyro[j, 0, 0], gyro[j, 0, 1], gyro[j, 0, 2]
            if w0 < imu_lo:
                w0, saturated = imu_lo, True
            elif w0 > imu_hi:
                w0, saturated = imu_hi, True
            if w1 < imu_lo:
                w1, saturated = imu_lo, True
            elif w1 > imu_hi:
                w1, saturated = imu_hi, True
            if w2 < imu_lo:
                w2, saturated = imu_lo, True
            elif w2 > imu_hi:
                w2, saturated = imu_hi, True
            for c in range(width):
                Q_ROWS[n, c] = 0.0
            Q_ROWS[n, 2] = w0
            Q_ROWS[n, 3] = w1
            Q_ROWS[n, 4] = w2
            Q_ROWS[n, 5] = 1.0 if saturated else 0.0
            Q_DUE[n] = t_s + imu_lat
            Q_M[n] = imu_m
            Q_TS[n] = np.nan
            n += 1
            n_imu += 1
        if st_due[j]:
            q0, q1, q2, q3 = q[j, 0, 0], q[j, 0, 1], q[j, 0, 2], q[j, 0, 3]
            if q0 < 0:  # same rotation, canonical sign
                q0, q1, q2, q3 = -q0, -q1, -q2, -q3
            # min(max(c, -1.0), 1.0) as Python evaluates it (a NaN passes through)
            q0 = -1.0 if -1.0 > q0 else q0
            q0 = 1.0 if 1.0 < q0 else q0
            q1 = -1.0 if -1.0 > q1 else q1
            q1 = 1.0 if 1.0 < q1 else q1
            q2 = -1.0 if -1.0 > q2 else q2
            q2 = 1.0 if 1.0 < q2 else q2
            q3 = -1.0 if -1.0 > q3 else q3
            q3 = 1.0 if 1.0 < q3 else q3
            seq = st_seq[0]
            st_seq[0] = (seq + 1) & 0x0F
            due = t_s + st_lat
            for c in range(width):
                Q_ROWS[n, c] = 0.0
                Q_ROWS[n + 1, c] = 0.0
            Q_ROWS[n, st_cols[0]] = q0
            Q_ROWS[n, st_cols[1]] = q1
            Q_ROWS[n, st_cols[2]] = 1.0 if valid[j, 0] else 0.0
            Q_ROWS[n, st_cols[3]] = float(blind[j, 0])
            Q_ROWS[n, st_cols[4]] = float(seq)
            Q_DUE[n] = due
            Q_M[n] = st_ms[0]
            Q_TS[n] = np.nan
            Q_ROWS[n + 1, st_cols[5]] = q2
            Q_ROWS[n + 1, st_cols[6]] = q3
            Q_ROWS[n + 1, st_cols[7]] = float(seq)
            Q_DUE[n + 1] = due
            Q_M[n + 1] = st_ms[1]
            Q_TS[n + 1] = t_s
            n += 2
            n_st += 1
    Q_N[0] = n
    return n_imu * 1000 + n_st


@njit(cache=True)
def take_due(t_s, Q_DUE, Q_M, Q_ROWS, Q_TS, Q_N, age_col, OUT_IDX, OUT_ROWS, start):
    """``Devices.rows_due(t_s)``: the queued rows due by t_s, in due order (stable: queue order among equal
    due times), written to OUT_IDX/OUT_ROWS from ``start`` with a transmission-time row's age_ms (slot
    ``age_col``) set for t_s; the rest stay queued in order. Returns how many were written."""
    n = Q_N[0]
    cut = t_s + DUE_EPS_S
    width = Q_ROWS.shape[1]
    order = np.empty(n, np.int64)
    k = 0
    for i in range(n):
        if Q_DUE[i] <= cut:
            # insertion sort by due time, after any equal one (stable)
            p = k
            while p > 0 and Q_DUE[order[p - 1]] > Q_DUE[i]:
                order[p] = order[p - 1]
                p -= 1
            order[p] = i
            k += 1
    for r in range(k):
        i = order[r]
        OUT_IDX[start + r] = Q_M[i]
        for c in range(width):
            OUT_ROWS[start + r, c] = Q_ROWS[i, c]
        if not math.isnan(Q_TS[i]):
            age = np.rint((t_s - Q_TS[i]) * 1000.0)  # round(): half to even, as Python's
            if age < 0.0:
                age = 0.0
            if age > 255.0:
                age = 255.0
            OUT_ROWS[start + r, age_col] = age
    if k:
        m = 0
        for i in range(n):
            if not Q_DUE[i] <= cut:
                if m != i:
                    Q_DUE[m] = Q_DUE[i]
                    Q_M[m] = Q_M[i]
                    Q_TS[m] = Q_TS[i]
                    for c in range(width):
                        Q_ROWS[m, c] = Q_ROWS[i, c]
                m += 1
        Q_N[0] = m
    return k


@njit(cache=True)
def wheel_status_rows(t_s, X, U_APPLIED, W_KT, TEMP, FLAGS, wheel_state, timeout_s, status_ms, cols, ranges,
                      OUT_IDX, OUT_ROWS, start):
    """``Devices.wheel_status_rows`` of run 0 of a WorldBatch (``World.wheel_status`` then
    ``WheelNode.status_row`` per wheel), from ``start``. cols: (speed, torque, current, temp, fault) slots;
    ranges (4, 2): speed, torque, current, temp limits. Returns the number of wheels."""
    N = wheel_state.shape[0]
    width = OUT_ROWS.shape[1]
    for i in range(N):
        r = start + i
        speed = X[7 + i, 0]
        applied = U_APPLIED[i, 0]
        current = applied / W_KT[i, 0]
        temp = TEMP[i, 0]
        flags = FLAGS[i, 0]
        fault = 0
        if flags & FAULT_SPEED_LIMIT:
            fault |= WHEEL_FAULT_OVERSPEED
        if flags & (FAULT_STUCK | FAULT_NO_TORQUE):
            fault |= WHEEL_FAULT_DRIVE
        last = wheel_state[i, WS_LAST_T]
        if not math.isnan(last) and t_s - last > timeout_s[i] + DUE_EPS_S:
            fault |= WHEEL_FAULT_CMD_TIMEOUT
        # _clamp: lo if value < lo, hi if value > hi (a NaN passes through)
        if speed < ranges[0, 0]:
            speed = ranges[0, 0]
            fault |= WHEEL_FAULT_OVERSPEED
        elif speed > ranges[0, 1]:
            speed = ranges[0, 1]
            fault |= WHEEL_FAULT_OVERSPEED
        if applied < ranges[1, 0]:
            applied = ranges[1, 0]
        elif applied > ranges[1, 1]:
            applied = ranges[1, 1]
        if current < ranges[2, 0]:
            current = ranges[2, 0]
        elif current > ranges[2, 1]:
            current = ranges[2, 1]
        if temp < ranges[3, 0]:
            temp = ranges[3, 0]
        elif temp > ranges[3, 1]:
            temp = ranges[3, 1]
        for c in range(width):
            OUT_ROWS[r, c] = 0.0
        OUT_IDX[r] = status_ms[i]
        OUT_ROWS[r, cols[0]] = speed
        OUT_ROWS[r, cols[1]] = applied
        OUT_ROWS[r, cols[2]] = current
        OUT_ROWS[r, cols[3]] = np.rint(temp)  # round(): half to even, as Python's
        OUT_ROWS[r, cols[4]] = float(fault)
    return N


@njit(cache=True, inline="always")
def take_wheel_command(wheel_state, w, values, i, torque_col, tick_lsb_col, t_s):
    """``WheelNode.on_command`` of wheel ``w`` for the delivered command in value row ``i``, received at ``t_s``."""
    wheel_state[w, WS_CMD] = values[i, torque_col]
    wheel_state[w, WS_TICK] = values[i, tick_lsb_col]
    wheel_state[w, WS_LAST_T] = t_s
    wheel_state[w, WS_APPLIED] += 1.0


@njit(cache=True)
def apply_received(status, ids, values, first, end, cmd_wheel_of_id, torque_col, tick_lsb_col, cycle_done_id,
                   done_tick_col, heartbeat_id, t_s, wheel_state, counts):
    """``Simulator._on_delivered`` for the kernel-classified frames first..end-1 of a received burst (class
    code <= 1: delivered), in order: a wheel command is taken by its wheel (``wheel_state``), heartbeats
    are counted, and at a CYCLE_DONE it stops (its tick in counts[3]) so that the caller judges the tick.
    counts: [wheel commands, heartbeats, CYCLE_DONE seen (0/1), its tick]. Returns the index after the
    last frame handled."""
    for i in range(first, end):
        if status[i] > 1:
            continue
        fid = ids[i]
        w = cmd_wheel_of_id[fid] if 0 <= fid < cmd_wheel_of_id.shape[0] else -1
        if w >= 0:
            take_wheel_command(wheel_state, w, values, i, torque_col, tick_lsb_col, t_s)
            counts[0] += 1
        elif fid == cycle_done_id:
            counts[2] = 1
            counts[3] = np.int64(values[i, done_tick_col])
            return i + 1
        elif fid == heartbeat_id:
            counts[1] += 1
    return end


# receive_commands' integer state (rs) slots (its tally's pair count where comms.bus.kernels.tally_add keeps it)
RS_WHEEL_CMDS, RS_HEARTBEATS, RS_CYCLE_DONE, RS_STALE, RS_DONE = 0, 2, 3, 4, 5
RS_NTALLY = S_NTALLY
RS_SIZE = 6
# its constants (``consts``: these slots, then kind_of_id and cmd_wheel_of_id, n_ids each, then the CRC table)
(RC_N_CODES, RC_BUS_ROW, RC_TORQUE_COL, RC_TICK_LSB_COL, RC_DONE_ID, RC_DONE_TICK_COL, RC_HEARTBEAT_ID,
 RC_N_IDS) = range(8)
RC_SIZE = 8


# Devices' packed state (Devices._pack_state; hil_sim.world.world.pack_arrays): its slots, then the places of its
# float / int scalars
(DS_IMU_CLOCK, DS_ST_CLOCK, DS_WHEEL_STATE, DS_TIMEOUT, DS_STATUS_RANGES, DS_SCALARS, DS_SIG_F,
 DS_ST_MS, DS_ST_COLS, DS_ST_SEQ, DS_Q_N, DS_STATUS_MS, DS_STATUS_COLS, DS_ISCALARS, DS_MSG_I, DS_SIG_I, DS_CRC,
 DS_FRAME_IDS, DS_DLC) = range(19)  # (DS_SIG_F..: the ICD codec table's arrays, DS_FRAME_IDS/DLC by message)
DSS_IMU_LAT, DSS_IMU_LO, DSS_IMU_HI, DSS_ST_LAT = range(4)  # float scalars
DSS_IMU_M, DSS_AGE_COL, DSS_SYNC_M, DSS_SYNC_COLS = range(4)  # int scalars (SYNC's 3 slots from DSS_SYNC_COLS)
# a period's plan and scratch (Devices._bind_period): slots, int scalars
(DP_U_SEQ, DP_NO_NORMALS, DP_J_DT, DP_TIMES, DP_T_END, DP_GYRO_SEQ, DP_ST_Q_SEQ,
 DP_OUT, DP_ISCALARS, DP_ST_BLIND_SEQ,
 DP_IMU_DUE, DP_ST_DUE, DP_SAT_SEQ, DP_ST_VALID_SEQ) = range(14)
DPS_DIST_N, DPS_DIST_POS, DPS_IMU_POS, DPS_ST_POS, DPS_N_RUNS = range(5)


@njit(cache=True)
def tick_rows(t_s, tick, period_ms, SF, SI, WF, WI, Q_DUE, Q_M, Q_ROWS, Q_TS, OUT_IDX, OUT_ROWS):
    """The frames of ``Simulator.begin_tick`` as rows, on the devices' (SF, SI) and the world's (WF, WI) packed
    state: from row 1 the sensor rows due by t_s (``take_due``) then the wheel statuses
    (``wheel_status_rows``), in row 0 SYNC (tick, frames_following = min(rows after it, 255), period_ms).
    Returns the number of rows (SYNC included)."""
    isc = view1(SI, SI, DS_ISCALARS)
    n = 1 + take_due(t_s, Q_DUE, Q_M, Q_ROWS, Q_TS, view1(SI, SI, DS_Q_N), isc[DSS_AGE_COL], OUT_IDX, OUT_ROWS, 1)
    n += wheel_status_rows(t_s, view2(WF, WI, wd.WP_X), view2(WF, WI, wd.WP_U_APPLIED),
                           view3(WF, WI, wd.WP_W)[W_KT], view2(WF, WI, wd.WP_TEMP), view2(WI, WI, wd.WP_FLAGS),
                           view2(SF, SI, DS_WHEEL_STATE), view1(SF, SI, DS_TIMEOUT), view1(SI, SI, DS_STATUS_MS),
                           view1(SI, SI, DS_STATUS_COLS), view2(SF, SI, DS_STATUS_RANGES), OUT_IDX, OUT_ROWS, n)
    sync_cols = isc[DSS_SYNC_COLS:DSS_SYNC_COLS + 3]
    for c in range(OUT_ROWS.shape[1]):
        OUT_ROWS[0, c] = 0.0
    OUT_IDX[0] = isc[DSS_SYNC_M]
    OUT_ROWS[0, sync_cols[0]] = tick
    OUT_ROWS[0, sync_cols[1]] = float(min(n - 1, 255))
    OUT_ROWS[0, sync_cols[2]] = period_ms
    return n


@njit(cache=True)
def tick_burst_packed(t_s, tick, period_ms, SF, SI, WF, WI, Q_DUE, Q_M, Q_ROWS, Q_TS, OUT_IDX, OUT_ROWS, counters,
                      sent):
    """``tick_rows``, then its n rows encoded as ``E2ESender.burst`` encodes them (``encode_range``
    with the sender's alive ``counters`` and ``sent`` counts) into new arrays. Returns (n, rows encoded,
    frame ids, data (n, 8), lengths): a FrameBurst's arrays when all n are encoded."""
    n = tick_rows(t_s, tick, period_ms, SF, SI, WF, WI, Q_DUE, Q_M, Q_ROWS, Q_TS, OUT_IDX, OUT_ROWS)
    data = np.zeros((n, MAX_DLC), dtype=np.uint8)
    done = encode_range(OUT_IDX, OUT_ROWS, counters, sent, data, view2(SI, SI, DS_MSG_I), view3(SI, SI, DS_SIG_I),
                        view3(SF, SI, DS_SIG_F), view1(SI, SI, DS_CRC), n)
    frame_ids = view1(SI, SI, DS_FRAME_IDS)
    dlc = view1(SI, SI, DS_DLC)
    ids = np.empty(n, dtype=np.int64)
    lengths = np.empty(n, dtype=np.int64)
    for i in range(n):
        ids[i] = frame_ids[OUT_IDX[i]]
        lengths[i] = dlc[OUT_IDX[i]]
    return n, done, ids, data, lengths


@njit(cache=True)
def receive_commands(ids, lengths, data, now, awaited, status, values, consts, SF, SI, seq, last_ok_t, tally, rs):
    """``Simulator``'s receive of a burst in one call, on the ICD codec table and the wheels' command state in
    the devices' packed state (SF, SI: ``Devices._pack_state``): each frame classified and counted by
    ``comms.bus.kernels.classify_counted`` (``status``, ``values``, the receiver's ``seq`` / ``last_ok_t``,
    ``tally`` with ``rs[RS_NTALLY]`` pairs), as the flight side's collect_rows does, then a delivered one
    applied as :func:`apply_received` applies it (wheel commands into the wheel state; heartbeats,
    CYCLE_DONEs and stale ones, i.e. for another tick than ``awaited``, counted in ``rs``; ``rs[RS_DONE]``
    set by CYCLE_DONE(awaited)). Returns the index after the last frame handled: after CYCLE_DONE(awaited)
    (later frames stay for later, as classify_until's stop leaves them), the burst's end, or before a frame
    for the Python path (``status`` FALLBACK_CODE)."""
    n_codes = consts[RC_N_CODES]
    bus_row = consts[RC_BUS_ROW]
    torque_col = consts[RC_TORQUE_COL]
    tick_lsb_col = consts[RC_TICK_LSB_COL]
    done_id = consts[RC_DONE_ID]
    done_col = consts[RC_DONE_TICK_COL]
    heartbeat_id = consts[RC_HEARTBEAT_ID]
    n_ids = consts[RC_N_IDS]
    kind_of_id = consts[RC_SIZE:RC_SIZE + n_ids]
    cmd_wheel_of_id = consts[RC_SIZE + n_ids:RC_SIZE + 2 * n_ids]
    crc_table = consts[RC_SIZE + 2 * n_ids:]
    msg_i, sig_i, sig_f = view2(SI, SI, DS_MSG_I), view3(SI, SI, DS_SIG_I), view3(SF, SI, DS_SIG_F)
    wheel_state = view2(SF, SI, DS_WHEEL_STATE)
    stop = float(awaited)
    n = ids.shape[0]
    for i in range(n):
        code = classify_counted(i, ids, lengths, data, values, now, kind_of_id, msg_i, sig_i, sig_f, crc_table, seq,
                                last_ok_t, tally, rs, bus_row, n_codes)
        status[i] = code
        if code == FALLBACK_CODE:
            return i
        if code > OK_SOME_LOST_CODE:
            continue
        fid = ids[i]
        w = cmd_wheel_of_id[fid]
        if w >= 0:
            take_wheel_command(wheel_state, w, values, i, torque_col, tick_lsb_col, now)
            rs[RS_WHEEL_CMDS] += 1
        elif fid == done_id:
            rs[RS_CYCLE_DONE] += 1
            if np.int64(values[i, done_col]) == awaited:
                rs[RS_DONE] = 1
            else:
                rs[RS_STALE] += 1
            if stop <= values[i, done_col] <= stop:
                return i + 1
        elif fid == heartbeat_id:
            rs[RS_HEARTBEATS] += 1
    return n


@njit(cache=True)
def period_packed(t_base, SF, SI, DF, DI, DB, WF, WI, WB, sun_c, moon_c, dist_buf, imu_buf, st_buf, Q_DUE, Q_M,
                  Q_ROWS, Q_TS):
    """One GNC period of ``Devices.step_world`` in one call, on the devices' (SF, SI), the period's (DF, DI,
    DB) and the world's
    (WF, WI, WB) packed state: the step times (times[j] = t_base + j_dt[j]; when t_base is NaN the times slot
    is already filled), ``plan_period``, the world's ``_world_period_kernel`` with its normals read from the
    streams' buffers where they stand (what ``NormalStream.take_rows`` would slice: dist_n numbers per step
    when dist_n > 0, else the zero rows; 6 * n_runs per gyro sample; 3 * n_runs per star-tracker sample),
    the world's last gyro sample (``WorldBatch.finish_period``), then ``queue_samples``.
    out: [steps done, gyro samples, star-tracker samples] (the caller advances the streams and the world's
    time); nothing is queued when a step was refused (steps done < J). out[0] = -1, and nothing done at
    all, when a buffer may not hold the period's normals (the caller takes the three-call path, whose draws
    refill it)."""
    DL = DI
    WL = WI
    times = view1(DF, DL, DP_TIMES)
    J = times.shape[0] - 1
    isc = view1(DI, DL, DP_ISCALARS)
    out = view1(DI, DL, DP_OUT)
    dist_n, dist_pos, imu_pos, st_pos, n_runs = (isc[DPS_DIST_N], isc[DPS_DIST_POS], isc[DPS_IMU_POS],
                                                 isc[DPS_ST_POS], isc[DPS_N_RUNS])
    k_imu = 6 * n_runs
    k_st = 3 * n_runs
    if (dist_pos + dist_n * J > dist_buf.shape[0] or imu_pos + k_imu * J > imu_buf.shape[0]
            or st_pos + k_st * J > st_buf.shape[0]):
        out[0] = -1
        return
    if not math.isnan(t_base):
        j_dt = view1(DF, DL, DP_J_DT)
        for j in range(J + 1):
            times[j] = t_base + j_dt[j]
    imu_due = view1(DB, DL, DP_IMU_DUE)
    st_due = view1(DB, DL, DP_ST_DUE)
    u_seq = view3(DF, DL, DP_U_SEQ)
    counts = plan_period(times, view1(SF, SI, DS_IMU_CLOCK), view1(SF, SI, DS_ST_CLOCK), imu_due, st_due,
                         view2(SF, SI, DS_WHEEL_STATE), view1(SF, SI, DS_TIMEOUT), u_seq)
    n_imu = counts // 1000
    n_st = counts % 1000
    if dist_n > 0:
        normals = dist_buf[dist_pos:dist_pos + dist_n * J].reshape((J, dist_n))
    else:
        normals = view2(DF, DL, DP_NO_NORMALS)
    imu_normals = imu_buf[imu_pos:imu_pos + k_imu * n_imu].reshape((n_imu, k_imu))
    st_normals = st_buf[st_pos:st_pos + k_st * n_st].reshape((n_st, k_st))
    wsc = view1(WF, WL, wd.WP_SCALARS)
    T_END = view1(DF, DL, DP_T_END)
    GYRO_SEQ = view3(DF, DL, DP_GYRO_SEQ)
    SAT_SEQ = view2(DB, DL, DP_SAT_SEQ)
    ST_Q_SEQ = view3(DF, DL, DP_ST_Q_SEQ)
    ST_VALID_SEQ = view2(DB, DL, DP_ST_VALID_SEQ)
    ST_BLIND_SEQ = view2(DI, DL, DP_ST_BLIND_SEQ)
    done = _world_period_kernel(
        view2(WF, WL, wd.WP_X), view2(WF, WL, wd.WP_D), view2(WF, WL, wd.WP_TEMP), view3(WF, WL, wd.WP_G),
        view3(WF, WL, wd.WP_W), view2(WF, WL, wd.WP_B), u_seq, normals, wsc[wd.WPS_DT_SUB],
        view1(WI, WL, wd.WP_ISCALARS)[wd.WPS_N_SUB], view2(WF, WL, wd.WP_U_APPLIED), view2(WI, WL, wd.WP_FLAGS),
        view2(WF, WL, wd.WP_DECAY), view2(WF, WL, wd.WP_GM), view1(WB, WL, wd.WP_HAS_COULOMB),
        view2(WF, WL, wd.WP_WORK), T_END, view2(WF, WL, wd.WP_ORB), sun_c, moon_c, wsc[wd.WPS_EPH_T0],
        wsc[wd.WPS_EPH_H], view2(WF, WL, wd.WP_AUX), imu_due, view1(WF, WL, wd.WP_CLOCK), imu_normals,
        view2(WF, WL, wd.WP_BIAS), view2(WF, WL, wd.WP_GYRO_P), GYRO_SEQ, SAT_SEQ, st_due, view2(WF, WL, wd.WP_ST_P),
        view3(WF, WL, wd.WP_ST_BASIS), st_normals, view2(WF, WL, wd.WP_ST_Q), view1(WB, WL, wd.WP_ST_VALID),
        view1(WI, WL, wd.WP_ST_BLIND), ST_Q_SEQ, ST_VALID_SEQ, ST_BLIND_SEQ)
    out[0] = done
    out[1] = n_imu
    out[2] = n_st
    if done:
        wsc[wd.WPS_T_END] = T_END[done - 1]
        if imu_due[done - 1]:
            gyro_out = view2(WF, WL, wd.WP_GYRO_OUT)
            gyro_sat = view1(WB, WL, wd.WP_GYRO_SAT)
            for m in range(gyro_out.shape[0]):
                for c in range(3):
                    gyro_out[m, c] = GYRO_SEQ[done - 1, m, c]
                gyro_sat[m] = SAT_SEQ[done - 1, m]
    if done == J:
        ssc = view1(SF, SI, DS_SCALARS)
        queue_samples(times, imu_due, GYRO_SEQ, SAT_SEQ, ssc[DSS_IMU_LAT], ssc[DSS_IMU_LO], ssc[DSS_IMU_HI],
                      view1(SI, SI, DS_ISCALARS)[DSS_IMU_M], st_due, ST_Q_SEQ, ST_VALID_SEQ, ST_BLIND_SEQ,
                      ssc[DSS_ST_LAT], view1(SI, SI, DS_ST_MS), view1(SI, SI, DS_ST_COLS), view1(SI, SI, DS_ST_SEQ),
                      Q_DUE, Q_M, Q_ROWS, Q_TS, view1(SI, SI, DS_Q_N))
