"""End-to-end protection of bus frames (AUTOSAR E2E profile 1 style) and the receiver's classifier.

Every frame of the ICD carries, in its first 12 bits:
  * ``E2E_CRC`` (byte 0): CRC-8 SAE J1850 (poly 0x1D, init 0xFF, xor-out 0xFF) computed over the frame's
    16-bit data ID (low byte, then high byte: profile 1 "both bytes" mode) followed by payload bytes
    1..DLC-1. The data ID is not transmitted, so a frame that arrives under the wrong CAN ID (or from a
    sender built against another ICD) fails the CRC even when its bytes are intact.
  * ``E2E_Counter`` (bits 8..11): alive counter, +1 mod 16 per transmission of that frame.

The receiver (:class:`E2EReceiver`) classifies each frame; only ``ok`` and ``ok_some_lost`` frames are
handed to the application. Every classification is counted per message, so a bad frame is visible in
housekeeping and never reaches the estimator.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Iterable, Mapping, NamedTuple

import numpy as np

from comms.bus.crc import e2e_crc
from comms.bus.kernels import (CLASS_OF_CODE, ECHO_CODE, FALLBACK_CODE, FRAME_CLASSES, KIND_ECHO, KIND_FALLBACK,
                               KIND_UNKNOWN, OLD_FRAME_WINDOW, TIMEOUT_CODE, UNKNOWN_CODE, classify_rows)

if TYPE_CHECKING:  # pragma: no cover
    import can

    from comms.bus.burst import FrameBurst
    from comms.bus.icd import Icd

# ---------------------------------------------------------------------------------------- classes
# The names are the kernels' table (comms.bus.kernels.CLASS_OF_CODE: a class's position there is its code).
# OK_SOME_LOST: counter jumped by 2..max_delta: data good, some frames lost. REPEATED: same counter as the last
# accepted frame (duplicate / stuck counter). WRONG_SEQUENCE: counter jumped forward by more than max_delta, or
# went backwards. BAD_LENGTH: DLC differs from the ICD. OUT_OF_RANGE: CRC good but a signal outside its ICD
# range: sender bug. UNKNOWN_ID: identifier not in the ICD (or extended/remote/error frame). OWN_ECHO: a frame
# this node sent itself. TIMEOUT: no valid frame within the message's E2ETimeoutMs.
(OK, OK_SOME_LOST, REPEATED, WRONG_SEQUENCE, CRC_ERROR, BAD_LENGTH, OUT_OF_RANGE, UNKNOWN_ID, OWN_ECHO, _PYTHON_PATH,
 TIMEOUT) = CLASS_OF_CODE

DELIVERED = frozenset({OK, OK_SOME_LOST})
ALL_CLASSES = FRAME_CLASSES + (TIMEOUT,)
BUS_KEY = "_bus"  # counters for frames that cannot be attributed to an ICD message


class ReceivedFrame(NamedTuple):
    """Result of classifying one frame. ``signals`` is only filled for delivered frames.

    Immutable; a NamedTuple rather than a frozen dataclass because one is built per received frame
    (a frozen dataclass's __init__ costs ~5x more)."""

    name: str | None
    frame_id: int
    status: str
    t: float
    counter: int | None = None
    signals: Mapping[str, float] | None = None

    @property
    def delivered(self) -> bool:
        return self.status in DELIVERED


class CheckedFrame(NamedTuple):
    """One frame of a burst as classified by :meth:`E2EReceiver.take`: as :class:`ReceivedFrame`, with the
    decoded signals of a delivered frame as ``row``, the kernels' value row (``Icd.column`` gives a
    signal's slot) instead of a dict."""

    name: str | None
    frame_id: int
    status: str
    delivered: bool
    counter: int | None = None
    row: list | None = None


class CheckedBurst:
    """A received burst being classified (:meth:`E2EReceiver.classify_until`): ``pos`` is the next frame
    to classify; for each classified frame i, ``codes[i]`` its class code (FRAME_CLASSES index, or
    kernels.UNKNOWN_CODE / ECHO_CODE) and, when delivered, ``row(i)`` its decoded value row (``values[i]``
    as the kernel wrote it)."""

    __slots__ = ("burst", "ids", "status", "values", "codes", "rows", "pos", "n", "fallback")

    def __init__(self, burst: "FrameBurst", width: int) -> None:
        self.burst = burst
        self.n = n = len(burst)
        self.ids = burst.ids.tolist()
        self.status = np.full(n, -1, dtype=np.int64)  # -1: not classified yet
        self.values = np.zeros((n, width))
        self.codes: list = [None] * n
        self.rows: dict[int, list] = {}  # value rows of delivered frames the Python path classified
        self.pos = 0
        self.fallback: dict[int, ReceivedFrame | None] = {}  # frames the Python path classified

    def row(self, i: int) -> list:
        """The value row of delivered frame ``i`` (Python floats)."""
        return self.rows[i] if i in self.rows else self.values[i].tolist()


CODE_CLASS = CLASS_OF_CODE[:ECHO_CODE + 1]  # the class of each code a classified frame can have
_NO_MASK = np.zeros(2048, dtype=np.bool_)
NO_STOP = (-1, 0, 0.0, -1.0, _NO_MASK, 0)  # classify_until: classify everything
PYTHON_RUN = 2  # classify_until judges this few frames frame by frame in Python (a compiled call costs more)


@dataclass
class E2EReceiver:
    """Classifies received frames against the ICD and keeps per-message counters.

    ``ignore_ids``: identifiers this node transmits itself. Transports that loop frames back to the
    sender (python-can's udp_multicast does) would otherwise make a node judge its own frames; those are
    counted under ``_bus/own_echo`` and otherwise ignored.
    ``watch``: message names whose silence counts as a timeout (default: every message not ignored).

    Frames are classified in bursts by the compiled kernel (comms.bus.kernels.classify_rows) on this
    receiver's sequence state arrays. ``classify`` (one frame), runs of one or two frames, and frames the
    kernel cannot judge (error, remote and extended frames, messages of a DBC layout outside its table)
    take the Python path here, on the same state: the same rules, checked against one reference in
    tests/fsw/test_bus_kernels.py.
    """

    icd: "Icd"
    ignore_ids: frozenset[int] = frozenset()
    watch: Iterable[str] | None = None
    start_t: float = 0.0
    counters: dict[str, dict[str, int]] = field(init=False)
    _watched: list | None = field(init=False, default=None, repr=False)

    def __post_init__(self) -> None:
        self.ignore_ids = frozenset(self.ignore_ids)
        names = [m.name for m in self.icd.messages.values() if m.frame_id not in self.ignore_ids]
        self.watch = tuple(self.watch) if self.watch is not None else tuple(names)
        self.counters = {name: {c: 0 for c in ALL_CLASSES} for name in names}
        self.counters[BUS_KEY] = {UNKNOWN_ID: 0, OWN_ECHO: 0, "error_frame": 0}
        table = self.icd.table
        n_messages = len(self.icd.message_names)
        # sequence state per message index: (last counter or -1, timed out), time of the last valid frame
        self._seq = np.zeros((n_messages, 2), dtype=np.int64)
        self._seq[:, 0] = -1
        self._last_ok_t = np.full(n_messages, float(self.start_t))
        # frame id -> message index (table messages not ignored), or what else the id is (kernels.KIND_*)
        kind = np.full(len(table.index_of_id), KIND_UNKNOWN, dtype=np.int64)
        for spec in self.icd.messages.values():
            if spec.frame_id not in self.ignore_ids:
                m = self.icd.message_index[spec.name]
                kind[spec.frame_id] = m if table.index_of_id[spec.frame_id] == m else KIND_FALLBACK
        kind[[i for i in self.ignore_ids if 0 <= i < len(kind)]] = KIND_ECHO
        self._kind_of_id = kind
        self._width = table.start.shape[1]
        self._table = (table.msg_i, table.sig_i, table.sig_f, table.crc_table, self._seq, self._last_ok_t)
        # frame id -> (spec, its counts, its message index), for the messages this receiver judges
        self._by_id = {m.frame_id: (m, self.counters[m.name], self.icd.message_index[m.name])
                       for m in self.icd.messages.values() if m.frame_id not in self.ignore_ids}
        self._slots = {m.name: ("E2E_CRC", "E2E_Counter") + m.signals for m in self.icd.messages.values()}

    @property
    def kernel_state(self) -> tuple:
        """(kind_of_id, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t): the arrays a compiled caller
        (comms.bus.kernels.collect_rows) classifies with, this receiver's own sequence state included."""
        return (self._kind_of_id,) + self._table

    def tally_targets(self, n_codes: int) -> list:
        """For each key ``row * n_codes + code`` of a compiled caller's tally (row: message index, or the
        number of messages for the bus-level counts; code: a kernels class code, or kernels.TIMEOUT_CODE),
        the (counts dict, class) it adds to, None where there is none."""
        names = self.icd.message_names
        targets: list = [None] * ((len(names) + 1) * n_codes)
        for m, name in enumerate(names):
            counts = self.counters.get(name)
            if counts is None:
                continue  # ignored (own) messages are never judged
            for code, cls in enumerate(FRAME_CLASSES):
                targets[m * n_codes + code] = (counts, cls)
            targets[m * n_codes + TIMEOUT_CODE] = (counts, TIMEOUT)
        bus = self.counters[BUS_KEY]
        targets[len(names) * n_codes + UNKNOWN_CODE] = (bus, UNKNOWN_ID)
        targets[len(names) * n_codes + ECHO_CODE] = (bus, OWN_ECHO)
        return targets

    def watched_timeouts(self) -> tuple[np.ndarray, np.ndarray]:
        """The watched messages with a timeout (message indices) and their limits [s], as check_timeouts
        judges them."""
        watched = self._timeout_limits()
        return (np.array([m for _, m, _ in watched], dtype=np.int64),
                np.array([lim for _, _, lim in watched], dtype=np.float64))

    def _timeout_limits(self) -> list[tuple[str, int, float]]:
        """(name, message index, limit [s]) of each watched message with a timeout: its E2ETimeoutMs, and a
        nanosecond more against the round-off of times built from ticks."""
        return [(name, self.icd.message_index[name], self.icd.messages[name].timeout_s + 1e-9) for name in self.watch
                if self.icd.messages[name].timeout_s > 0]

    def slots(self, name: str) -> tuple[str, ...]:
        """The value-row slots of message ``name`` (E2E_CRC, E2E_Counter, its signals)."""
        return self._slots[name]

    # ----------------------------------------------------------------------------------- bursts
    def check(self, burst: "FrameBurst") -> CheckedBurst:
        """``burst`` ready to be classified (:meth:`classify_until`, :meth:`take`); nothing judged yet."""
        return CheckedBurst(burst, self._width)

    def classify_until(self, checked: CheckedBurst, now_s: float, stop: tuple = NO_STOP,
                       limit: int | None = None) -> int:
        """Classify the frames of ``checked`` from ``pos`` on (at most ``limit``), received at ``now_s``, in
        order, up to and including a delivered frame that meets ``stop`` = (frame id, value slot, low,
        high, id mask, count): that frame id with its slot in [low, high], or the count-th delivered frame
        whose id is in the mask. Counts them; returns the index after the last one classified (``pos``
        moves there). Later frames stay unjudged, as if still queued."""
        n = checked.n if limit is None else min(checked.n, checked.pos + limit)
        burst = checked.burst
        ids_arr = burst.ids if n == len(burst.ids) else burst.ids[:n]
        stop_id, stop_col, stop_lo, stop_hi, mask, left = stop
        pos = checked.pos
        while pos < n:
            if n - pos <= PYTHON_RUN:
                end = pos  # a frame or two (a SIL reading frames as they arrive): the Python path is cheaper
            else:
                end = classify_rows(ids_arr, burst.lengths, burst.data, checked.status, checked.values, pos, now_s,
                                    stop_id, stop_col, stop_lo, stop_hi, mask, left, self._kind_of_id, *self._table)
                self._count(checked, pos, end)
                if end >= n or checked.status[end] != FALLBACK_CODE:
                    pos = end
                    break
                # frames the kernel classified count toward the stop rule; the next one takes the Python path
                left -= sum(1 for j in range(pos, end) if checked.codes[j] <= 1 and mask[checked.ids[j]])
            frame = self.classify(burst.message(end), now_s)
            checked.fallback[end] = frame
            checked.codes[end] = ECHO_CODE if frame is None else CODE_CLASS.index(frame.status)
            pos = end + 1
            if frame is not None and frame.delivered:
                row = [float(frame.signals[k]) for k in self._slots[frame.name]]
                row += [0.0] * (self._width - len(row))  # the kernels' row width
                checked.rows[end] = row
                if frame.frame_id == stop_id and stop_lo <= row[stop_col] <= stop_hi:
                    break
                if 0 <= frame.frame_id < len(mask) and mask[frame.frame_id]:
                    left -= 1
                    if left <= 0:
                        break
        checked.pos = pos
        return pos

    def _count(self, checked: CheckedBurst, first: int, end: int) -> None:
        """Counts, codes and delivered rows of frames first..end-1, as the kernel classified them."""
        if end <= first:
            return
        codes = checked.status[first:end].tolist()
        checked.codes[first:end] = codes
        by_id, bus, ids, classes = self._by_id, self.counters[BUS_KEY], checked.ids, FRAME_CLASSES
        for j, code in enumerate(codes, first):
            if code < UNKNOWN_CODE:
                by_id[ids[j]][1][classes[code]] += 1
            elif code == UNKNOWN_CODE:
                bus[UNKNOWN_ID] += 1
            else:
                bus[OWN_ECHO] += 1

    def take(self, checked: CheckedBurst, now_s: float) -> CheckedFrame | None:
        """Classify the next frame of ``checked`` (received at ``now_s``): the same outcome and counts as
        ``classify`` of that frame's message; None for the node's own echoed frames."""
        i = checked.pos
        self.classify_until(checked, now_s, limit=1)
        return self.frame_at(checked, i)

    def frame_at(self, checked: CheckedBurst, i: int) -> CheckedFrame | None:
        """Frame ``i`` of ``checked`` as classified (None for an own echo)."""
        code = checked.codes[i]
        if code == ECHO_CODE:
            return None
        if i in checked.fallback:
            frame = checked.fallback[i]
            return CheckedFrame(frame.name, frame.frame_id, frame.status, frame.delivered, frame.counter,
                                checked.rows.get(i))
        fid = checked.ids[i]
        if code == UNKNOWN_CODE:
            return CheckedFrame(None, fid, UNKNOWN_ID, False)
        spec = self._by_id[fid][0]
        row = checked.row(i) if code <= 1 else None
        counter = int(checked.values[i, 1]) if code <= 3 else None
        return CheckedFrame(spec.name, fid, CODE_CLASS[code], code <= 1, counter, row)

    # ----------------------------------------------------------------------------------- frames
    def classify(self, msg: "can.Message", now_s: float) -> ReceivedFrame | None:
        """Classify one frame received at ``now_s`` (receiver clock, s). Never raises for any frame.

        Returns None for the node's own echoed frames, else the classification (with decoded signals
        only when delivered). One frame at a time this is the Python path (the generated per-message
        codec, the rules of ``_sequence``) on the same state as the bursts' kernel: a compiled call
        costs more than it saves for one frame.
        """
        try:  # fast path: a plain data frame of a watched ICD message (attributes as can.Message has them)
            entry = self._by_id.get(msg.arbitration_id)
            if entry is not None and not (msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame):
                return self._classify_known(entry[0], msg, now_s)
        except AttributeError:
            pass
        return self._classify_message(msg, now_s)

    def _classify_message(self, msg: "can.Message", now_s: float) -> ReceivedFrame | None:
        """The Python path of a frame the kernel does not judge (see the class docstring)."""
        frame_id = int(getattr(msg, "arbitration_id", -1))
        if getattr(msg, "is_error_frame", False):
            self.counters[BUS_KEY]["error_frame"] += 1
            return ReceivedFrame(None, frame_id, UNKNOWN_ID, now_s)
        extended = bool(getattr(msg, "is_extended_id", False))
        if frame_id in self.ignore_ids and not extended:
            self.counters[BUS_KEY][OWN_ECHO] += 1
            return None
        spec = None if (extended or getattr(msg, "is_remote_frame", False)) else self.icd.by_id.get(frame_id)
        if spec is None or spec.name not in self.counters:
            self.counters[BUS_KEY][UNKNOWN_ID] += 1
            return ReceivedFrame(None, frame_id, UNKNOWN_ID, now_s)
        return self._classify_known(spec, msg, now_s)

    def _classify_known(self, spec: Any, msg: "can.Message", now_s: float) -> ReceivedFrame:
        """A data frame of a (not ignored) ICD message, frame by frame in Python: the kernel's steps."""
        name, frame_id = spec.name, spec.frame_id
        counts = self.counters[name]
        codec = spec.codec
        data = bytes(msg.data) if msg.data is not None else b""
        if len(data) != spec.dlc:
            counts[BAD_LENGTH] += 1
            return ReceivedFrame(name, frame_id, BAD_LENGTH, now_s)
        if (codec.crc(data) if codec is not None else e2e_crc(spec.data_id, data[1:])) != data[0]:
            counts[CRC_ERROR] += 1
            return ReceivedFrame(name, frame_id, CRC_ERROR, now_s)
        signals = codec.unpack_checked(data) if codec is not None else self.icd.decode_checked(spec, data)
        if signals is None:
            counts[OUT_OF_RANGE] += 1
            return ReceivedFrame(name, frame_id, OUT_OF_RANGE, now_s)
        counter = int(signals["E2E_Counter"])
        m = self.icd.message_index[name]
        status = self._sequence(m, spec.max_delta_counter, counter)
        counts[status] += 1
        if status in DELIVERED:
            self._last_ok_t[m] = now_s
            self._seq[m, 1] = 0
            return ReceivedFrame(name, frame_id, status, now_s, counter, signals)
        return ReceivedFrame(name, frame_id, status, now_s, counter)

    def _sequence(self, m: int, max_delta: int, counter: int) -> str:
        """The alive-counter rules (the kernel's, for the Python path)."""
        last, timed_out = self._seq[m].tolist()
        if last < 0 or timed_out:
            # First frame, or first after a timeout: nothing to compare with, (re)start the sequence.
            self._seq[m, 0] = counter
            return OK
        delta = (counter - last) & 0x0F
        if delta == 0:
            return REPEATED
        if delta >= 16 - OLD_FRAME_WINDOW:
            # Counter 1..3 behind: an old (delayed) frame. Rejected without moving the reference, so the
            # fresh frames around it stay in sequence.
            return WRONG_SEQUENCE
        # A forward jump resynchronises on the received counter even when too large, so that one lost
        # burst costs one rejected frame (profile 1's state machine recovers on the next frame).
        self._seq[m, 0] = counter
        if delta == 1:
            return OK
        if delta <= max_delta:
            return OK_SOME_LOST
        return WRONG_SEQUENCE

    # --------------------------------------------------------------------------------- timeouts
    def check_timeouts(self, now_s: float) -> list[str]:
        """Count a timeout for each watched message silent for longer than its E2ETimeoutMs.

        One timeout is counted when a message goes silent (not one per call); it re-arms when a valid
        frame arrives. Returns the names of the messages currently timed out.
        """
        stale = []
        watched = self._watched
        if watched is None:  # called every tick: the lookups are done once
            watched = self._watched = [(name, m, limit, self.counters[name])
                                       for name, m, limit in self._timeout_limits()]
        last_ok = self._last_ok_t.tolist()
        for name, m, limit, counts in watched:
            if now_s - last_ok[m] > limit:
                if not self._seq[m, 1]:
                    self._seq[m, 1] = 1
                    counts[TIMEOUT] += 1
                stale.append(name)
        return stale

    def reset_clock(self, now_s: float) -> None:
        """Restart timeout supervision at ``now_s`` (e.g. when a lockstep run starts at tick 0)."""
        self._last_ok_t[:] = now_s
        self._seq[:, 1] = 0

    def totals(self) -> dict[str, int]:
        """Counts per class summed over all messages (plus the bus-level counters)."""
        out: dict[str, int] = {c: 0 for c in ALL_CLASSES}
        for name, counts in self.counters.items():
            for cls, n in counts.items():
                out[cls] = out.get(cls, 0) + n
        return out
