"""The spacecraft's CAN devices, wrapping the truth models (``hil_sim.world.world.World``).

Each node behaves like its hardware on the bus:
  * :class:`WheelNode`: applies the latest valid RWn_CMD; after ``cmd_timeout_s`` without one it zeroes
    its torque and raises the "command timeout" fault bit; reports RWn_STATUS every GNC tick.
  * :class:`ImuNode`: samples the gyro at the IMU rate; each sample becomes an IMU_RATE frame
    ``latency_s`` later.
  * :class:`StarTrackerNode`: samples at its own rate; ST_QUAT_A/B go out ``latency_s`` later with the
    sample's age at transmission in ``age_ms``.
  * :class:`DoorNode` (missions with a door only): drives the aperture door toward the latest valid
    DOOR_CMD, reports DOOR_STATUS every GNC tick after the wheel statuses.

Nodes never touch the bus themselves: they hand frames (with the simulation time at which they are due)
to the simulator, which owns the bus, the SYNC protocol and fault injection. A node hands each frame as
the ICD message index and its value row (``Icd.column`` slots); the simulator encodes a tick's frames in
one compiled call (``E2ESender.burst``). The nodes of one spacecraft share one ``E2ESender`` (each
message has one sending node, so the alive counters are per message as on the hardware).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol, Sequence

import can
import numpy as np

from comms.bus.burst import FrameBurst
from comms.bus.icd import WHEEL_FAULT_CMD_TIMEOUT as FAULT_CMD_TIMEOUT
from comms.bus.icd import WHEEL_FAULT_DRIVE as FAULT_DRIVE
from comms.bus.icd import WHEEL_FAULT_OVERSPEED as FAULT_OVERSPEED
from comms.bus.icd import E2ESender, Icd
from comms.dictionary import MAX_WHEELS
from hil_sim.devices import kernels as dk
from hil_sim.devices.kernels import DUE_EPS_S as _EPS_S
from hil_sim.devices.kernels import WS_APPLIED, WS_CMD, WS_LAST_T, WS_TICK
from hil_sim.world.dynamics import FAULT_NO_TORQUE as _WORLD_NO_TORQUE
from hil_sim.world.dynamics import FAULT_SPEED_LIMIT as _WORLD_SPEED_LIMIT
from hil_sim.world.dynamics import FAULT_STUCK as _WORLD_STUCK
from hil_sim.world.world import pack_arrays



class WorldLike(Protocol):
    """What the devices need from a world (hil_sim.world.world.World satisfies it)."""

    t: float
    n_wheels: int

    def imu_sample(self) -> Any: ...
    def star_tracker_sample(self) -> Any: ...
    def wheel_status(self) -> Sequence[Any]: ...


class PendingFrame(NamedTuple):
    """A frame due on the bus at simulation time ``due_s``: message index ``m`` (``Icd.message_index``)
    and its value row, fixed (``row``) or made at transmission time (``row_at(t_tx)``, e.g. the star
    tracker's age). (A NamedTuple: about fifteen are made per GNC tick, a dataclass costs several times
    more to build.)"""

    due_s: float
    source: str
    m: int
    row: list | None
    row_at: Any  # Callable[[float], list] when row is None
    sender: E2ESender

    def values(self, t_tx: float) -> list:
        return self.row if self.row is not None else self.row_at(t_tx)

    def build(self, t_tx: float) -> can.Message:
        """The frame, encoded now for transmission at ``t_tx`` (its alive counter advances)."""
        return _encode(self.sender, [self.m], [self.values(t_tx)]).message(0)


def _encode(sender: E2ESender, idx: Sequence[int], rows: Sequence[list]) -> Any:
    """One compiled encode of the rows (a FrameBurst)."""
    return sender.burst(np.array(idx, dtype=np.int64), np.array(rows, dtype=float).reshape(len(idx), -1))


def _row_maker(icd: Icd, name: str) -> tuple[int, Any]:
    """(message index, ``make(**signals) -> value row``) for message ``name``."""
    width = icd.table.start.shape[1]
    cols = {sig: icd.column(name, sig) for sig in icd.spec(name).signals}

    def make(**signals: float) -> list:
        row = [0.0] * width
        for sig, value in signals.items():
            row[cols[sig]] = value
        return row

    return icd.message_index[name], make


def _clamp(value: float, lo: float, hi: float) -> tuple[float, bool]:
    if value < lo:
        return lo, True
    if value > hi:
        return hi, True
    return value, False


class WheelNode:
    """Reaction wheel drive electronics, node RW``index`` (1-based).

    Its command state (held torque, time and tick of the last command, commands applied) lives in one row
    of a float array (``state``: ``hil_sim.devices.kernels`` WS_* columns; the Devices' ``wheel_state`` row
    of this wheel), which the compiled tick kernels read and write too."""

    def __init__(self, index: int, icd: Icd, cmd_timeout_s: float = 0.3, sender: E2ESender | None = None,
                 state: np.ndarray | None = None) -> None:
        self.index = index
        self.icd = icd
        self.cmd_timeout_s = cmd_timeout_s
        self.sender = sender or E2ESender(self.icd)
        self.state = state if state is not None else np.array([0.0, math.nan, 0.0, math.nan])
        self.name = f"RW{self.index}"
        self.cmd_name = f"RW{self.index}_CMD"
        self.status_name = f"RW{self.index}_STATUS"
        self._status_ranges: tuple[tuple[float, float], ...] | None = None
        self.status_m = self.icd.message_index[self.status_name]
        self._status_cols = [self.icd.column(self.status_name, signal)
                             for signal in ("speed", "torque", "current", "temp", "fault")]
        self._status_template = [0.0] * self.icd.table.start.shape[1]

    @property
    def torque_cmd_Nm(self) -> float:
        return float(self.state[WS_CMD])

    @property
    def last_cmd_t(self) -> float | None:
        """Simulation time of the last valid command, None before the first."""
        t = float(self.state[WS_LAST_T])
        return None if math.isnan(t) else t

    @property
    def commands_applied(self) -> int:
        return int(self.state[WS_APPLIED])

    @property
    def last_cmd_tick(self) -> int | None:
        tick = float(self.state[WS_TICK])
        return None if math.isnan(tick) else int(tick)

    def on_command(self, signals: dict, t_s: float) -> None:
        """A valid RWn_CMD (already E2E-checked) arrived at simulation time ``t_s``."""
        state = self.state
        state[WS_CMD] = float(signals["torque_cmd"])
        state[WS_TICK] = int(signals["tick_lsb"])
        state[WS_LAST_T] = t_s
        state[WS_APPLIED] += 1.0

    def timed_out(self, t_s: float) -> bool:
        last = self.last_cmd_t
        return last is None or t_s - last > self.cmd_timeout_s + _EPS_S

    def torque_at(self, t_s: float) -> float:
        """Motor torque command in force at ``t_s`` [N m] (0 before the first command and after a timeout)."""
        return 0.0 if self.timed_out(t_s) else self.torque_cmd_Nm

    def status_frame(self, status: Any, t_s: float) -> can.Message:
        """RWn_STATUS from the truth wheel status (speed, applied torque, current, temperature, flags)."""
        return _encode(self.sender, [self.status_m], [self.status_row(status, t_s)]).message(0)

    def status_row(self, status: Any, t_s: float) -> list:
        """The value row of ``status_frame``."""
        fault = 0
        if status.fault & _WORLD_SPEED_LIMIT:
            fault |= FAULT_OVERSPEED
        if status.fault & (_WORLD_STUCK | _WORLD_NO_TORQUE):
            fault |= FAULT_DRIVE
        if self.last_cmd_t is not None and self.timed_out(t_s):
            fault |= FAULT_CMD_TIMEOUT
        ranges = self._status_ranges
        if ranges is None:
            ranges = self._status_ranges = tuple(self.icd.signal_range(self.status_name, signal)
                                                 for signal in ("speed", "torque", "current", "temp"))
        (speed_lo, speed_hi), torque_range, current_range, temp_range = ranges
        speed, clipped = _clamp(float(status.speed_rad_s), speed_lo, speed_hi)
        if clipped:
            fault |= FAULT_OVERSPEED
        row = self._status_template.copy()
        row[self._status_cols[0]] = speed
        row[self._status_cols[1]] = _clamp(float(status.torque_Nm), *torque_range)[0]
        row[self._status_cols[2]] = _clamp(float(status.current_A), *current_range)[0]
        row[self._status_cols[3]] = round(_clamp(float(status.temp_C), *temp_range)[0])
        row[self._status_cols[4]] = fault
        return row


@dataclass
class _SampledNode:
    """A sensor node that samples at its own rate and publishes ``latency_s`` after each sample."""

    icd: Icd
    rate_hz: float
    latency_s: float = 0.0
    sender: E2ESender | None = None
    samples: int = 0

    def __post_init__(self) -> None:
        self.sender = self.sender or E2ESender(self.icd)
        self.period_s = 1.0 / self.rate_hz
        self.clock = np.array([0.0, self.period_s])  # [next due time, period]: the tick kernels' view

    @property
    def next_due_s(self) -> float:
        return float(self.clock[0])

    @next_due_s.setter
    def next_due_s(self, value: float) -> None:
        self.clock[0] = value

    def _sample_due(self, t_s: float) -> bool:
        """True (and the next due time advanced past ``t_s``) when a sample is due at ``t_s``."""
        if t_s + _EPS_S < self.next_due_s:
            return False
        self.next_due_s += self.period_s * max(1, math.floor((t_s - self.next_due_s + _EPS_S) / self.period_s) + 1)
        return True

    def due_flags(self, times_s: Sequence[float]) -> list[bool]:
        """``[self._sample_due(t) for t in times_s]`` (the same state changes), in one compiled call per
        period (``device_kernels.due_flags_kernel``, the rule of ``_sample_due``)."""
        times = np.asarray(times_s, dtype=np.float64)
        out = np.zeros(len(times), dtype=np.bool_)
        self.clock[0] = dk.due_flags_kernel(times, self.clock[0], self.clock[1], out, 0)
        return out.tolist()


@dataclass
class ImuNode(_SampledNode):
    """Gyro node: one IMU_RATE frame per sample, ``latency_s`` after the sample."""

    def __post_init__(self) -> None:
        super().__post_init__()
        self._range = self.icd.signal_range("IMU_RATE", "omega_x")
        self._m = self.icd.message_index["IMU_RATE"]
        cols = [self.icd.column("IMU_RATE", s) for s in ("omega_x", "omega_y", "omega_z", "saturated")]
        if cols != [2, 3, 4, 5]:  # frames_for writes the row directly in this layout
            raise ValueError(f"IMU_RATE in {self.icd.path}: expected signals omega_x, omega_y, omega_z, saturated")
        self._pad = [0.0] * (self.icd.table.start.shape[1] - 6)

    def poll(self, world: WorldLike, t_s: float) -> list[PendingFrame]:
        """Sample if a sample is due at ``t_s`` (world at t_s); returns the frame(s) to publish later."""
        if not self._sample_due(t_s):
            return []
        sample = world.imu_sample()
        return self.frames_for(sample.omega_BN_B, sample.saturated, t_s)

    def frames_for(self, omega_BN_B: Any, saturated: bool, t_s: float) -> list[PendingFrame]:
        """The frame(s) of a gyro sample taken at ``t_s`` (``poll`` once the sample is due)."""
        saturated = bool(saturated)
        lo, hi = self._range
        w = list(omega_BN_B) if type(omega_BN_B) is list else np.asarray(omega_BN_B, dtype=float).tolist()
        for j in range(3):  # _clamp, inlined (10 samples per tick)
            if w[j] < lo:
                w[j], saturated = lo, True
            elif w[j] > hi:
                w[j], saturated = hi, True
        row = [0.0, 0.0, w[0], w[1], w[2], float(saturated)] + self._pad
        self.samples += 1
        return [PendingFrame(t_s + self.latency_s, "IMU", self._m, row, None, self.sender)]


@dataclass
class StarTrackerNode(_SampledNode):
    """Star tracker node: ST_QUAT_A + ST_QUAT_B per sample, ``latency_s`` after the exposure."""

    latency_s: float = 0.05

    def __post_init__(self) -> None:
        super().__post_init__()
        self.seq_state = np.zeros(1, dtype=np.int64)  # the next sample_seq (the tick kernels' view)
        self._a_m, self._a_row = _row_maker(self.icd, "ST_QUAT_A")
        self._b_m, self._b_row = _row_maker(self.icd, "ST_QUAT_B")
        self.a_cols = [self.icd.column("ST_QUAT_A", s) for s in ("q_w", "q_x", "valid", "blind_source", "sample_seq")]
        self.b_cols = [self.icd.column("ST_QUAT_B", s) for s in ("q_y", "q_z", "sample_seq")]
        self.age_col = self.icd.column("ST_QUAT_B", "age_ms")

    @property
    def _seq(self) -> int:
        return int(self.seq_state[0])

    @_seq.setter
    def _seq(self, value: int) -> None:
        self.seq_state[0] = value

    def poll(self, world: WorldLike, t_s: float) -> list[PendingFrame]:
        if not self._sample_due(t_s):
            return []
        sample = world.star_tracker_sample()
        return self.frames_for(sample.q_NS, sample.valid, sample.blind_source, t_s)

    def frames_for(self, q_NS: Any, valid: bool, blind_source: int, t_s: float) -> list[PendingFrame]:
        """The frames of a star-tracker sample taken at ``t_s`` (``poll`` once the sample is due)."""
        q = np.asarray(q_NS, dtype=float)
        if q[0] < 0:  # same rotation, canonical sign (keeps the scalar part non-negative)
            q = -q
        seq = self._seq
        self._seq = (self._seq + 1) & 0x0F
        self.samples += 1
        qw, qx, qy, qz = (min(max(c, -1.0), 1.0) for c in q.tolist())  # np.clip to [-1, 1], on floats
        a = self._a_row(q_w=qw, q_x=qx, valid=int(valid), blind_source=int(blind_source), sample_seq=seq)
        row_b = _AgeRow(t_s, self._b_row(q_y=qy, q_z=qz, sample_seq=seq, age_ms=0), self.age_col)
        due = t_s + self.latency_s
        return [PendingFrame(due, "STR", self._a_m, a, None, self.sender),
                PendingFrame(due, "STR", self._b_m, None, row_b, self.sender)]


class _AgeRow:
    """The value row of ST_QUAT_B: fixed but for ``age_ms``, the sample's age at transmission ``t_tx``."""

    __slots__ = ("t_sample", "row", "age_col")

    def __init__(self, t_sample: float, row: list, age_col: int) -> None:
        self.t_sample, self.row, self.age_col = t_sample, row, age_col

    def __call__(self, t_tx: float) -> list:
        row = self.row.copy()
        row[self.age_col] = min(255, max(0, round((t_tx - self.t_sample) * 1000.0)))
        return row


# DOOR_STATUS.state and .fault codes (see the DBC comments)
DOOR_CLOSED, DOOR_OPEN, DOOR_CLOSING, DOOR_OPENING, DOOR_STOPPED = range(5)
DOOR_FAULT_STALLED, DOOR_FAULT_CMD_TIMEOUT = 1, 2


@dataclass(frozen=True)
class DoorParams:
    """A protective aperture door as built: full-stroke times [s], where it starts, and the silence after which
    its drive closes it by itself [s] (0: it holds its position when the commands stop)."""

    close_time_s: float
    open_time_s: float
    initially_open: bool = False
    close_on_silence_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("close_time_s", "open_time_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"DoorParams.{name}: must be a finite number > 0 [s], got {value!r}")
        if not (math.isfinite(self.close_on_silence_s) and self.close_on_silence_s >= 0):
            raise ValueError(f"DoorParams.close_on_silence_s: must be a finite number >= 0 [s], "
                             f"got {self.close_on_silence_s!r}")


class DoorNode:
    """Aperture door drive, node DOOR: its truth (``position``, 0 closed .. 1 fully open) and its frames.

    It moves the door toward the end the latest valid DOOR_CMD asks for, linearly in time at its stroke's
    rate, and reports DOOR_STATUS every GNC tick. After ``close_on_silence_s`` without a valid command (once
    it has had one) it closes the door by itself: a flight software that stopped talking cannot leave the
    instrument open. Door failures (``hil_sim.devices.faults`` kinds door_stuck_open, door_stuck_closed, door_slow)
    act on the motion while their window is open: a door stuck open cannot close, one stuck closed cannot
    open (the drive reports the stall), a slow one takes ``delay_s`` longer for a full stroke. The motion is
    advanced once per GNC period (``advance``), the failures looked up at the period's start."""

    def __init__(self, icd: Icd, params: DoorParams, sender: E2ESender | None = None, faults: Sequence[Any] = (),
                 record: Any = None) -> None:
        self.icd = icd
        self.params = params
        self.sender = sender or E2ESender(icd)
        self.position = 1.0 if params.initially_open else 0.0
        self.commanded_open = bool(params.initially_open)
        self.last_cmd_t: float | None = None
        self.commands_applied = 0
        self.silenced = False  # closed by itself after a command silence (until the next valid command)
        self.motion = 0  # -1 closing, +1 opening, 0 still, over the last period
        self.stalled = False
        self.faults = [f for f in faults if str(getattr(f, "kind", "")).startswith("door_")]
        self._record = record  # (t_s, spec, detail): logs a failure when its window opens
        self._logged: set[int] = set()
        self.status_m, self._status_row = _row_maker(icd, "DOOR_STATUS")

    @property
    def target_open(self) -> bool:
        """The end the drive is driving to (closed after a command silence)."""
        return self.commanded_open and not self.silenced

    def on_command(self, open_door: bool, t_s: float) -> None:
        """A valid DOOR_CMD (already E2E-checked) arrived at simulation time ``t_s``."""
        self.commanded_open = bool(open_door)
        self.last_cmd_t = t_s
        self.silenced = False
        self.commands_applied += 1

    def _failure(self, t_s: float) -> Any:
        for i, f in enumerate(self.faults):
            if f.start_s <= t_s < f.end_s:
                if i not in self._logged and self._record is not None:
                    self._logged.add(i)
                    self._record(t_s, f, f"door at {100.0 * self.position:.1f} % open")
                return f
        return None

    def advance(self, t0_s: float, t1_s: float) -> None:
        """Move the door over [t0_s, t1_s] (one GNC period)."""
        p = self.params
        last = self.last_cmd_t
        if last is not None and p.close_on_silence_s > 0 and t1_s - last > p.close_on_silence_s + _EPS_S:
            self.silenced = True
        target = 1.0 if self.target_open else 0.0
        fault = self._failure(t0_s)
        kind = fault.kind if fault is not None else ""
        if target == self.position:
            self.motion, self.stalled = 0, False
            return
        opening = target > self.position
        if (kind == "door_stuck_open" and not opening) or (kind == "door_stuck_closed" and opening):
            self.motion, self.stalled = 0, True
            return
        stroke_s = p.open_time_s if opening else p.close_time_s
        if kind == "door_slow":
            stroke_s += float(fault.delay_s or 0.0)
        step = (t1_s - t0_s) / stroke_s
        self.position = min(target, self.position + step) if opening else max(target, self.position - step)
        self.motion, self.stalled = (1 if opening else -1), False

    def status_row(self, t_s: float) -> list:  # noqa: ARG002 - the state is the last period's end
        """DOOR_STATUS's value row: position [%], state, the command held, fault bits."""
        pos = self.position
        if pos <= 0.0:
            state = DOOR_CLOSED
        elif pos >= 1.0:
            state = DOOR_OPEN
        elif self.motion < 0:
            state = DOOR_CLOSING
        elif self.motion > 0:
            state = DOOR_OPENING
        else:
            state = DOOR_STOPPED
        fault = (DOOR_FAULT_STALLED if self.stalled else 0) | (DOOR_FAULT_CMD_TIMEOUT if self.silenced else 0)
        return self._status_row(position=min(100.0, max(0.0, 100.0 * pos)), state=state,
                                commanded_open=1 if self.target_open else 0, fault=fault)


@dataclass
class DeviceTiming:
    """Device behaviour not in the truth parameters: latencies [s] and the wheels' command timeout [s].

    The IMU's default latency is 0: a real gyro's (~1 ms) is below the dynamics step, and with 0 the
    frames of tick k are exactly the samples of (t_{k-1}, t_k], the times the flight-side driver assigns.
    """

    imu_latency_s: float = 0.0
    star_tracker_latency_s: float = 0.05
    wheel_cmd_timeout_s: float = 0.3

    def __post_init__(self) -> None:
        for name in ("imu_latency_s", "star_tracker_latency_s", "wheel_cmd_timeout_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"DeviceTiming.{name}: must be a finite number >= 0 [s], got {value!r}")


class Devices:
    """All nodes of one spacecraft: the wheels, the IMU and the star tracker.

    Frames sampled but not yet due wait in an array queue (see ``hil_sim.devices.kernels``). With a
    ``hil_sim.world.world.World`` a GNC period (``step_world``) and a tick's frames (``tick_rows``) take a few
    compiled calls; any other world goes through the nodes' Python (``sample_sensors``, ``wheel_status_rows``),
    on the same state and with the same frames."""

    def __init__(self, icd: Icd, wheels: list[WheelNode], imu: ImuNode, star_tracker: StarTrackerNode,
                 sender: E2ESender | None = None, door: DoorNode | None = None) -> None:
        self.icd = icd
        self.wheels = wheels
        self.imu = imu
        self.star_tracker = star_tracker
        self.door = door  # the aperture door's drive (None: no door, nothing of it on the bus)
        self.sender = sender or self.imu.sender  # the nodes' (shared) sender
        n = len(wheels)
        # the wheels' command state, one row each (WheelNode.state is a view of its row)
        self.wheel_state = np.empty((n, 4))
        for i, w in enumerate(wheels):
            self.wheel_state[i] = w.state
            w.state = self.wheel_state[i]
        self.wheel_timeout_s = np.array([w.cmd_timeout_s for w in wheels], dtype=float)
        self.width = width = icd.table.start.shape[1]
        cap = 64
        self.q_due, self.q_m = np.zeros(cap), np.zeros(cap, dtype=np.int64)
        self.q_rows, self.q_ts = np.zeros((cap, width)), np.zeros(cap)
        self.q_n = np.zeros(1, dtype=np.int64)
        self._out_idx, self._out_rows = np.zeros(0, dtype=np.int64), np.zeros((0, width))
        self._status_ms = np.array([w.status_m for w in wheels], dtype=np.int64)
        self._world_key: Any = None
        self._world_batch: Any = None  # _world_key's one-run batch (None: not a World)
        self._plan: tuple | None = None
        self._tick_args: tuple | None = None  # tick_rows' kernel arguments (see there)
        self._bound: tuple = ()  # what the packed state was bound for (_bind_period)
        st = star_tracker
        self._st_ms = np.array([st._a_m, st._b_m], dtype=np.int64)
        self._st_cols = np.array(st.a_cols + st.b_cols, dtype=np.int64)
        lo, hi = imu._range
        self._imu_range = (float(lo), float(hi))
        self._pack_state()
        self._warm_kernels()

    def _pack_state(self) -> None:
        """The state the per-tick kernels (``device_kernels.period_packed``, ``tick_rows``) read and
        write, as views of a few buffers (``hil_sim.world.world.pack_arrays``, slots DS_*): the sensors' clocks,
        the wheels' command state, the queue's count, and the constants of the frames they make."""
        imu, st = self.imu, self.star_tracker
        lo, hi = self._imu_range
        sync = [self.icd.column("SYNC", s) for s in ("tick", "frames_following", "period_ms")]
        table = self.icd.table  # the codec's constants (tick_burst_packed encodes), copied
        floats = [imu.clock, st.clock, self.wheel_state, self.wheel_timeout_s, self._status_ranges(),
                  np.array([float(imu.latency_s), lo, hi, float(st.latency_s)]), table.sig_f]
        ints = [self._st_ms, self._st_cols, st.seq_state, self.q_n, self._status_ms, self._status_cols(),
                np.array([imu._m, st.age_col, self.icd.message_index["SYNC"]] + sync, dtype=np.int64),
                table.msg_i, table.sig_i, table.crc_table,
                np.array([self.icd.messages[n].frame_id for n in self.icd.message_names], dtype=np.int64), table.dlc]
        self.packed_f, self.packed_i, _, views = pack_arrays(floats, ints, [])
        (imu.clock, st.clock, self.wheel_state, self.wheel_timeout_s, _, _, _,
         self._st_ms, self._st_cols, st.seq_state, self.q_n, _, _, self._packed_iscalars, _, _, _, _, _) = views
        for i, w in enumerate(self.wheels):
            w.state = self.wheel_state[i]

    def _warm_kernels(self) -> None:
        """Call the kernels a run may reach only later (the three-call period path when a normal stream
        refills, ``take_due`` of real-time runs) once with nothing to do and the types a run passes, so that
        they compile (or load) here, at set-up, and with the warm-up (hil_sim.warmup), not inside a tick."""
        steps = 0
        u_seq, none = np.zeros((steps, 1, len(self.wheels))), np.zeros(steps, dtype=np.bool_)
        times = np.zeros(steps + 1)
        dk.plan_period(times, self.imu.clock.copy(), self.star_tracker.clock.copy(), none, none, self.wheel_state,
                       self.wheel_timeout_s, u_seq)
        lo, hi = self._imu_range
        dk.queue_samples(times, none, np.zeros((steps, 1, 3)), np.zeros((steps, 1), dtype=np.bool_), 0.0, lo, hi,
                         0, none, np.zeros((steps, 1, 4)), np.zeros((steps, 1), dtype=np.bool_),
                         np.zeros((steps, 1), dtype=np.int64), 0.0, self._st_ms, self._st_cols,
                         self.star_tracker.seq_state.copy(), self.q_due, self.q_m, self.q_rows, self.q_ts,
                         self.q_n.copy())
        idx, rows = self._out(1)
        dk.take_due(-math.inf, self.q_due, self.q_m, self.q_rows, self.q_ts, np.zeros(1, dtype=np.int64),
                    self.star_tracker.age_col, idx, rows, 0)

    @property
    def pending_count(self) -> int:
        """Frames sampled and not yet handed out (``rows_due``)."""
        return int(self.q_n[0])

    @classmethod
    def for_world(cls, world: WorldLike, icd: Icd, timing: DeviceTiming | None = None,
                  door: DoorParams | None = None) -> "Devices":
        timing = timing or DeviceTiming()
        n = int(world.n_wheels)
        if not 1 <= n <= MAX_WHEELS:
            raise ValueError(f"the ICD has nodes RW1..RW{MAX_WHEELS}; this spacecraft has {n} wheels")
        imu_rate = 1.0 / float(getattr(world, "imu_period_s", 0.01))
        st_rate = 1.0 / float(getattr(world, "star_tracker_period_s", 0.1))
        sender = E2ESender(icd)
        return cls(
            icd=icd,
            wheels=[WheelNode(i, icd, timing.wheel_cmd_timeout_s, sender=sender) for i in range(1, n + 1)],
            imu=ImuNode(icd, imu_rate, timing.imu_latency_s, sender=sender),
            star_tracker=StarTrackerNode(icd, st_rate, timing.star_tracker_latency_s, sender=sender),
            sender=sender,
            door=DoorNode(icd, door, sender=sender) if door is not None else None,
        )

    # ------------------------------------------------------------------------------- the queue
    def _reserve(self, extra: int) -> None:
        """Room for ``extra`` more queued rows."""
        n, cap = int(self.q_n[0]), self.q_due.shape[0]
        if n + extra <= cap:
            return
        cap = max(2 * cap, n + extra)
        self._tick_args = None  # the queue's arrays change
        for name in ("q_due", "q_m", "q_rows", "q_ts"):
            old = getattr(self, name)
            new = np.zeros((cap,) + old.shape[1:], dtype=old.dtype)
            new[:n] = old[:n]
            setattr(self, name, new)

    def _push(self, frames: list[PendingFrame]) -> None:
        """Queue frames made by the nodes' Python (``poll``)."""
        if not frames:
            return
        self._reserve(len(frames))
        for p in frames:
            n = int(self.q_n[0])
            self.q_due[n], self.q_m[n] = p.due_s, p.m
            if p.row is not None:
                self.q_rows[n], self.q_ts[n] = p.row, math.nan
            elif isinstance(p.row_at, _AgeRow):
                self.q_rows[n], self.q_ts[n] = p.row_at.row, p.row_at.t_sample
            else:  # pragma: no cover - every node's row_at is an _AgeRow
                raise TypeError(f"cannot queue a frame whose row is made by {p.row_at!r}")
            self.q_n[0] = n + 1

    def _out(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Output rows for ``n`` frames (reused from call to call)."""
        if self._out_idx.shape[0] < n:
            self._out_idx, self._out_rows = np.zeros(n, dtype=np.int64), np.zeros((n, self.width))
        return self._out_idx, self._out_rows

    # ------------------------------------------------------------------------------- sampling
    def sample_sensors(self, world: WorldLike, t_s: float) -> None:
        """Called with the world at ``t_s`` (after each dynamics step): sensors sample when due."""
        self._push(self.imu.poll(world, t_s))
        self._push(self.star_tracker.poll(world, t_s))

    def _fast_world(self, world: Any) -> Any:
        """The one-run batch the tick kernels read of a ``hil_sim.world.world.World`` (None for any other world)."""
        if world is self._world_key:
            return self._world_batch
        from hil_sim.world.world import World
        self._world_key = world
        self._world_batch = world.batch if type(world) is World and world.batch.n_runs == 1 else None
        return self._world_batch

    def step_world(self, world: Any, dt_s: float, times_s: Sequence[float]) -> None:
        """``world.step(dt_s, wheel_torques(times_s[j]))`` then ``sample_sensors(world, times_s[j + 1])``
        for each step j, through the world's one-call ``advance_sampled`` (the same numbers and frames).
        With a ``hil_sim.world.world.World``: one compiled call (``_step_fused``), else three (commands and due
        flags, world, frame rows)."""
        batch = self._fast_world(world)
        if batch is None:
            self._step_world_python(world, dt_s, times_s)
            return
        times = np.asarray(times_s, dtype=float)
        steps = times.shape[0] - 1
        if steps and self._step_fused(world, batch, dt_s, times, steps):
            return
        self._step_planned(world, dt_s, times, steps)

    def step_period(self, world: Any, dt_s: float, steps: int, t_s: float) -> None:
        """``step_world(world, dt_s, times)`` with times[j] = t_s + j_dt[j], j_dt = arange(steps + 1) * dt_s
        (the simulator's sub-step times of a period, the same sums), made inside the compiled call."""
        batch = self._world_batch if world is self._world_key else self._fast_world(world)
        if batch is not None and steps and self._step_fused(world, batch, dt_s, None, steps, t_s):
            return
        self.step_world(world, dt_s, t_s + np.arange(steps + 1) * dt_s)

    def _step_planned(self, world: Any, dt_s: float, times: np.ndarray, steps: int) -> None:
        """``step_world`` in three compiled calls (commands and due flags, world, frame rows)."""
        plan = self._plan
        if plan is None or plan[0].shape[0] != steps:
            plan = self._plan = (np.zeros((steps, 1, len(self.wheels))), np.zeros(steps, dtype=np.bool_),
                                 np.zeros(steps, dtype=np.bool_))
        u_seq, imu_due, st_due = plan
        imu, st = self.imu, self.star_tracker
        counts = dk.plan_period(times, imu.clock, st.clock, imu_due, st_due, self.wheel_state, self.wheel_timeout_s,
                                u_seq)
        gyro, sat, q, valid, blind = world.advance_planned(dt_s, u_seq, imu_due, st_due, counts // 1000,
                                                           counts % 1000)
        self._reserve(3 * steps)
        lo, hi = self._imu_range
        counts = dk.queue_samples(times, imu_due, gyro, sat, float(imu.latency_s), lo, hi, imu._m, st_due, q, valid,
                                  blind, float(st.latency_s), self._st_ms, self._st_cols, st.seq_state, self.q_due,
                                  self.q_m, self.q_rows, self.q_ts, self.q_n)
        imu.samples += counts // 1000
        st.samples += counts % 1000

    def _bind_period(self, b: Any, dt_s: float, n_sub: int, steps: int) -> None:
        """The period's plan and scratch of ``device_kernels.period_packed`` as views of three buffers (slots
        DP_*). Bound again when the period's length, the sub-steps or the world's batch change."""
        M = b.n_runs
        dist_n = n_sub * M * 3 if b._has_random_disturbance and n_sub > 0 else 0
        floats = [np.zeros((steps, 1, len(self.wheels))), np.zeros((steps, M * 3)), np.arange(steps + 1) * dt_s,
                  np.zeros(steps + 1), np.zeros(steps), np.zeros((steps, M, 3)), np.zeros((steps, M, 4))]
        ints = [np.zeros(3, dtype=np.int64), np.array([dist_n, 0, 0, 0, M], dtype=np.int64),
                np.zeros((steps, M), dtype=np.int64)]
        bools = [np.zeros(steps, dtype=np.bool_), np.zeros(steps, dtype=np.bool_), np.zeros((steps, M), dtype=np.bool_),
                 np.zeros((steps, M), dtype=np.bool_)]
        self.period_f, self.period_i, self.period_b, views = pack_arrays(floats, ints, bools)
        (u_seq, _, _, self._times, _, _, _, self._period_counts, self._period_iscalars, _, imu_due, st_due, _, _) = views
        self._plan = (u_seq, imu_due, st_due)
        self._period_steps = (dist_n * steps, 6 * M, 3 * M)  # the draws of a period, of a sample
        self._bound = (b, dt_s, n_sub, steps)

    def _step_fused(self, world: Any, b: Any, dt_s: float, times: np.ndarray | None, steps: int,
                    t_s: float = math.nan) -> bool:
        """``step_world`` in one compiled call (``device_kernels.period_packed``) when the world's normal
        streams hold the period's numbers in their buffers (else False, nothing done: the caller takes the
        three-call path, whose draws refill them). ``times``: the step times, or None to make them from
        ``t_s`` (``step_period``)."""
        n_sub = world.sub_steps(dt_s)
        bound = self._bound
        if not bound or bound[0] is not b or bound[1] != dt_s or bound[2] != n_sub or bound[3] != steps:
            self._bind_period(b, dt_s, n_sub, steps)
        nd, ni, ns = b.normals_disturbance, b.normals_imu, b.normals_star_tracker
        isc = self._period_iscalars
        isc[dk.DPS_DIST_POS] = nd._pos
        isc[dk.DPS_IMU_POS] = ni._pos
        isc[dk.DPS_ST_POS] = ns._pos
        if times is not None:
            self._times[:] = times
        table = b.prepare_packed(dt_s, n_sub, steps)
        self._reserve(3 * steps)
        dk.period_packed(t_s, self.packed_f, self.packed_i, self.period_f, self.period_i, self.period_b, b.packed_f,
                         b.packed_i, b.packed_b, table[1], table[2], nd._buf, ni._buf, ns._buf, self.q_due, self.q_m,
                         self.q_rows, self.q_ts)
        done, n_imu, n_st = self._period_counts.tolist()
        if done < 0:
            return False
        # the draws take_rows would have made (made before the kernel: also when a step is refused)
        dist, per_imu, per_st = self._period_steps
        nd._pos += dist
        ni._pos += per_imu * n_imu
        ns._pos += per_st * n_st
        b.finish_packed(done, steps, self._plan[0])
        self.imu.samples += n_imu
        self.star_tracker.samples += n_st
        return True

    def _step_world_python(self, world: Any, dt_s: float, times_s: Sequence[float]) -> None:
        if isinstance(times_s, np.ndarray):
            times_s = times_s.tolist()  # plain floats in the frames, as the nodes' Python makes them
        steps = len(times_s) - 1
        first = [w.torque_at(times_s[0]) for w in self.wheels]
        if first == [w.torque_at(times_s[-2]) for w in self.wheels]:
            # a wheel's command only changes here by timing out, once: same at both ends, same throughout
            u = np.empty((steps, len(first)))
            u[:] = first
        else:
            u = np.array([[w.torque_at(t) for w in self.wheels] for t in times_s[:-1]])
        sample_times = times_s[1:]
        imu_due = self.imu.due_flags(sample_times)
        st_due = self.star_tracker.due_flags(sample_times)
        gyro, sat, q, valid, blind = world.advance_sampled(dt_s, u, imu_due, st_due)
        gyro_rows, sat_rows = gyro.tolist(), sat.tolist()  # plain floats for the frames (one conversion)
        for j in range(steps):
            if imu_due[j]:
                self._push(self.imu.frames_for(gyro_rows[j], sat_rows[j], times_s[j + 1]))
            if st_due[j]:
                self._push(self.star_tracker.frames_for(q[j], valid[j], blind[j], times_s[j + 1]))

    # ------------------------------------------------------------------------------- frames out
    def _tick_kernel_args(self, world: Any, sync_m: int, sync_cols: np.ndarray) -> tuple | None:
        """``tick_rows``'s arguments after (t_s, tick, period_ms), for ``world`` (None when it is not a
        ``hil_sim.world.world.World``); kept while the world, the queue's arrays and the output rows' room hold."""
        args = self._tick_args
        if args is None or args[0] is not world or args[1] < 1 + self.q_n.item(0) + len(self.wheels):
            b = self._fast_world(world)
            if b is None:
                return None
            if sync_m != self._packed_iscalars[dk.DSS_SYNC_M] or list(sync_cols) != self._packed_iscalars[
                    dk.DSS_SYNC_COLS:dk.DSS_SYNC_COLS + 3].tolist():  # pragma: no cover - the ICD's SYNC
                raise ValueError("tick_rows: SYNC's index or slots differ from the ICD's")
            idx, rows = self._out(1 + int(self.q_n[0]) + len(self.wheels) + 16)
            args = self._tick_args = (world, idx.shape[0], (self.packed_f, self.packed_i, b.packed_f, b.packed_i,
                                                            self.q_due, self.q_m, self.q_rows, self.q_ts, idx, rows))
        return args[2]

    def tick_rows(self, world: Any, t_s: float, tick: int, period_ms: int, sync_m: int,
                  sync_cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, int] | None:
        """A tick's frames as rows (one compiled call): SYNC(tick) in row 0, then ``rows_due(t_s)`` and
        ``wheel_status_rows(world, t_s)``; returns (message indices, rows, count) or None when ``world``
        is not a ``hil_sim.world.world.World`` (then the caller takes the Python path). ``sync_m``/``sync_cols``:
        SYNC's message index and its (tick, frames_following, period_ms) slots (the ICD's)."""
        args = self._tick_kernel_args(world, sync_m, sync_cols)
        if args is None:
            return None
        n = dk.tick_rows(t_s, float(tick), float(period_ms), *args)
        return args[-2], args[-1], n

    def tick_burst(self, world: Any, t_s: float, tick: int, period_ms: int, sync_m: int,
                   sync_cols: np.ndarray) -> FrameBurst | None:
        """``tick_rows`` encoded by the nodes' sender (``self.sender.burst`` of its rows: the same bytes and
        alive counters), in the same compiled call; None when ``world`` is not a ``hil_sim.world.world.World``."""
        args = self._tick_kernel_args(world, sync_m, sync_cols)
        if args is None:
            return None
        sender = self.sender
        n, done, ids, data, lengths = dk.tick_burst_packed(t_s, float(tick), float(period_ms), *args, sender._counter,
                                                           sender._sent)
        if done < n:  # a row the compiled codec refused: the checked path names the error
            return sender.burst(args[-2][:n], args[-1][:n], data, done)
        return FrameBurst(ids, data, lengths)

    def _status_cols(self) -> np.ndarray:
        cols = getattr(self, "_status_cols_arr", None)
        if cols is None:
            w = self.wheels[0]
            if any(node._status_cols != w._status_cols for node in self.wheels):  # pragma: no cover - ICD layout
                raise ValueError("RWn_STATUS messages differ in layout")
            cols = self._status_cols_arr = np.array(w._status_cols, dtype=np.int64)
        return cols

    def _status_ranges(self) -> np.ndarray:
        ranges = getattr(self, "_status_ranges_arr", None)
        if ranges is None:
            per_wheel = [tuple(self.icd.signal_range(w.status_name, s) for s in ("speed", "torque", "current", "temp"))
                         for w in self.wheels]
            if any(r != per_wheel[0] for r in per_wheel):  # pragma: no cover - ICD layout
                raise ValueError("RWn_STATUS messages differ in ranges")
            ranges = self._status_ranges_arr = np.array(per_wheel[0], dtype=float)
        return ranges

    def frames_due(self, t_s: float) -> list[can.Message]:
        """Sensor frames whose transmission time has come by ``t_s``, oldest first, built at ``t_s``."""
        idx, rows = self.rows_due(t_s)
        return _encode(self.sender, idx, rows).messages() if idx else []

    def rows_due(self, t_s: float) -> tuple[list[int], list[list]]:
        """``frames_due`` as message indices and value rows (not yet encoded)."""
        idx, rows = self._out(int(self.q_n[0]))
        k = dk.take_due(t_s, self.q_due, self.q_m, self.q_rows, self.q_ts, self.q_n, self.star_tracker.age_col,
                        idx, rows, 0)
        return idx[:k].tolist(), rows[:k].tolist()

    def wheel_status_frames(self, world: WorldLike, t_s: float) -> list[can.Message]:
        idx, rows = self.wheel_status_rows(world, t_s)
        return _encode(self.sender, idx, rows).messages()

    def wheel_status_rows(self, world: WorldLike, t_s: float) -> tuple[list[int], list[list]]:
        """``wheel_status_frames`` as message indices and value rows."""
        return ([node.status_m for node in self.wheels],
                [node.status_row(status, t_s) for node, status in zip(self.wheels, world.wheel_status())])

    def wheel_torques(self, t_s: float) -> np.ndarray:
        return np.array([w.torque_at(t_s) for w in self.wheels])
