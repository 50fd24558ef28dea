"""The ICD codec and the E2E check as compiled (numba) kernels over whole bursts of frames.

A GNC tick moves ~22 frames; one Python codec call per frame cost a few microseconds each (bit fields,
scaling, range checks and the CRC byte loop in Python). Here the DBC is turned into a signal table at load
time (:class:`CodecTable`, built by :class:`comms.bus.icd.Icd`) and two kernels walk that table for every
frame of a burst in one call:

  * :func:`encode_burst`: application values (one row per frame) -> frame bytes with alive counter and
    E2E CRC in byte 0, the same bytes as ``Icd.encode`` (cantools' arithmetic: ``round((v - offset) /
    scale)`` with round-half-even, two's complement fields, little-endian layout);
  * :func:`classify_rows`: frame bytes -> the receiver's classification (length, CRC, decode with
    ``raw * scale + offset``, the accept bounds, the alive-counter sequence on the receiver's state
    arrays) and the decoded values, stopping where the caller's wait ends (a tick's SYNC, its last
    announced frame, the awaited CYCLE_DONE) so that later frames are classified later, as before.

:class:`comms.bus.e2e.E2EReceiver` owns the state and keeps the counts per class (its public housekeeping
view) and the timeouts in Python. Messages the table cannot describe (big-endian or float signals, multiplexing)
are marked unsupported and take the per-frame cantools path. tests/fsw/test_bus_kernels.py checks both
kernels bit-exact against the per-frame codec, and the classification against a reference
implementation of the rules, for every message of the DBC.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from comms.dictionary import MAX_WHEELS

# The receiver's classes, one table: a class's code (the kernels' status and tally codes) is its position here
# and comms.bus.e2e takes the names from it. Codes 0..6 are the classes of a frame of an ICD message
# (FRAME_CLASSES), then an unknown id, the node's own echo, a frame left to the Python path, and a timeout.
CLASS_OF_CODE = ("ok", "ok_some_lost", "repeated", "wrong_sequence", "crc_error", "bad_length", "out_of_range",
                 "unknown_id", "own_echo", "python_path", "timeout")
(OK_CODE, OK_SOME_LOST_CODE, REPEATED_CODE, WRONG_SEQUENCE_CODE, CRC_ERROR_CODE, BAD_LENGTH_CODE, OUT_OF_RANGE_CODE,
 UNKNOWN_CODE, ECHO_CODE, FALLBACK_CODE, TIMEOUT_CODE) = range(len(CLASS_OF_CODE))
FRAME_CLASSES = CLASS_OF_CODE[:OUT_OF_RANGE_CODE + 1]
N_CODES = len(CLASS_OF_CODE)  # a tally key is row * N_CODES + code
# kind_of_id entries below 0 (>= 0: the message index)
KIND_UNKNOWN, KIND_ECHO, KIND_FALLBACK = -1, -2, -3
# A counter this many steps behind the reference is taken for a delayed old frame (see E2EReceiver._sequence);
# with a 4-bit counter a larger backwards step cannot be told from a forward jump, which resynchronises.
OLD_FRAME_WINDOW = 3
MAX_DLC = 8


@dataclass(frozen=True)
class CodecTable:
    """The DBC's signals as arrays, message index m (``Icd.message_index``), signal slot k.

    Slots 0 and 1 are E2E_CRC and E2E_Counter, application signals follow in DBC order (slot 2 + their
    index in ``MessageSpec.signals``). ``index_of_id``: frame id (11 bit) -> m, -1 when the id is not a
    message the table supports."""

    index_of_id: np.ndarray   # (2048,) int64
    dlc: np.ndarray           # (M,) int64
    seed: np.ndarray          # (M,) int64: CRC-8 register after the data ID bytes
    nsig: np.ndarray          # (M,) int64
    start: np.ndarray         # (M, S) int64, bit position (little endian)
    length: np.ndarray        # (M, S) int64, bits
    signed: np.ndarray        # (M, S) bool
    scale: np.ndarray         # (M, S) float64
    offset: np.ndarray        # (M, S) float64
    vmin: np.ndarray          # (M, S) float64: the DBC range, enforced before encoding
    vmax: np.ndarray
    alo: np.ndarray           # (M, S) float64: the receiver's accept bounds (range +- half an LSB)
    ahi: np.ndarray
    crc_table: np.ndarray     # (256,) int64
    max_delta: np.ndarray     # (M,) int64: E2EMaxDeltaCounter

    def __post_init__(self) -> None:
        # the kernels take the table packed in three arrays (a compiled call's cost grows with its arguments)
        object.__setattr__(self, "msg_i", np.ascontiguousarray(np.stack([self.dlc, self.seed, self.nsig,
                                                                          self.max_delta], axis=1)))
        object.__setattr__(self, "sig_i", np.ascontiguousarray(np.stack(
            [self.start, self.length, self.signed.astype(np.int64)], axis=2)))
        object.__setattr__(self, "sig_f", np.ascontiguousarray(np.stack(
            [self.scale, self.offset, self.vmin, self.vmax, self.alo, self.ahi], axis=2)))
        # ... and msg_i, sig_i and the CRC table in one for encode_burst (T_* header)
        m, s = self.sig_i.shape[0], self.sig_i.shape[1]
        head = np.array([m, s, T_HEAD, T_HEAD + 4 * m, T_HEAD + 4 * m + 3 * m * s], dtype=np.int64)
        object.__setattr__(self, "packed_i", np.ascontiguousarray(np.concatenate(
            [head, self.msg_i.ravel(), self.sig_i.ravel(), self.crc_table.astype(np.int64)])))


_I = "int64[::1]"
(T_M, T_S, T_OFF_MSG, T_OFF_SIG, T_OFF_CRC) = range(5)  # CodecTable.packed_i's header
T_HEAD = T_OFF_CRC + 1
_I2 = "int64[:, ::1]"
_F2 = "float64[:, ::1]"


@njit(cache=True)
def encode_range(idx, values, counters, sent, out, msg_i, sig_i, sig_f, crc_table, n):  # pragma: no cover - compiled
    """Encode row i < ``n`` of ``values`` (slots 2.. of message ``idx[i]``) into ``out[i, :dlc]`` with the message's
    alive counter ``counters[m]`` (then advanced mod 16, and ``sent[m]`` counted) and its E2E CRC. Stops at
    the first row it cannot encode (a value outside its DBC range or NaN, a raw value not fitting its
    bits, an unsupported message): returns how many rows were encoded; the caller takes the checked
    per-frame path for that row. Table: ``msg_i[m] = (dlc, crc seed, signals, max delta)``,
    ``sig_i[m, k] = (start bit, bits, signed)``, ``sig_f[m, k] = (scale, offset, min, max, accept low,
    accept high)``. The one encoder of both ends of the bus (:func:`encode_burst`, :func:`command_rows`,
    the simulator's tick)."""
    for i in range(n):
        m = idx[i]
        if m < 0:
            return i
        word = np.uint64(counters[m] & 15) << np.uint64(8)
        for k in range(2, msg_i[m, 2]):
            v = values[i, k]
            if not (sig_f[m, k, 2] <= v <= sig_f[m, k, 3]):
                return i
            r = np.rint((v - sig_f[m, k, 1]) / sig_f[m, k, 0])
            bits = sig_i[m, k, 1]
            if sig_i[m, k, 2]:
                lo, hi = -float(1 << (bits - 1)), float((1 << (bits - 1)) - 1)
            else:
                lo, hi = 0.0, float((1 << bits) - 1)
            if not (lo <= r <= hi):
                return i
            mask = (np.uint64(1) << np.uint64(bits)) - np.uint64(1)
            word |= (np.uint64(np.int64(r)) & mask) << np.uint64(sig_i[m, k, 0])
        size = msg_i[m, 0]
        for b in range(size):
            out[i, b] = np.uint8((word >> np.uint64(8 * b)) & np.uint64(255))
        c = crc_table[msg_i[m, 1] ^ out[i, 1]]
        for b in range(2, size):
            c = crc_table[c ^ out[i, b]]
        out[i, 0] = np.uint8(c ^ 255)
        counters[m] = (counters[m] + 1) & 15
        sent[m] += 1
    return n


@njit(f"int64({_I2}, {_I}, float64[:, :, ::1], {_I}, {_F2}, uint8[:, ::1])", cache=True)
def encode_burst(cs, ti, sig_f, idx, values, out):  # pragma: no cover - compiled
    """:func:`encode_range` over all rows of ``idx`` with few arguments (a compiled call's cost grows with them,
    ~0.15 us per array): the sender's alive counters and sent counts as the rows of ``cs``, the table's msg_i,
    sig_i and CRC table packed in ``ti`` (``CodecTable.packed_i``). (The sender's and the table's arrays come
    first: a sender binds them once, functools.partial.)"""
    m, s = ti[T_M], ti[T_S]
    msg_i = ti[ti[T_OFF_MSG]:ti[T_OFF_MSG] + 4 * m].reshape((m, 4))
    sig_i = ti[ti[T_OFF_SIG]:ti[T_OFF_SIG] + 3 * m * s].reshape((m, s, 3))
    crc_table = ti[ti[T_OFF_CRC]:ti[T_OFF_CRC] + 256]
    return encode_range(idx, values, cs[0], cs[1], out, msg_i, sig_i, sig_f, crc_table, idx.shape[0])


@njit(cache=True, inline="always")
def judge_frame(i, m, now, lengths, data, values, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t):  # pragma: no cover
    """The class code of frame ``i`` of message index ``m`` (a plain data frame of a table message), received at
    ``now``: length, CRC, decode into ``values[i]`` with the accept bounds, then the alive-counter rules on
    ``seq[m]``; a delivered frame sets ``last_ok_t[m]`` and re-arms the timeout. The one implementation of the
    rules (:func:`classify_frame`, :func:`collect_rows`)."""
    size = msg_i[m, 0]
    if lengths[i] != size:
        return BAD_LENGTH_CODE
    c = crc_table[msg_i[m, 1] ^ data[i, 1]]
    for b in range(2, size):
        c = crc_table[c ^ data[i, b]]
    if (c ^ 255) != data[i, 0]:
        return CRC_ERROR_CODE
    word = np.uint64(0)
    for b in range(size):
        word |= np.uint64(data[i, b]) << np.uint64(8 * b)
    for k in range(msg_i[m, 2]):
        bits = sig_i[m, k, 1]
        r = np.int64((word >> np.uint64(sig_i[m, k, 0])) & ((np.uint64(1) << np.uint64(bits)) - np.uint64(1)))
        if sig_i[m, k, 2] and r >= (np.int64(1) << (bits - 1)):
            r -= np.int64(1) << bits
        v = r * sig_f[m, k, 0] + sig_f[m, k, 1]
        if not (sig_f[m, k, 4] <= v <= sig_f[m, k, 5]):
            return OUT_OF_RANGE_CODE
        values[i, k] = v
    code = OK_CODE
    counter = np.int64(values[i, 1])
    last = seq[m, 0]
    if last < 0 or seq[m, 1] != 0:  # first frame, or first after a timeout: (re)start the sequence
        seq[m, 0] = counter
    else:
        delta = (counter - last) & 15
        if delta == 0:
            code = REPEATED_CODE
        elif delta >= 16 - OLD_FRAME_WINDOW:
            code = WRONG_SEQUENCE_CODE  # an old, delayed frame: the reference stays
        else:
            seq[m, 0] = counter
            if delta == 1:
                code = OK_CODE
            elif delta <= msg_i[m, 3]:
                code = OK_SOME_LOST_CODE
            else:
                code = WRONG_SEQUENCE_CODE
    if code <= OK_SOME_LOST_CODE:
        last_ok_t[m] = now
        seq[m, 1] = 0
    return code


@njit(cache=True, inline="always")
def unjudged_code(fid, kind_of_id):  # pragma: no cover - compiled
    """The class code of a frame id that is not judged as a table message: UNKNOWN_CODE, ECHO_CODE, or
    FALLBACK_CODE (an id outside the table, or a message for the Python path); -1 for a message to judge
    (``kind_of_id[fid]`` its index)."""
    if fid < 0 or fid >= kind_of_id.shape[0]:
        return FALLBACK_CODE
    m = kind_of_id[fid]
    if m >= 0:
        return -1
    if m == KIND_UNKNOWN:
        return UNKNOWN_CODE
    if m == KIND_ECHO:
        return ECHO_CODE
    return FALLBACK_CODE


@njit(cache=True, inline="always")  # (a call with this many arrays costs ~0.1 us a frame)
def classify_frame(i, ids, lengths, data, values, now, kind_of_id, msg_i, sig_i, sig_f, crc_table, seq,
                   last_ok_t):  # pragma: no cover - compiled
    """The class code of frame ``i`` of a burst received at ``now``: :func:`unjudged_code`, else
    :func:`judge_frame` (decoded values into ``values[i]``, the sequence state updated): the classification
    of both ends of the bus (:func:`classify_rows`, the simulator's receive of the flight software's
    commands; :func:`collect_rows` decodes the id itself, see there)."""
    fid = ids[i]
    code = unjudged_code(fid, kind_of_id)
    if code >= 0:
        return code
    return judge_frame(i, kind_of_id[fid], now, lengths, data, values, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t)


@njit(cache=True)
def tally_add(tally, st, key):  # pragma: no cover - compiled
    """One more of ``key`` (message row * N_CODES + code) in the (key, count) pairs of ``tally``, of which
    ``st[S_NTALLY]`` are in use (a pair is added for a new key)."""
    k = st[S_NTALLY]
    for j in range(k):
        if tally[j, 0] == key:
            tally[j, 1] += 1
            return
    tally[k, 0] = key
    tally[k, 1] = 1
    st[S_NTALLY] = k + 1


@njit(cache=True, inline="always")  # (a call with this many arrays costs ~0.1 us a frame)
def classify_counted(i, ids, lengths, data, values, now, kind_of_id, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t,
                     tally, st, bus_row, n_codes):  # pragma: no cover - compiled
    """:func:`classify_frame`, the class counted in ``tally`` (:func:`tally_add`, key row * ``n_codes`` + code)
    on its message's row, or on ``bus_row`` for an unknown id or an own echo; a frame for the Python path is
    not counted here."""
    code = classify_frame(i, ids, lengths, data, values, now, kind_of_id, msg_i, sig_i, sig_f, crc_table, seq,
                          last_ok_t)
    if code < UNKNOWN_CODE:
        tally_add(tally, st, kind_of_id[ids[i]] * n_codes + code)
    elif code != FALLBACK_CODE:
        tally_add(tally, st, bus_row * n_codes + code)
    return code


@njit("int64(int64[::1], int64[::1], uint8[:, ::1], int64[::1], float64[:, ::1], int64, float64, int64, int64, "
      "float64, float64, boolean[::1], int64, int64[::1], int64[:, ::1], int64[:, :, ::1], float64[:, :, ::1], "
      "int64[::1], int64[:, ::1], float64[::1])", cache=True)
def classify_rows(ids, lengths, data, status, values, first, now, stop_id, stop_col, stop_lo, stop_hi, count_mask,
                  count_left, kind_of_id, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t):  # pragma: no cover
    """The E2E receiver's classification of frames ``first``.. in order (comms.bus.e2e.E2EReceiver, whose
    Python docstrings give the rules): ``status[i]`` its class code, ``values[i]`` the decoded signals of a
    frame that passed the length and CRC checks. Sequence state per message: ``seq[m] = (last counter or
    -1, timed out)``, ``last_ok_t[m]``; ``kind_of_id[id]``: message index or KIND_*; the table as in
    :func:`encode_range`.

    Returns the index after the last frame classified: all of them, or it stops before a frame for the
    Python path (FALLBACK_CODE: not a plain data frame, or a message outside the table), or after a
    delivered frame that ends the caller's wait: id ``stop_id`` with slot ``stop_col`` in [stop_lo,
    stop_hi], or the ``count_left``-th delivered frame whose id is in ``count_mask``."""
    n = ids.shape[0]
    for i in range(first, n):
        code = classify_frame(i, ids, lengths, data, values, now, kind_of_id, msg_i, sig_i, sig_f, crc_table, seq,
                              last_ok_t)
        status[i] = code
        if code == FALLBACK_CODE:
            return i
        if code <= OK_SOME_LOST_CODE:
            fid = ids[i]
            if fid == stop_id and stop_lo <= values[i, stop_col] <= stop_hi:
                return i + 1
            if count_mask[fid]:
                count_left -= 1
                if count_left <= 0:
                    return i + 1
    return n


# ------------------------------------------------------------------------------ the driver's lockstep tick
# role_of_id[id] for collect_rows: what the flight-side driver does with a delivered frame of that id
ROLE_NONE, ROLE_DEVICE, ROLE_SYNC, ROLE_IMU, ROLE_ST_A, ROLE_ST_B = -1, 0, 1, 2, 3, 4
ROLE_WHEEL = 10  # + wheel index (0-based)
# collect_rows' integer state (st) slots
# (S_NTALLY: pairs in ``tally`` not yet added to the counters; S_UNEXPECTED, S_STALE, S_INCOMPLETE: the
# driver's running counts)
(S_PHASE, S_NTALLY, S_UNEXPECTED, S_STALE, S_INCOMPLETE, S_GROW, S_HAS_LAST, S_LAST, S_TICK, S_EXPECTED,
 S_RECEIVED, S_FAILED, S_PENDING, S_P_TICK, S_P_FOLLOWING, S_SUPERVISED, S_IMU_N, S_ST_HAVE_A, S_ST_HAVE_B,
 S_ST_SEQ_A, S_ST_SEQ_B, S_ST_NEW, S_ST_VALID, S_ST_BLIND, S_WHEEL_NEW) = range(25)
S_IMU_SAT = S_WHEEL_NEW + MAX_WHEELS  # the tick's gyro samples flagged saturated
S_WHEEL_FAULT = S_IMU_SAT + 1  # + wheel index: the fault flags of its status this tick, -1 when none came
NO_FID = -(1 << 40)  # collect_rows' first_fid when frame ``first`` is not judged yet
# a run of SYNCs too far ahead of the last tick: the newest one's tick and how many came one tick apart
S_CHAIN_TICK = S_WHEEL_FAULT + MAX_WHEELS
S_CHAIN_N = S_CHAIN_TICK + 1
S_SIZE = S_CHAIN_N + 1
# A SYNC is plausible when its tick follows the reference tick by 1..MAX_SYNC_STEP and it keeps the period.
# Anything else is counted (S_STALE) and ignored: a replayed log or a forged frame that passed the CRC by
# chance (1 in 256) can no longer move onboard time. A simulator that really moved on (the flight software
# stalled past MAX_SYNC_STEP ticks) is followed again after RESYNC_RUN SYNCs in a row one tick apart, a run
# that random or replayed frames do not make.
MAX_SYNC_STEP = 100
RESYNC_RUN = 3
# ... and its configuration slots (cfg): value-row columns of the signals the driver reads
(C_TICK, C_FOLLOWING, C_PERIOD, C_IMU_X, C_IMU_Y, C_IMU_Z, C_IMU_SAT, C_QW, C_QX, C_VALID, C_BLIND, C_SEQ_A,
 C_QY, C_QZ, C_SEQ_B, C_AGE, C_SPEED, C_TORQUE, C_CURRENT, C_TEMP, C_FAULT, C_N_CODES, C_BUS_ROW,
 C_OFF_KIND, C_OFF_ROLE, C_OFF_CRC, C_OFF_WATCH, C_N_WATCH, C_N_MSG, C_N_SIG, C_WIDTH, C_OFF_MSG, C_OFF_SIG,
 C_OFF_HALVES, C_OFF_SIGF, C_N_TALLY) = range(36)
C_SIZE = C_N_TALLY + 1
# The constant integer arrays travel as one (``consts``: cfg, then kind_of_id, role_of_id, the CRC table,
# the watched messages and the table's msg_i and sig_i at the C_OFF_* offsets; a compiled call's cost grows
# with its arguments, ~0.15 us per array), the tally after the integer state (``st``: S_SIZE on), the
# watched messages' timeout limits, the star tracker halves A, B (C_OFF_HALVES) and the table's sig_f
# (C_OFF_SIGF) after the float state (``ft``: F_SIZE on), and the wheels' status rows in ``ft`` too
# (F_WHEEL_ROWS: one copy of ``ft[:F_SIZE]`` is a closed tick's float outputs).
# ... and its float state (ft) slots
F_T_TICK, F_PERIOD, F_P_PERIOD_MS, F_ST_T, F_ST_Q = 0, 1, 2, 3, 4  # F_ST_Q..F_ST_Q+3: q_NS
F_WHEEL_T = 8  # + wheel index: the time of each wheel's newest status
F_WHEEL_SPEED = F_WHEEL_T + MAX_WHEELS  # + wheel index: the speed of its status this tick, NaN when none came
F_WHEEL_ROWS = F_WHEEL_SPEED + MAX_WHEELS  # + 5 * wheel index: its newest status (speed, torque, current, temp, fault)
F_SIZE = F_WHEEL_ROWS + 5 * MAX_WHEELS
PHASE_SYNC, PHASE_TICK, PHASE_DONE = 0, 1, 2  # waiting for SYNC(k) / for tick k's frames / tick closed


@njit(cache=True)
def _sync_plausible(st, ft, cfg, values, j, has_ref, ref):  # pragma: no cover - compiled
    # SYNC in row j against the reference tick ``ref`` (the last closed or the current one); counts the rest
    tk = np.int64(values[j, cfg[C_TICK]])
    if has_ref == 0:
        return tk >= 0
    if tk <= ref:
        st[S_STALE] += 1
        return False
    if tk - ref <= MAX_SYNC_STEP and abs(values[j, cfg[C_PERIOD]] - 1000.0 * ft[F_PERIOD]) < 1e-6:
        st[S_CHAIN_N] = 0
        return True
    if st[S_CHAIN_N] > 0 and tk == st[S_CHAIN_TICK] + 1:
        st[S_CHAIN_N] += 1
    else:
        st[S_CHAIN_N] = 1
    st[S_CHAIN_TICK] = tk
    if st[S_CHAIN_N] >= RESYNC_RUN:
        st[S_CHAIN_N] = 0
        return True
    st[S_STALE] += 1
    return False


@njit(cache=True)
def _start_tick(st, ft, cfg, values, i, seq, last_ok_t):  # pragma: no cover - compiled
    # SYNC(k) in row i of ``values`` (or the pending one when i < 0) starts tick k
    if i >= 0:
        tick = np.int64(values[i, cfg[C_TICK]])
        following = np.int64(values[i, cfg[C_FOLLOWING]])
        period_ms = values[i, cfg[C_PERIOD]]
    else:
        tick, following, period_ms = st[S_P_TICK], st[S_P_FOLLOWING], ft[F_P_PERIOD_MS]
        st[S_PENDING] = 0
    ft[F_PERIOD] = period_ms / 1000.0
    ft[F_T_TICK] = tick * ft[F_PERIOD]
    if st[S_SUPERVISED] == 0:  # timeouts count from the first tick (FswBusDriver._start_supervision)
        last_ok_t[:] = ft[F_T_TICK]
        seq[:, 1] = 0
        st[S_SUPERVISED] = 1
    st[S_TICK] = tick
    st[S_EXPECTED] = following
    st[S_RECEIVED] = 0
    st[S_FAILED] = 0
    st[S_IMU_N] = 0
    st[S_IMU_SAT] = 0
    st[S_ST_NEW] = 0
    for w in range(MAX_WHEELS):
        st[S_WHEEL_NEW + w] = 0
        st[S_WHEEL_FAULT + w] = -1
        ft[F_WHEEL_SPEED + w] = np.nan
    st[S_PHASE] = PHASE_TICK if following > 0 else PHASE_DONE


@njit(cache=True)
def count_timeouts(now, watch, watch_limit, seq, last_ok_t, tally, st, n_codes):  # pragma: no cover - compiled
    """E2EReceiver.check_timeouts' rule on the receiver's state arrays, shared by both ends of the bus: one
    timeout counted in ``tally`` when watched message ``watch[j]`` has been silent for longer than
    ``watch_limit[j]`` at ``now``, re-armed by a valid frame (``seq[m, 1]``)."""
    for j in range(watch.shape[0]):
        m = watch[j]
        if now - last_ok_t[m] > watch_limit[j]:
            if seq[m, 1] == 0:
                seq[m, 1] = 1
                tally_add(tally, st, m * n_codes + TIMEOUT_CODE)


@njit("void(int64[::1], float64[::1], int64[::1], float64[::1], int64[:, ::1], float64[::1], int64[:, ::1], int64)",
      cache=True)  # (a signature: compiled at import, also where no tick of the warm-up closes incomplete)
def finish_tick(st, ft, watch, watch_limit, seq, last_ok_t, tally, n_codes):  # pragma: no cover - compiled
    """The end of a lockstep tick: incomplete or not, the timeouts (E2EReceiver.check_timeouts' rule: one
    counted when a watched message goes silent for longer than its limit, re-armed by a valid frame), and
    the tick becomes the last one."""
    if st[S_RECEIVED] < st[S_EXPECTED]:
        st[S_INCOMPLETE] += 1
    count_timeouts(ft[F_T_TICK], watch, watch_limit, seq, last_ok_t, tally, st, n_codes)
    st[S_LAST] = st[S_TICK]
    st[S_HAS_LAST] = 1
    st[S_PHASE] = PHASE_DONE


@njit(cache=True)
def star_tracker_pair(st, ft, cfg, st_half, now):  # pragma: no cover - compiled
    """A star tracker sample once both halves (ST_QUAT_A, ST_QUAT_B value rows in ``st_half``) of one
    ``sample_seq`` are in: q_NS (q_w, q_x from A; q_y, q_z from B), valid and blind source from A, time of
    validity ``now`` - B's age; the halves are then cleared."""
    if st[S_ST_HAVE_A] == 0 or st[S_ST_HAVE_B] == 0 or st[S_ST_SEQ_A] != st[S_ST_SEQ_B]:
        return
    ft[F_ST_Q] = st_half[0, cfg[C_QW]]
    ft[F_ST_Q + 1] = st_half[0, cfg[C_QX]]
    ft[F_ST_Q + 2] = st_half[1, cfg[C_QY]]
    ft[F_ST_Q + 3] = st_half[1, cfg[C_QZ]]
    ft[F_ST_T] = now - st_half[1, cfg[C_AGE]] / 1000.0
    st[S_ST_VALID] = 1 if st_half[0, cfg[C_VALID]] != 0.0 else 0
    st[S_ST_BLIND] = np.int64(st_half[0, cfg[C_BLIND]])
    st[S_ST_NEW] = 1
    st[S_ST_HAVE_A] = 0
    st[S_ST_HAVE_B] = 0


@njit(cache=True, inline="always")
def _collect_views(consts, ft, st_all):  # pragma: no cover - compiled
    """collect_rows' views of the packed arrays (the layout FswBusDriver._init_lockstep writes): cfg, the
    codec table (msg_i, sig_i, sig_f), the state st and its tally, the per-id kind and role, the CRC table,
    the watched messages and their limits, and the star tracker's halves."""
    cfg = consts[:C_SIZE]
    m_n, s_n, width = cfg[C_N_MSG], cfg[C_N_SIG], cfg[C_WIDTH]
    msg_i = consts[cfg[C_OFF_MSG]:cfg[C_OFF_MSG] + 4 * m_n].reshape((m_n, 4))
    sig_i = consts[cfg[C_OFF_SIG]:cfg[C_OFF_SIG] + 3 * m_n * s_n].reshape((m_n, s_n, 3))
    sig_f = ft[cfg[C_OFF_SIGF]:cfg[C_OFF_SIGF] + 6 * m_n * s_n].reshape((m_n, s_n, 6))
    st = st_all[:S_SIZE]
    tally = st_all[S_SIZE:S_SIZE + 2 * cfg[C_N_TALLY]].reshape((cfg[C_N_TALLY], 2))
    kind_of_id = consts[cfg[C_OFF_KIND]:cfg[C_OFF_ROLE]]
    role_of_id = consts[cfg[C_OFF_ROLE]:cfg[C_OFF_CRC]]
    crc_table = consts[cfg[C_OFF_CRC]:cfg[C_OFF_WATCH]]
    watch = consts[cfg[C_OFF_WATCH]:cfg[C_OFF_WATCH] + cfg[C_N_WATCH]]
    watch_limit = ft[F_SIZE:F_SIZE + cfg[C_N_WATCH]]
    st_half = ft[cfg[C_OFF_HALVES]:cfg[C_OFF_HALVES] + 2 * width].reshape((2, width))
    return cfg, msg_i, sig_i, sig_f, st, tally, kind_of_id, role_of_id, crc_table, watch, watch_limit, st_half


@njit(cache=True)
def _between_ticks(st, ft, cfg, values, j, role, seq, last_ok_t):  # pragma: no cover - compiled
    """A delivered frame while waiting for SYNC(k): a plausible SYNC starts tick k, a device frame belongs to
    no announced tick."""
    if role == ROLE_SYNC:
        if _sync_plausible(st, ft, cfg, values, j, st[S_HAS_LAST], st[S_LAST]):
            _start_tick(st, ft, cfg, values, j, seq, last_ok_t)
    elif role >= ROLE_DEVICE:
        st[S_UNEXPECTED] += 1


@njit(cache=True)
def _sync_in_tick(st, ft, cfg, values, j):  # pragma: no cover - compiled
    """A delivered SYNC during tick k: one of a later tick is kept pending and closes tick k, an older one is
    stale (counted by _sync_plausible)."""
    tk = np.int64(values[j, cfg[C_TICK]])
    if _sync_plausible(st, ft, cfg, values, j, 1, st[S_TICK]):
        # the next tick already started: keep its SYNC, close this one
        st[S_PENDING] = 1
        st[S_P_TICK] = tk
        st[S_P_FOLLOWING] = np.int64(values[j, cfg[C_FOLLOWING]])
        ft[F_P_PERIOD_MS] = values[j, cfg[C_PERIOD]]
        st[S_PHASE] = PHASE_DONE


@njit(cache=True)
def _receive_gyro(st, cfg, values, j, imu):  # pragma: no cover - compiled
    """The gyro frame's (x, y, z, saturated) as the tick's next ``imu`` row, the saturated ones counted."""
    k = st[S_IMU_N]
    imu[k, 0] = values[j, cfg[C_IMU_X]]
    imu[k, 1] = values[j, cfg[C_IMU_Y]]
    imu[k, 2] = values[j, cfg[C_IMU_Z]]
    imu[k, 3] = values[j, cfg[C_IMU_SAT]]
    if imu[k, 3] != 0.0:
        st[S_IMU_SAT] += 1
    st[S_IMU_N] = k + 1


@njit(cache=True)
def _receive_star_tracker_half(st, ft, cfg, values, j, h, st_half, now):  # pragma: no cover - compiled
    """Half h (0: ST_QUAT_A, 1: ST_QUAT_B) into ``st_half``: a sample once both of one ``sample_seq`` are in."""
    for c in range(values.shape[1]):
        st_half[h, c] = values[j, c]
    st[S_ST_HAVE_A + h] = 1
    st[S_ST_SEQ_A + h] = np.int64(values[j, cfg[C_SEQ_A if h == 0 else C_SEQ_B]])
    star_tracker_pair(st, ft, cfg, st_half, now)


@njit(cache=True)
def _receive_wheel_status(st, ft, cfg, values, j, w, now):  # pragma: no cover - compiled
    """Wheel w's status into ``ft``'s rows (F_WHEEL_ROWS), the tick's speed and fault flag."""
    r = F_WHEEL_ROWS + 5 * w
    ft[r] = values[j, cfg[C_SPEED]]
    ft[r + 1] = values[j, cfg[C_TORQUE]]
    ft[r + 2] = values[j, cfg[C_CURRENT]]
    ft[r + 3] = values[j, cfg[C_TEMP]]
    ft[r + 4] = values[j, cfg[C_FAULT]]
    ft[F_WHEEL_T + w] = now
    st[S_WHEEL_NEW + w] = 1
    ft[F_WHEEL_SPEED + w] = ft[r]
    st[S_WHEEL_FAULT + w] = np.int64(ft[r + 4])  # truncation, as WheelStatus' int()


@njit("int64(int64[::1], float64[:, ::1], int64[::1], float64[::1], int64[::1], int64[:, ::1], float64[::1], "
      "float64[:, ::1], int64[::1], int64[::1], uint8[:, ::1], int64, int64)", cache=True)
def collect_rows(status, values, st_all, ft, consts, seq, last_ok_t, imu, ids, lengths, data, first,
                 first_fid):  # pragma: no cover - compiled
    """FswBusDriver.collect_tick's work on frames ``first``.. of a burst (``ids``, ``lengths``, ``data``), in one
    call (the driver's arrays come first, bound once: functools.partial), each frame classified by
    :func:`judge_frame` as :func:`classify_frame` does (``status``, ``values``, the receiver's ``seq`` /
    ``last_ok_t``) and counted as :func:`classify_counted` counts, in ``tally`` ((message row * n_codes +
    code, count) pairs, ``st[S_NTALLY]`` of them), then what the driver does with it, by phase
    (``st[S_PHASE]``):

      * waiting for SYNC(k) (:func:`_between_ticks`): a delivered SYNC after the last tick starts tick k
        (t_k = k * period, the timeout supervision on the first tick); one at or before it is stale
        (counted); a delivered device frame belongs to no announced tick (counted unexpected);
      * tick k: a delivered device frame is received (:func:`_receive_gyro`, :func:`_receive_star_tracker_half`,
        :func:`_receive_wheel_status`), one that fails E2E counts as failed; a SYNC of a later tick is kept
        pending and closes the tick, an older one is stale (:func:`_sync_in_tick`); the announced count of
        received frames closes it. A closed tick runs :func:`finish_tick`.

    Returns the index after the last frame handled: where the tick closed or the burst ended, or before a
    frame for the Python path (``status`` FALLBACK_CODE) or a gyro frame with ``imu`` full (``st[S_GROW]``)."""
    (cfg, msg_i, sig_i, sig_f, st, tally, kind_of_id, role_of_id, crc_table, watch, watch_limit,
     st_half) = _collect_views(consts, ft, st_all)
    n = ids.shape[0]
    n_codes = cfg[C_N_CODES]
    i = first
    if st[S_PHASE] == PHASE_SYNC and st[S_PENDING] != 0:
        _start_tick(st, ft, cfg, values, -1, seq, last_ok_t)  # a SYNC seen while finishing the last tick
    while i < n and st[S_PHASE] != PHASE_DONE:
        now = ft[F_T_TICK]
        if i == first and first_fid != NO_FID:  # judged by the Python path: status[i], values[i] and counts set
            code = status[i]
            role = role_of_id[first_fid] if 0 <= first_fid < role_of_id.shape[0] else ROLE_NONE
        else:  # unjudged_code's decode, written out: the gyro-row check must come between the id and the
            # judgement, and classify_counted here cost 1.4 us a tick (17 frames) even inlined
            fid = ids[i]
            if fid < 0 or fid >= kind_of_id.shape[0]:
                status[i] = FALLBACK_CODE
                return i
            m = kind_of_id[fid]
            role = role_of_id[fid]
            if m == KIND_FALLBACK:
                status[i] = FALLBACK_CODE
                return i
            if m < 0:
                code = UNKNOWN_CODE if m == KIND_UNKNOWN else ECHO_CODE
                status[i] = code
                tally_add(tally, st, cfg[C_BUS_ROW] * n_codes + code)
            else:
                if role == ROLE_IMU and st[S_PHASE] == PHASE_TICK and st[S_IMU_N] >= imu.shape[0]:
                    st[S_GROW] = 1
                    return i
                code = judge_frame(i, m, now, lengths, data, values, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t)
                status[i] = code
                tally_add(tally, st, m * n_codes + code)
        i += 1
        j = i - 1
        if code > OK_SOME_LOST_CODE:
            if st[S_PHASE] == PHASE_TICK and role >= ROLE_DEVICE:
                st[S_FAILED] += 1
            continue
        if st[S_PHASE] == PHASE_SYNC:
            _between_ticks(st, ft, cfg, values, j, role, seq, last_ok_t)
            continue
        # PHASE_TICK
        if role == ROLE_SYNC:
            _sync_in_tick(st, ft, cfg, values, j)
            continue
        if role < ROLE_DEVICE:
            continue
        st[S_RECEIVED] += 1
        if role == ROLE_IMU:
            _receive_gyro(st, cfg, values, j, imu)
        elif role == ROLE_ST_A or role == ROLE_ST_B:
            _receive_star_tracker_half(st, ft, cfg, values, j, role - ROLE_ST_A, st_half, now)
        elif role >= ROLE_WHEEL:
            _receive_wheel_status(st, ft, cfg, values, j, role - ROLE_WHEEL, now)
        if st[S_RECEIVED] >= st[S_EXPECTED]:
            st[S_PHASE] = PHASE_DONE
    if st[S_PHASE] == PHASE_DONE:  # (never called once the tick is closed)
        finish_tick(st, ft, watch, watch_limit, seq, last_ok_t, tally, n_codes)
    return i


# command_rows' packed arrays (a compiled call's cost grows with its arguments, ~0.15 us per array here):
# ``ic`` ints: this header, then the messages (n_w + 1), the value slots (torque, tick_lsb, CYCLE_DONE's tick),
# the table's msg_i, sig_i and CRC table at the offsets the header gives; ``fc`` floats: the limits (n_w x 2),
# the table's sig_f, then the value rows ((n_w + 1) x width, written by each call) at the header's offsets
(CMD_NW, CMD_M, CMD_S, CMD_WIDTH, CMD_OFF_IDX, CMD_OFF_COLS, CMD_OFF_MSG, CMD_OFF_SIG, CMD_OFF_CRC, CMD_OFF_SIGF,
 CMD_OFF_VALUES) = range(11)
CMD_HEAD = CMD_OFF_VALUES + 1


def pack_commands(limits: np.ndarray, idx: np.ndarray, cols: np.ndarray, width: int, msg_i: np.ndarray,
                  sig_i: np.ndarray, sig_f: np.ndarray, crc_table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ic, fc) for :func:`command_rows` (layout above); the value rows are ``fc[ic[CMD_OFF_VALUES]:]``."""
    nw = len(limits)
    m, s = sig_i.shape[0], sig_i.shape[1]
    head = np.zeros(CMD_HEAD, dtype=np.int64)
    parts = [np.asarray(idx, dtype=np.int64), np.asarray(cols, dtype=np.int64), msg_i.ravel(), sig_i.ravel(),
             crc_table.astype(np.int64)]
    offsets = np.cumsum([CMD_HEAD] + [len(p) for p in parts])
    head[:CMD_OFF_IDX] = nw, m, s, width
    head[CMD_OFF_IDX:CMD_OFF_CRC + 1] = offsets[:5]
    head[CMD_OFF_SIGF] = 2 * nw
    head[CMD_OFF_VALUES] = 2 * nw + sig_f.size
    ic = np.ascontiguousarray(np.concatenate([head] + parts))
    fc = np.concatenate([np.asarray(limits, dtype=np.float64).ravel(), sig_f.ravel(), np.zeros((nw + 1) * width)])
    return ic, fc


@njit("int64(int64[::1], float64[::1], int64[:, ::1], float64[::1], int64, int64, int64, uint8[:, ::1])", cache=True)
def command_rows(ic, fc, cs, torques, tick_lsb, done_tick, with_done, out):  # pragma: no cover - compiled
    """FswBusDriver.send_wheel_torques' frames in one call (the driver's packed arrays ``ic``, ``fc``
    (:func:`pack_commands`) and its sender's alive counters and sent counts ``cs`` = (counters, sent) first,
    bound once: functools.partial): wheel i's command row (``torques[i]`` limited to
    ``limits[i]`` = (low, high), NaN or infinite sent as 0, and ``tick_lsb``) and, ``with_done`` (0 / 1), the
    CYCLE_DONE row (``done_tick``) into ``values`` (slots ``cols`` = torque, tick_lsb, CYCLE_DONE's tick),
    then encoded by :func:`encode_range` (messages ``idx``). Returns the rows encoded (fewer when one
    cannot be)."""
    nw, m, s, width = ic[CMD_NW], ic[CMD_M], ic[CMD_S], ic[CMD_WIDTH]
    idx = ic[ic[CMD_OFF_IDX]:ic[CMD_OFF_IDX] + nw + 1]
    cols = ic[ic[CMD_OFF_COLS]:ic[CMD_OFF_COLS] + 3]
    msg_i = ic[ic[CMD_OFF_MSG]:ic[CMD_OFF_MSG] + 4 * m].reshape((m, 4))
    sig_i = ic[ic[CMD_OFF_SIG]:ic[CMD_OFF_SIG] + 3 * m * s].reshape((m, s, 3))
    crc_table = ic[ic[CMD_OFF_CRC]:ic[CMD_OFF_CRC] + 256]
    limits = fc[:2 * nw].reshape((nw, 2))
    sig_f = fc[ic[CMD_OFF_SIGF]:ic[CMD_OFF_SIGF] + 6 * m * s].reshape((m, s, 6))
    values = fc[ic[CMD_OFF_VALUES]:ic[CMD_OFF_VALUES] + (nw + 1) * width].reshape((nw + 1, width))
    counters = cs[0]
    sent = cs[1]
    n = torques.shape[0]
    values[:, :] = 0.0
    for i in range(n):
        tau = torques[i]
        if not np.isfinite(tau):
            tau = 0.0
        else:  # min(max(tau, low), high), as Python's min and max pick
            if limits[i, 0] > tau:
                tau = limits[i, 0]
            if limits[i, 1] < tau:
                tau = limits[i, 1]
        values[i, cols[0]] = tau
        values[i, cols[1]] = tick_lsb
    values[n, cols[2]] = done_tick
    return encode_range(idx, values, counters, sent, out, msg_i, sig_i, sig_f, crc_table,
                        n + 1 if with_done != 0 else n)
