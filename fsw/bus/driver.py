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
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, NamedTuple, Sequence

import can
import numpy as np

from fsw.bus.e2e import CheckedBurst, CheckedFrame, E2EReceiver
from fsw.bus.icd import E2ESender, Icd
from fsw.bus.transport import recv_burst, send_burst

FSW_NODE = "FSW"
MAX_WHEELS = 6
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


@dataclass
class TickInputs:
    """Everything the flight software received for lockstep tick ``tick`` (t = tick * period_s).

    ``imu`` is the newest gyro sample of the tick, ``imu_samples`` all of them in arrival order (100 Hz IMU
    at 10 Hz GNC gives 10); a field is None when nothing valid arrived for it during this tick.
    ``complete`` is False when fewer than the announced frames arrived before the timeout.
    """

    tick: int
    t: float
    period_s: float
    imu: ImuSample | None
    star_tracker: StarTrackerSample | None
    wheels: list[WheelStatus | None]
    imu_samples: list[ImuSample] = field(default_factory=list)
    frames_expected: int = 0
    frames_received: int = 0

    @property
    def complete(self) -> bool:
        return self.frames_received >= self.frames_expected


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


class FswBusDriver:
    """The flight software's bus driver (see module docstring).

    ``bus``: an open python-can bus (``fsw.bus.open_bus``); ``icd``: the loaded ICD; ``n_wheels``: 1..6
    (wheels beyond n_wheels are ignored); ``clock``: monotonic clock for real-time ages.
    """

    def __init__(self, bus: can.BusABC, icd: Icd, n_wheels: int,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not 1 <= n_wheels <= MAX_WHEELS:
            raise ValueError(f"n_wheels must be 1..{MAX_WHEELS} (the ICD has RW1..RW{MAX_WHEELS}), got {n_wheels}")
        self.bus = bus
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
        self._st_half: dict[str, tuple[int, dict, float]] = {}
        # value-row slots (Icd.column) of the signals the driver reads
        self._col = {(n, sig): icd.column(n, sig) for n in icd.message_names for sig in icd.spec(n).signals}
        self._imu_cols = [self._col["IMU_RATE", s] for s in ("omega_x", "omega_y", "omega_z", "saturated")]
        self._wheel_cols = [self._col["RW1_STATUS", s] for s in ("speed", "torque", "current", "temp", "fault")]
        self._sync_cols = [self._col["SYNC", s] for s in ("tick", "frames_following", "period_ms")]
        self._imu_id = icd.spec("IMU_RATE").frame_id
        self._st_ids = {icd.spec(n).frame_id: n for n in ("ST_QUAT_A", "ST_QUAT_B")}
        # the commands' message indices and value rows (one compiled encode per cycle)
        self._cmd_idx = np.array([icd.message_index[f"RW{i}_CMD"] for i in range(1, n_wheels + 1)]
                                 + [icd.message_index["CYCLE_DONE"]], dtype=np.int64)
        self._cmd_torque_col = self._col["RW1_CMD", "torque_cmd"]
        self._cmd_tick_col = self._col["RW1_CMD", "tick_lsb"]
        self._done_tick_col = self._col["CYCLE_DONE", "tick"]
        self._rx: CheckedBurst | None = None  # frames read off the bus, not yet classified
        self._no_mask = np.zeros(2048, dtype=np.bool_)
        self._device_mask = np.zeros(2048, dtype=np.bool_)  # classify_until's count of a tick's frames
        self._device_mask[[i for i in self._device_ids if i < 2048]] = True
        # newest samples (real time and lockstep alike)
        self._imu: ImuSample | None = None
        self._imu_rx: float | None = None
        self._imu_batch: list[ImuSample] = []
        self._imu_parts: list[np.ndarray] = []  # lockstep: this tick's IMU value rows, in order
        self._st: StarTrackerSample | None = None
        self._st_rx: float | None = None
        self._st_new = False
        self._wheels: list[WheelStatus | None] = [None] * n_wheels
        self._wheels_rx: list[float | None] = [None] * n_wheels
        self._wheels_new = [False] * n_wheels
        self._pending_sync: dict | None = None  # a SYNC seen while finishing the previous tick
        self._timeout_s = 0.0  # collect_tick's timeout, and its deadline once a wait has begun
        self._deadline: float | None = None
        self._realtime = False  # set by collect_latest: frames answer the newest SYNC seen (module docstring)
        self._rt_sync_tick: int | None = None  # newest SYNC tick received in real time
        self._rt_done_tick: int | None = None  # SYNC tick last answered with CYCLE_DONE
        self.t_tick = 0.0
        self.period_s = 0.0
        self.last_tick: int | None = None
        self.incomplete_ticks = 0
        self.stale_syncs = 0
        self.unexpected_frames = 0
        self.tx_errors = 0
        self._supervision_started = False

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
        """
        self._timeout_s = max(0.0, timeout_s)
        self._deadline = None  # set when the queue first runs empty (see _next_burst)
        self._realtime = False
        sync = self._pending_sync
        self._pending_sync = None
        tick_col, following_col, period_col = self._sync_cols
        while sync is None:  # frames before SYNC(k) are classified and not used
            rx = self._next_burst(limit=1)  # SYNC(k) comes first
            if rx is None:
                return None
            first = rx.pos
            after = -math.inf if self.last_tick is None else self.last_tick + 1
            end = self.receiver.classify_until(rx, self.t_tick, (self._sync_id, tick_col, after, math.inf,
                                                                 self._no_mask, 0))
            for i in range(first, end):
                if rx.codes[i] > 1:
                    continue  # not delivered
                fid = rx.ids[i] if not rx.fallback else self._frame_id(rx, i)
                if fid == self._sync_id:
                    row = rx.row(i)
                    if not self._stale_sync(row):
                        sync = row  # the kernel stopped after it
                elif fid in self._device_ids:
                    self.unexpected_frames += 1  # belongs to no announced tick
        tick = int(sync[tick_col])
        self.period_s = float(sync[period_col]) / 1000.0
        self.t_tick = tick * self.period_s
        self._start_supervision(self.t_tick)
        expected = int(sync[following_col])
        self._begin_tick()
        received = failed = 0
        while received < expected:
            rx = self._next_burst(FRAME_GRACE_S if received + failed >= expected else None,
                                  max(1, expected - received))
            if rx is None:
                break
            first = rx.pos
            # up to the tick's last announced frame, or a SYNC of a later tick
            end = self.receiver.classify_until(rx, self.t_tick, (self._sync_id, tick_col, tick + 1, math.inf,
                                                                 self._device_mask, expected - received))
            imu_id, device_ids, codes, ids = self._imu_id, self._device_ids, rx.codes, rx.ids
            imu_rows: list[int] = []
            for i in range(first, end):
                fid = ids[i] if not rx.fallback else self._frame_id(rx, i)
                if codes[i] <= 1:  # delivered
                    if fid == imu_id:
                        received += 1
                        if i not in rx.rows:
                            imu_rows.append(i)  # read from the kernel's value array, once per run
                            continue
                        if imu_rows:  # keep the order: the kernel's rows so far, then this one
                            self._imu_parts.append(rx.values[imu_rows])
                            imu_rows = []
                        self._apply_row(fid, rx.rows[i], self.t_tick)
                    elif fid == self._sync_id:
                        row = rx.row(i)
                        if not self._stale_sync(row, tick):
                            self._pending_sync = row  # next tick already started: stop here
                    elif fid in device_ids:
                        received += 1
                        self._apply_row(fid, rx.row(i), self.t_tick)
                elif fid in device_ids:
                    failed += 1
            if imu_rows:
                self._imu_parts.append(rx.values[imu_rows])
            if self._pending_sync is not None:
                break
        if received < expected:
            self.incomplete_ticks += 1
        self.receiver.check_timeouts(self.t_tick)
        self.last_tick = tick
        return self._tick_inputs(tick, expected, received)

    def _frame_id(self, rx: CheckedBurst, i: int) -> int:
        frame = self.receiver.frame_at(rx, i)
        return -1 if frame is None else frame.frame_id

    def _stale_sync(self, row: list, current: int | None = None) -> bool:
        """A SYNC (value row) for a tick at or before the current (or last) one: replayed or stale, counted,
        ignored."""
        last = self.last_tick if current is None else current
        if last is not None and int(row[self._sync_cols[0]]) <= last:
            self.stale_syncs += 1
            return True
        return False

    def _begin_tick(self) -> None:
        self._imu_batch = []
        self._imu_parts = []
        self._st_new = False
        self._wheels_new = [False] * self.n_wheels

    def _tick_inputs(self, tick: int, expected: int, received: int) -> TickInputs:
        samples = []
        if self._imu_parts:
            # the tick's gyro samples in one array, straight from the decoded frames (not one per frame)
            x, y, z, sat = self._imu_cols
            rows = self._imu_parts[0] if len(self._imu_parts) == 1 else np.concatenate(self._imu_parts)
            omega = rows[:, x:z + 1] if (y, z) == (x + 1, x + 2) else rows[:, [x, y, z]]
            flags = rows[:, sat].tolist()
            n = len(flags)
            # The IMU frames of tick k were sampled over (t_{k-1}, t_k]; spread their times evenly.
            samples = [ImuSample(omega[i], bool(flags[i]), self.t_tick - (n - 1 - i) * self.period_s / n)
                       for i in range(n)]
            self._imu = ImuSample(omega[-1], samples[-1].saturated, self.t_tick)
            self._imu_rx = self.t_tick
        wheels = [w if new else None for w, new in zip(self._wheels, self._wheels_new)]
        return TickInputs(
            tick=tick, t=self.t_tick, period_s=self.period_s,
            imu=samples[-1] if samples else None,
            star_tracker=self._st if self._st_new else None,
            wheels=wheels, imu_samples=samples,
            frames_expected=expected, frames_received=received,
        )

    def _next_burst(self, grace_s: float | None = None, limit: int | None = None) -> CheckedBurst | None:
        """The frames read off the bus not yet classified, within the call's timeout; None on timeout.
        ``grace_s``: when the queue is empty, wait at most this long (still within the timeout);
        ``limit``: the frames the caller still expects (``recv_burst``).

        Frames are read off the bus as bursts (everything queued) and classified in compiled calls
        (``E2EReceiver.classify_until``) that stop where the tick's wait ends: the rest stays unjudged for
        the next call, exactly as if it were still queued."""
        rx = self._rx
        if rx is not None and rx.pos < rx.n:
            return rx
        # Frames come in bursts after SYNC: try without waiting first, and read the clock only when the
        # queue is empty (clock reads are system calls on some hosts, e.g. the vcan-vm guest): the first
        # wait of a call starts the deadline and waits the whole timeout, without a clock read.
        burst = recv_burst(self.bus, 0.0, limit)
        if burst is None:
            if self._timeout_s <= 0.0:
                return None
            if self._deadline is None:
                remaining = self._timeout_s
                self._deadline = time.monotonic() + remaining
            else:
                remaining = self._deadline - time.monotonic()
                if remaining <= 0.0:
                    return None
            if grace_s is not None:
                remaining = min(remaining, grace_s)
            burst = recv_burst(self.bus, remaining, limit)
            if burst is None:
                return None
        self._rx = rx = self.receiver.check(burst)
        return rx

    def _start_supervision(self, now: float) -> None:
        # Timeouts count from the first time the application asks for data, on the clock it uses.
        if not self._supervision_started:
            self.receiver.reset_clock(now)
            self._supervision_started = True

    # ----------------------------------------------------------------------------------- real time
    def collect_latest(self) -> LatestInputs:
        """Drain the bus without blocking and return the newest valid samples with their ages [s]."""
        self._imu_batch = []
        self._realtime = True
        self._start_supervision(self.clock())
        while True:
            rx = self._rx
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
            wheels=list(self._wheels), wheel_ages_s=[age(r) for r in self._wheels_rx],
            imu_samples=list(self._imu_batch),
        )

    # ------------------------------------------------------------------------------ frame -> sample
    def _apply(self, frame: CheckedFrame, now: float) -> None:
        if frame.delivered:
            self._apply_row(frame.frame_id, frame.row, now)

    def _apply_row(self, fid: int, row: list, now: float) -> None:
        """A delivered frame (id, value row) into the newest samples."""
        if fid == self._imu_id:
            if not self._realtime:
                self._imu_parts.append(np.array([row]))  # lockstep: the samples are made per tick (_tick_inputs)
                return
            x, y, z, sat = self._imu_cols
            sample = ImuSample(np.array([row[x], row[y], row[z]]), bool(row[sat]), now)
            self._imu, self._imu_rx = sample, now
            self._imu_batch.append(sample)
        elif fid in self._st_ids:
            name = self._st_ids[fid]
            self._star_tracker_half(name, {sig: row[self._col[name, sig]] for sig in self.icd.spec(name).signals},
                                    now)
        elif fid in self._wheel_index:
            i = self._wheel_index[fid]
            speed, torque, current, temp, fault = self._wheel_cols
            self._wheels[i] = WheelStatus(row[speed], row[torque], row[current], row[temp], int(row[fault]), now)
            self._wheels_rx[i] = now
            self._wheels_new[i] = True

    def _star_tracker_half(self, name: str, s: dict, now: float) -> None:
        seq = int(s["sample_seq"])
        self._st_half[name] = (seq, s, now)
        a, b = self._st_half.get("ST_QUAT_A"), self._st_half.get("ST_QUAT_B")
        if a is None or b is None or a[0] != b[0]:
            return
        sa, sb = a[1], b[1]
        q = np.array([sa["q_w"], sa["q_x"], sb["q_y"], sb["q_z"]])
        t_valid = now - float(sb["age_ms"]) / 1000.0
        self._st = StarTrackerSample(q, bool(sa["valid"]), int(sa["blind_source"]), t_valid)
        self._st_rx = now
        self._st_new = True
        self._st_half.clear()

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
        while len(burst):
            try:
                sent = send_burst(self.bus, burst, TX_TIMEOUT_S)
            except can.CanError:
                sent = 0
            if sent >= len(burst):
                return
            self.tx_errors += 1
            burst = burst.tail(sent + 1)

    def send_wheel_torques(self, tick: int, torques_Nm: Sequence[float], cycle_done: bool = False) -> None:
        """Send RW1_CMD..RWn_CMD for ``tick``, and with ``cycle_done`` the lockstep CYCLE_DONE(tick) in
        the same burst. Values are limited to the ICD range (+-1.638 N m); NaN is sent as 0 (the
        allocation upstream must saturate first; this only keeps the bus valid)."""
        if len(torques_Nm) != self.n_wheels:
            raise ValueError(f"send_wheel_torques: expected {self.n_wheels} torques, got {len(torques_Nm)}")
        if self._realtime and self._rt_sync_tick is not None:
            tick = self._rt_sync_tick  # the application's cycle count means nothing to the simulator
        tick_lsb = tick & 0xFFFF
        n = self.n_wheels
        with_done = cycle_done and not self._realtime
        values = np.zeros((n + 1, self.icd.table.start.shape[1]))
        for i, ((_, lo, hi), tau) in enumerate(zip(self._cmd_ranges, torques_Nm)):
            tau = float(tau)
            values[i, self._cmd_torque_col] = 0.0 if not math.isfinite(tau) else min(max(tau, lo), hi)
        values[:n, self._cmd_tick_col] = tick_lsb
        values[n, self._done_tick_col] = tick & 0xFFFFFFFF
        idx = self._cmd_idx if with_done else self._cmd_idx[:n]
        self._send_burst(self._sender.burst(idx, values[:len(idx)]))
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
        self._send(self._sender.frame("FSW_HEARTBEAT", {"mode": int(mode) & 0x0F, "cycle": cycle & 0xFFFFFFFF}))
