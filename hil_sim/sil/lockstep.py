"""The SIL time keeper: devices on the bus, SYNC/CYCLE_DONE lockstep, real-time pacing, fault injection.

One GNC tick k (period T, t_k = k T):

  begin_tick()   sensor frames due by t_k and the wheel statuses at t_k go through the fault injector;
                 SYNC(k, frames_following = number of ICD device frames that follow) goes out first,
                 then those frames.
  ...            the flight software runs its cycle and sends RWn_CMD(k) and CYCLE_DONE(k)
  end_tick()     frames from the flight software are taken off the bus (lockstep: until CYCLE_DONE(k)
                 or ``cycle_done_timeout_s``, counted as a timeout; the world steps anyway with the held
                 commands), wheel nodes take valid commands, then the world steps over [t_k, t_k + T]
                 at the dynamics rate while sensors sample when due.

Three ways to drive it, sharing that code:
  * ``run_lockstep(n)``: multi-process SIL (flight software in another process on a real bus);
  * in-process (campaigns' fast mode): ``begin_tick()``; run the FSW cycle on a ``virtual`` bus in the
    same thread; ``end_tick(wait_s=0)``. No threads, no sleeps;
  * ``run_realtime(n)``: SYNC paced to the monotonic clock; never waits for the flight software; sensor
    frames go out at their own due times between SYNCs; commands are applied at the dynamics step during
    which they arrive ("late commands applied late").

Lockstep runs are deterministic: no wall-clock value enters the frames or the world.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable

import can
import numpy as np

from comms.bus.burst import FrameBurst
from comms.bus.e2e import NO_STOP, PYTHON_RUN, CheckedBurst, CheckedFrame, E2EReceiver
from comms.bus.kernels import ECHO_CODE, MAX_DLC, N_CODES, count_timeouts
from comms.bus.icd import Icd
from comms.bus.transport import recv_burst, send_batch, send_burst
from hil_sim.devices import kernels as dk
from hil_sim.devices.kernels import apply_received
from hil_sim.devices.nodes import Devices, DeviceTiming, WorldLike
from hil_sim.devices.magnetic import MagneticNodes
from hil_sim.world import environment as env
from hil_sim.devices.faults import DOOR_FAULT_KINDS, FaultInjector, FaultSpec, WheelFailures, bus_faults

SIM_NODES = ("SIM", "IMU", "STR", "RW1", "RW2", "RW3", "RW4", "RW5", "RW6", "DOOR", "MAG", "CSS", "MTQ")


@dataclass
class SimStats:
    """Counters of the time keeper (the bus E2E counters are in ``Simulator.receiver.counters``)."""

    ticks: int = 0
    frames_sent: int = 0
    cycle_done: int = 0
    cycle_done_timeouts: int = 0   # lockstep: no CYCLE_DONE(k) within the timeout
    cycle_done_late: int = 0       # real time: CYCLE_DONE(k) arrived after tick k+1 began (or never)
    stale_cycle_done: int = 0      # a CYCLE_DONE for another tick than the one awaited
    wheel_commands: int = 0
    heartbeats: int = 0
    realtime_overruns: int = 0     # real time: the simulator itself fell behind the clock
    tx_errors: int = 0             # frames the bus refused (transmit queue full, bus error)
    max_lateness_s: float = 0.0


class Simulator:
    """Devices + time keeper for one world on one bus (see the module docstring).

    ``world``: hil_sim.world.world.World (or anything with its methods); ``bus``: an open python-can bus;
    ``icd``: the loaded ICD; ``gnc_period_s``: T (a multiple of ``dynamics_dt_s``, itself by default the
    world's max integration step); ``faults``: FaultSpec / mission BusFault entries.
    ``on_frame(direction, t_s, msg)``: sees every frame sent ("tx") or received ("rx", own echoes left out),
    at simulation time ``t_s``; alone it takes the simulator off its burst paths (every frame made a
    ``can.Message``). ``on_burst(direction, t_s, burst, rows)``: with ``on_frame``, the same observer for
    whole bursts (frames ``rows`` of a FrameBurst, in order; None: all): the burst paths stay, ``on_frame``
    sees only the frames of the paths that handle messages (the fault injector's, the real-time sends).
    """

    def __init__(self, world: WorldLike, bus: can.BusABC, icd: Icd | None = None, *,
                 gnc_period_s: float = 0.1, dynamics_dt_s: float | None = None,
                 timing: DeviceTiming | None = None, faults: Iterable[Any] = (), fault_seed: int = 0,
                 cycle_done_timeout_s: float = 2.0, clock: Callable[[], float] = time.monotonic,
                 on_frame: Callable[[str, float, can.Message], None] | None = None,
                 on_burst: Callable[[str, float, FrameBurst, Iterable[int] | None], None] | None = None,
                 door: Any = None, magnetic: Any = None) -> None:
        self.world = world
        self.bus = bus
        self.icd = icd or Icd()
        self._init_timing(world, gnc_period_s, dynamics_dt_s)
        self._world_samples = hasattr(world, "advance_sampled")
        self.devices = Devices.for_world(world, self.icd, timing, door=door)
        self.n_wheels = len(self.devices.wheels)
        self.fault_specs = [FaultSpec.from_any(f) for f in faults or ()]  # as given (campaigns read them back)
        self.wheel_failures = WheelFailures(self.fault_specs)  # on the mechanism, at their time
        self.injector = FaultInjector(self.icd, bus_faults(self.fault_specs), seed=fault_seed)
        self._init_door()
        self._init_magnetic(magnetic, fault_seed)
        self._faults = self.injector.faults  # (empty: the injector never acts, ``bool(injector)`` is False)
        self.cycle_done_timeout_s = cycle_done_timeout_s
        self.clock = clock
        if on_burst is not None and on_frame is None:
            raise ValueError("on_burst needs on_frame (the frames of the fault injector's paths are messages)")
        self.on_frame = on_frame
        self.on_burst = on_burst
        self._init_sync()
        self._init_receiver()
        self._init_receive_commands()
        # Lockstep waits wake only for CYCLE_DONE where the bus can filter wake-ups (socketcan): the wheel
        # commands before it queue without a context switch each (see _receive_until_done).
        self._wait_for = getattr(bus, "wait_for", None)
        if self._wait_for is not None:
            bus.watch([self._cycle_done_id])
        self._init_clock(world)

    def _init_timing(self, world: WorldLike, gnc_period_s: float, dynamics_dt_s: float | None) -> None:
        """The GNC period T (whole milliseconds, for SYNC.period_ms) and the dynamics steps within it."""
        if dynamics_dt_s is None:
            params = getattr(world, "params", None)
            dynamics_dt_s = float(getattr(params, "max_integration_step_s", 0.01))
        n_sub = round(gnc_period_s / dynamics_dt_s)
        if n_sub < 1 or not math.isclose(n_sub * dynamics_dt_s, gnc_period_s, rel_tol=1e-9, abs_tol=1e-12):
            raise ValueError(f"gnc_period_s ({gnc_period_s} s) must be a whole multiple of dynamics_dt_s "
                             f"({dynamics_dt_s} s)")
        period_ms = gnc_period_s * 1000.0
        if abs(period_ms - round(period_ms)) > 1e-9 or not 1 <= round(period_ms) <= 4095:
            raise ValueError(f"gnc_period_s ({gnc_period_s} s) must be whole milliseconds in 1..4095 (SYNC.period_ms)")
        self.period_s = gnc_period_s
        self.period_ms = int(round(period_ms))
        self.n_sub = n_sub
        self.dt_s = gnc_period_s / n_sub
        self._j_dt = np.arange(n_sub + 1) * self.dt_s  # j * dt_s, j = 0..n_sub
        self._j_dt_end = float(self._j_dt[-1])

    def _init_sync(self) -> None:
        """SYNC's sender, row and columns, and the command columns the received frames are applied by."""
        self._sync_sender = self.devices.sender  # one sender (alive counters per message) for all SIM nodes
        self._sync_m = self.icd.message_index["SYNC"]
        self._sync_row = [0.0] * self.icd.table.start.shape[1]
        self._sync_cols = [self.icd.column("SYNC", s) for s in ("tick", "frames_following", "period_ms")]
        self._sync_cols_arr = np.array(self._sync_cols, dtype=np.int64)
        self._torque_col = self.icd.column("RW1_CMD", "torque_cmd")
        self._tick_lsb_col = self.icd.column("RW1_CMD", "tick_lsb")
        self._done_tick_col = self.icd.column("CYCLE_DONE", "tick")
        self._rx: CheckedBurst | None = None  # frames read off the bus, not yet handled

    def _init_receiver(self) -> None:
        """The receiver of the flight software's frames (its own left out) and the per-frame apply's tables."""
        own = self.icd.ids_sent_by(*SIM_NODES)
        watch = [f"RW{i}_CMD" for i in range(1, self.n_wheels + 1)] + ["CYCLE_DONE"]
        self.receiver = E2EReceiver(self.icd, ignore_ids=own, watch=watch)
        self._cmd_index = {self.icd.spec(f"RW{i}_CMD").frame_id: i - 1 for i in range(1, self.n_wheels + 1)}
        self._cycle_done_id = self.icd.spec("CYCLE_DONE").frame_id
        self._heartbeat_id = self.icd.spec("FSW_HEARTBEAT").frame_id
        # frame id -> wheel (0-based) of its command, -1 for any other id (the received-frames kernel's table)
        self._cmd_wheel_of_id = np.full(len(self.icd.table.index_of_id), -1, dtype=np.int64)
        for fid, w in self._cmd_index.items():
            self._cmd_wheel_of_id[fid] = w
        self._rx_counts = np.zeros(4, dtype=np.int64)
        # the per-frame apply of the paced (real-time) and fault-window paths: a fast-mode run never reaches
        # it, so load (or compile) it here, with nothing to apply, not inside a real-time run's first tick
        apply_received(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 1)), 0, 0,
                       self._cmd_wheel_of_id, self._torque_col, self._tick_lsb_col, self._cycle_done_id,
                       self._done_tick_col, self._heartbeat_id, 0.0, self.devices.wheel_state, self._rx_counts)

    def _init_receive_commands(self) -> None:
        """The arrays of receive_commands (a tick's commands classified, counted and applied in one compiled
        call)."""
        # the constants packed once, the tally of (counter key, count) pairs and its targets, the state
        n_codes = N_CODES  # tally codes: the kernels' class codes (as the flight-side driver)
        n_messages = len(self.icd.message_names)
        kind_of_id = self.receiver.kernel_state[0]
        cfg = np.zeros(dk.RC_SIZE, dtype=np.int64)
        cfg[[dk.RC_N_CODES, dk.RC_BUS_ROW, dk.RC_TORQUE_COL, dk.RC_TICK_LSB_COL, dk.RC_DONE_ID, dk.RC_DONE_TICK_COL,
             dk.RC_HEARTBEAT_ID, dk.RC_N_IDS]] = (n_codes, n_messages, self._torque_col, self._tick_lsb_col,
                                                  self._cycle_done_id, self._done_tick_col, self._heartbeat_id,
                                                  len(kind_of_id))
        self._rc_consts = np.ascontiguousarray(np.concatenate(
            [cfg, kind_of_id, self._cmd_wheel_of_id, self.receiver.kernel_state[4]]).astype(np.int64))
        self._rc_table = self.receiver.kernel_state[1:4] + self.receiver.kernel_state[5:]
        self._rc_tally = np.zeros(((n_messages + 1) * n_codes, 2), dtype=np.int64)
        self._rc_targets = self.receiver.tally_targets(n_codes)
        self._rc_state = np.zeros(dk.RS_SIZE, dtype=np.int64)
        self._rc_n_codes = n_codes
        self._rc_watch = self.receiver.watched_timeouts()  # (message indices, limits) as check_timeouts has them
        self._rc_status = np.zeros(0, dtype=np.int64)
        self._rc_args: tuple | None = None  # (see _take_burst)
        # receive_commands reads the codec table from the devices' packed copy of it
        if not all(np.array_equal(a, b) for a, b in zip(self._rc_table[:3], (self.icd.table.msg_i,
                                                                              self.icd.table.sig_i,
                                                                              self.icd.table.sig_f))):
            raise ValueError("Simulator: the receiver's codec table is not the ICD's")  # pragma: no cover
        # count_timeouts' arguments after the time (bound once: the same arrays every tick)
        self._ct_args = (self._rc_watch[0], self._rc_watch[1], self._rc_table[3], self._rc_table[4], self._rc_tally,
                         self._rc_state, n_codes)
        self._rc_values = np.zeros((0, self.icd.table.start.shape[1]))
        # the lockstep receive of a whole burst is first reached in tick 0, which a SIL flies while the flight
        # software runs its first cycle (on the vcan-vm guest's one CPU): load (or compile) it here, with no
        # frame, as apply_received above
        d = self.devices
        dk.receive_commands(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64),
                            np.zeros((0, MAX_DLC), dtype=np.uint8), 0.0, 0, self._rc_status, self._rc_values,
                            self._rc_consts, d.packed_f, d.packed_i, self._rc_table[3], self._rc_table[4],
                            self._rc_tally, self._rc_state)

    def _init_clock(self, world: WorldLike) -> None:
        """Tick 0 at the world's time, no tick open; the sensors sample the initial state (t = t0) before the
        first tick."""
        self.tick = 0
        self.t0_s = float(world.t)
        self.t_s = self.t0_s + self.tick * self.period_s
        self.stats = SimStats()
        self._done_ticks: set[int] = set()
        self._tick_open = False
        self._awaiting: int | None = None
        self._rt_anchor: float | None = None  # real time: clock() at tick 0's start (ticks at anchor + k T)
        self._answer_offsets: list[float] = []  # real time: CYCLE_DONE(k) arrival - tick k's start [s]
        self.rt_phase_shift_s: float | None = None  # real time: the delay _lock_phase applied last
        self._phase_locked = False
        self.devices.sample_sensors(world, self.t0_s)

    def _init_door(self) -> None:
        """The aperture door's drive (``door``: hil_sim.devices.nodes.DoorParams; None: no door and nothing of it on
        the bus): its failures from the faults, its command's id and slot."""
        self.door = self.devices.door
        failures = [f for f in self.injector.faults if f.kind in DOOR_FAULT_KINDS]
        if failures and self.door is None:
            raise ValueError(f"fault {failures[0].kind}: this spacecraft has no door (spacecraft.door)")
        if self.door is not None:
            self.door.faults = failures
            self.door._record = self.injector.record_device
            self._door_cmd_id = self.icd.spec("DOOR_CMD").frame_id
            self._door_open_col = self.icd.column("DOOR_CMD", "open")

    def _init_magnetic(self, magnetic: Any, seed: int) -> None:
        """The magnetometer, sun sensors and rods (``magnetic``: hil_sim.devices.magnetic.MagneticParams; None:
        none of them, nothing of them on the bus), and the residual dipole the rods' dipole adds to."""
        self.magnetic = MagneticNodes(self.icd, magnetic, seed=seed) if magnetic is not None else None
        self._residual_dipole_B = None
        if self.magnetic is not None and magnetic.magnetorquers is not None:
            b = self.world.batch
            if b.B.shape[0] <= env.ENV_DIPOLE or not int(b.B[env.ENV_FLAGS, 0]) & 4:
                raise ValueError("magnetorquers: the world's dipole torque is off (DisturbanceParams.dipole_torque)")
            self._residual_dipole_B = b.B[env.ENV_DIPOLE:env.ENV_DIPOLE + 3, 0].copy()

    def _apply_rods(self, t_s: float) -> None:
        """The rods' dipole held from ``t_s`` on, added to the residual's row the dynamics' dipole torque reads."""
        if self._residual_dipole_B is not None:
            self.world.batch.B[env.ENV_DIPOLE:env.ENV_DIPOLE + 3, 0] = (self._residual_dipole_B
                                                                        + self.magnetic.rods_dipole_B(t_s))

    def _extra_rows(self, t: float) -> list[tuple[int, list]]:
        """The optional devices' frames of the tick (the door's status, then the magnetic devices')."""
        extra = [(self.door.status_m, self.door.status_row(t))] if self.door is not None else []
        return extra + (self.magnetic.rows(self.world, t) if self.magnetic is not None else [])

    def _append_device_rows(self, out: Any, idx: list, rows: list, t: float) -> Any:
        """The optional devices' frames appended to the tick's rows (``out`` of ``Devices.tick_rows`` with SYNC's
        frames_following counted again, or the lists ``idx``/``rows``); returns ``out``."""
        extra = self._extra_rows(t)
        if out is None:
            for m, row in extra:
                idx.append(m)
                rows.append(row)
            return None
        out_idx, out_rows, n = out
        if n + len(extra) > out_idx.shape[0]:
            out_idx = np.concatenate([out_idx, np.zeros(8, dtype=out_idx.dtype)])
            out_rows = np.concatenate([out_rows, np.zeros((8, out_rows.shape[1]))])
        for m, row in extra:
            out_idx[n] = m
            out_rows[n] = row
            n += 1
        out_rows[0, self._sync_cols[1]] = float(min(n - 1, 255))
        return out_idx, out_rows, n

    def _magnetic_commands(self, ids: np.ndarray, status: np.ndarray, values: np.ndarray, first: int, end: int,
                           t_s: float) -> None:
        """The delivered MTQ_COMMAND frames among frames first..end-1 of a classified burst, in order."""
        cols = self.magnetic.command_cols
        for i in np.flatnonzero(ids[first:end] == self.magnetic.command_id).tolist():
            if status[first + i] <= 1:
                self.magnetic.on_command([values[first + i, c] for c in cols], t_s)

    def _door_commands(self, ids: np.ndarray, status: np.ndarray, values: np.ndarray, first: int, end: int,
                       t_s: float) -> None:
        """The delivered DOOR_CMD frames among frames first..end-1 of a classified burst, in order."""
        for i in np.flatnonzero(ids[first:end] == self._door_cmd_id).tolist():
            if status[first + i] <= 1:
                self.door.on_command(values[first + i, self._door_open_col] >= 0.5, t_s)

    @property
    def _per_frame(self) -> bool:
        """Frames observed one by one, as messages (``on_frame`` without ``on_burst``; either may be set
        after construction): the simulator leaves its burst paths."""
        return self.on_frame is not None and self.on_burst is None

    # ------------------------------------------------------------------------------------ time
    # ``t_s``: simulation time of the current tick, t0 + k T (exact, not accumulated), an attribute set with
    # ``tick`` (read several times a tick: by the flight software's clock, the timeline, the recorders)

    def _fail_wheels(self, t_s: float) -> None:
        """Physical wheel faults due by ``t_s``: the world's wheel fails, and the injector's log says so."""
        for wheel, mode, f in self.wheel_failures.due(t_s):
            self.world.set_wheel_failure(wheel, mode)
            self.injector.record(t_s, f.kind, f.message, self.icd.spec(f.message).frame_id,
                                  f"wheel {wheel + 1} {mode}")

    def _sub_t(self, j: int) -> float:
        return self.t0_s + self.tick * self.period_s + j * self.dt_s

    # ------------------------------------------------------------------------------- tick phases
    def begin_tick(self) -> int:
        """Publish SYNC(k) and the device frames of tick k. Returns the number of frames sent."""
        if self._tick_open:
            raise RuntimeError("begin_tick() called twice without end_tick()")
        t = self.t_s
        tick = self.tick & 0xFFFFFFFF
        if self.wheel_failures:
            self._fail_wheels(t)
        if not self._faults and self.door is None and self.magnetic is None:
            # no fault to inject: SYNC first, then the device frames, made and encoded in one compiled call
            # where the world allows (alive counters are per message, so encoding SYNC with the others gives
            # the bytes it always had), one burst
            burst = self.devices.tick_burst(self.world, t, tick, self.period_ms, self._sync_m, self._sync_cols_arr)
            if burst is not None:
                self._send_burst(burst, t)
                self._tick_open = True
                self._awaiting = self.tick
                return len(burst)
        # the tick's rows in one compiled call where the world allows (SYNC in row 0, then the device rows)
        out = self.devices.tick_rows(self.world, t, tick, self.period_ms, self._sync_m, self._sync_cols_arr)
        sync = self._sync_row
        sync[self._sync_cols[0]] = tick
        sync[self._sync_cols[2]] = self.period_ms
        if out is None:
            idx, rows = self.devices.rows_due(t)
            status_idx, status_rows = self.devices.wheel_status_rows(self.world, t)
            idx, rows = idx + status_idx, rows + status_rows
        if self.door is not None or self.magnetic is not None:
            out = self._append_device_rows(out, idx if out is None else [], rows if out is None else [], t)
        if self.injector and not self.injector.passes_through(t):
            # faults active now: the frames one by one through the injector (it edits, drops and adds)
            if out is None:
                frames = self._sync_sender.burst(np.array(idx, dtype=np.int64), np.array(rows)).messages()
            else:
                out_idx, out_rows, n = out
                frames = self._sync_sender.burst(out_idx[1:n], out_rows[1:n]).messages()
            frames = self.injector.process(frames, t)
            following = sum(1 for m in frames if m.arbitration_id in self.icd.by_id)
            sync[self._sync_cols[1]] = min(following, 255)
            sync_frame = self._sync_sender.burst(np.array([self._sync_m]), np.array([sync])).message(0)
            out = self.injector.process([sync_frame], t, extras=False)
            # one burst: the flight software wakes once with the whole tick queued, not once per frame
            self._send_all(out + frames, t)
            sent = len(out) + len(frames)
        else:
            # SYNC first, then the device frames: one compiled encode, one burst (alive counters are per
            # message, so encoding SYNC with the others gives the bytes it always had)
            if out is None:
                sync[self._sync_cols[1]] = min(len(idx), 255)
                burst = self._sync_sender.burst(np.array([self._sync_m] + idx, dtype=np.int64),
                                                np.array([sync] + rows))
            else:
                out_idx, out_rows, n = out
                burst = self._sync_sender.burst(out_idx[:n], out_rows[:n])
            self._send_burst(burst, t)
            sent = len(burst)
        self._tick_open = True
        self._awaiting = self.tick
        return sent

    def end_tick(self, wait_s: float | None = None) -> bool:
        """Take the flight software's frames, then step the world over one GNC period.

        ``wait_s``: how long to wait for CYCLE_DONE(k) (default ``cycle_done_timeout_s``; 0 = only what
        is queued, the in-process mode). Returns True if CYCLE_DONE(k) was received.
        """
        if not self._tick_open:
            raise RuntimeError("end_tick() without begin_tick()")
        k = self.tick
        wait = self.cycle_done_timeout_s if wait_s is None else wait_s
        done = self._receive_until_done(k, max(0.0, wait))
        if not done:
            self.stats.cycle_done_timeouts += 1
        self._advance_period(paced=None)
        return done

    def _advance_period(self, paced: Callable[[int], None] | None) -> None:
        """Step the world over [t_k, t_k + T] in dynamics steps; ``paced(j)`` runs before step j (real time)."""
        if paced is None and self._world_samples:
            # not paced: the whole period in one compiled call (same numbers as the loop below)
            # _sub_t(j) for j = 0..n_sub: (t0 + k T) + j dt, the same sums (made in the compiled call)
            t_k = self.t_s
            self._apply_rods(t_k)
            self.devices.step_period(self.world, self.dt_s, self.n_sub, t_k)
            if self.door is not None:
                self.door.advance(t_k, t_k + self._j_dt_end)
            # the receiver's check_timeouts(_sub_t(n_sub)) compiled
            rs = self._rc_state
            count_timeouts(t_k + self._j_dt_end, *self._ct_args)
            n_tally = rs.item(dk.RS_NTALLY)
            if n_tally:
                self._settle_tally(n_tally)
        else:
            self._apply_rods(self._sub_t(0))
            for j in range(self.n_sub):
                if paced is not None:
                    paced(j)
                t = self._sub_t(j)
                self.world.step(self.dt_s, self.devices.wheel_torques(t))
                self.devices.sample_sensors(self.world, self._sub_t(j + 1))
            if self.door is not None:
                self.door.advance(self._sub_t(0), self._sub_t(self.n_sub))
            self.receiver.check_timeouts(self._sub_t(self.n_sub))
        self.tick += 1
        self.t_s = self.t0_s + self.tick * self.period_s
        self.stats.ticks += 1
        self._tick_open = False

    # ---------------------------------------------------------------------------------- receiving
    def _receive_until_done(self, k: int, wait_s: float) -> bool:
        t_s = self.t_s
        if self._faults:  # (without faults nothing is ever held)
            for msg in self.injector.release(t_s, "rx"):  # flight-software frames delayed by a fault
                self._classify(msg, t_s)
        # With a doorbell (socketcan) a waiting tick starts with the wait: this tick's answer comes after this
        # tick's SYNC, which has just been sent (earlier frames still queued are read after the wake-up).
        wait_first = self._wait_for is not None and wait_s > 0.0
        # The first wait takes the whole timeout without a clock read (in the vcan-vm guest a read costs
        # ~15 us, and one wait per tick is the rule); a further wait counts the timeout from its start.
        deadline, waited = None, False
        while True:
            if k in self._done_ticks:
                self._done_ticks.discard(k)
                return True
            rx = self._rx
            if rx is not None and rx.pos < rx.n:
                self._handle_next(rx, t_s, k)
                continue
            burst = None if wait_first else recv_burst(self.bus, 0.0)  # clock reads only when it is empty
            wait_first = False
            if burst is not None:
                if self._take_burst(burst, t_s, k):
                    return True
                continue
            if burst is None:
                if not waited:
                    waited, remaining = True, wait_s
                else:
                    now = time.monotonic()
                    if deadline is None:
                        deadline = now + wait_s
                    remaining = deadline - now
                    if remaining <= 0.0:
                        return False
                if self._wait_for is None:
                    burst = recv_burst(self.bus, remaining)
                elif self._wait_for(remaining):
                    # CYCLE_DONE rang: it and the commands sent before it are queued (or arriving: the
                    # kernel may deliver to the doorbell socket first), so this returns at once
                    burst = recv_burst(self.bus, remaining)
                else:
                    burst = recv_burst(self.bus, 0.0)  # no CYCLE_DONE in time: take what did come
                if burst is None:
                    return False
            if self._take_burst(burst, t_s, k):
                return True

    def _take_burst(self, burst: FrameBurst, t_s: float, k: int) -> bool:
        """A burst read off the bus while awaiting CYCLE_DONE(k): in one compiled call
        (device_kernels.receive_commands: E2E, counts, wheel commands, CYCLE_DONE) where that is what
        ``_handle_next`` would do (no fault active on received frames, no per-frame observer, more frames
        than the receiver judges one by one), else into ``_rx`` for ``_handle_next``. Frames the compiled call
        leaves (after CYCLE_DONE(k), or from one for the receiver's Python path on) wait in ``_rx`` too.
        Returns whether CYCLE_DONE(k) came (else the caller goes on: ``_rx``, the bus)."""
        n = len(burst)
        if (n <= PYTHON_RUN or self._per_frame or self._awaiting != k
                or (self._faults and not self.injector.passes_through(t_s, "rx"))):
            self._rx = self.receiver.check(burst)
            return False
        if self._rc_status.shape[0] < n:
            self._rc_status = np.zeros(2 * n, dtype=np.int64)
            self._rc_values = np.zeros((2 * n, self._rc_values.shape[1]))
            self._rc_args = None
        args = self._rc_args
        if args is None:
            # receive_commands' arguments after the time and tick, bound while the scratch holds
            d = self.devices
            args = self._rc_args = (self._rc_status, self._rc_values, self._rc_consts, d.packed_f, d.packed_i,
                                    self._rc_table[3], self._rc_table[4], self._rc_tally, self._rc_state)
        rs = self._rc_state
        end = dk.receive_commands(burst.ids, burst.lengths, burst.data, t_s, k, *args)
        if self.door is not None:
            self._door_commands(burst.ids, self._rc_status, self._rc_values, 0, end, t_s)
        if self.magnetic is not None:
            self._magnetic_commands(burst.ids, self._rc_status, self._rc_values, 0, end, t_s)
        if self.on_burst is not None and end:
            self._log_rx(burst, self._rc_status[:end].tolist(), 0, end, t_s)
        wheel_cmds, n_tally, heartbeats, cycle_done, stale, done = rs.tolist()
        rs.fill(0)
        if n_tally:
            self._settle_tally(n_tally)
        stats = self.stats
        if wheel_cmds:
            stats.wheel_commands += wheel_cmds
        if heartbeats:
            stats.heartbeats += heartbeats
        if cycle_done:
            stats.cycle_done += cycle_done
            stats.stale_cycle_done += stale
        if end < n:  # the rest as if still queued (from a frame for the Python path, or after CYCLE_DONE(k))
            rx = self._rx = self.receiver.check(burst)
            rx.pos = end
        return done != 0

    def _settle_tally(self, n_tally: int) -> None:
        """The compiled calls' counts (the first ``n_tally`` (key, count) pairs in ``_rc_tally``) into the
        receiver's counters; the tally emptied (``_rc_state[RS_NTALLY]``)."""
        targets = self._rc_targets
        for key, count in self._rc_tally[:n_tally].tolist():
            counts, cls = targets[key]
            counts[cls] += count
        self._rc_state[dk.RS_NTALLY] = 0

    def poll(self, t_s: float) -> int:
        """Handle everything queued now, stamping it with simulation time ``t_s``. Returns the count."""
        n = 0
        for msg in self.injector.release(t_s, "rx"):
            self._classify(msg, t_s)
        while True:
            rx = self._rx
            if rx is None or rx.pos >= rx.n:
                burst = recv_burst(self.bus, 0.0)
                if burst is None:
                    return n
                rx = self._rx = self.receiver.check(burst)
            n += self._handle_next(rx, t_s)

    def _handle_next(self, rx: CheckedBurst, t_s: float, awaited: int | None = None) -> int:
        """Frames read off the bus: through the fault injector when faults are active (frame by frame, as
        messages), else classified in one compiled call, up to CYCLE_DONE(``awaited``) when given (later
        frames stay for later, as if still queued). Returns how many frames were handled."""
        if self.injector and not self.injector.passes_through(t_s, "rx"):
            msg = rx.burst.message(rx.pos)
            rx.pos += 1
            self._handle_rx(msg, t_s)
            return 1
        first = rx.pos
        stop = NO_STOP if awaited is None else (self._cycle_done_id, self._done_tick_col, awaited, awaited,
                                                 NO_STOP[4], 0)
        end = self.receiver.classify_until(rx, t_s, stop)
        if self.on_burst is not None and end > first:
            self._log_rx(rx.burst, rx.codes, first, end, t_s)
        if not self._per_frame and not rx.fallback:
            # every frame judged by the compiled classifier: the delivered ones applied in one compiled call
            # (a CYCLE_DONE returns to here, in order, for its tick)
            if self.door is not None:
                self._door_commands(rx.burst.ids, rx.status, rx.values, first, end, t_s)
            if self.magnetic is not None:
                self._magnetic_commands(rx.burst.ids, rx.status, rx.values, first, end, t_s)
            counts = self._rx_counts
            i = first
            while i < end:
                i = apply_received(rx.status, rx.burst.ids, rx.values, i, end, self._cmd_wheel_of_id,
                                   self._torque_col, self._tick_lsb_col, self._cycle_done_id, self._done_tick_col,
                                   self._heartbeat_id, t_s, self.devices.wheel_state, counts)
                if counts[2]:
                    counts[2] = 0
                    self._on_cycle_done(int(counts[3]))
            if counts[0] or counts[1]:
                self.stats.wheel_commands += int(counts[0])
                self.stats.heartbeats += int(counts[1])
                counts[0] = counts[1] = 0
            return end - first
        per_frame = self._per_frame
        for i in range(first, end):
            code = rx.codes[i]
            if code == ECHO_CODE:
                continue
            if per_frame:
                self.on_frame("rx", t_s, rx.burst.message(i))
            if code <= 1:  # delivered
                fid = rx.ids[i] if i not in rx.fallback else rx.fallback[i].frame_id
                self._on_delivered(fid, rx.row(i), t_s)
        return end - first

    def _log_rx(self, burst: FrameBurst, codes: list, first: int, end: int, t_s: float) -> None:
        """``on_burst`` of received frames ``first``..``end``-1 classified with class codes ``codes`` (indexed
        as the burst): own echoes left out, as the per-frame observer never sees them."""
        if ECHO_CODE in codes[first:end]:
            self.on_burst("rx", t_s, burst, [i for i in range(first, end) if codes[i] != ECHO_CODE])
        else:
            self.on_burst("rx", t_s, burst, range(first, end))

    def _handle_rx(self, msg: can.Message, t_s: float) -> None:
        for m in (self.injector.process([msg], t_s, extras=False, direction="rx") if self.injector else [msg]):
            self._classify(m, t_s)

    def _classify(self, msg: can.Message, t_s: float) -> None:
        checked = self.receiver.check(FrameBurst.from_messages([msg]))
        self._deliver(self.receiver.take(checked, t_s), t_s, msg)

    def _deliver(self, frame: CheckedFrame | None, t_s: float, msg: can.Message | None) -> None:
        if frame is None:
            return
        if self.on_frame is not None:
            self.on_frame("rx", t_s, msg)
        if frame.delivered:
            self._on_delivered(frame.frame_id, frame.row, t_s)

    def _on_delivered(self, fid: int, row: list, t_s: float) -> None:
        """A frame from the flight software that passed E2E (id, value row), at simulation time ``t_s``."""
        if fid in self._cmd_index:
            self.devices.wheels[self._cmd_index[fid]].on_command(
                {"torque_cmd": row[self._torque_col], "tick_lsb": row[self._tick_lsb_col]}, t_s)
            self.stats.wheel_commands += 1
        elif fid == self._cycle_done_id:
            self._on_cycle_done(int(row[self._done_tick_col]))
        elif fid == self._heartbeat_id:
            self.stats.heartbeats += 1
        elif self.door is not None and fid == self._door_cmd_id:
            self.door.on_command(row[self._door_open_col] >= 0.5, t_s)
        elif self.magnetic is not None and fid == self.magnetic.command_id:
            self.magnetic.on_command([row[c] for c in self.magnetic.command_cols], t_s)

    def _on_cycle_done(self, tick: int) -> None:
        self.stats.cycle_done += 1
        if tick == self._awaiting:
            self._done_ticks.add(tick)
            if self._rt_anchor is not None and len(self._answer_offsets) < PHASE_LOCK_ANSWERS:
                self._answer_offsets.append(self.clock() - (self._rt_anchor + tick * self.period_s))
        else:
            self.stats.stale_cycle_done += 1

    def _lock_phase(self) -> None:
        """Real time, once a schedule (again after a stall): delay the tick schedule so the flight software's cycle, which runs on its own
        clock, falls ``PHASE_LOCK_TARGET`` of a period after each tick's start.

        Two free-running periodic schedules keep whatever phase they started with. The flight software starts
        first, so its cycles would sit just before the simulator's ticks, and CYCLE_DONE(k) would reach the
        simulator a few milliseconds before tick k+1: any delay on the host then makes it late. A bench's
        simulator aligns its frame to the flight computer's cycle the same way (a sync pulse)."""
        offsets = sorted(self._answer_offsets)
        median = offsets[len(offsets) // 2]
        shift = (median - PHASE_LOCK_TARGET * self.period_s) % self.period_s
        self._rt_anchor += shift
        self.rt_phase_shift_s = shift
        self._phase_locked = True

    def _publish_due(self, t_s: float) -> None:
        """Real time: sensor frames go out when due (between SYNCs), as on the hardware bus."""
        due = self.devices.frames_due(t_s)
        if self.injector:
            due = self.injector.release(t_s, "tx") + self.injector.process(due, t_s, extras=False)
        self._send_all(due, t_s)

    def _send_burst(self, burst: FrameBurst, t_s: float) -> None:
        """``_send_all`` of a burst: as the burst where the bus carries bursts (in process)."""
        if self._per_frame:
            self._send_all(burst.messages(), t_s)
            return
        while len(burst):
            n = send_burst(self.bus, burst, timeout=0.05)
            self.stats.frames_sent += n
            if self.on_burst is not None and n:
                self.on_burst("tx", t_s, burst, None if n >= len(burst) else range(n))
            if n >= len(burst):
                return
            self.stats.tx_errors += 1
            burst = burst.tail(n + 1)

    def _send_all(self, msgs: list[can.Message], t_s: float) -> None:
        """Send ``msgs`` in order (one system call on socketcan); a refused frame (transmit queue full,
        bus error) is counted and skipped, the run goes on."""
        i = 0
        while i < len(msgs):
            n = send_batch(self.bus, msgs[i:], timeout=0.05)
            self.stats.frames_sent += n
            if self.on_frame is not None:
                for msg in msgs[i:i + n]:
                    self.on_frame("tx", t_s, msg)
            i += n
            if i < len(msgs):
                self.stats.tx_errors += 1
                i += 1

    # -------------------------------------------------------------------------------------- loops
    def step_in_process(self, fsw_cycle: Callable[[], Any]) -> bool:
        """One tick with the flight software in this process (same thread, virtual bus):
        begin_tick(); fsw_cycle(); end_tick(wait_s=0). Returns whether CYCLE_DONE(k) was seen."""
        self.begin_tick()
        fsw_cycle()
        return self.end_tick(wait_s=0.0)

    def run_tick(self, realtime: bool, wait_s: float | None = None) -> bool:
        """One tick, paced to the clock (``realtime``) or in lockstep (waiting up to ``wait_s``, default
        ``cycle_done_timeout_s``); returns whether the flight software's CYCLE_DONE came in time."""
        if realtime:
            late_before = self.stats.cycle_done_late
            self.run_realtime(1)
            return self.stats.cycle_done_late == late_before
        self.begin_tick()
        return self.end_tick(wait_s)

    def run_lockstep(self, n_ticks: int, on_tick: Callable[["Simulator"], None] | None = None) -> SimStats:
        """Multi-process lockstep: each tick waits for CYCLE_DONE(k) (up to cycle_done_timeout_s)."""
        for _ in range(n_ticks):
            self.begin_tick()
            self.end_tick()
            if on_tick is not None:
                on_tick(self)
        return self.stats

    def run_realtime(self, n_ticks: int, on_tick: Callable[["Simulator"], None] | None = None,
                     sleep: Callable[[float], None] = time.sleep) -> SimStats:
        """Real time: tick k starts at wall time start + k T; the world advances one dynamics step per
        dt of wall time; frames are handled when they arrive. Never waits for the flight software."""
        if self._rt_anchor is None or self.clock() - (self._rt_anchor + self.tick * self.period_s) > self.period_s:
            # the first tick, or a pause of more than a period (a resumed run, a host that stalled the
            # loop): the schedule starts again now, and its phase is measured and locked again
            self._rt_anchor = self.clock() - self.tick * self.period_s
            self._answer_offsets.clear()
            self._phase_locked = False
        elif len(self._answer_offsets) == PHASE_LOCK_ANSWERS and not self._phase_locked:
            self._lock_phase()
        start = self._rt_anchor

        def pace(j: int) -> None:
            target = start + (self.tick * self.period_s) + j * self.dt_s
            now = self.clock()
            if target > now:
                sleep(target - now)
            else:
                lateness = now - target
                self.stats.max_lateness_s = max(self.stats.max_lateness_s, lateness)
                if lateness > self.dt_s:
                    self.stats.realtime_overruns += 1
            self.poll(self._sub_t(j))
            if j:
                self._publish_due(self._sub_t(j))

        for _ in range(n_ticks):
            pace(0)
            awaited = self.tick
            self.begin_tick()
            self._advance_period(paced=lambda j: pace(j) if j else self.poll(self._sub_t(0)))
            # CYCLE_DONE(k) must have arrived before tick k+1 begins; anything later is late. The last
            # poll above was one dynamics step before that: wait for the tick's end and take what came.
            end = start + self.tick * self.period_s
            now = self.clock()
            if end > now:
                sleep(end - now)
            self.poll(self.t_s)
            if awaited in self._done_ticks:
                self._done_ticks.discard(awaited)
            else:
                self.stats.cycle_done_late += 1
            if on_tick is not None:
                on_tick(self)
        return self.stats


PHASE_LOCK_ANSWERS = 3  # real time: answers measured before the tick schedule is aligned (once)
PHASE_LOCK_TARGET = 0.5  # real time: where in the tick the flight software's cycle is put [fraction of T]: as much room
# for a late SYNC (the simulator delayed) as for a late answer (the flight software delayed)


# ------------------------------------------------------------------------------------------------------
# A minimal flight-software stand-in (tests, benchmarks, bus bring-up): it is NOT the flight software.
# ------------------------------------------------------------------------------------------------------
class RateDampingResponder:
    """Answers each SYNC like the flight software would, with a rate-damping law on the wheels.

    Wheel torques tau = gain * pinv(A) omega_meas (A: 3 x n wheel axes in body), which removes body rate
    (the wheels absorb the momentum). Uses the real ``FswBusDriver``; runs in process or in its own
    process (``keepout bus respond --bus SPEC --wheels N``).
    """

    def __init__(self, driver: Any, wheel_axes_B: Any, gain_Nm_per_rad_s: float = 2.0) -> None:
        import numpy as np

        self.driver = driver
        self.pinv = np.linalg.pinv(np.asarray(wheel_axes_B, dtype=float).T)
        self.gain = gain_Nm_per_rad_s
        self.cycles = 0
        self.last_inputs = None

    def cycle(self, timeout_s: float = 0.0) -> bool:
        """Collect one tick's inputs, send torques and CYCLE_DONE. False if no SYNC arrived."""
        import numpy as np

        inputs = self.driver.collect_tick(timeout_s)
        if inputs is None:
            return False
        self.last_inputs = inputs
        omega = inputs.imu.omega_BN_B if inputs.imu is not None else np.zeros(3)
        torques = self.gain * (self.pinv @ omega)
        self.driver.send_wheel_torques(inputs.tick, torques, cycle_done=True)
        self.cycles += 1
        if self.cycles % 10 == 0:
            self.driver.send_heartbeat(0, self.cycles)
        return True
