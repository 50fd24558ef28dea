"""The flight software application: wires bus driver, estimator, guidance, control, FDIR, TM/TC.

`FlightSoftware(config, driver, telemetry, dispatcher)`:

* ``run_cycle(inputs)``: one GNC cycle (telecommands, estimate, guide, control, wheel torques and
  CYCLE_DONE on the bus, FDIR, GNC telemetry); ``inputs`` is a lockstep `TickInputs` or a real-time
  `LatestInputs`;
* ``run_lockstep()`` / ``run_realtime()``: the executive's loops (see `fsw.executive`);
* telecommand handlers for NOOP, RESET_COUNTERS, SET_MODE, SET_TARGET, SET_GAINS are registered on the
  dispatcher.

The flight software learns about the world only through the bus driver and telecommands.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from itertools import repeat

import numpy as np

from fsw.assumption_check import MAX_RESTARTS, AssumptionChecker
from fsw.bus.driver import TickInputs
from fsw.control import RateController
from comms.dictionary import MODES
from fsw.door import DoorController
from fsw.estimation import _NO_SAMPLES, AttitudeEstimator
from fsw.executive import Executive
from fsw.fdir import STATUS_LOST, Fdir, WheelSpeedResidual
from fsw.guidance import Guidance

# A housekeeping period in which at least BUS_BURST_FRAMES frames fail their CRC or do not decode is a burst:
# a bus fault (BUS_CORRUPT, one a minute at most, and the bus_corrupt_bursts counter), not a sensor's or a
# wheel's (those monitors judge their own frames' absence, with their own persistence).
BUS_BURST_FRAMES = 5
BUS_EVENT_PERIOD_S = 60.0
# TARGET_REACHED: the error below REACHED_ERROR_DEG and the estimated body rate below REACHED_RATE_DEG_S for
# REACHED_DWELL_S in a row (a slew passing through its target at speed is not "reached")
REACHED_ERROR_DEG = 0.05
REACHED_RATE_DEG_S = 0.01
REACHED_DWELL_S = 5.0
_CORRUPT_CLASSES = ("crc_error", "bad_length", "out_of_range", "wrong_sequence")
# longest run of cycles [s] in which a wheel's status frames arrive only corrupt and the wheel still counts
# as heard (a bus fault); past it nothing has been read from the wheel for that long: silence
CORRUPT_STATUS_HEARD_S = 10.0
# the E2E classes that housekeeping totals over the received messages
_HK_CLASSES = ("ok", "ok_some_lost", "crc_error", "wrong_sequence", "repeated", "bad_length", "out_of_range", "timeout")
_FDIR_HK_KEYS: dict[str, str] = {}  # FDIR monitor name -> its HK channel (fdir_<monitor>), filled as met
_NAN6, _ZERO6 = [math.nan] * 6, [0.0] * 6  # fillers of the GNC packet's six zone and wheel slots
# RWn_STATUS fault bits (config/icd/keepout.dbc): 1 overspeed, 2 command timeout, 4 drive fault.
WHEEL_OVERSPEED = 0x01
WHEEL_FAULT_MASK = 0x02 | 0x04


def _norm(v: list[float]) -> float:
    """Euclidean norm of a short list of floats (numpy's call overhead is most of a 3-vector's norm)."""
    total = 0.0
    for x in v:
        total += x * x
    return math.sqrt(total)


_statm: tuple[int, int, int] | None = None  # (pid, descriptor of /proc/<pid>/statm, page size)


def _resident_bytes() -> int | None:
    """This process's resident set size [bytes], what ``psutil.Process().memory_info().rss`` reports on
    Linux (resident pages of /proc/self/statm), read through one descriptor kept open: psutil costs
    ~0.2 ms a call, once per housekeeping cycle. None where /proc is not available."""
    global _statm
    try:
        pid = os.getpid()
        if _statm is None or _statm[0] != pid:  # "self" is resolved at open: a forked child opens its own
            _statm = (pid, os.open(f"/proc/{pid}/statm", os.O_RDONLY), os.sysconf("SC_PAGE_SIZE"))
        return int(os.pread(_statm[1], 128, 0).split()[1]) * _statm[2]
    except (OSError, ValueError, IndexError, AttributeError):
        return None


class _NullTelemetry:
    """Stand-in when no telemetry sender is given (bench, some tests): records events only."""

    def __init__(self):
        self.events: list[tuple[str, dict]] = []
        self.counters = {"packets_sent": 0, "send_errors": 0, "events_sent": 0, "events_throttled": 0}

    def send_channels(self, packet_name, values=None, time_s=None):
        self.counters["packets_sent"] += 1

    def event(self, name, /, time_s=None, **args):
        self.events.append((name, args))
        return True

    def reset_counters(self):
        for k in self.counters:
            self.counters[k] = 0


def freeze_heap() -> None:
    """Move everything allocated so far out of the cyclic garbage collector's reach.

    A full collection walks every tracked object: with numpy, scipy, astropy, numba and the ICD loaded that
    is ~200 k objects and 0.1-0.2 s, which lands inside some GNC cycle as a slip (seen in the 24 h soak).
    Start-up objects live as long as the process, so they are frozen once before the first cycle and
    later collections only visit what the cycles allocate.
    """
    import gc

    gc.collect()
    gc.freeze()


def single_threaded_math() -> None:
    """Run numpy's and scipy's BLAS on the calling thread only.

    OpenBLAS splits a large enough product over worker threads of its own, one per CPU, under normal
    scheduling; a real-time cycle thread would then wait for a worker that the host has preempted. Every
    library that threadpoolctl knows gets one thread, for the rest of the process.
    """
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)  # applied at once; the returned handle is only needed to undo it


def prepare_cycle_thread() -> None:
    """What every cycle loop does before its first cycle: ``freeze_heap`` and ``single_threaded_math``."""
    freeze_heap()
    single_threaded_math()


def enter_realtime(priority: int) -> list[tuple[str, str]]:
    """Prepare this thread for paced cycles; returns (event name, reason) pairs to report.

    Freezes the start-up heap and keeps BLAS on this thread (``prepare_cycle_thread``). With
    ``priority`` > 0 the thread runs SCHED_FIFO (no time-sharing with the host's other work) and all pages
    are locked in memory (no page fault mid-cycle).
    """
    import ctypes
    import ctypes.util
    import os

    prepare_cycle_thread()
    if priority <= 0:
        return []
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return [("RT_SCHEDULING_UNAVAILABLE", f"SCHED_FIFO {priority}: {exc}")]
    events = [("RT_SCHEDULING", f"SCHED_FIFO priority {priority}")]
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    MCL_CURRENT, MCL_FUTURE = 1, 2
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        events.append(("RT_SCHEDULING_UNAVAILABLE", f"mlockall: {os.strerror(ctypes.get_errno())}"))
    return events


def _budget_free_at(duration_s: float, max_cpu_fraction: float) -> float:
    """Host time from which the next periodic assumption check may start, so the background check uses at
    most ``max_cpu_fraction`` of a core. In real time a 0.5 s check every 10 s is 5 %; in lockstep, where
    onboard time runs 20-50x faster than the host clock, the onboard period alone would keep the worker
    busy all the time, stealing the CPU that the simulator and the flight software need."""
    if not math.isfinite(duration_s) or duration_s <= 0.0:
        return -math.inf
    return time.monotonic() + duration_s * (1.0 / max_cpu_fraction - 1.0)


@dataclass
class CycleRecord:
    """Last cycle's outputs (for tests, bench and SIL summaries)."""

    t: float
    mode: str
    q_est_NB: np.ndarray
    omega_cmd_BN_B: np.ndarray
    wheel_torque_cmd_Nm: np.ndarray
    margins_deg: list
    margin_min_deg: float
    pointing_error_deg: float
    att_error_deg: float
    exec_time_ms: float


class FlightSoftware:
    """``plugins``: `fsw.plugins.Plugin`s (at most one guidance, one estimator) flown under keepout's guard
    (`fsw.plugin_guard`); without them the cycle runs keepout's own code only. `fsw.assembly` builds it."""

    def __init__(self, config, driver, telemetry=None, dispatcher=None, clock=time.perf_counter, plugins=()):
        self.cfg = config
        self.driver = driver
        self.telemetry = telemetry if telemetry is not None else _NullTelemetry()
        if hasattr(self.telemetry, "clock"):
            # every packet, including the dispatcher's command events, carries onboard time
            self.telemetry.clock = lambda: self.t_s
        self.dispatcher = dispatcher
        self.clock = clock
        self.n_wheels = len(config.spacecraft.wheels)
        self.period_s = config.gnc_period_s
        self.t_s = 0.0
        self.cycle = 0
        self.plugins = {p.kind: p for p in plugins}
        self.estimator = AttitudeEstimator(config.estimator, np.asarray(config.spacecraft.star_tracker_q_BS))
        self.guidance = Guidance(config, events=self._event)
        if self.plugins:
            self._install_plugins()
        self.control = RateController(config)
        self.fdir = Fdir(config, self.n_wheels, event=self._event)
        self.wheel_residual = WheelSpeedResidual(self.control.Js)
        # the protective aperture door (fsw.door), when the spacecraft has one
        self.door = DoorController(config.door, self.period_s, driver, self._event) if config.door is not None else None
        self.executive = Executive(
            config.rates.gnc_rate_hz, config.rates.housekeeping_rate_hz, config.rates.slip_event_throttle_s,
            gnc_task=self._gnc_task, hk_task=self.housekeeping, on_slip=self._on_slip, clock=clock,
        )
        self.checker = AssumptionChecker(config.law.assumption_check, on_worker_lost=self._check_worker_lost)
        self._last_check_t = -math.inf
        self._check_budget_free_at = -math.inf  # host monotonic time from which a periodic check may start
        self._corrupt_src: dict | None = None
        self._corrupt_dicts: tuple[list[dict], list[str], list[dict], list[str]] = ([], [], [], [])
        self._hk_src: dict | None = None  # the driver's counters that _hk_dicts lists
        self._hk_src_len = 0
        self._hk_dicts: list[dict] = []
        self._max_speed = np.ascontiguousarray(self.control.max_speed, dtype=float)  # fixed at start-up
        # configuration the cycle reads every tick, fixed at start-up (no telecommand changes it)
        self._st_max_age_s = config.estimator.star_tracker_max_age_s
        self._gnc_tm_every = config.tmtc.gnc_packet_every_n_cycles
        self._corrupt_totals: tuple[int, int] = (0, 0)  # (IMU, star tracker) E2E rejections so far
        # bus-fault bursts (see _bus_fault_check): frames failing E2E or decoding seen so far, bursts counted,
        # the frames of the bursts not yet reported and when BUS_CORRUPT was last raised
        self._bus_failed_seen, self._bus_bursts, self._bus_burst_frames = 0, 0, 0
        self._bus_event_t = -math.inf
        self._st_was_valid = True
        self._st_outage_start = 0.0
        self._target_reached = False
        self._held_cycles = 0
        self._rt_t0: float | None = None
        # sensors heard from at least once (their FDIR monitors are armed from then on)
        self._imu_seen = False
        self._st_seen = False
        self._wheel_seen = np.zeros(self.n_wheels, dtype=np.bool_)
        # wheels whose status frames arrive but fail E2E: heard, not silent (_heard_through_corruption)
        self._wheel_status_msgs = [f"RW{i + 1}_STATUS" for i in range(self.n_wheels)]
        self._wheel_corrupt_src: dict | None = None
        self._wheel_corrupt_dicts: list = []
        self._wheel_corrupt_seen: list[int] = []
        self._wheel_corrupt_since = [math.nan] * self.n_wheels
        self._wheel_corrupt_pairs: tuple[list, list] = ([], [])
        self._wheel_corrupt_total = 0
        self._wheel_corrupt_streak = False
        self.inject_overrun_s = 0.0  # test hook: busy-wait this long in the next GNC cycle
        self.last: CycleRecord | None = None
        self.mode_reason = "INIT"
        self._start_wall = time.monotonic()
        if dispatcher is not None:
            self._register_commands(dispatcher)
        self._warm_up()
        self._event("FSW_STARTED", gnc_rate_hz=config.rates.gnc_rate_hz)
        if self.plugins:
            self._start_plugins()

    def _install_plugins(self) -> None:
        """The selected plug-ins in place of keepout's estimator and guidance law, each inside its guard."""
        from fsw.plugin_guard import GuardedEstimator, GuardedGuidance

        cfg = self.cfg
        if "estimator" in self.plugins:
            self.estimator = GuardedEstimator(cfg.estimator, np.asarray(cfg.spacecraft.star_tracker_q_BS),
                                              self.plugins["estimator"], self._event)
        if "guidance" in self.plugins:
            self.guidance = GuardedGuidance(cfg, self.plugins["guidance"], lambda: self.set_mode("SAFE", "FDIR"),
                                            events=self._event)

    def _start_plugins(self) -> None:
        if "guidance" in self.plugins:
            self.guidance.arm()  # after the warm-up: the plug-in sees flight states only
        for kind, plugin in self.plugins.items():
            self._event("PLUGIN_STARTED", kind=kind.upper(), name=plugin.name[:40])

    def _warm_up(self) -> None:
        """Load the compiled kernels, freeze the heap and start the check worker now, so the first cycle is
        not late.

        Runs the estimator's cycle as the GNC cycle calls it (`AttitudeEstimator._tick`) on a scratch
        instance (initialisation, a fused fix, a cycle without gyro samples) and every guidance mode once on
        the real zones (events muted), then restores the initial mode.
        """
        q = np.array([1.0, 0.0, 0.0, 0.0])
        scratch = AttitudeEstimator(self.cfg.estimator, np.asarray(self.cfg.spacecraft.star_tracker_q_BS))
        scratch._tick(self.period_s, np.zeros((1, 3)), q, 0.0)
        scratch._tick(self.period_s, np.zeros((2, 3)), np.array([0.99, 0.1, 0.0, 0.0]), 0.0, math.hypot(0.99, 0.1))
        scratch._tick(self.period_s, _NO_SAMPLES, None, 0.0)
        g = self.guidance
        events, g.events = g.events, (lambda name, **args: None)
        try:
            for mode in ("SAFE", "POINTING", "QUATERNION"):
                g.set_mode(mode)
                g.step(0.0, self.period_s, q, np.zeros(3))
        finally:
            g.set_mode(self.cfg.initial_mode)
            g.events = events
            g.forget_law_state()
        # the collection over the start-up heap now, before FSW_STARTED starts the simulator's SIL loop
        # (the cycle loops freeze again: then there is nothing left to walk)
        prepare_cycle_thread()
        self.checker.start()

    # ------------------------------------------------------------------------------------ events
    def _event(self, name: str, /, **args) -> None:
        try:
            self.telemetry.event(name, time_s=self.t_s, **args)
        except TypeError:
            self.telemetry.event(name, **args)

    def _on_slip(self, group: str, exec_ms: float, total: int, late_ms: float = 0.0) -> None:
        self._event("CYCLE_SLIP", rate_group=group, exec_time_ms=exec_ms, count=total, late_ms=late_ms)

    @property
    def mode(self) -> str:
        return self.guidance.mode

    def set_mode(self, mode: str, cause: str = "TELECOMMAND") -> None:
        old = self.guidance.mode
        self.guidance.set_mode(mode)
        self.mode_reason = cause
        self._target_reached = False
        self._held_cycles = 0
        if old != mode or mode == "SAFE":
            self._event("MODE_CHANGED", from_mode=old, to_mode=mode, cause=cause)

    # ---------------------------------------------------------------------------------- commands
    def _register_commands(self, d) -> None:
        d.register("NOOP", self._cmd_noop)
        d.register("RESET_COUNTERS", self._cmd_reset_counters)
        d.register("SET_MODE", self._cmd_set_mode)
        d.register("SET_TARGET", self._cmd_set_target)
        d.register("SET_GAINS", self._cmd_set_gains)

    def _cmd_noop(self) -> None:
        return None

    def _cmd_reset_counters(self) -> None:
        self.executive.reset_counters()
        self.fdir.reset_counters()
        if hasattr(self.telemetry, "reset_counters"):
            self.telemetry.reset_counters()
        if self.dispatcher is not None:
            self.dispatcher.reset_counters()
        self._event("COUNTERS_RESET")

    def _cmd_set_mode(self, mode) -> None:
        mode = str(mode)
        if mode not in MODES:
            from comms.telecommand import CommandValidationError

            raise CommandValidationError(f"SET_MODE: unknown mode {mode!r}")
        self.set_mode(mode, "TELECOMMAND")

    def _cmd_set_target(self, kind, c0, c1, c2, c3=0.0) -> None:
        from comms.telecommand import CommandValidationError

        kind = str(kind)
        if kind == "DIRECTION":
            v = np.array([c0, c1, c2], dtype=float)
        else:
            v = np.array([c0, c1, c2, c3], dtype=float)
        n = float(np.linalg.norm(v))
        if not math.isfinite(n) or abs(n - 1.0) > 1e-3:
            raise CommandValidationError(f"SET_TARGET: {kind} must be a unit vector (norm {n:.6f})",
                                         "TARGET_NOT_UNIT")
        v = v / n
        hit = self.guidance.target_violation(kind, v)
        if hit is not None:
            zone, margin = hit
            bodies = self._zone_bodies(kind)
            self._event("TARGET_REJECTED", zone=zone, body=bodies[zone] if zone < len(bodies) else "INERTIAL", margin_deg=margin)
            raise CommandValidationError(f"SET_TARGET: target inside keep-out zone {zone} (margin {margin:.3f} deg)",
                                         "TARGET_IN_KEEP_OUT")
        if kind == "DIRECTION":
            self.guidance.set_target_direction(v)
        else:
            self.guidance.set_target_quaternion(v)
        self._target_reached = False
        self._held_cycles = 0
        c = list(v) + [0.0] * (4 - len(v))
        self._event("TARGET_SET", kind=kind, c0=c[0], c1=c[1], c2=c[2], c3=c[3])

    def _zone_bodies(self, kind: str) -> list[str]:
        if kind == "DIRECTION":
            return [{"sun": "SUN", "moon": "MOON", "earth": "EARTH", "inertial": "INERTIAL"}[s.body] for s in self.guidance.slots]
        return ["ATTITUDE"] * len(self.guidance.s3_law_zones)

    def _cmd_set_gains(self, k1, kappa, eps, rate_limit_deg_s) -> None:
        from comms.telecommand import CommandValidationError

        try:
            self.guidance.set_gains(k1, kappa, "auto" if eps == 0 else eps, rate_limit_deg_s)
        except ValueError as exc:  # GainsRefused says why in its code; anything else is inadmissible gains
            raise CommandValidationError(f"SET_GAINS: {exc}", getattr(exc, "code", "GAINS_INADMISSIBLE")) from None
        self._event("GAINS_SET", k1=k1, kappa=kappa, eps=eps, rate_limit_deg_s=rate_limit_deg_s)

    # ------------------------------------------------------------------------------------ cycles
    def run_cycle(self, inputs) -> CycleRecord:
        """One tick of the executive: the GNC cycle, and the housekeeping group when it is due."""
        tick = int(inputs.tick) if hasattr(inputs, "tick") else self.cycle
        self.executive.run_tick(inputs, tick, self.period_s)
        return self.last

    def _gnc_task(self, inputs, slipped_before: bool) -> None:
        """One GNC cycle, its stages in order: read the inputs, estimate, guide, control (wheel torques and
        CYCLE_DONE out), FDIR, target reached, telemetry. The hot path: each stage is one call, or in line where
        a call would cost more than it tells (commands out, the record), and what the stages share is passed
        along, not kept on ``self``."""
        t_start = self.executive.tick_start  # the executive's clock read just before this call
        dt = self.period_s
        lockstep = type(inputs) is TickInputs  # the driver's own inputs: the array fast paths of the readers
        tick, realtime = self._start_cycle(inputs, lockstep)
        if self.dispatcher is not None:
            self.dispatcher.poll()
        if self.inject_overrun_s > 0.0:
            self._overrun()

        # ---- inputs
        imu, samples = self._read_imu(inputs, lockstep, realtime, dt)
        st = inputs.star_tracker
        st_fresh, q_NS, st_latency, nq = self._read_star_tracker(inputs, st, realtime)
        speeds, faults = self._read_wheels(inputs, lockstep, realtime, dt)

        # ---- estimation (propagate across every IMU sample of the tick)
        est = self.estimator
        innovation_deg = est._tick(dt, samples, q_NS if st_fresh else None, st_latency, nq)
        if st_fresh != self._st_was_valid:  # the star tracker was lost or is back
            self._st_events(st, st_fresh)

        # ---- guidance and control
        omega = est.omega_BN_B
        g = self.guidance.step(self.t_s, dt, est.q_NB if est.initialized else None, omega)
        ctrl = self.control.step(dt, g.omega_cmd_BN_B, omega, speeds)
        if self.door is not None:  # DOOR_CMD before the wheel commands' CYCLE_DONE
            self._door_cycle(tick, g)
        try:
            self.driver.send_wheel_torques(tick, ctrl.wheel_torque_cmd_Nm, cycle_done=not realtime)
        except Exception as exc:  # noqa: BLE001 - a transmit failure is reported, the loop goes on
            self._bus_tx_errors = getattr(self, "_bus_tx_errors", 0) + 1
            self._event("FATAL_ERROR", reason=f"bus send failed: {type(exc).__name__}: {exc}"[:110])

        # ---- FDIR, then the target
        self._fdir_cycle(dt, speeds, faults, ctrl, imu, st, st_fresh, innovation_deg, g, slipped_before)
        if not self._target_reached:
            self._watch_target(g, omega, dt)

        # ---- the cycle's record (its execution time up to here) and telemetry
        exec_ms = 1e3 * (self.clock() - t_start)
        self.last = CycleRecord(self.t_s, g.mode, est.q_NB.copy(), g.omega_cmd_BN_B, ctrl.wheel_torque_cmd_Nm,
                                g.margins_deg, g.margin_min_deg, g.pointing_error_deg, g.att_error_deg, exec_ms)
        if self.cycle % self._gnc_tm_every == 0:
            self._send_gnc_tm(g, ctrl, speeds, imu is not None, st, st_fresh, exec_ms)
        self.cycle += 1

    def _start_cycle(self, inputs, lockstep: bool) -> tuple[int, bool]:
        """(tick, real time?) of this cycle, with onboard time ``t_s`` set: a lockstep tick's own time, or in
        real time the driver clock since the first cycle."""
        if lockstep or hasattr(inputs, "tick"):
            self.t_s = float(inputs.t)
            return int(inputs.tick), False
        if self._rt_t0 is None:
            self._rt_t0 = float(inputs.t)
        self.t_s = float(inputs.t) - self._rt_t0
        return self.cycle, True

    def _overrun(self) -> None:
        """The test hook ``inject_overrun_s``: busy-wait that long once, as a cycle that runs late."""
        end = self.clock() + self.inject_overrun_s
        self.inject_overrun_s = 0.0
        while self.clock() < end:
            pass

    def _read_imu(self, inputs, lockstep: bool, realtime: bool, dt: float):
        """(newest valid gyro sample or None, the cycle's gyro rates as the estimator's (n, 3) samples). In
        real time a sample older than 2.5 cycles counts as none."""
        imu = inputs.imu
        if realtime:
            age = inputs.imu_age_s
            if imu is not None and (age is None or age > 2.5 * dt):
                imu = None
        if imu is not None and not getattr(imu, "valid", True):
            imu = None
        # lockstep as the driver delivers it: the tick's decoded gyro rows (every one valid) are the
        # estimator's (n, 3) samples as they are, without building an ImuSample per row
        samples = inputs.fresh_imu_omega_BN_B() if lockstep else None
        if samples is None:
            imu_samples = getattr(inputs, "imu_samples", None) or ()
            imu_samples = [s.omega_BN_B for s in imu_samples if getattr(s, "valid", True)] or (
                [imu.omega_BN_B] if imu is not None else None)
            samples = _NO_SAMPLES if imu_samples is None else np.array(imu_samples, dtype=float).reshape(-1, 3)
        return imu, samples

    def _read_star_tracker(self, inputs, st, realtime: bool):
        """(fresh?, q_NS, latency [s], |q_NS|) of the star tracker sample ``st``: fresh when valid, no older
        than star_tracker_max_age_s and of a norm the estimator can use (q_NS None when not valid)."""
        if st is None or not st.valid:
            return False, None, 0.0, 1.0
        if realtime:
            st_latency = float(inputs.star_tracker_age_s or 0.0)
        else:
            st_latency = max(0.0, float(inputs.t) - float(st.t))
        q_NS = np.ascontiguousarray(st.q_NS, dtype=float)
        nq = _norm(q_NS.tolist())
        return not st_latency > self._st_max_age_s and 0.9 < nq < 1.1, q_NS, st_latency, nq

    def _read_wheels(self, inputs, lockstep: bool, realtime: bool, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(speeds, fault flags) of the wheels: NaN and -1 for a wheel with no status this cycle (in real time,
        none for 3 cycles), 0 for one heard through corrupt frames (`_heard_through_corruption`)."""
        wheel_arrays = inputs.fresh_wheel_arrays() if lockstep else None
        if wheel_arrays is None:
            wheels = inputs.wheels
            if realtime:
                ages = inputs.wheel_ages_s
                wheels = [w if (w is not None and a is not None and a < 3 * dt) else None for w, a in zip(wheels, ages)]
            speeds = np.array([w.speed_rad_s if w is not None else math.nan for w in wheels], dtype=float)
            faults = np.array([w.fault if w is not None else -1 for w in wheels], dtype=np.int64)
        else:
            speeds, faults = wheel_arrays
        return speeds, self._heard_through_corruption(faults)

    def _fdir_cycle(self, dt: float, speeds, faults, ctrl, imu, st, st_fresh: bool, innovation_deg: float, g,
                    slipped_before: bool) -> None:
        """Every FDIR monitor on this cycle, then its actions. Sensor monitors are armed once the sensor has
        been heard from: a flight software started before its devices must not trip on silence."""
        imu_corrupt, st_corrupt = self._corrupt_deltas()
        self._imu_seen = self._imu_seen or imu is not None
        # a tracker that answers but is blind (Sun/Moon/rate) has been heard: its silence is then a fault
        self._st_seen = self._st_seen or st is not None
        # one compiled call: per wheel the speed residual, the fault flags and the heard-from marks, then
        # every monitor
        actions = self.fdir.evaluate_cycle(
            self.wheel_residual, dt, speeds, faults, ctrl.wheel_torque_cmd_Nm, self.control.active, self._wheel_seen,
            self._max_speed, WHEEL_FAULT_MASK, WHEEL_OVERSPEED,
            imu is None and self._imu_seen, imu_corrupt, (not st_fresh) and self._st_seen, st_corrupt, innovation_deg,
            g.margins_deg,  # every mode: SAFE keeps out too, so a violation is one in SAFE
            g.zone_bodies, slipped_before)
        for action in actions:
            self._execute(action)

    def _watch_target(self, g, omega: np.ndarray, dt: float) -> None:
        """TARGET_REACHED, once per target: held, not passed through. The error and the body rate must stay
        within tolerance for a dwell; a slew that arrives fast and overshoots resets the count."""
        err = g.pointing_error_deg if g.mode == "POINTING" else g.att_error_deg
        if g.mode != "SAFE" and err == err:
            held = err < REACHED_ERROR_DEG and math.degrees(_norm(omega.tolist())) < REACHED_RATE_DEG_S
            self._held_cycles = self._held_cycles + 1 if held else 0
            if self._held_cycles * dt >= REACHED_DWELL_S:
                self._target_reached = True
                self._event("TARGET_REACHED", error_deg=err)

    def _door_cycle(self, tick: int, g) -> None:
        """The aperture door's cycle (`fsw.door`) on the boresight's physical sky margins (the guidance's in
        POINTING and SAFE; in QUATERNION, whose margins are the attitude zones', taken from its sky zones
        here), the braking the wheels can give (none with fewer than three usable: active and not in
        WHEEL_FAULT) and KEEP_OUT_VIOLATION (last cycle's FDIR: this cycle's runs after the commands)."""
        gd = self.guidance
        known = self.estimator.initialized
        if g.zone_bodies and g.zone_bodies[0] != "ATTITUDE":
            margins, bodies = g.margins_deg, g.zone_bodies
        elif gd.slots and known:
            gd._update_sky(self.t_s)
            margins, _ = gd._sky_margins(g.boresight_N)
            bodies = gd._slot_body_codes()
        else:
            margins, bodies = [], []
        ctl = self.control
        faulty = [m.state == "TRIPPED" for m in self.fdir.wheel_fault]
        usable = sum(1 for i, active in enumerate(ctl.active.tolist()) if active and not faulty[i])
        brake_deg_s2 = math.degrees(ctl.max_accel) if usable >= 3 else 0.0
        violation = self.fdir.keepout_red.state == "TRIPPED"
        self.door.cycle(self.t_s, tick, margins, bodies, known, brake_deg_s2, violation)

    def _st_events(self, st, st_fresh: bool) -> None:
        if not st_fresh and self._st_was_valid:
            self._st_outage_start = self.t_s
            if st is not None and st.blind_source:
                self._event("ST_BLINDED", source=("NONE", "SUN", "MOON", "RATE")[min(int(st.blind_source), 3)])
        elif st_fresh and not self._st_was_valid:
            self._event("ST_RECOVERED", outage_s=self.t_s - self._st_outage_start)
        self._st_was_valid = st_fresh

    def _heard_through_corruption(self, faults: np.ndarray) -> np.ndarray:
        """Wheel fault flags with a wheel whose status frames arrived this cycle but failed E2E (CRC, length,
        range, sequence) counted as heard, not silent (no flag, its speed unknown): corrupt frames are a bus
        fault (BUS_CORRUPT), not a wheel's, and the wheel still obeys its commands. A streak of such cycles
        longer than CORRUPT_STATUS_HEARD_S is silence after all (nothing has been read from it for that long)."""
        counters = self.driver.counters
        if counters is not self._wheel_corrupt_src:
            self._wheel_corrupt_src = counters
            self._wheel_corrupt_dicts = [counters.get(m) for m in self._wheel_status_msgs]
            self._wheel_corrupt_seen = [self._status_rejections(d) for d in self._wheel_corrupt_dicts]
            pairs = [(d, k) for d in self._wheel_corrupt_dicts if d is not None for k in _CORRUPT_CLASSES]
            self._wheel_corrupt_pairs = ([d for d, _ in pairs], [k for _, k in pairs])
            self._wheel_corrupt_total = sum(self._wheel_corrupt_seen)
        # the usual cycle: no status frame rejected since the last one and no streak running (a C-level sum)
        total = sum(map(dict.get, *self._wheel_corrupt_pairs, repeat(0)))
        if total == self._wheel_corrupt_total and not self._wheel_corrupt_streak:
            return faults
        self._wheel_corrupt_total = total
        out = faults
        for i, d in enumerate(self._wheel_corrupt_dicts):
            total = self._status_rejections(d)
            rejected = total != self._wheel_corrupt_seen[i]
            self._wheel_corrupt_seen[i] = total
            if faults[i] >= 0 or not rejected:
                self._wheel_corrupt_since[i] = math.nan
                continue
            self._wheel_corrupt_streak = True
            if math.isnan(self._wheel_corrupt_since[i]):
                self._wheel_corrupt_since[i] = self.t_s
            if self.t_s - self._wheel_corrupt_since[i] <= CORRUPT_STATUS_HEARD_S:
                if out is faults:
                    out = np.array(faults, dtype=np.int64)
                out[i] = 0
        self._wheel_corrupt_streak = any(not math.isnan(t) for t in self._wheel_corrupt_since)
        return out

    @staticmethod
    def _status_rejections(counts: dict | None) -> int:
        return 0 if counts is None else sum(counts.get(k, 0) for k in _CORRUPT_CLASSES)

    def _corrupt_deltas(self) -> tuple[int, int]:
        """(IMU, star tracker) frames rejected by E2E since the last cycle."""
        counters = self.driver.counters
        if counters is not self._corrupt_src:
            # the per-message counter dicts live as long as the receiver: look them up once, as the
            # (dict, class) pairs each sensor's total sums (IMU dicts, IMU classes, tracker dicts, classes)
            self._corrupt_src = counters
            self._corrupt_dicts = tuple(
                part
                for msgs in (("IMU_RATE",), ("ST_QUAT_A", "ST_QUAT_B"))
                for part in ([counters[m] for m in msgs if m in counters for _ in _CORRUPT_CLASSES],
                             [k for m in msgs if m in counters for k in _CORRUPT_CLASSES]))
        imu_dicts, imu_keys, st_dicts, st_keys = self._corrupt_dicts
        # integer sums in C (map over dict.get): the same totals as a loop
        imu_total = sum(map(dict.get, imu_dicts, imu_keys, repeat(0)))
        st_total = sum(map(dict.get, st_dicts, st_keys, repeat(0)))
        imu_prev, st_prev = self._corrupt_totals
        self._corrupt_totals = (imu_total, st_total)
        return max(0, imu_total - imu_prev), max(0, st_total - st_prev)

    def _execute(self, action) -> None:
        a = action.action
        if a in ("isolate_wheel", "isolate_wheel_safe") and action.wheel is not None:
            if not self._isolate_wheel(action.wheel):
                a = "safe"  # the others cannot control three axes, or a wheel was already lost
        if a == "reset_estimator":
            self.estimator.reset()
            self._event("ESTIMATOR_RESET", reason=f"FDIR {action.monitor}")
        if a in ("safe", "isolate_wheel_safe") and self.guidance.mode != "SAFE":
            self.set_mode("SAFE", "FDIR")

    def _isolate_wheel(self, wheel: int) -> bool:
        """Take ``wheel`` out of the allocation and fly on with the others: the rate loop's acceleration limit
        and the guidance's slew limits shrink to what they can give (worst axis), so the braking distances
        behind the keep-out guarantee still hold. False (the caller enters SAFE) when the rest cannot
        control three axes or when this is the second wheel lost."""
        ctl = self.control
        if not ctl.active[wheel]:
            return True
        second = not ctl.active.all()
        if not ctl.isolate(wheel):
            if self.fdir.wheel_fault_reasons[wheel] == STATUS_LOST:
                # only its status is lost and the rest cannot control three axes: keep flying it, open loop
                self._event("WHEEL_RESTORED", wheel=wheel + 1, reason=f"{STATUS_LOST}; the other wheels cannot "
                            "control three axes")
                return True
            if not self._restore_silent_wheel(wheel):
                # truly lost with too few left for three axes: out of the allocation all the same, so the
                # rest give the least-squares torque (what they can of it) instead of a share sent to a dead
                # wheel; the caller enters SAFE
                ctl.restore(wheel, active=False)
                self.wheel_residual.forget()
                self._event("WHEEL_ISOLATED", wheel=wheel + 1)
                return False
            second = False  # three usable wheels again: fly on
        self.wheel_residual.forget()
        self._event("WHEEL_ISOLATED", wheel=wheel + 1)
        accel_deg_s2, rate_deg_s = ctl.slew_authority()
        ctl.max_accel = min(ctl.max_accel, math.radians(accel_deg_s2))
        rate, accel = self.guidance.reduce_slew_authority(math.degrees(ctl.max_accel), rate_deg_s)
        self._event("SLEW_LIMITS_REDUCED", rate_limit_deg_s=rate, accel_deg_s2=accel,
                    wheels=int(ctl.active.sum()))
        return not second

    def _restore_silent_wheel(self, failing: int) -> bool:
        """Graceful degradation: when isolating ``failing`` would leave fewer wheels than three-axis control
        needs, bring back a wheel that was isolated only because its status is lost (its drive still obeys
        the commands; FDIR saw no drive fault, no command timeout, no speed residual before the silence) and
        isolate ``failing`` instead. True when that leaves wheels spanning three axes."""
        ctl = self.control
        reasons = self.fdir.wheel_fault_reasons
        for spare in range(ctl.n):
            if ctl.active[spare] or spare == failing or reasons[spare] != STATUS_LOST:
                continue
            ctl.restore(spare)
            if ctl.isolate(failing):
                self._event("WHEEL_RESTORED", wheel=spare + 1, reason=f"{STATUS_LOST}; wheel {failing + 1} "
                            f"{reasons[failing] or 'failed'}")
                return True
            ctl.restore(spare, active=False)  # no better: keep the allocation as it was
        return False

    # ---------------------------------------------------------------------------------- telemetry
    def _send_gnc_tm(self, g, ctrl, speeds, imu_valid, st, st_fresh, exec_ms) -> None:
        est = self.estimator
        margins = list(g.margins_deg)[:6]
        margins += _NAN6[len(margins):]  # the packet's six slots, NaN where there is no zone
        wheel_speed = speeds.tolist() + _NAN6[self.n_wheels:]
        wheel_tau = ctrl.wheel_torque_cmd_Nm.tolist() + _ZERO6[self.n_wheels:]
        values = {
            "cycle": self.cycle,
            "mode": g.mode,
            "safe_phase": g.safe_phase,
            "q_est_NB": est.q_NB,
            "omega_est_BN_B": est.omega_BN_B,
            "omega_cmd_BN_B": g.omega_cmd_BN_B,
            "rate_norm_deg_s": math.degrees(_norm(est.omega_BN_B.tolist())),
            "bias_est_B": est.bias_B,
            "cov_trace": est._attitude_trace() if est.initialized else math.nan,
            "st_age_s": est.coasting_s,
            "boresight_N": g.boresight_N,
            "target_N": g.target_N,
            "q_target_NB": g.q_target_NB,
            "pointing_error_deg": g.pointing_error_deg,
            "att_error_deg": g.att_error_deg,
            "roll_error_deg": g.roll_error_deg,
            "active_zone": g.active_zone,
            "zone_count": g.zone_count,
            "margin_deg": margins,
            "margin_min_deg": g.margin_min_deg,
            "eps": g.eps,
            "eps_max": g.eps_max,
            "kappa": self.guidance.kappa,
            "k1": self.guidance.k1,
            "zones_merged": g.zones_merged,
            "assumptions_ok": g.assumptions_ok,
            "torque_cmd_B_Nm": ctrl.torque_cmd_B_Nm,
            "torque_scale": ctrl.torque_scale,
            "wheel_speed_rad_s": wheel_speed,
            "wheel_torque_cmd_Nm": wheel_tau,
            "sun_N": g.sun_N,
            "moon_N": g.moon_N,
            "st_valid": bool(st_fresh),
            "imu_valid": bool(imu_valid),
            "st_blind_source": ("NONE", "SUN", "MOON", "RATE")[min(int(st.blind_source), 3)] if st is not None else "NONE",
            "exec_time_ms": exec_ms,
        }
        try:
            self.telemetry.send_channels("GNC", values, time_s=self.t_s)
        except TypeError:
            self.telemetry.send_channels("GNC", values)

    def _check_worker_lost(self, reason: str, restarts: int, dropped: bool) -> None:
        if dropped:
            self._event("CHECK_WORKER_DROPPED", restarts=min(restarts - 1, 255))
        else:
            self._event("CHECK_WORKER_LOST", reason=reason, restarts=restarts, max_restarts=MAX_RESTARTS)

    def housekeeping(self) -> None:
        """Housekeeping rate group: assumption checks (throttled), heartbeat, HK telemetry."""
        gd = self.guidance
        result = self.checker.poll()
        if result is not None:
            gd.apply_check_result(result)
            self._check_budget_free_at = _budget_free_at(result.duration_s, self.cfg.law.check_max_cpu_fraction)
        if gd.mode in ("POINTING", "QUATERNION"):
            due = (self.t_s - self._last_check_t >= self.cfg.law.check_period_s
                   and (self.checker.mode != "process" or time.monotonic() >= self._check_budget_free_at))
            if (gd.checks_dirty or due) and not self.checker.busy:
                if self.checker.submit(gd.assumption_snapshot()):
                    gd.mark_checked()
                    self._last_check_t = self.t_s
                    if self.checker.mode == "inline":
                        gd.apply_check_result(self.checker.poll())
        try:
            self.driver.send_heartbeat(MODES.index(gd.mode), self.cycle)
        except Exception:  # noqa: BLE001
            self._bus_tx_errors = getattr(self, "_bus_tx_errors", 0) + 1
        self._send_hk_tm()

    def hk_values(self) -> dict:
        ex = self.executive
        counters = self.driver.counters
        if counters is not self._hk_src or len(counters) != self._hk_src_len:
            # the per-message counter dicts live as long as the receiver: list the messages' ones once
            self._hk_src, self._hk_src_len = counters, len(counters)
            self._hk_dicts = [c for name, c in counters.items() if not name.startswith("_")]
        dicts = self._hk_dicts
        # each E2E class summed over the messages in C (map over dict.get): the same integers as a loop
        n = {k: sum(map(dict.get, dicts, repeat(k), repeat(0))) for k in _HK_CLASSES}
        bus = counters.get("_bus", {})
        tm = self.telemetry.counters
        values = {
            "uptime_s": time.monotonic() - self._start_wall,
            "hk_mode": self.guidance.mode,
            "cycles": self.cycle,
            "slips_gnc": ex.gnc.slips,
            "slips_hk": ex.hk.slips,
            "exec_max_ms_gnc": ex.gnc.exec_max_ms,
            "exec_mean_ms_gnc": ex.gnc.exec_mean_ms,
            "exec_max_ms_hk": ex.hk.exec_max_ms,
            "exec_mean_ms_hk": ex.hk.exec_mean_ms,
            "jitter_max_ms": 1e3 * ex.jitter.max_s,
            "bus_rx_ok": n["ok"] + n["ok_some_lost"],
            "bus_crc_errors": n["crc_error"],
            "bus_alive_errors": n["wrong_sequence"] + n["ok_some_lost"],
            "bus_repeated": n["repeated"],
            "bus_decode_errors": n["bad_length"] + n["out_of_range"] + getattr(getattr(self.driver, "bus", None), "decode_errors", 0),
            "bus_auth_failures": getattr(getattr(self.driver, "bus", None), "auth_failures", 0),
            "bus_timeouts": n["timeout"],
            "bus_tx_errors": getattr(self, "_bus_tx_errors", 0),
            "bus_unknown_ids": bus.get("unknown_id", 0) + bus.get("error_frame", 0),
            "bus_stale_syncs": getattr(self.driver, "stale_syncs", 0),
            "bus_unexpected_frames": getattr(self.driver, "unexpected_frames", 0),
            "imu_stale_cycles": self.fdir.stale_counts["IMU"],
            "st_stale_cycles": self.fdir.stale_counts["STAR_TRACKER"],
            "tm_packets_sent": tm.get("packets_sent", 0),
            "tm_send_errors": tm.get("send_errors", 0),
            "events_sent": tm.get("events_sent", 0),
            "events_throttled": tm.get("events_throttled", 0),
            "fdir_trips": self.fdir.trips,
            "wheels_isolated": self.control.isolated_mask,
        }
        keys = _FDIR_HK_KEYS
        for mon, state in self.fdir.states().items():
            key = keys.get(mon)
            if key is None:
                key = keys[mon] = f"fdir_{mon.lower()}"
            values[key] = state
        if self.dispatcher is not None:
            values.update(self.dispatcher.hk_values())
        return values

    def _bus_fault_check(self, values: dict) -> None:
        """Count a burst of corrupt frames as a bus fault: `bus_corrupt_bursts`, and BUS_CORRUPT at most every
        BUS_EVENT_PERIOD_S of onboard time with the frames of the bursts since the last one."""
        failed = int(values["bus_crc_errors"]) + int(values["bus_decode_errors"])
        new = failed - self._bus_failed_seen if failed >= self._bus_failed_seen else failed  # (RESET_COUNTERS)
        self._bus_failed_seen = failed
        if new >= BUS_BURST_FRAMES:
            self._bus_bursts += 1
            self._bus_burst_frames += new
        if self._bus_burst_frames and self.t_s - self._bus_event_t >= BUS_EVENT_PERIOD_S:
            self._event("BUS_CORRUPT", count=self._bus_burst_frames, bursts=self._bus_bursts)
            self._bus_burst_frames, self._bus_event_t = 0, self.t_s
        values["bus_corrupt_bursts"] = self._bus_bursts

    def _send_hk_tm(self) -> None:
        values = self.hk_values()
        self._bus_fault_check(values)
        rss = _resident_bytes()
        if rss is not None:
            values["rss_mb"] = rss / 1e6
        try:
            self.telemetry.send_channels("HK", values, time_s=self.t_s)
        except TypeError:
            self.telemetry.send_channels("HK", values)

    # -------------------------------------------------------------------------------------- loops
    def run_lockstep(self, max_ticks: int | None = None, timeout_s: float | None = None,
                     first_sync_timeout_s: float | None = None) -> int:
        """Run one GNC cycle per SYNC tick until ``max_ticks`` or the simulator stops sending SYNC.

        ``first_sync_timeout_s``: before the first SYNC, keep waiting this long in all (a bench where the
        simulator is started by hand); after it, ``timeout_s`` without SYNC ends the run."""
        timeout = self.cfg.rates.lockstep_timeout_s if timeout_s is None else timeout_s
        give_up_at = time.monotonic() + (first_sync_timeout_s or 0.0)

        def still_starting() -> bool:
            return self.executive.last_tick is None and time.monotonic() < give_up_at

        prepare_cycle_thread()
        n = self.executive.run_lockstep(self.driver.collect_tick, timeout, max_ticks, on_timeout=still_starting)
        return n

    def run_realtime(self, duration_s: float | None = None) -> int:
        """Run on the monotonic clock for ``duration_s`` (None: until stop())."""
        for severity_event, reason in enter_realtime(self.cfg.rates.realtime_priority):
            self._event(severity_event, reason=reason)
        return self.executive.run_realtime(self.driver.collect_latest, duration_s)

    def stop(self) -> None:
        self.executive.stop()

    def shutdown(self) -> None:
        self._event("FSW_STOPPED", cycles=self.cycle)
        self.checker.close()
