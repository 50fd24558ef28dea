"""The ICD codec and the E2E check as compiled (numba) kernels over whole bursts of frames.

A GNC tick moves ~22 frames; one Python codec call per frame cost a few microseconds each (bit fields,
scaling, range checks and the CRC byte loop in Python). Here the DBC is turned into a signal table at load
time (:class:`CodecTable`, built by :class:`fsw.bus.icd.Icd`) and two kernels walk that table for every
frame of a burst in one call:

  * :func:`encode_rows`: application values (one row per frame) -> frame bytes with alive counter and
    E2E CRC in byte 0, the same bytes as ``Icd.encode`` (cantools' arithmetic: ``round((v - offset) /
    scale)`` with round-half-even, two's complement fields, little-endian layout);
  * :func:`classify_rows`: frame bytes -> the receiver's classification (length, CRC, decode with
    ``raw * scale + offset``, the accept bounds, the alive-counter sequence on the receiver's state
    arrays) and the decoded values, stopping where the caller's wait ends (a tick's SYNC, its last
    announced frame, the awaited CYCLE_DONE) so that later frames are classified later, as before.

:class:`fsw.bus.e2e.E2EReceiver` owns the state and keeps the counts per class (its public housekeeping
view) and the timeouts in Python. Messages the table cannot describe (big-endian or float signals, multiplexing)
are marked unsupported and take the per-frame cantools path. tests/fsw/test_bus_kernels.py checks both
kernels bit-exact against the per-frame codec, and the classification against a reference
implementation of the rules, for every message of the DBC.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

# classify_rows' per-frame class codes: fsw.bus.e2e.FRAME_CLASSES in order (0 ok .. 6 out_of_range), then
UNKNOWN_CODE, ECHO_CODE, FALLBACK_CODE = 7, 8, 9  # unknown id, own echo, judged by the Python path
OK_CODE, OK_SOME_LOST_CODE, REPEATED_CODE, WRONG_SEQUENCE_CODE = 0, 1, 2, 3
CRC_ERROR_CODE, BAD_LENGTH_CODE, OUT_OF_RANGE_CODE = 4, 5, 6
# kind_of_id entries below 0 (>= 0: the message index)
KIND_UNKNOWN, KIND_ECHO, KIND_FALLBACK = -1, -2, -3
OLD_FRAME_WINDOW = 3  # see fsw.bus.e2e
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

    def encode(self, idx: np.ndarray, values: np.ndarray, counters: np.ndarray, sent: np.ndarray,
               out: np.ndarray) -> int:
        """:func:`encode_rows` over this table."""
        return encode_rows(idx, values, counters, sent, out, self.msg_i, self.sig_i, self.sig_f, self.crc_table)


_I = "int64[::1]"
_I2 = "int64[:, ::1]"
_F2 = "float64[:, ::1]"


@njit(f"int64({_I}, {_F2}, {_I}, {_I}, uint8[:, ::1], {_I2}, int64[:, :, ::1], float64[:, :, ::1], {_I})",
      cache=True)
def encode_rows(idx, values, counters, sent, out, msg_i, sig_i, sig_f, crc_table):  # pragma: no cover - compiled
    """Encode row i of ``values`` (slots 2.. of message ``idx[i]``) into ``out[i, :dlc]`` with the message's
    alive counter ``counters[m]`` (then advanced mod 16, and ``sent[m]`` counted) and its E2E CRC. Stops at
    the first row it cannot encode (a value outside its DBC range or NaN, a raw value not fitting its
    bits, an unsupported message): returns how many rows were encoded; the caller takes the checked
    per-frame path for that row. Table: ``msg_i[m] = (dlc, crc seed, signals, max delta)``,
    ``sig_i[m, k] = (start bit, bits, signed)``, ``sig_f[m, k] = (scale, offset, min, max, accept low,
    accept high)``."""
    n = idx.shape[0]
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


@njit("int64(int64[::1], int64[::1], uint8[:, ::1], int64[::1], float64[:, ::1], int64, float64, int64, int64, "
      "float64, float64, boolean[::1], int64, int64[::1], int64[:, ::1], int64[:, :, ::1], float64[:, :, ::1], "
      "int64[::1], int64[:, ::1], float64[::1])", cache=True)
def classify_rows(ids, lengths, data, status, values, first, now, stop_id, stop_col, stop_lo, stop_hi, count_mask,
                  count_left, kind_of_id, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t):  # pragma: no cover
    """The E2E receiver's classification of frames ``first``.. in order (fsw.bus.e2e.E2EReceiver, whose
    Python docstrings give the rules): ``status[i]`` its class code, ``values[i]`` the decoded signals of a
    frame that passed the length and CRC checks. Sequence state per message: ``seq[m] = (last counter or
    -1, timed out)``, ``last_ok_t[m]``; ``kind_of_id[id]``: message index or KIND_*; the table as in
    :func:`encode_rows`.

    Returns the index after the last frame classified: all of them, or it stops before a frame for the
    Python path (FALLBACK_CODE: not a plain data frame, or a message outside the table), or after a
    delivered frame that ends the caller's wait: id ``stop_id`` with slot ``stop_col`` in [stop_lo,
    stop_hi], or the ``count_left``-th delivered frame whose id is in ``count_mask``."""
    n = ids.shape[0]
    for i in range(first, n):
        fid = ids[i]
        if fid < 0 or fid >= kind_of_id.shape[0]:
            status[i] = FALLBACK_CODE
            return i
        m = kind_of_id[fid]
        if m < 0:
            if m == KIND_UNKNOWN:
                status[i] = UNKNOWN_CODE
                continue
            if m == KIND_ECHO:
                status[i] = ECHO_CODE
                continue
            status[i] = FALLBACK_CODE
            return i
        size = msg_i[m, 0]
        if lengths[i] != size:
            status[i] = BAD_LENGTH_CODE
            continue
        c = crc_table[msg_i[m, 1] ^ data[i, 1]]
        for b in range(2, size):
            c = crc_table[c ^ data[i, b]]
        if (c ^ 255) != data[i, 0]:
            status[i] = CRC_ERROR_CODE
            continue
        word = np.uint64(0)
        for b in range(size):
            word |= np.uint64(data[i, b]) << np.uint64(8 * b)
        code = OK_CODE
        for k in range(msg_i[m, 2]):
            bits = sig_i[m, k, 1]
            r = np.int64((word >> np.uint64(sig_i[m, k, 0])) & ((np.uint64(1) << np.uint64(bits)) - np.uint64(1)))
            if sig_i[m, k, 2] and r >= (np.int64(1) << (bits - 1)):
                r -= np.int64(1) << bits
            v = r * sig_f[m, k, 0] + sig_f[m, k, 1]
            if not (sig_f[m, k, 4] <= v <= sig_f[m, k, 5]):
                code = OUT_OF_RANGE_CODE
                break
            values[i, k] = v
        if code == OUT_OF_RANGE_CODE:
            status[i] = code
            continue
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
        status[i] = code
        if code <= OK_SOME_LOST_CODE:
            last_ok_t[m] = now
            seq[m, 1] = 0
            if fid == stop_id and stop_lo <= values[i, stop_col] <= stop_hi:
                return i + 1
            if count_mask[fid]:
                count_left -= 1
                if count_left <= 0:
                    return i + 1
    return n
