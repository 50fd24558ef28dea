"""Flight-software side of the bus: turns ICD frames into typed samples and commands into frames.

Two ways to read the bus:
  * lockstep (:meth:`FswBusDriver.collect_tick`): wait for SYNC(k), then for the ``frames_following``
    device frames of tick k; times are simulation times t_k = k * period (from SYNC), so runs are
    deterministic whatever the host load;
  * real time (:meth:`FswBusDriver.collect_latest`): take whatever has arrived, newest sample of each
    kind with its age on the monotonic clock. The flight software's cycles are not aligned with the
    simulator's SYNC frames then, so the driver answers the newest SYNC it has seen: after a real-time
    cycle's wheel commands it sends CYCLE_DONE(k) for that SYNC k (once per SYNC), and the commands
    carry k in ``tick_lsb``. The simulator can then tell a cycle that kept up from a late one.

Only frames the E2E receiver delivers (ok / ok_some_lost) reach these samples, and only those count
toward the frames a lockstep tick waits for: frames that fail E2E (corrupt, repeated, out of sequence)
cannot close a tick early. A SYNC whose tick is not after the last one (a replayed or stale SYNC) is
counted (``stale_syncs``) and ignored, and in lockstep a device frame that arrives outside every
announced tick (after a tick closed, before the next SYNC: replayed, injected or late) is counted
(``unexpected_frames``) and not used. See docs/bus.md for what E2E can and cannot stop.

A lockstep tick costs a handful of Python calls whatever its frames: one compiled call per burst read
(``comms.bus.kernels.collect_rows``) classifies the frames on the receiver's state, counts them, keeps the
tick's bookkeeping and writes the decoded samples into this driver's arrays; the counts reach the
receiver's per-message counters once per tick, and ``TickInputs`` holds the gyro samples as one array
(its ``ImuSample`` list is built when first read). The wheel commands and CYCLE_DONE are limited and
encoded by one compiled call (``kernels.command_rows``). Real time reads frame by frame, as they arrive.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Callable, NamedTuple, Sequence

import can
import numpy as np

import comms.bus.kernels as K
from comms.bus.burst import FrameBurst
from comms.bus.e2e import CODE_CLASS, CheckedBurst, CheckedFrame, E2EReceiver
from comms.bus.icd import E2ESender, Icd
from comms.bus.kernels import MAX_DLC
from comms.bus.transport import recv_burst, send_batch
from comms.dictionary import MAX_WHEELS

FSW_NODE = "FSW"
_F8 = np.dtype(np.float64)
TX_TIMEOUT_S = 0.05  # how long a send may wait for room in the transmit queue
# Once every announced frame of a tick has arrived but some failed E2E, the tick waits this much longer
# (queue empty) for good frames before it closes incomplete: the simulator sends a tick as one burst, so
# the wait only matters when frames were corrupted, and a flood of bad frames cannot close it before the
# burst is read.
FRAME_GRACE_S = 0.02


class ImuSample(NamedTuple):
    """One gyro sample: omega_BN_B [rad/s] in body axes; ``t`` its time [s] (sim time in lockstep).
    (The sample types are NamedTuples, immutable like frozen dataclasses and built ~4x faster: a tick
    makes about twenty of them.)"""

    omega_BN_B: np.ndarray
    saturated: bool
    t: float
    valid: bool = True


class StarTrackerSample(NamedTuple):
    """Star tracker attitude q_NS (scalar first, as transmitted: not renormalised), valid flag,
    blind source (0 none, 1 sun, 2 moon, 3 rate) and time of validity ``t`` [s] (exposure time)."""

    q_NS: np.ndarray
    valid: bool
    blind_source: int
    t: float


class WheelStatus(NamedTuple):
    """Reaction wheel report: speed [rad/s], applied torque [N m], motor current [A], temperature [degC],
    fault bit flags (1 overspeed, 2 command timeout, 4 drive fault), report time ``t`` [s]."""

    speed_rad_s: float
    torque_Nm: float
    current_A: float
    temp_C: float
    fault: int
    t: float


class TickInputs:
    """Everything the flight software received for lockstep tick ``tick`` (t = tick * period_s).

    ``imu`` is the newest gyro sample of the tick, ``imu_samples`` all of them in arrival order (100 Hz IMU
    at 10 Hz GNC gives 10); a field is None when nothing valid arrived for it during this tick.
    ``complete`` is False when fewer than the announced frames arrived before the timeout.

    ``imu_omega_BN_B`` is the tick's gyro rates as one (n, 3) array [rad/s] (the ``omega_BN_B`` of
    ``imu_samples``, in order), ``wheel_speed_rad_s`` the wheels' speeds (NaN: no status this tick): the
    driver fills them from the decoded frames and builds the ``ImuSample`` / ``WheelStatus`` objects of
    ``imu_samples`` and ``wheels`` only when those lists are first read.
    """

    __slots__ = ("tick", "t", "period_s", "imu", "star_tracker", "_wheels", "_imu_samples", "frames_expected",
                 "frames_received", "_imu_omega", "_imu_saturated", "_wheel_rows", "_wheel_new", "_wheel_src",
                 "_wheel_arrays")

    def __init__(self, tick: int, t: float, period_s: float, imu: ImuSample | None,
                 star_tracker: StarTrackerSample | None, wheels: list[WheelStatus | None],
                 imu_samples: list[ImuSample] | None = None, frames_expected: int = 0, frames_received: int = 0,
                 *, imu_omega_BN_B: np.ndarray | None = None, imu_saturated: list | None = None,
                 wheel_rows: np.ndarray | None = None, wheel_new: list | None = None) -> None:
        self.tick, self.t, self.period_s = tick, t, period_s
        self.imu, self.star_tracker, self._wheels = imu, star_tracker, wheels
        self._wheel_rows, self._wheel_new = wheel_rows, wheel_new
        self._wheel_src = self._wheel_arrays = None
        self.frames_expected, self.frames_received = frames_expected, frames_received
        if imu_samples is None and imu_omega_BN_B is None:
            imu_samples = []
        self._imu_samples = imu_samples
        self._imu_omega = imu_omega_BN_B
        self._imu_saturated = imu_saturated

    @classmethod
    def _of_tick(cls, tick: int, t: float, period_s: float, imu: ImuSample | None,
                 star_tracker: StarTrackerSample | None, frames_expected: int, frames_received: int,
                 omega: np.ndarray | None, saturated: list | None, wheel_new: list, src: np.ndarray,
                 speeds: np.ndarray, faults: np.ndarray) -> "TickInputs":
        """A lockstep tick as FswBusDriver._settle closes it, slot by slot (no keyword parsing): gyro rows
        ``omega`` (None: no sample) with their saturated flags (None: none saturated), the wheels' status
        rows at ``src[F_WHEEL_ROWS:]`` (a closed tick's copy of the driver's float state), the tick's wheel
        speeds and fault flags as ``fresh_wheel_arrays`` gives them."""
        self = object.__new__(cls)
        self.tick, self.t, self.period_s, self.imu, self.star_tracker = tick, t, period_s, imu, star_tracker
        self.frames_expected, self.frames_received = frames_expected, frames_received
        self._wheels = self._wheel_rows = None
        self._wheel_new, self._wheel_src, self._wheel_arrays = wheel_new, src, (speeds, faults)
        self._imu_samples = None if omega is not None else []
        self._imu_omega, self._imu_saturated = omega, saturated
        return self

    @property
    def complete(self) -> bool:
        return self.frames_received >= self.frames_expected

    @property
    def imu_samples(self) -> list[ImuSample]:
        samples = self._imu_samples
        if samples is None:
            # The IMU frames of tick k were sampled over (t_{k-1}, t_k]; spread their times evenly.
            omega, flags, t, period_s = self._imu_omega, self._imu_saturated, self.t, self.period_s
            if flags is None:  # (the driver passes no flags when no sample of the tick was saturated)
                flags = [0.0] * len(omega)
            n = len(flags)
            samples = [ImuSample(omega[i], bool(flags[i]), t - (n - 1 - i) * period_s / n) for i in range(n)]
            self._imu_samples = samples
        return samples

    @imu_samples.setter
    def imu_samples(self, samples: list[ImuSample]) -> None:
        self._imu_samples, self._imu_omega = samples, None

    def _status_rows(self) -> np.ndarray | None:
        """The wheels' status rows (speed, torque, current, temp, fault) the tick closed with."""
        rows = self._wheel_rows
        if rows is None and self._wheel_src is not None:
            n = len(self._wheel_new)
            rows = self._wheel_rows = self._wheel_src[K.F_WHEEL_ROWS:K.F_WHEEL_ROWS + 5 * n].reshape(n, 5)
        return rows

    @property
    def wheels(self) -> list[WheelStatus | None]:
        wheels = self._wheels
        if wheels is None and self._wheel_new is not None:
            new, rows = self._wheel_new, self._status_rows()
            wheels = [None] * len(new)
            if rows is not None:
                t = self.t
                for w, r in enumerate(rows.tolist()):
                    if new[w]:
                        wheels[w] = WheelStatus(r[0], r[1], r[2], r[3], int(r[4]), t)
            self._wheels = wheels
        return wheels

    @wheels.setter
    def wheels(self, wheels: list[WheelStatus | None]) -> None:
        self._wheels, self._wheel_rows, self._wheel_src, self._wheel_arrays = wheels, None, None, None

    @property
    def wheel_speed_rad_s(self) -> np.ndarray:
        """Each wheel's speed reported this tick [rad/s], NaN for a wheel that reported nothing (the
        ``speed_rad_s`` of ``wheels`` as one array)."""
        if self._wheel_arrays is not None and self._wheels is None:
            return self._wheel_arrays[0].copy()
        if self._wheel_rows is not None and self._wheels is None:
            speeds = self._wheel_rows[:, 0].copy()
            speeds[[not x for x in self._wheel_new]] = np.nan
            return speeds
        return np.array([math.nan if w is None else float(w.speed_rad_s) for w in self.wheels], dtype=float)

    @property
    def imu_omega_BN_B(self) -> np.ndarray:
        if self._imu_omega is None:
            self._imu_omega = (np.array([s.omega_BN_B for s in self._imu_samples], dtype=float)
                               if self._imu_samples else np.zeros((0, 3)))
        return self._imu_omega

    def fresh_imu_omega_BN_B(self) -> np.ndarray | None:
        """The tick's gyro rates as the driver decoded them, an (n, 3) array with n >= 1 and every sample
        valid, while ``imu_samples`` has been neither built nor set; else None (read ``imu_samples``)."""
        if self._imu_samples is None:
            return self._imu_omega
        return None

    def fresh_wheel_arrays(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(speed [rad/s], fault flags) per wheel as the driver decoded them, NaN and -1 for a wheel with no
        status this tick (the ``speed_rad_s`` and ``fault`` of ``wheels``), while ``wheels`` has been neither
        built nor set; else None (read ``wheels``)."""
        new = self._wheel_new
        if self._wheels is not None or new is None:
            return None
        if self._wheel_arrays is not None:  # as the driver's tick closed them (kernels.F_WHEEL_SPEED...)
            return self._wheel_arrays
        rows = self._wheel_rows
        if rows is None:
            n = len(new)
            return np.full(n, np.nan), np.full(n, -1, dtype=np.int64)
        speeds = rows[:, 0].copy()
        faults = rows[:, 4].astype(np.int64)  # int(x) of each row's float: truncation, as WheelStatus has it
        if not all(new):
            old = np.logical_not(np.array(new, dtype=np.bool_))
            speeds[old] = np.nan
            faults[old] = -1
        return speeds, faults

    def _fields(self) -> tuple:
        return (self.tick, self.t, self.period_s, self.imu, self.star_tracker, self.wheels, self.imu_samples,
                self.frames_expected, self.frames_received)

    def __eq__(self, other: object) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        return self._fields() == other._fields()

    __hash__ = None  # type: ignore[assignment]  # mutable, as the dataclass it replaces

    def __repr__(self) -> str:
        names = ("tick", "t", "period_s", "imu", "star_tracker", "wheels", "imu_samples", "frames_expected",
                 "frames_received")
        return "TickInputs(" + ", ".join(f"{k}={v!r}" for k, v in zip(names, self._fields())) + ")"


@dataclass
class LatestInputs:
    """Real-time view: newest valid sample of each kind, with its age [s] on the driver clock (None if never)."""

    t: float
    imu: ImuSample | None
    imu_age_s: float | None
    star_tracker: StarTrackerSample | None
    star_tracker_age_s: float | None
    wheels: list[WheelStatus | None]
    wheel_ages_s: list[float | None]
    imu_samples: list[ImuSample] = field(default_factory=list)


# kernels.C_* slots: the value-row column of each signal collect_rows reads
_COLLECT_SIGNALS = ((K.C_TICK, ("SYNC", "tick")), (K.C_FOLLOWING, ("SYNC", "frames_following")),
                    (K.C_PERIOD, ("SYNC", "period_ms")), (K.C_IMU_X, ("IMU_RATE", "omega_x")),
                    (K.C_IMU_Y, ("IMU_RATE", "omega_y")), (K.C_IMU_Z, ("IMU_RATE", "omega_z")),
                    (K.C_IMU_SAT, ("IMU_RATE", "saturated")), (K.C_QW, ("ST_QUAT_A", "q_w")),
                    (K.C_QX, ("ST_QUAT_A", "q_x")), (K.C_VALID, ("ST_QUAT_A", "valid")),
                    (K.C_BLIND, ("ST_QUAT_A", "blind_source")), (K.C_SEQ_A, ("ST_QUAT_A", "sample_seq")),
                    (K.C_QY, ("ST_QUAT_B", "q_y")), (K.C_QZ, ("ST_QUAT_B", "q_z")),
                    (K.C_SEQ_B, ("ST_QUAT_B", "sample_seq")), (K.C_AGE, ("ST_QUAT_B", "age_ms")),
                    (K.C_SPEED, ("RW1_STATUS", "speed")), (K.C_TORQUE, ("RW1_STATUS", "torque")),
                    (K.C_CURRENT, ("RW1_STATUS", "current")), (K.C_TEMP, ("RW1_STATUS", "temp")),
                    (K.C_FAULT, ("RW1_STATUS", "fault")))


class _TickCount:
    """A count of the driver's kept in the compiled tick's integer state (``_st_i[slot]``), read and set as
    an int attribute."""

    def __init__(self, slot: int, doc: str) -> None:
        self.slot = slot
        self.__doc__ = doc

    def __get__(self, driver: "FswBusDriver | None", owner: type) -> "int | _TickCount":
        return self if driver is None else int(driver._st_i[self.slot])

    def __set__(self, driver: "FswBusDriver", n: int) -> None:
        driver._st_i[self.slot] = n


class FswBusDriver:
    """The flight software's bus driver (see module docstring).

    ``bus``: an open python-can bus (``fsw.bus.open_bus``); ``icd``: the loaded ICD; ``n_wheels``: 1..6
    (wheels beyond n_wheels are ignored); ``clock``: monotonic clock for real-time ages.
    """

    def __init__(self, bus: can.BusABC, icd: Icd, n_wheels: int,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not 1 <= n_wheels <= MAX_WHEELS:
            raise ValueError(f"n_wheels must be 1..{MAX_WHEELS} (the ICD has RW1..RW{MAX_WHEELS}), got {n_wheels}")
        self.bus = bus  # (the property: binds the bus's burst methods)
        self.icd = icd
        self.n_wheels = n_wheels
        self.clock = clock
        self._sender = E2ESender(icd)
        own = icd.ids_sent_by(FSW_NODE)
        watch = [n for n in icd.names_sent_by("SIM", "IMU", "STR", *[f"RW{i}" for i in range(1, n_wheels + 1)])]
        self.receiver = E2EReceiver(icd, ignore_ids=own, watch=watch)
        self._device_ids = frozenset(icd.by_id) - own - {icd.spec("SYNC").frame_id}
        self._sync_id = icd.spec("SYNC").frame_id
        self._wheel_index = {icd.spec(f"RW{i}_STATUS").frame_id: i - 1 for i in range(1, n_wheels + 1)}
        self._cmd_ranges = [(f"RW{i}_CMD", *icd.signal_range(f"RW{i}_CMD", "torque_cmd")) for i in range(1, n_wheels + 1)]
        # value-row slots (Icd.column) of the signals the driver reads
        self._col = {(n, sig): icd.column(n, sig) for n in icd.message_names for sig in icd.spec(n).signals}
        self._imu_cols = [self._col["IMU_RATE", s] for s in ("omega_x", "omega_y", "omega_z", "saturated")]
        self._wheel_cols = [self._col["RW1_STATUS", s] for s in ("speed", "torque", "current", "temp", "fault")]
        self._sync_cols = [self._col["SYNC", s] for s in ("tick", "frames_following", "period_ms")]
        self._imu_id = icd.spec("IMU_RATE").frame_id
        # the commands' message indices and value rows (one compiled encode per cycle)
        self._cmd_idx = np.array([icd.message_index[f"RW{i}_CMD"] for i in range(1, n_wheels + 1)]
                                 + [icd.message_index["CYCLE_DONE"]], dtype=np.int64)
        self._cmd_torque_col = self._col["RW1_CMD", "torque_cmd"]
        self._cmd_tick_col = self._col["RW1_CMD", "tick_lsb"]
        self._done_tick_col = self._col["CYCLE_DONE", "tick"]
        self._rx: CheckedBurst | _LockstepRx | None = None  # frames read off the bus, not yet classified
        # newest samples (real time and lockstep alike)
        self._imu: ImuSample | None = None
        self._imu_rx: float | None = None
        self._imu_batch: list[ImuSample] = []
        self._st: StarTrackerSample | None = None
        self._st_rx: float | None = None
        self._timeout_s = 0.0  # collect_tick's timeout, and its deadline once a wait has begun
        self._deadline: float | None = None
        self._waited = False  # collect_tick's first wait has begun (it takes the whole timeout)
        self._realtime = False  # set by collect_latest: frames answer the newest SYNC seen (module docstring)
        self._rt_sync_tick: int | None = None  # newest SYNC tick received in real time
        self._rt_done_tick: int | None = None  # SYNC tick last answered with CYCLE_DONE
        self.t_tick = 0.0
        self.period_s = 0.0
        self.last_tick: int | None = None
        self.tx_errors = 0
        self._kept: dict[int, tuple[list, float] | None] = {}  # keep_latest: frame id -> (value row, time)
        self._kept_ids = np.zeros(0, dtype=np.int64)
        self._one_frame: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # send_frame's message index and row
        self._ahead: list[FrameBurst] = []  # frames to send ahead of the next wheel commands (send_frame)
        self._init_lockstep(icd, n_wheels)

    def _init_lockstep(self, icd: Icd, n_wheels: int) -> None:
        """The arrays of the compiled lockstep tick (kernels.collect_rows): its state, what it does with each
        frame id, the signals' slots, and the tick's decoded samples; then the compiled command encoder's."""
        # kernels.S_*: phase, counts, pending SYNC, samples; then the tally (key, count pairs)
        self._n_codes = K.N_CODES  # tally codes: the kernels' class codes
        n_tally = (len(icd.message_names) + 1) * self._n_codes
        self._st_all = np.zeros(K.S_SIZE + 2 * n_tally, dtype=np.int64)
        self._st_i = self._st_all[:K.S_SIZE]
        col = self._col
        cfg = np.zeros(K.C_SIZE, dtype=np.int64)
        for slot, key in _COLLECT_SIGNALS:
            cfg[slot] = col[key]
        cfg[K.C_N_CODES] = self._n_codes
        cfg[K.C_BUS_ROW] = len(icd.message_names)
        role = self._frame_roles(icd)
        kind_of_id, msg_i, sig_i, sig_f, crc_table, seq, last_ok_t = self.receiver.kernel_state
        self._watch, watch_limit = self.receiver.watched_timeouts()
        cfg[K.C_OFF_KIND] = K.C_SIZE
        cfg[K.C_OFF_ROLE] = cfg[K.C_OFF_KIND] + len(kind_of_id)
        cfg[K.C_OFF_CRC] = cfg[K.C_OFF_ROLE] + len(role)
        cfg[K.C_OFF_WATCH] = cfg[K.C_OFF_CRC] + len(crc_table)
        cfg[K.C_N_WATCH] = len(self._watch)
        width = icd.table.start.shape[1]
        cfg[K.C_N_MSG], cfg[K.C_N_SIG], cfg[K.C_WIDTH] = sig_i.shape[0], sig_i.shape[1], width
        cfg[K.C_OFF_MSG] = cfg[K.C_OFF_WATCH] + len(self._watch)
        cfg[K.C_OFF_SIG] = cfg[K.C_OFF_MSG] + msg_i.size
        cfg[K.C_OFF_HALVES] = K.F_SIZE + len(watch_limit)
        cfg[K.C_OFF_SIGF] = cfg[K.C_OFF_HALVES] + 2 * width
        cfg[K.C_N_TALLY] = n_tally
        self._consts = np.concatenate([cfg, kind_of_id, role, crc_table, self._watch, msg_i.ravel(), sig_i.ravel()])
        self._cfg = self._consts[:K.C_SIZE]
        # kernels.F_*, the watched messages' limits, the star tracker halves, the table's sig_f (C_OFF_*)
        self._ft = np.zeros(cfg[K.C_OFF_SIGF] + sig_f.size)
        self._ft[K.F_SIZE:K.F_SIZE + len(watch_limit)] = watch_limit
        self._ft[cfg[K.C_OFF_SIGF]:] = sig_f.ravel()
        self._ft[K.F_WHEEL_T:K.F_WHEEL_T + MAX_WHEELS] = np.nan  # no status from that wheel yet
        self._ft[K.F_WHEEL_SPEED:K.F_WHEEL_SPEED + MAX_WHEELS] = np.nan
        self._st_i[K.S_WHEEL_FAULT:K.S_WHEEL_FAULT + MAX_WHEELS] = -1
        self._ft_out = self._ft[:K.F_SIZE]  # a closed tick's float outputs (copied once per tick)
        self._watch_limit = self._ft[K.F_SIZE:K.F_SIZE + len(watch_limit)]
        self._table = (msg_i, sig_i, sig_f, seq, last_ok_t)
        self._st_ab = {icd.spec("ST_QUAT_A").frame_id: 0, icd.spec("ST_QUAT_B").frame_id: 1}
        self._width = width
        self._imu_buf = np.zeros((64, 4))  # the tick's gyro rows (x, y, z, saturated); grows when full
        # the star tracker's halves (A, B) waiting for their pair; each wheel's newest status row (in ft)
        self._st_half = self._ft[cfg[K.C_OFF_HALVES]:cfg[K.C_OFF_HALVES] + 2 * width].reshape(2, width)
        self._wheel_buf = self._ft[K.F_WHEEL_ROWS:K.F_WHEEL_ROWS + 5 * n_wheels].reshape(n_wheels, 5)
        self._tally_flat = self._st_all[K.S_SIZE:]
        self._tally = self._tally_flat.reshape(n_tally, 2)
        self._tally_targets = self.receiver.tally_targets(self._n_codes)
        self._status_buf = np.zeros(64, dtype=np.int64)  # a lockstep burst's class codes and value rows
        self._values_buf = np.zeros((64, width))
        self._bind_collect()
        self._rx_reuse = _LockstepRx(None, 0)  # the lockstep burst being read (one object, reused)
        self._no_frames = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 8), dtype=np.uint8))
        self._init_commands(icd, n_wheels, width)

    def _frame_roles(self, icd: Icd) -> np.ndarray:
        """role_of_id for collect_rows: what the lockstep tick does with a delivered frame of each id."""
        role = np.full(2048, K.ROLE_NONE, dtype=np.int64)
        role[[i for i in self._device_ids if 0 <= i < 2048]] = K.ROLE_DEVICE
        role[self._sync_id] = K.ROLE_SYNC
        role[self._imu_id] = K.ROLE_IMU
        role[icd.spec("ST_QUAT_A").frame_id] = K.ROLE_ST_A
        role[icd.spec("ST_QUAT_B").frame_id] = K.ROLE_ST_B
        for fid, w in self._wheel_index.items():
            role[fid] = K.ROLE_WHEEL + w
        return role

    def _init_commands(self, icd: Icd, n_wheels: int, width: int) -> None:
        """The wheel commands' and the heartbeat's frames, encoded by kernels.command_rows."""
        # the commands' frame ids / lengths (with and without CYCLE_DONE; never edited: bursts share them)
        ids = np.array([icd.spec(icd.message_names[m]).frame_id for m in self._cmd_idx], dtype=np.int64)
        dlc = icd.table.dlc[self._cmd_idx].copy()
        self._cmd_frames = {True: (ids, dlc), False: (ids[:n_wheels], dlc[:n_wheels])}
        self._cmd_limits = np.array([[lo, hi] for _, lo, hi in self._cmd_ranges], dtype=np.float64)
        self._cmd_cols = np.array([self._cmd_torque_col, self._cmd_tick_col, self._done_tick_col], dtype=np.int64)
        self._cmd_shape = {True: (n_wheels + 1, MAX_DLC), False: (n_wheels, MAX_DLC)}
        table = icd.table
        # kernels.command_rows with the driver's arrays bound (the cycle passes only the torques and tick)
        ic, fc = K.pack_commands(self._cmd_limits, self._cmd_idx, self._cmd_cols, width, table.msg_i, table.sig_i,
                                 table.sig_f, table.crc_table)
        self._cmd_values = fc[ic[K.CMD_OFF_VALUES]:].reshape(n_wheels + 1, width)  # the rows each call writes
        self._command_rows = partial(K.command_rows, ic, fc, self._sender._cs)
        # the heartbeat as a one-frame burst (the in-process bus carries it as arrays, not a can.Message)
        self._hb_idx = np.array([icd.message_index["FSW_HEARTBEAT"]], dtype=np.int64)
        self._hb_cols = (self._col["FSW_HEARTBEAT", "mode"], self._col["FSW_HEARTBEAT", "cycle"])
        self._hb_values = np.zeros((1, width))

    def _bind_collect(self) -> None:
        """kernels.collect_rows with the driver's arrays bound (again whenever a buffer is replaced)."""
        seq, last_ok_t = self._table[3], self._table[4]
        self._collect_rows = partial(K.collect_rows, self._status_buf, self._values_buf, self._st_all, self._ft,
                                     self._consts, seq, last_ok_t, self._imu_buf)

    @property
    def bus(self) -> can.BusABC:
        return self._bus

    @bus.setter
    def bus(self, bus: can.BusABC) -> None:
        # a bus that carries bursts (LightVirtualBus) is read and written through its own methods, looked
        # up once here rather than per call (transport.recv_burst / send_burst do that lookup)
        self._bus = bus
        self._recv_carry = getattr(bus, "recv_burst", None)
        self._send_carry = getattr(bus, "send_burst", None)
        # keepout's own buses (batched socketcan/UDP, light virtual) return from a waiting read with frames or
        # at the timeout, never before: their first wait of a call needs no deadline (see _wait_burst)
        self._whole_waits = callable(getattr(bus, "recv_queued", None)) or callable(self._recv_carry)

    @property
    def _supervision_started(self) -> bool:
        return bool(self._st_i[K.S_SUPERVISED])

    # the driver's counts live in the compiled tick's state (kernels.S_*), which counts them as it goes
    incomplete_ticks = _TickCount(K.S_INCOMPLETE, "Lockstep ticks closed with fewer than their announced frames.")
    stale_syncs = _TickCount(K.S_STALE, "SYNC frames for a tick at or before the current (or last) one.")
    unexpected_frames = _TickCount(K.S_UNEXPECTED,
                                   "Delivered device frames outside every announced tick (lockstep).")

    # ------------------------------------------------------------------------------------ counters
    @property
    def counters(self) -> dict[str, dict[str, int]]:
        """E2E classification counts per received message (plus ``_bus`` for unknown ids / own echoes)."""
        return self.receiver.counters

    @property
    def sent(self) -> dict[str, int]:
        return dict(self._sender.sent)

    # ------------------------------------------------------------------------------------ lockstep
    def collect_tick(self, timeout_s: float) -> TickInputs | None:
        """Wait up to ``timeout_s`` for SYNC(k) and its announced frames; None if no SYNC arrived.

        ``timeout_s`` bounds the waiting of the whole call (SYNC plus its frames), counted from the first
        time the receive queue is empty; 0 means "only what is queued now", the in-process fast mode. Late
        frames of a tick are used at the next tick, as received.

        The frames are classified and applied by one compiled call per burst (kernels.collect_rows: E2E,
        counts, SYNC and tick bookkeeping, the decoded samples into this driver's arrays); frames the
        compiled table cannot judge take the receiver's Python path and are then applied by the same call.
        """
        self._timeout_s = max(0.0, timeout_s)
        self._deadline = None  # set when the queue first runs empty (see _next_burst)
        self._waited = False  # the call's first wait has begun
        self._realtime = False
        st = self._st_i
        st[K.S_PHASE] = K.PHASE_SYNC
        rx = self._rx
        if rx is not None and type(rx) is not _LockstepRx:
            rx = self._lockstep_rx(rx.burst.tail(rx.pos)) if rx.pos < rx.n else None
        phase = K.PHASE_SYNC
        if st[K.S_PENDING]:  # SYNC(k) came while finishing the last tick: start k with no frame read
            ids, lengths, data = self._no_frames
            self._collect(ids, lengths, data, 0, K.NO_FID)
            phase = st.item(K.S_PHASE)
        grace_end = None  # when the announced count is covered by good and failed frames: the grace's end
        while phase != K.PHASE_DONE:
            if phase == K.PHASE_SYNC:
                if rx is None or rx.pos >= rx.n:  # SYNC(k) comes first
                    burst = self._wait_burst(None, 1)
                    rx = None if burst is None else self._lockstep_rx(burst)
                if rx is None:
                    self._settle()
                    return None
            else:
                received, failed, expected = st[K.S_RECEIVED:K.S_FAILED + 1].tolist() + [int(st[K.S_EXPECTED])]
                grace = None
                if received + failed >= expected:
                    # One grace for the tick, not one per burst: a stream of junk frames (a flood, frames
                    # that fail E2E) would otherwise renew it and hold the tick open until the timeout.
                    now = self.clock()
                    grace_end = now + FRAME_GRACE_S if grace_end is None else grace_end
                    grace = max(0.0, grace_end - now)
                if grace == 0.0:  # the grace is over: what this burst still holds, and no further read
                    rx = self._rx if self._rx is not None and self._rx.pos < self._rx.n else None
                else:
                    rx = self._next_lockstep_burst(grace, max(1, expected - received))
                if rx is None:  # the tick closes incomplete
                    K.finish_tick(st, self._ft, self._watch, self._watch_limit, self._table[3], self._table[4],
                                  self._tally, self._n_codes)
                    break
            burst = rx.burst
            start = rx.pos
            end = rx.pos = self._collect_rows(burst.ids, burst.lengths, burst.data, rx.pos, K.NO_FID)
            if end < rx.n:  # the tick closed, or the gyro rows are full, or a frame for the Python path
                if st[K.S_GROW]:
                    end = rx.pos = self._collect(burst.ids, burst.lengths, burst.data, end, K.NO_FID)
                while end < rx.n and self._status_buf[end] == K.FALLBACK_CODE:
                    end = rx.pos = self._collect_fallback(rx, end)
            if self._kept:
                self._keep_rows(burst.ids, start, end)
            phase = st.item(K.S_PHASE)
        return self._settle()

    # ------------------------------------------------------------------ device frames without a sample type
    def keep_latest(self, name: str) -> None:
        """Keep the newest delivered value row of message ``name`` (a device frame, such as the aperture
        door's DOOR_STATUS, that a lockstep tick counts but makes no sample of) for :meth:`latest`."""
        fid = self.icd.spec(name).frame_id
        self._kept.setdefault(fid, None)
        self._kept_ids = np.array(sorted(self._kept), dtype=np.int64)

    def latest(self, name: str) -> tuple[list, float] | None:
        """(value row, time received [s]: the tick's time in lockstep) of the newest delivered ``name`` frame
        (``keep_latest``), None before the first. The row's slots are ``Icd.column``'s."""
        return self._kept.get(self.icd.spec(name).frame_id)

    def _keep_rows(self, ids: np.ndarray, first: int, end: int) -> None:
        """The delivered frames of kept messages among frames first..end-1 of the lockstep burst."""
        window = ids[first:end]
        for fid in self._kept_ids.tolist():  # (one or two kept messages: a comparison each, no set search)
            for i in np.flatnonzero(window == fid).tolist():
                j = first + i
                if 0 <= self._status_buf[j] <= 1:  # delivered (ok, ok_some_lost)
                    self._kept[fid] = (self._values_buf[j].tolist(), float(self._ft[K.F_T_TICK]))

    def send_frame(self, name: str, signals: dict[str, float], with_commands: bool = False) -> None:
        """One frame of message ``name`` (E2E protected, encoded now), sent at once as a one-frame burst, or
        with ``with_commands`` ahead of the next ``send_wheel_torques`` frames in their burst (one send; in
        lockstep before CYCLE_DONE). A refused frame is counted in ``tx_errors``; a signal the message does
        not have raises KeyError."""
        one = self._one_frame.get(name)
        if one is None:
            one = self._one_frame[name] = (np.array([self.icd.message_index[name]], dtype=np.int64),
                                           np.zeros((1, self._width)))
        idx, row = one
        row[0, :] = 0.0
        col = self._col
        for sig, value in signals.items():
            row[0, col[name, sig]] = value
        burst = self._sender.burst(idx, row)
        if with_commands:
            self._ahead.append(burst)
        else:
            self._send_burst(burst)

    def _collect(self, ids: np.ndarray, lengths: np.ndarray, data: np.ndarray, first: int, first_fid: int) -> int:
        """kernels.collect_rows on frames ``first``.. (growing the gyro rows when the kernel asks)."""
        st = self._st_i
        while True:
            if st[K.S_GROW]:
                st[K.S_GROW] = 0
                self._grow_imu()
            end = self._collect_rows(ids, lengths, data, first, first_fid)
            if end >= len(ids) or not st[K.S_GROW]:
                return end
            first, first_fid = end, K.NO_FID

    def _grow_imu(self) -> None:
        self._imu_buf = np.concatenate([self._imu_buf, np.zeros_like(self._imu_buf)])
        self._bind_collect()

    def _collect_fallback(self, rx: "_LockstepRx", i: int) -> int:
        """Frame ``i`` of ``rx`` by the receiver's Python path (a frame the compiled table cannot judge), then
        applied by collect_rows as a judged frame; returns where the next call starts."""
        frame = self.receiver.classify(rx.burst.message(i), float(self._ft[K.F_T_TICK]))
        if frame is None:  # the node's own echo
            self._status_buf[i] = K.ECHO_CODE
            fid = -1
        else:
            self._status_buf[i] = CODE_CLASS.index(frame.status)
            fid = frame.frame_id
            if frame.delivered:
                row = [float(frame.signals[k]) for k in self.receiver.slots(frame.name)]
                self._values_buf[i, :] = 0.0
                self._values_buf[i, :len(row)] = row
        st = self._st_i
        if st[K.S_IMU_N] >= len(self._imu_buf):
            self._grow_imu()
        burst = rx.burst
        return self._collect(burst.ids, burst.lengths, burst.data, i, fid)

    def _settle(self) -> TickInputs | None:
        """This call's counts into the receiver's per-message counters and the driver's; the tick's inputs
        when it closed (else None)."""
        vals = self._st_i.tolist()
        k = vals[K.S_NTALLY]
        if k:
            self._st_i[K.S_NTALLY] = 0
            targets = self._tally_targets
            pairs = iter(self._tally_flat[:2 * k].tolist())  # key, count, key, count...: one flat list
            for key, count in zip(pairs, pairs):
                counts, cls = targets[key]
                counts[cls] += count
        if vals[K.S_PHASE] != K.PHASE_DONE:
            return None
        tick = vals[K.S_TICK]
        self.last_tick = tick
        # one copy of the float state holds the tick's outputs: its time, the star tracker's q_NS, the
        # wheels' speeds this tick and their status rows (the arrays below are views of this copy)
        out = self._ft_out.copy()
        t = self.t_tick = out.item(K.F_T_TICK)
        period_s = self.period_s = out.item(K.F_PERIOD)
        n = vals[K.S_IMU_N]
        imu = omega = flags = None
        if n:
            # the tick's gyro samples straight from the decoded rows (ImuSample objects only when asked for)
            buf = self._imu_buf
            omega = buf[:n, :3].copy()
            if vals[K.S_IMU_SAT]:
                flags = buf[:n, 3].tolist()
            imu = self._imu = ImuSample(omega[n - 1], bool(buf.item(n - 1, 3)), t)
            self._imu_rx = t
        st_sample = None
        if vals[K.S_ST_NEW]:
            st_sample = self._st = StarTrackerSample(out[K.F_ST_Q:K.F_ST_Q + 4], bool(vals[K.S_ST_VALID]),
                                                     vals[K.S_ST_BLIND], out.item(K.F_ST_T))
            self._st_rx = t
        nw = self.n_wheels
        return TickInputs._of_tick(tick, t, period_s, imu, st_sample, vals[K.S_EXPECTED], vals[K.S_RECEIVED], omega,
                                   flags, vals[K.S_WHEEL_NEW:K.S_WHEEL_NEW + nw], out,
                                   out[K.F_WHEEL_SPEED:K.F_WHEEL_SPEED + nw],
                                   self._st_i[K.S_WHEEL_FAULT:K.S_WHEEL_FAULT + nw].copy())

    def _lockstep_rx(self, burst: FrameBurst) -> "_LockstepRx":
        n = len(burst.ids)
        if n > len(self._status_buf):
            size = max(n, 2 * len(self._status_buf))
            self._status_buf = np.zeros(size, dtype=np.int64)
            self._values_buf = np.zeros((size, self._width))
            self._bind_collect()
        rx = self._rx = self._rx_reuse  # (the burst before it is read to its end: nothing else holds it)
        rx.burst, rx.n, rx.pos = burst, n, 0
        return rx

    def _next_lockstep_burst(self, grace_s: float | None, limit: int) -> "_LockstepRx | None":
        rx = self._rx
        if rx is not None and rx.pos < rx.n:
            return rx
        burst = self._wait_burst(grace_s, limit)
        return None if burst is None else self._lockstep_rx(burst)

    def _stale_sync(self, row: list, current: int | None = None) -> bool:
        """A SYNC (value row) for a tick at or before the current (or last) one: replayed or stale, counted,
        ignored."""
        last = self.last_tick if current is None else current
        if last is not None and int(row[self._sync_cols[0]]) <= last:
            self.stale_syncs += 1
            return True
        return False

    def _next_burst(self, grace_s: float | None = None, limit: int | None = None) -> CheckedBurst | None:
        """The frames read off the bus not yet classified, within the call's timeout; None on timeout.
        ``grace_s``: when the queue is empty, wait at most this long (still within the timeout);
        ``limit``: the frames the caller still expects (``recv_burst``).

        Frames are read off the bus as bursts (everything queued) and classified in compiled calls
        (``E2EReceiver.classify_until``) that stop where the tick's wait ends: the rest stays unjudged for
        the next call, exactly as if it were still queued."""
        rx = self._rx
        if rx is not None and rx.pos < rx.n:
            if type(rx) is _LockstepRx:
                self._rx = rx = self.receiver.check(rx.burst.tail(rx.pos))
            return rx
        burst = self._wait_burst(grace_s, limit)
        if burst is None:
            return None
        self._rx = rx = self.receiver.check(burst)
        return rx

    def _wait_burst(self, grace_s: float | None, limit: int | None) -> FrameBurst | None:
        """The next burst off the bus within the call's timeout (see _next_burst); None on timeout."""
        # Frames come in bursts after SYNC: try without waiting first, and read the clock only when the
        # queue is empty (clock reads are system calls on some hosts, e.g. the vcan-vm guest): the first
        # wait of a call starts the deadline and waits the whole timeout, without a clock read.
        carry = self._recv_carry
        if self._timeout_s > 0.0 and not self._waited and self._whole_waits:
            # the call's first wait: the whole timeout, without a clock read or an empty read first (the
            # bus returns what is queued at once, and nothing only when the timeout has passed)
            self._waited = True
            first_s = self._timeout_s if grace_s is None else min(self._timeout_s, grace_s)
            return carry(first_s) if carry is not None else recv_burst(self._bus, first_s, limit)
        burst = carry(0.0) if carry is not None else recv_burst(self._bus, 0.0, limit)
        if burst is None:
            if self._timeout_s <= 0.0:
                return None
            if self._deadline is None:  # a further wait: the timeout counts from here
                remaining = self._timeout_s
                self._deadline = time.monotonic() + remaining
            else:
                remaining = self._deadline - time.monotonic()
                if remaining <= 0.0:
                    return None
            if grace_s is not None:
                remaining = min(remaining, grace_s)
            burst = carry(remaining) if carry is not None else recv_burst(self._bus, remaining, limit)
        return burst

    def _start_supervision(self, now: float) -> None:
        # Timeouts count from the first time the application asks for data, on the clock it uses.
        if not self._st_i[K.S_SUPERVISED]:
            self.receiver.reset_clock(now)
            self._st_i[K.S_SUPERVISED] = 1

    # ----------------------------------------------------------------------------------- real time
    def collect_latest(self) -> LatestInputs:
        """Drain the bus without blocking and return the newest valid samples with their ages [s]."""
        self._imu_batch = []
        self._realtime = True
        self._start_supervision(self.clock())
        while True:
            rx = self._rx
            if type(rx) is _LockstepRx:
                rx = self._rx = self.receiver.check(rx.burst.tail(rx.pos)) if rx.pos < rx.n else None
            if rx is None or rx.pos >= rx.n:
                burst = recv_burst(self.bus, 0.0)
                if burst is None:
                    break
                rx = self._rx = self.receiver.check(burst)
            now = self.clock()
            frame = self.receiver.take(rx, now)
            if frame is not None:
                if frame.frame_id == self._sync_id and frame.delivered \
                        and not self._stale_sync(frame.row, self._rt_sync_tick):
                    self._rt_sync_tick = int(frame.row[self._sync_cols[0]])
                self._apply(frame, now)
        now = self.clock()
        self.receiver.check_timeouts(now)

        def age(rx: float | None) -> float | None:
            return None if rx is None else now - rx

        return LatestInputs(
            t=now, imu=self._imu, imu_age_s=age(self._imu_rx),
            star_tracker=self._st, star_tracker_age_s=age(self._st_rx),
            wheels=self._newest_wheels(), wheel_ages_s=[age(r) for r in self._wheels_rx()],
            imu_samples=list(self._imu_batch),
        )

    # ------------------------------------------------------------------------------ frame -> sample
    def _apply(self, frame: CheckedFrame, now: float) -> None:
        if frame.delivered:
            self._apply_row(frame.frame_id, frame.row, now)

    def _apply_row(self, fid: int, row: list, now: float) -> None:
        """A delivered frame (id, value row) into the newest samples (real time; lockstep does this in
        kernels.collect_rows, on the same star tracker halves)."""
        if fid == self._imu_id:
            x, y, z, sat = self._imu_cols
            sample = ImuSample(np.array([row[x], row[y], row[z]]), bool(row[sat]), now)
            self._imu, self._imu_rx = sample, now
            self._imu_batch.append(sample)
        elif fid in self._st_ab:
            self._star_tracker_half(self._st_ab[fid], row, now)
        elif fid in self._wheel_index:
            i = self._wheel_index[fid]
            self._wheel_buf[i, :5] = [row[c] for c in self._wheel_cols]  # speed, torque, current, temp, fault
            self._ft[K.F_WHEEL_T + i] = now
        elif fid in self._kept:
            self._kept[fid] = (list(row), now)

    def _wheels_rx(self) -> list[float | None]:
        """The time of each wheel's newest status (None: none yet)."""
        return [None if t != t else t for t in self._ft[K.F_WHEEL_T:K.F_WHEEL_T + self.n_wheels].tolist()]

    def _newest_wheels(self) -> list[WheelStatus | None]:
        """Each wheel's newest status (lockstep and real time keep it in the same rows)."""
        return [None if t is None else WheelStatus(r[0], r[1], r[2], r[3], int(r[4]), t)
                for r, t in zip(self._wheel_buf.tolist(), self._wheels_rx())]

    def _star_tracker_half(self, half: int, row: list, now: float) -> None:
        """Half ``half`` (0: ST_QUAT_A, 1: ST_QUAT_B) of a star tracker sample: the sample once both halves
        of one ``sample_seq`` are in (kernels.star_tracker_pair's rule, on its state)."""
        st, cfg = self._st_i, self._cfg
        self._st_half[half, :len(row)] = row
        st[K.S_ST_HAVE_A + half] = 1
        st[K.S_ST_SEQ_A + half] = int(row[cfg[K.C_SEQ_A] if half == 0 else cfg[K.C_SEQ_B]])
        if not (st[K.S_ST_HAVE_A] and st[K.S_ST_HAVE_B]) or st[K.S_ST_SEQ_A] != st[K.S_ST_SEQ_B]:
            return
        a, b = self._st_half.tolist()
        q = np.array([a[cfg[K.C_QW]], a[cfg[K.C_QX]], b[cfg[K.C_QY]], b[cfg[K.C_QZ]]])
        t_valid = now - float(b[cfg[K.C_AGE]]) / 1000.0
        self._st = StarTrackerSample(q, bool(a[cfg[K.C_VALID]]), int(a[cfg[K.C_BLIND]]), t_valid)
        self._st_rx = now
        st[K.S_ST_HAVE_A] = st[K.S_ST_HAVE_B] = 0

    # ------------------------------------------------------------------------------------- sending
    def _send(self, msg: can.Message) -> None:
        # A full transmit queue or a bus error is a fault to count (FDIR sees it), not a crash.
        try:
            self.bus.send(msg, timeout=TX_TIMEOUT_S)
        except can.CanError:
            self.tx_errors += 1

    def _send_burst(self, burst) -> None:
        """Send in order as one burst (one system call over socketcan: in the emulated guest a call costs
        15-30 us; one queue entry in process). A refused frame is counted and the rest are still tried,
        exactly as with one send per frame."""
        carry = self._send_carry  # (transport.send_burst's two ways, the bus's looked up once)
        n = len(burst.ids)
        while n:
            try:
                sent = int(carry(burst, TX_TIMEOUT_S)) if carry is not None else \
                    send_batch(self._bus, burst.messages(), TX_TIMEOUT_S)
            except can.CanError:
                sent = 0
            if sent >= n:
                return
            self.tx_errors += 1
            burst = burst.tail(sent + 1)
            n = len(burst.ids)

    def send_wheel_torques(self, tick: int, torques_Nm: Sequence[float], cycle_done: bool = False) -> None:
        """Send RW1_CMD..RWn_CMD for ``tick``, and with ``cycle_done`` the lockstep CYCLE_DONE(tick) in
        the same burst. Values are limited to the ICD range (+-1.638 N m); NaN is sent as 0 (the
        allocation upstream must saturate first; this only keeps the bus valid)."""
        if len(torques_Nm) != self.n_wheels:
            raise ValueError(f"send_wheel_torques: expected {self.n_wheels} torques, got {len(torques_Nm)}")
        if self._realtime and self._rt_sync_tick is not None:
            tick = self._rt_sync_tick  # the application's cycle count means nothing to the simulator
        with_done = cycle_done and not self._realtime
        tau = torques_Nm
        if type(tau) is not np.ndarray or tau.dtype != _F8 or tau.ndim != 1 or not tau.flags.c_contiguous:
            tau = np.array(list(map(float, torques_Nm)), dtype=np.float64)
        ids, dlc = self._cmd_frames[with_done]
        out = np.zeros(self._cmd_shape[with_done], dtype=np.uint8)
        # the limits, NaN -> 0, the rows and their encoding in one compiled call (kernels.command_rows)
        done = self._command_rows(tau, tick & 0xFFFF, tick & 0xFFFFFFFF, 1 if with_done else 0, out)
        if done < len(ids):  # a row the compiled codec refused: the checked path names the error
            burst = self._sender.burst(self._cmd_idx[:len(ids)], self._cmd_values[:len(ids)].copy(), out, done)
        else:
            burst = FrameBurst(ids, out, dlc)
        if self._ahead:
            burst = FrameBurst.join(self._ahead + [burst])
            self._ahead = []
        self._send_burst(burst)
        if self._realtime:
            self._answer_latest_sync()

    def send_cycle_done(self, tick: int) -> None:
        """CYCLE_DONE(tick) (lockstep). In real time it answers the newest SYNC seen instead (see
        the module docstring), at most once per SYNC."""
        if self._realtime:
            self._answer_latest_sync()
            return
        self._send(self._sender.frame("CYCLE_DONE", {"tick": tick & 0xFFFFFFFF}))

    def _answer_latest_sync(self) -> None:
        k = self._rt_sync_tick
        if k is None or k == self._rt_done_tick:
            return  # no SYNC yet, or this one was answered by an earlier cycle
        self._rt_done_tick = k
        self._send(self._sender.frame("CYCLE_DONE", {"tick": k & 0xFFFFFFFF}))

    def send_heartbeat(self, mode: int, cycle: int) -> None:
        # the frame E2ESender.frame builds, encoded in one compiled call and sent as a burst (a refused frame
        # counted as _send counts it)
        row = self._hb_values
        row[0, self._hb_cols[0]] = int(mode) & 0x0F
        row[0, self._hb_cols[1]] = cycle & 0xFFFFFFFF
        self._send_burst(self._sender.burst(self._hb_idx, row))


class _LockstepRx:
    """A burst being read by collect_tick: frames ``pos``.. not handled yet (their class codes and value rows
    go to the driver's buffers, reused from burst to burst)."""

    __slots__ = ("burst", "n", "pos")

    def __init__(self, burst: FrameBurst, n: int) -> None:
        self.burst, self.n, self.pos = burst, n, 0
