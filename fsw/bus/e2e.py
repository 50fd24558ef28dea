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

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Iterable, Mapping, NamedTuple

import numpy as np

from fsw.bus.kernels import BAD_LENGTH_CODE, CANDIDATE, CRC_ERROR_CODE, OUT_OF_RANGE_CODE

if TYPE_CHECKING:  # pragma: no cover
    import can

    from fsw.bus.burst import FrameBurst
    from fsw.bus.icd import Icd

# ---------------------------------------------------------------------------------------------- CRC-8
_POLY = 0x1D


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ _POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_TABLE = _make_table()


def crc8_sae_j1850(data: bytes | bytearray | Iterable[int], crc: int = 0xFF, final_xor: bool = True) -> int:
    """CRC-8 SAE J1850: poly 0x1D, init 0xFF, xor-out 0xFF (check value of b"123456789" is 0x4B).

    ``crc`` is the running register (so a CRC can be computed over pieces); pass ``final_xor=False`` for
    all but the last piece.
    """
    for byte in data:
        crc = _TABLE[(crc ^ byte) & 0xFF]
    return crc ^ 0xFF if final_xor else crc


def e2e_crc(data_id: int, payload_without_crc: bytes | bytearray) -> int:
    """Profile-1 style CRC over the 16-bit data ID (low byte first) and the payload after the CRC byte."""
    reg = crc8_sae_j1850((data_id & 0xFF, (data_id >> 8) & 0xFF), final_xor=False)
    return crc8_sae_j1850(payload_without_crc, crc=reg)


# ---------------------------------------------------------------------------------------- classes
OK = "ok"
OK_SOME_LOST = "ok_some_lost"      # counter jumped by 2..max_delta: data good, some frames lost
REPEATED = "repeated"              # same counter as the last accepted frame (duplicate / stuck counter)
WRONG_SEQUENCE = "wrong_sequence"  # counter jumped forward by more than max_delta, or went backwards
CRC_ERROR = "crc_error"
TIMEOUT = "timeout"                # no valid frame within the message's E2ETimeoutMs
BAD_LENGTH = "bad_length"          # DLC differs from the ICD
OUT_OF_RANGE = "out_of_range"      # CRC good but a signal outside its ICD range: sender bug
UNKNOWN_ID = "unknown_id"          # identifier not in the ICD (or extended/remote/error frame)

DELIVERED = frozenset({OK, OK_SOME_LOST})
# A counter this many steps behind the reference is taken for a delayed old frame (see _sequence); with a
# 4-bit counter a larger backwards step cannot be told from a forward jump, which resynchronises.
OLD_FRAME_WINDOW = 3
FRAME_CLASSES = (OK, OK_SOME_LOST, REPEATED, WRONG_SEQUENCE, CRC_ERROR, BAD_LENGTH, OUT_OF_RANGE)
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
    """A received burst after the compiled check (length, CRC, decode, ranges: no state changed yet);
    :meth:`E2EReceiver.take` classifies its frames in order, ``pos`` being the next one."""

    __slots__ = ("burst", "ids", "status", "rows", "pos", "n")

    def __init__(self, burst: "FrameBurst", ids: list, status: list, rows: list) -> None:
        self.burst, self.ids, self.status, self.rows = burst, ids, status, rows
        self.pos, self.n = 0, len(ids)


_CODE_CLASS = {BAD_LENGTH_CODE: BAD_LENGTH, CRC_ERROR_CODE: CRC_ERROR, OUT_OF_RANGE_CODE: OUT_OF_RANGE}


@dataclass
class _SequenceState:
    last_counter: int | None = None
    last_ok_t: float | None = None
    timed_out: bool = False


@dataclass
class E2EReceiver:
    """Classifies received frames against the ICD and keeps per-message counters.

    ``ignore_ids``: identifiers this node transmits itself. Transports that loop frames back to the
    sender (python-can's udp_multicast does) would otherwise make a node judge its own frames; those are
    counted under ``_bus/own_echo`` and otherwise ignored.
    ``watch``: message names whose silence counts as a timeout (default: every message not ignored).
    """

    icd: "Icd"
    ignore_ids: frozenset[int] = frozenset()
    watch: Iterable[str] | None = None
    start_t: float = 0.0
    counters: dict[str, dict[str, int]] = field(init=False)
    _state: dict[str, _SequenceState] = field(init=False)
    _watched: list | None = field(init=False, default=None, repr=False)

    def __post_init__(self) -> None:
        self.ignore_ids = frozenset(self.ignore_ids)
        names = [m.name for m in self.icd.messages.values() if m.frame_id not in self.ignore_ids]
        self.watch = tuple(self.watch) if self.watch is not None else tuple(names)
        self.counters = {name: {c: 0 for c in ALL_CLASSES} for name in names}
        self.counters[BUS_KEY] = {UNKNOWN_ID: 0, "own_echo": 0, "error_frame": 0}
        self._state = {name: _SequenceState(last_ok_t=self.start_t) for name in names}
        # frame id -> what classify needs for that message (ignored ids are not in it: they take the full path)
        self._fast = {m.frame_id: (m, self.counters[m.name], self._state[m.name], m.codec)
                      for m in self.icd.messages.values() if m.frame_id not in self.ignore_ids}
        # the compiled check's table without this node's own ids (those take classify's echo path)
        index_of_id = self.icd.table.index_of_id.copy()
        index_of_id[[i for i in self.ignore_ids if 0 <= i < len(index_of_id)]] = -1
        self._table = dataclasses.replace(self.icd.table, index_of_id=index_of_id)
        self._slots = {m.name: ("E2E_CRC", "E2E_Counter") + m.signals for m in self.icd.messages.values()}

    # ----------------------------------------------------------------------------------- bursts
    def check(self, burst: "FrameBurst") -> CheckedBurst:
        """The stateless part of classifying every frame of ``burst``, in one compiled call (see
        fsw.bus.kernels); :meth:`take` then classifies the frames one by one, in order, as ``classify``."""
        n = len(burst)
        status = np.empty(n, dtype=np.int64)
        values = np.zeros((n, self._table.start.shape[1]))
        self._table.check(burst.ids, burst.lengths, burst.data, status, values)
        return CheckedBurst(burst, burst.ids.tolist(), status.tolist(), values.tolist())

    def take(self, checked: CheckedBurst, now_s: float) -> CheckedFrame | None:
        """Classify the next frame of ``checked`` (received at ``now_s``): the same outcome and counts as
        ``classify`` of that frame's message; None for the node's own echoed frames."""
        i = checked.pos
        checked.pos = i + 1
        code = checked.status[i]
        if code == CANDIDATE:
            spec, counts, state, _ = self._fast[checked.ids[i]]
            row = checked.rows[i]
            counter = int(row[1])
            status = self._sequence(spec, counter)
            counts[status] += 1
            if status in DELIVERED:
                state.last_ok_t = now_s
                state.timed_out = False
                return CheckedFrame(spec.name, spec.frame_id, status, True, counter, row)
            return CheckedFrame(spec.name, spec.frame_id, status, False, counter)
        cls = _CODE_CLASS.get(code)
        if cls is not None:
            spec, counts = self._fast[checked.ids[i]][:2]
            counts[cls] += 1
            return CheckedFrame(spec.name, spec.frame_id, cls, False)
        frame = self.classify(checked.burst.message(i), now_s)  # not in the table: the message path
        if frame is None:
            return None
        row = None
        if frame.signals is not None:
            row = [float(frame.signals[name]) for name in self._slots[frame.name]]
        return CheckedFrame(frame.name, frame.frame_id, frame.status, frame.delivered, frame.counter, row)

    # ----------------------------------------------------------------------------------- frames
    def classify(self, msg: "can.Message", now_s: float) -> ReceivedFrame | None:
        """Classify one frame received at ``now_s`` (receiver clock, s). Never raises for any frame.

        Returns None for the node's own echoed frames, else the classification (with decoded signals
        only when delivered).
        """
        try:  # fast path: a plain data frame of a watched ICD message (attributes as can.Message has them)
            entry = self._fast.get(msg.arbitration_id)
            if entry is not None and not (msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame):
                return self._classify_known(entry, msg, now_s)
        except AttributeError:
            pass
        frame_id = int(getattr(msg, "arbitration_id", -1))
        if getattr(msg, "is_error_frame", False):
            self.counters[BUS_KEY]["error_frame"] += 1
            return ReceivedFrame(None, frame_id, UNKNOWN_ID, now_s)
        if frame_id in self.ignore_ids and not msg.is_extended_id:
            self.counters[BUS_KEY]["own_echo"] += 1
            return None
        spec = None if (msg.is_extended_id or msg.is_remote_frame) else self.icd.by_id.get(frame_id)
        if spec is None or spec.name not in self.counters:
            self.counters[BUS_KEY][UNKNOWN_ID] += 1
            return ReceivedFrame(None, frame_id, UNKNOWN_ID, now_s)
        return self._classify_known(self._fast[frame_id], msg, now_s)

    def _classify_known(self, entry: tuple, msg: "can.Message", now_s: float) -> ReceivedFrame:
        """``classify`` for a data frame whose id is a (not ignored) ICD message: the same steps."""
        spec, counts, state, codec = entry
        name, frame_id = spec.name, spec.frame_id
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
        status = self._sequence(spec, counter)
        counts[status] += 1
        if status in DELIVERED:
            state.last_ok_t = now_s
            state.timed_out = False
            return ReceivedFrame(name, frame_id, status, now_s, counter, signals)
        return ReceivedFrame(name, frame_id, status, now_s, counter)

    def _sequence(self, spec: Any, counter: int) -> str:
        state = self._state[spec.name]
        if state.last_counter is None or state.timed_out:
            # First frame, or first after a timeout: nothing to compare with, (re)start the sequence.
            state.last_counter = counter
            return OK
        delta = (counter - state.last_counter) & 0x0F
        if delta == 0:
            return REPEATED
        if delta >= 16 - OLD_FRAME_WINDOW:
            # Counter 1..3 behind: an old (delayed) frame. Rejected without moving the reference, so the
            # fresh frames around it stay in sequence.
            return WRONG_SEQUENCE
        # A forward jump resynchronises on the received counter even when too large, so that one lost
        # burst costs one rejected frame (profile 1's state machine recovers on the next frame).
        state.last_counter = counter
        if delta == 1:
            return OK
        if delta <= spec.max_delta_counter:
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
            watched = self._watched = [(name, self._state[name], self.icd.messages[name].timeout_s + 1e-9,
                                        self.counters[name]) for name in self.watch
                                       if self.icd.messages[name].timeout_s > 0]
        for name, state, limit, counts in watched:
            last = state.last_ok_t if state.last_ok_t is not None else self.start_t
            if now_s - last > limit:
                if not state.timed_out:
                    state.timed_out = True
                    counts[TIMEOUT] += 1
                stale.append(name)
        return stale

    def reset_clock(self, now_s: float) -> None:
        """Restart timeout supervision at ``now_s`` (e.g. when a lockstep run starts at tick 0)."""
        for state in self._state.values():
            state.last_ok_t = now_s
            state.timed_out = False

    def totals(self) -> dict[str, int]:
        """Counts per class summed over all messages (plus the bus-level counters)."""
        out: dict[str, int] = {c: 0 for c in ALL_CLASSES}
        for name, counts in self.counters.items():
            for cls, n in counts.items():
                out[cls] = out.get(cls, 0) + n
        return out
