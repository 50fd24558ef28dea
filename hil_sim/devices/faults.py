"""Bus fault injection, per DBC message and simulated-time window.

The injector sits in the simulator between its devices and the bus (frames the simulated hardware
transmits) and between the bus and its devices (frames the flight software transmits), so a fault can
hit either direction. Kinds (``FaultSpec.kind``):

  drop           the frame is not transmitted
  delay          the frame is transmitted ``delay_s`` later (at the first opportunity after)
  duplicate      the frame is transmitted twice (receiver: ``repeated``)
  corrupt        bit ``bit`` of the payload is flipped after E2E protection (receiver: ``crc_error``)
  stick_counter  the alive counter freezes at its value when the window opens; the CRC stays correct
                 (receiver: ``repeated`` for every frame after the first)
  babble         the message's sending node babbles: ``babble_per_tick`` frames with identifier
                 ``babble_id`` (default 0x001, higher priority than SYNC) and random payloads are sent
                 each tick (receiver: ``unknown_id``; real frames still get through)
  silent         the message's sending node stops transmitting all its frames (receiver: ``timeout``)

Two kinds act on the wheel itself, not on frames (`WheelFailures`): ``wheel_stuck`` (its bearing seizes)
and ``wheel_no_torque`` (its motor or driver dies), for the wheel of message ``RWn_CMD`` / ``RWn_STATUS``
from ``start_s`` on, for good (a failed mechanism does not heal at ``end_s``).

Door failures act on the aperture door's mechanism (``hil_sim.devices.nodes.DoorNode``), not on frames; ``message``
names one of the door's frames (DOOR_CMD or DOOR_STATUS) and the window is when the mechanism is failed:

  door_stuck_open    the door cannot close (it stays where it is when commanded closed; the drive
                     reports the stall)
  door_stuck_closed  the door cannot open (likewise)
  door_slow          a full stroke takes ``delay_s`` longer

Every injected fault is appended to ``FaultInjector.log`` (simulation time, kind, message, frame id,
detail) and to the ``hil_sim.devices.faults`` logger. Random choices (``probability``, babble payloads) come from
a seeded generator, so runs stay deterministic.
"""
from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import can
import numpy as np

from comms.bus.icd import Icd

log = logging.getLogger("hil_sim.devices.faults")

FRAME_FAULT_KINDS = ("drop", "delay", "duplicate", "corrupt", "stick_counter", "babble", "silent")
DOOR_FAULT_KINDS = ("door_stuck_open", "door_stuck_closed", "door_slow")
# physical wheel faults -> the world's wheel failure mode (hil_sim.world.params.WHEEL_FAILURE_MODES)
WHEEL_FAULT_MODES = {"wheel_stuck": "stuck", "wheel_no_torque": "no_torque"}
FAULT_KINDS = FRAME_FAULT_KINDS + DOOR_FAULT_KINDS + tuple(WHEEL_FAULT_MODES)
DOOR_MESSAGES = ("DOOR_CMD", "DOOR_STATUS")
# a wheel named by its command or status frame (group 1: the 1-based wheel, group 2: CMD or STATUS)
WHEEL_MESSAGE = re.compile(r"RW([1-6])_(CMD|STATUS)")


@dataclass(frozen=True)
class FaultSpec:
    """One fault: ``kind`` on frames of DBC message ``message`` during [start_s, end_s) simulated time.

    Same fields as the mission file's ``faults`` entries (hil_sim.mission.model.BusFault), plus babble options.
    """

    kind: str
    message: str
    start_s: float
    end_s: float
    delay_s: float | None = None
    bit: int | None = None
    probability: float = 1.0
    babble_id: int = 0x001
    babble_per_tick: int = 50

    @classmethod
    def from_any(cls, fault: Any) -> "FaultSpec":
        """Accept a FaultSpec, a mission BusFault (pydantic) or a dict with the same fields."""
        if isinstance(fault, cls):
            return fault
        data = fault if isinstance(fault, dict) else (
            fault.model_dump() if hasattr(fault, "model_dump") else vars(fault))
        allowed = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise ValueError(f"fault {data!r}: unknown field(s) {unknown}; allowed: {sorted(allowed)}")
        return cls(**{k: v for k, v in data.items() if v is not None or k in ("delay_s", "bit")})

    def active(self, t_s: float) -> bool:
        return self.start_s <= t_s < self.end_s

    @property
    def on_frames(self) -> bool:
        """A fault of the frames (the injector's), not of a device's mechanism (a door failure)."""
        return self.kind in FRAME_FAULT_KINDS


@dataclass(frozen=True)
class FaultEvent:
    t_s: float
    kind: str
    message: str
    frame_id: int
    detail: str


class WheelFailures:
    """The physical wheel faults of a fault list, applied to the world at their time (`due`)."""

    def __init__(self, faults: Iterable[Any] = ()) -> None:
        pending = []
        for f in (FaultSpec.from_any(f) for f in faults):
            if f.kind not in WHEEL_FAULT_MODES:
                continue
            match = WHEEL_MESSAGE.fullmatch(f.message)
            if match is None:
                raise ValueError(f"fault {f.kind} on {f.message!r}: name the wheel by its RWn_CMD or RWn_STATUS message")
            pending.append((f.start_s, int(match.group(1)) - 1, WHEEL_FAULT_MODES[f.kind], f))
        self.pending = sorted(pending, key=lambda p: p[:2])

    def __bool__(self) -> bool:
        return bool(self.pending)

    def due(self, t_s: float) -> list[tuple[int, str, FaultSpec]]:
        """(wheel index, failure mode, fault) of every failure starting by ``t_s``, each once."""
        out = []
        while self.pending and self.pending[0][0] <= t_s + 1e-9:
            _, wheel, mode, f = self.pending.pop(0)
            out.append((wheel, mode, f))
        return out


def bus_faults(faults: Iterable[Any]) -> list[FaultSpec]:
    """The faults that act on frames (the physical wheel faults left out: `WheelFailures` applies those)."""
    return [f for f in (FaultSpec.from_any(f) for f in faults) if f.kind not in WHEEL_FAULT_MODES]


class FaultInjector:
    """Applies a list of faults to frames (see module docstring)."""

    def __init__(self, icd: Icd, faults: Iterable[Any] = (), seed: int = 0) -> None:
        self.icd = icd
        self.faults: list[FaultSpec] = [FaultSpec.from_any(f) for f in faults]
        for f in self.faults:
            self._validate(f)
        self.rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0xFA17,)))
        self.log: list[FaultEvent] = []
        self._held: dict[str, list[tuple[float, can.Message]]] = {"tx": [], "rx": []}
        self._stuck_counter: dict[int, int] = {}  # fault index -> frozen counter value

    def _validate(self, f: FaultSpec) -> None:
        if f.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind {f.kind!r} unknown; allowed: {FAULT_KINDS}")
        if f.message not in self.icd.messages:
            raise ValueError(f"fault on message {f.message!r}: not in the ICD; known: {sorted(self.icd.messages)}")
        if f.end_s <= f.start_s:
            raise ValueError(f"fault {f.kind} on {f.message}: end_s ({f.end_s}) must be after start_s ({f.start_s})")
        if f.kind == "delay" and not (f.delay_s and f.delay_s > 0):
            raise ValueError(f"fault delay on {f.message}: needs delay_s > 0 [s]")
        if f.kind in DOOR_FAULT_KINDS and f.message not in DOOR_MESSAGES:
            raise ValueError(f"fault {f.kind} on {f.message}: a door failure names a door frame, one of {DOOR_MESSAGES}")
        if f.kind == "door_slow" and not (f.delay_s and f.delay_s > 0):
            raise ValueError(f"fault door_slow on {f.message}: needs delay_s > 0 [s] (the extra stroke time)")
        if f.kind == "corrupt":
            dlc = self.icd.spec(f.message).dlc
            if f.bit is None or not 0 <= f.bit < 8 * dlc:
                raise ValueError(f"fault corrupt on {f.message}: needs bit in 0..{8 * dlc - 1}")
        if not 0 < f.probability <= 1:
            raise ValueError(f"fault {f.kind} on {f.message}: probability must be in (0, 1]")

    def __bool__(self) -> bool:
        return bool(self.faults)

    # ---------------------------------------------------------------------------------------- helpers
    def record(self, t_s: float, kind: str, message: str, frame_id: int, detail: str) -> None:
        event = FaultEvent(t_s, kind, message, frame_id, detail)
        self.log.append(event)
        log.info("t=%.3f s injected %s on %s (0x%03X): %s", t_s, kind, message, frame_id, detail)

    def record_device(self, t_s: float, f: FaultSpec, detail: str) -> None:
        """Log a device failure (a door kind) when its window opens, as the frame faults are logged."""
        spec = self.icd.messages.get(f.message)
        self.record(t_s, f.kind, f.message, spec.frame_id if spec is not None else -1, detail)

    def _hits(self, f: FaultSpec) -> bool:
        return f.probability >= 1.0 or self.rng.random() < f.probability

    def _node_of(self, message: str) -> set[str]:
        return set(self.icd.spec(message).senders)

    # ------------------------------------------------------------------------------------- processing
    def passes_through(self, t_s: float, direction: str = "tx") -> bool:
        """True when ``process`` at ``t_s`` would hand every frame on unchanged and add none: no fault
        window open and no delayed frame of ``direction`` due. The simulator then skips the injector
        (and the frame-by-frame path it needs) for the tick. Closes the windows ``process`` would."""
        for i, f in enumerate(self.faults):
            if f.on_frames and f.active(t_s):
                return False
            self._stuck_counter.pop(i, None)  # a window that closed releases its frozen counter
        return not any(t_due <= t_s + 1e-9 for t_due, _ in self._held[direction])

    def release(self, t_s: float, direction: str = "tx") -> list[can.Message]:
        """Delayed frames of ``direction`` ("tx": simulator -> bus, "rx": bus -> simulator) due by ``t_s``."""
        held = self._held[direction]
        if not held:
            return []
        due = [m for (t_due, m) in held if t_due <= t_s + 1e-9]
        self._held[direction] = [(t_due, m) for (t_due, m) in held if t_due > t_s + 1e-9]
        return due

    def process(self, frames: Sequence[can.Message], t_s: float, extras: bool = True,
                direction: str = "tx") -> list[can.Message]:
        """Frames to pass on now (at simulation time ``t_s``) in place of ``frames``.

        With ``extras`` (once per tick on the transmit path), delayed frames whose time has come come
        first and babble frames last.
        """
        out: list[can.Message] = self.release(t_s, direction) if extras else []
        active = [(i, f) for i, f in enumerate(self.faults) if f.on_frames and f.active(t_s)]
        for i, f in enumerate(self.faults):  # a window that closed releases its frozen counter
            if not f.active(t_s):
                self._stuck_counter.pop(i, None)
        for msg in frames:
            out.extend(self._one(msg, t_s, active, direction))
        for i, f in active if extras else ():
            if f.kind == "babble":
                for _ in range(f.babble_per_tick):
                    data = bytes(self.rng.integers(0, 256, size=8, dtype=np.uint8))
                    out.append(can.Message(arbitration_id=f.babble_id, data=data, is_extended_id=False))
                self.record(t_s, "babble", f.message, f.babble_id, f"{f.babble_per_tick} frames")
        return out

    def _one(self, msg: can.Message, t_s: float, active: list[tuple[int, FaultSpec]],
             direction: str) -> list[can.Message]:
        spec = self.icd.by_id.get(msg.arbitration_id)
        if spec is None or not active:
            return [msg]
        frames = [msg]
        for i, f in active:
            if f.kind == "silent":
                if self._node_of(f.message) & set(spec.senders) and self._hits(f):
                    self.record(t_s, "silent", spec.name, msg.arbitration_id, f"node {'/'.join(spec.senders)}")
                    return []
                continue
            if f.message != spec.name or f.kind == "babble" or not self._hits(f):
                continue
            if f.kind == "drop":
                self.record(t_s, "drop", spec.name, msg.arbitration_id, "")
                return []
            if f.kind == "delay":
                self._held[direction].append((t_s + float(f.delay_s), msg))
                self.record(t_s, "delay", spec.name, msg.arbitration_id, f"{f.delay_s} s")
                return []
            if f.kind == "duplicate":
                frames = frames + [frames[-1]]
                self.record(t_s, "duplicate", spec.name, msg.arbitration_id, "")
            elif f.kind == "corrupt":
                frames = [self._flip(m, int(f.bit)) for m in frames]
                self.record(t_s, "corrupt", spec.name, msg.arbitration_id, f"bit {f.bit}")
            elif f.kind == "stick_counter":
                frames = [self._stick(i, m, spec.name) for m in frames]
                self.record(t_s, "stick_counter", spec.name, msg.arbitration_id,
                             f"counter {self._stuck_counter[i]}")
        return frames

    @staticmethod
    def _flip(msg: can.Message, bit: int) -> can.Message:
        # Deliberate damage below the ICD layer: this is the one place bytes are edited by hand.
        data = bytearray(msg.data)
        data[bit // 8] ^= 1 << (bit % 8)
        return can.Message(arbitration_id=msg.arbitration_id, data=bytes(data), is_extended_id=False)

    def _stick(self, index: int, msg: can.Message, name: str) -> can.Message:
        _, signals = self.icd.decode(msg)
        counter = self._stuck_counter.setdefault(index, int(signals["E2E_Counter"]))
        app = {k: v for k, v in signals.items() if not k.startswith("E2E_")}
        return self.icd.encode(name, app, counter)  # valid CRC, frozen counter

    def held_count(self) -> int:
        return sum(len(h) for h in self._held.values())
