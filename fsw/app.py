"""The flight software application: wires bus driver, estimator, guidance, control, FDIR, TM/TC.

`FlightSoftware(config, driver, telemetry, dispatcher)`:

* ``run_cycle(inputs)``: one GNC cycle (telecommands, estimate, guide, control, wheel torques and
  CYCLE_DONE on the bus, FDIR, GNC telemetry); ``inputs`` is a lockstep `TickInputs` or a real-time
  `LatestInputs`, made a `fsw.records.SensorSnapshot` by `fsw.intake` before any stage reads it;
* ``run_lockstep()`` / ``run_realtime()``: the executive's loops (see `fsw.executive`), on a thread prepared
  by `fsw.runtime`;
* the housekeeping rate group (`fsw.housekeeping`) and the telecommand handlers (`fsw.command_handlers`)
  act on it through its public parts.

The flight software learns about the world only through the bus driver and telecommands.
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from comms.bus.icd import WHEEL_FAULT_CMD_TIMEOUT, WHEEL_FAULT_DRIVE, WHEEL_FAULT_OVERSPEED
from fsw import runtime
from fsw.assumption_check import MAX_RESTARTS, AssumptionChecker
from fsw.command_handlers import CommandHandlers
from fsw.control import RateController
from fsw.detumble import Detumbler
from fsw.door import DoorController
from fsw.eclipse import EclipseMonitor
from fsw.coarse_attitude import CoarseAttitude
from fsw.estimation import AttitudeEstimator
from fsw.executive import Executive
from fsw.fdir import STATUS_LOST, Fdir, WheelSpeedResidual
from fsw.guidance import Guidance
from fsw.housekeeping import Housekeeping
from fsw.intake import SensorIntake, vector_norm
from fsw.momentum import MomentumManager
from fsw.records import AttitudeEstimate, ControlOutput, CycleRecord, GuidanceOutput, SensorSnapshot

# TARGET_REACHED: the error below REACHED_ERROR_DEG and the estimated body rate below REACHED_RATE_DEG_S for
# REACHED_DWELL_S in a row (a slew passing through its target at speed is not "reached")
REACHED_ERROR_DEG = 0.05
REACHED_RATE_DEG_S = 0.01
REACHED_DWELL_S = 5.0
_NAN6, _ZERO6 = [math.nan] * 6, [0.0] * 6  # fillers of the GNC packet's six zone and wheel slots
_BLIND_SOURCES = ("NONE", "SUN", "MOON", "RATE")  # the star tracker's blind_source codes 0-3
# RWn_STATUS fault bits (the ICD's): overspeed is a monitor's business; a command timeout or drive fault isolates
WHEEL_OVERSPEED = WHEEL_FAULT_OVERSPEED
WHEEL_FAULT_MASK = WHEEL_FAULT_CMD_TIMEOUT | WHEEL_FAULT_DRIVE


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
        self.guidance = Guidance(config, events=self.event)
        if self.plugins:
            self._install_plugins()
        self.control = RateController(config)
        self.fdir = Fdir(config, self.n_wheels, event=self.event)
        self.wheel_residual = WheelSpeedResidual(self.control.Js)
        # the protective aperture door (fsw.door), when the spacecraft has one
        self.door = DoorController(config.door, self.period_s, driver, self.event) if config.door is not None else None
        self.executive = Executive(
            config.rates.gnc_rate_hz, config.rates.housekeeping_rate_hz, config.rates.slip_event_throttle_s,
            gnc_task=self.gnc_task, hk_task=self.housekeeping, on_slip=self._on_slip, clock=clock,
        )
        self.checker = AssumptionChecker(config.law.assumption_check, on_worker_lost=self._check_worker_lost)
        # the one place the cycle's inputs, whatever their shape, become a SensorSnapshot
        self.intake = SensorIntake(driver, self.n_wheels, self.period_s, config.estimator.star_tracker_max_age_s,
                                   magnetic=config.magnetic_devices)
        # the rods' dipole command [A m^2] sent every cycle when the spacecraft has rods (zero unless a law sets it)
        self.mtq_command_Am2 = np.zeros(3)
        self._mtq = config.magnetic_devices is not None and config.magnetic_devices.magnetorquers
        # the wheels' momentum unloaded through the rods (fsw.momentum), when enabled
        self.momentum = (MomentumManager(config.momentum_management, self.control.G, self.control.Js)
                         if config.momentum_management.enabled else None)
        # B-dot detumbling (fsw.detumble), when the mission configures the DETUMBLE mode
        self.detumble = Detumbler(config.detumble, self.period_s) if config.detumble is not None else None
        # the attitude held (or found) on the Sun sensors and the magnetometer while the star tracker is lost
        # (fsw.coarse_attitude), when configured
        self.coarse = (CoarseAttitude(config.coarse_attitude, self.event, self.guidance.ephem.jd0_utc)
                       if config.coarse_attitude is not None and not self.plugins.get("estimator") else None)
        self._coarse_margin = False  # the law's zones at the coarse attitude's margin (`_coarse_cycle`)
        self._max_speed = np.ascontiguousarray(self.control.max_speed, dtype=float)  # fixed at start-up
        # configuration the cycle reads every tick, fixed at start-up (no telecommand changes it)
        self._gnc_tm_every = config.tmtc.gnc_packet_every_n_cycles
        self.bus_tx_errors = 0  # wheel commands and heartbeats the bus refused
        self._st_was_valid = True
        self._st_outage_start = 0.0
        self._target_reached = False
        self._held_cycles = 0
        # sensors heard from at least once (their FDIR monitors are armed from then on)
        self._imu_seen = False
        self._st_seen = False
        self._wheel_seen = np.zeros(self.n_wheels, dtype=np.bool_)
        self.inject_overrun_s = 0.0  # test hook: busy-wait this long in the next GNC cycle
        self.last: CycleRecord | None = None
        self.mode_reason = "INIT"
        self.eclipse = EclipseMonitor(config, self.event, self.guidance.ephem)  # updated by housekeeping
        self.hk = Housekeeping(self)
        if dispatcher is not None:
            CommandHandlers(self).register(dispatcher)
        self._warm_up()
        self.event("FSW_STARTED", gnc_rate_hz=config.rates.gnc_rate_hz)
        if self.guidance.mode == "DETUMBLE":
            self.event("DETUMBLE_STARTED", rate_deg_s=math.nan)  # no gyro sample yet
        if self.plugins:
            self._start_plugins()

    def _install_plugins(self) -> None:
        """The selected plug-ins in place of keepout's estimator and guidance law, each inside its guard."""
        from fsw.plugin_guard import GuardedEstimator, GuardedGuidance

        cfg = self.cfg
        if "estimator" in self.plugins:
            self.estimator = GuardedEstimator(cfg.estimator, np.asarray(cfg.spacecraft.star_tracker_q_BS),
                                              self.plugins["estimator"], self.event)
        if "guidance" in self.plugins:
            self.guidance = GuardedGuidance(cfg, self.plugins["guidance"], lambda: self.set_mode("SAFE", "FDIR"),
                                            events=self.event)

    def _start_plugins(self) -> None:
        if "guidance" in self.plugins:
            self.guidance.arm()  # after the warm-up: the plug-in sees flight states only
        for kind, plugin in self.plugins.items():
            self.event("PLUGIN_STARTED", kind=kind.upper(), name=plugin.name[:40])

    def _warm_up(self) -> None:
        """Load the compiled kernels, freeze the heap and start the check worker now, so the first cycle is
        not late.

        Runs the estimator's cycle as the GNC cycle calls it (`AttitudeEstimator.update`) on a scratch
        instance (initialisation, a fused fix, a cycle without gyro samples) and every guidance mode once on
        the real zones (events muted), then restores the initial mode.
        """
        q = np.array([1.0, 0.0, 0.0, 0.0])
        scratch = AttitudeEstimator(self.cfg.estimator, np.asarray(self.cfg.spacecraft.star_tracker_q_BS))
        for gyro_B, q_NS in ((np.zeros((1, 3)), q), (np.zeros((2, 3)), np.array([0.99, 0.1, 0.0, 0.0])),
                             (np.zeros((0, 3)), None)):
            nq = vector_norm(q_NS.tolist()) if q_NS is not None else 1.0
            scratch.update(SensorSnapshot.of_measurements(self.period_s, gyro_B, q_NS, 0.0, nq))
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
        runtime.prepare_cycle_thread()
        self.checker.start()

    # ------------------------------------------------------------------------------------ events
    def event(self, name: str, /, **args) -> None:
        """Raise event ``name`` with ``args`` at onboard time."""
        try:
            self.telemetry.event(name, time_s=self.t_s, **args)
        except TypeError:
            self.telemetry.event(name, **args)

    def _on_slip(self, group: str, exec_ms: float, total: int, late_ms: float = 0.0) -> None:
        self.event("CYCLE_SLIP", rate_group=group, exec_time_ms=exec_ms, count=total, late_ms=late_ms)

    @property
    def mode(self) -> str:
        return self.guidance.mode

    def set_mode(self, mode: str, cause: str = "TELECOMMAND") -> None:
        old = self.guidance.mode
        if mode == "DETUMBLE" and self.detumble is None:
            raise ValueError("DETUMBLE is not configured (flight_software.detumble)")
        self.guidance.set_mode(mode)
        if mode == "DETUMBLE":
            self.detumble.reset()
            w = getattr(self.estimator, "omega_BN_B", None) if self.last is not None else None
            self.event("DETUMBLE_STARTED", rate_deg_s=math.degrees(vector_norm(np.asarray(w).tolist()))
                       if w is not None else math.nan)
        elif old == "DETUMBLE":
            self.mtq_command_Am2 = np.zeros(3)  # B-dot's last dipole must not outlive the mode
        self.mode_reason = cause
        self.restart_target_watch()
        if old != mode or mode == "SAFE":
            self.event("MODE_CHANGED", from_mode=old, to_mode=mode, cause=cause)

    def restart_target_watch(self) -> None:
        """A new mode or target: TARGET_REACHED is owed again, after a full dwell on it."""
        self._target_reached = False
        self._held_cycles = 0

    # ------------------------------------------------------------------------------------ cycles
    def run_cycle(self, inputs: Any) -> CycleRecord:
        """One tick of the executive: the GNC cycle, and the housekeeping group when it is due. ``inputs``:
        anything `fsw.intake.SensorIntake` reads (the driver's lockstep or real-time inputs)."""
        self.executive.run_tick(inputs, self.intake.tick_of(inputs, self.cycle), self.period_s)
        return self.last

    def gnc_task(self, inputs: Any, slipped_before: bool) -> None:
        """One GNC cycle. The inputs become this cycle's `SensorSnapshot` (`fsw.intake`), telecommands are
        handled, then each stage reads the record before it and writes its own: estimator
        (`AttitudeEstimate`), guidance (`GuidanceOutput`), control (`ControlOutput`; wheel torques and
        CYCLE_DONE out), FDIR; then the target watch, the cycle's record and telemetry. The hot path: each
        stage is one call, or in line where a call would cost more than it tells (commands out, the record)."""
        t_start = self.executive.tick_start  # the executive's clock read just before this call
        s = self.intake.snapshot(inputs, self.cycle)
        self.t_s = s.t_s
        if self.dispatcher is not None:
            self.dispatcher.poll()
        if self.inject_overrun_s > 0.0:
            self._overrun()

        est = self.estimator.update(s)
        if self.coarse is not None:
            est = self._coarse_cycle(s, est)
        if s.st_fresh != self._st_was_valid:  # the star tracker was lost or is back
            self._st_events(s)
        g = self.guidance.step(s.t_s, s.dt_s, est.q_NB if est.initialized else None, est.omega_BN_B)
        detumbling = g.mode == "DETUMBLE"
        if detumbling:  # B-dot on the rods, the wheels at zero torque
            ctrl = self.control.hold(s.wheel_speed_rad_s)
            self.mtq_command_Am2 = self.detumble.step(s.mag_S_T, est.omega_BN_B, s.dt_s)
        else:
            ctrl = self.control.step(s.dt_s, g.omega_cmd_BN_B, est.omega_BN_B, s.wheel_speed_rad_s)
        if self.door is not None:  # DOOR_CMD before the wheel commands' CYCLE_DONE
            self._door_cycle(s.tick, est, g)
        if self.momentum is not None and not detumbling:
            self.mtq_command_Am2 = self.momentum.step(s.mag_S_T, self.control.wheel_speed)
        if self._mtq:  # MTQ_COMMAND, as DOOR_CMD, in the wheel commands' burst before CYCLE_DONE
            d1, d2, d3 = self.mtq_command_Am2.tolist()
            self.driver.send_frame("MTQ_COMMAND", {"dipole_1": d1, "dipole_2": d2, "dipole_3": d3},
                                   with_commands=True)
        try:
            self.driver.send_wheel_torques(s.tick, ctrl.wheel_torque_cmd_Nm, cycle_done=not s.realtime)
        except Exception as exc:  # noqa: BLE001 - a transmit failure is reported, the loop goes on
            self.bus_tx_errors += 1
            self.event("FATAL_ERROR", reason=f"bus send failed: {type(exc).__name__}: {exc}"[:110])

        self._fdir_cycle(s, est, g, ctrl, slipped_before)
        if detumbling and self.detumble.complete and self.guidance.mode == "DETUMBLE":
            self._detumble_complete(est.omega_BN_B)
        if not self._target_reached:
            self._watch_target(g, est.omega_BN_B, s.dt_s)

        # the cycle's record (its execution time up to here) and telemetry; the estimator's state as FDIR
        # left it (a reset_estimator action forgets the attitude)
        exec_ms = 1e3 * (self.clock() - t_start)
        self.last = CycleRecord(s.t_s, g.mode, self.estimator.q_NB.copy(), g.omega_cmd_BN_B, ctrl.wheel_torque_cmd_Nm,
                                g.margins_deg, g.margin_min_deg, g.pointing_error_deg, g.att_error_deg, exec_ms)
        if self.cycle % self._gnc_tm_every == 0:
            self._send_gnc_tm(s, g, ctrl, exec_ms)
        self.cycle += 1

    def _coarse_cycle(self, s: Any, est: AttitudeEstimate) -> AttitudeEstimate:
        """The coarse attitude's cycle (`fsw.coarse_attitude`): the estimate it changed, and the law's zones
        grown to its margin while it flies (back to law.margin_deg when the star tracker returns)."""
        changed = self.coarse.cycle(self.estimator, s.css_mA, s.mag_S_T, not self.mtq_command_Am2.any(), s.t_s,
                                    self.guidance.ephem)
        if self.coarse.active != self._coarse_margin:
            self._coarse_margin = self.coarse.active
            self.guidance.use_coarse_margin(self._coarse_margin)
        if not changed:
            return est
        return AttitudeEstimate(self.estimator.q_NB, est.omega_BN_B, self.estimator.initialized, est.innovation_deg)

    def _detumble_complete(self, omega_BN_B: np.ndarray) -> None:
        """The rate has stayed below the threshold for the dwell: DETUMBLE_COMPLETE, then SAFE (rate damping
        on the wheels, then Sun acquisition); the next cycle's rods get zero (or momentum management's)."""
        self.event("DETUMBLE_COMPLETE", t_s=self.t_s, rate_deg_s=math.degrees(vector_norm(omega_BN_B.tolist())))
        self.set_mode("SAFE", "AUTONOMOUS")

    def _overrun(self) -> None:
        """The test hook ``inject_overrun_s``: busy-wait that long once, as a cycle that runs late."""
        end = self.clock() + self.inject_overrun_s
        self.inject_overrun_s = 0.0
        while self.clock() < end:
            pass

    def _fdir_cycle(self, s: SensorSnapshot, est: AttitudeEstimate, g: GuidanceOutput, ctrl: ControlOutput,
                    slipped_before: bool) -> None:
        """Every FDIR monitor on this cycle, then its actions. Sensor monitors are armed once the sensor has
        been heard from: a flight software started before its devices must not trip on silence."""
        self._imu_seen = self._imu_seen or s.imu_valid
        # a tracker that answers but is blind (Sun/Moon/rate) has been heard: its silence is then a fault
        self._st_seen = self._st_seen or s.st_heard
        # one compiled call: per wheel the speed residual, the fault flags and the heard-from marks, then
        # every monitor
        actions = self.fdir.evaluate_cycle(
            self.wheel_residual, s.dt_s, s.wheel_speed_rad_s, s.wheel_fault, ctrl.wheel_torque_cmd_Nm,
            self.control.active, self._wheel_seen, self._max_speed, WHEEL_FAULT_MASK, WHEEL_OVERSPEED,
            not s.imu_valid and self._imu_seen, s.imu_corrupt, (not s.st_fresh) and self._st_seen, s.st_corrupt,
            est.innovation_deg,
            g.margins_deg,  # every mode: SAFE keeps out too, so a violation is one in SAFE
            g.zone_bodies, slipped_before)
        for action in actions:
            self._execute(action)

    def _watch_target(self, g: GuidanceOutput, omega: np.ndarray, dt: float) -> None:
        """TARGET_REACHED, once per target: held, not passed through. The error and the body rate must stay
        within tolerance for a dwell; a slew that arrives fast and overshoots resets the count."""
        err = g.pointing_error_deg if g.mode == "POINTING" else g.att_error_deg
        if g.mode != "SAFE" and err == err:
            held = err < REACHED_ERROR_DEG and math.degrees(vector_norm(omega.tolist())) < REACHED_RATE_DEG_S
            self._held_cycles = self._held_cycles + 1 if held else 0
            if self._held_cycles * dt >= REACHED_DWELL_S:
                self._target_reached = True
                self.event("TARGET_REACHED", error_deg=err)

    def _door_cycle(self, tick: int, est: AttitudeEstimate, g: GuidanceOutput) -> None:
        """The aperture door's cycle (`fsw.door`) on the boresight's physical sky margins (the guidance's in
        POINTING and SAFE; in QUATERNION, whose margins are the attitude zones', taken from its sky zones
        here), the braking the wheels can give (none with fewer than three usable: active and not in
        WHEEL_FAULT) and KEEP_OUT_VIOLATION (last cycle's FDIR: this cycle's runs after the commands)."""
        gd = self.guidance
        known = est.initialized
        if g.zone_bodies and g.zone_bodies[0] != "ATTITUDE":
            margins, bodies = g.margins_deg, g.zone_bodies
        elif gd.slots and known:
            margins, bodies = gd.sky_margins_at(self.t_s, g.boresight_N)
        else:
            margins, bodies = [], []
        ctl = self.control
        faulty = [m.state == "TRIPPED" for m in self.fdir.wheel_fault]
        usable = sum(1 for i, active in enumerate(ctl.active.tolist()) if active and not faulty[i])
        brake_deg_s2 = math.degrees(ctl.max_accel) if usable >= 3 else 0.0
        violation = self.fdir.keepout_red.state == "TRIPPED"
        hold = "DETUMBLE" if g.mode == "DETUMBLE" else None  # a tumbling body cannot steer clear: shut throughout
        self.door.cycle(self.t_s, tick, margins, bodies, known, brake_deg_s2, violation, hold=hold)

    def _st_events(self, s: SensorSnapshot) -> None:
        if not s.st_fresh and self._st_was_valid:
            self._st_outage_start = self.t_s
            if s.st_blind_source:
                self.event("ST_BLINDED", source=_BLIND_SOURCES[min(int(s.st_blind_source), 3)])
        elif s.st_fresh and not self._st_was_valid:
            self.event("ST_RECOVERED", outage_s=self.t_s - self._st_outage_start)
        self._st_was_valid = s.st_fresh

    def _execute(self, action) -> None:
        a = action.action
        if a in ("isolate_wheel", "isolate_wheel_safe") and action.wheel is not None:
            if not self._isolate_wheel(action.wheel):
                a = "safe"  # the others cannot control three axes, or a wheel was already lost
        if a == "reset_estimator":
            self.estimator.reset()
            self.event("ESTIMATOR_RESET", reason=f"FDIR {action.monitor}")
        if a in ("safe", "isolate_wheel_safe") and self.guidance.mode == "DETUMBLE":
            # DETUMBLE ends in SAFE by itself; SAFE now would ask the wheels to stop a tumble they cannot hold
            # (the star tracker is blind and the gyro's monitors may trip at separation rates)
            self.event("FDIR_SAFE_DEFERRED", monitor=action.monitor)
        elif a in ("safe", "isolate_wheel_safe") and self.guidance.mode != "SAFE":
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
                self.event("WHEEL_RESTORED", wheel=wheel + 1, reason=f"{STATUS_LOST}; the other wheels cannot "
                            "control three axes")
                return True
            if not self._restore_silent_wheel(wheel):
                # truly lost with too few left for three axes: out of the allocation all the same, so the
                # rest give the least-squares torque (what they can of it) instead of a share sent to a dead
                # wheel; the caller enters SAFE
                ctl.restore(wheel, active=False)
                self.wheel_residual.forget()
                self.event("WHEEL_ISOLATED", wheel=wheel + 1)
                return False
            second = False  # three usable wheels again: fly on
        self.wheel_residual.forget()
        self.event("WHEEL_ISOLATED", wheel=wheel + 1)
        accel_deg_s2, rate_deg_s = ctl.slew_authority()
        ctl.max_accel = min(ctl.max_accel, math.radians(accel_deg_s2))
        rate, accel = self.guidance.reduce_slew_authority(math.degrees(ctl.max_accel), rate_deg_s)
        self.event("SLEW_LIMITS_REDUCED", rate_limit_deg_s=rate, accel_deg_s2=accel,
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
                self.event("WHEEL_RESTORED", wheel=spare + 1, reason=f"{STATUS_LOST}; wheel {failing + 1} "
                            f"{reasons[failing] or 'failed'}")
                return True
            ctl.restore(spare, active=False)  # no better: keep the allocation as it was
        return False

    # ---------------------------------------------------------------------------------- telemetry
    def _send_gnc_tm(self, s: SensorSnapshot, g: GuidanceOutput, ctrl: ControlOutput, exec_ms: float) -> None:
        est = self.estimator
        margins = list(g.margins_deg)[:6]
        margins += _NAN6[len(margins):]  # the packet's six slots, NaN where there is no zone
        wheel_speed = s.wheel_speed_rad_s.tolist() + _NAN6[self.n_wheels:]
        wheel_tau = ctrl.wheel_torque_cmd_Nm.tolist() + _ZERO6[self.n_wheels:]
        values = {
            "cycle": self.cycle,
            "mode": g.mode,
            "safe_phase": g.safe_phase,
            "q_est_NB": est.q_NB,
            "omega_est_BN_B": est.omega_BN_B,
            "omega_cmd_BN_B": g.omega_cmd_BN_B,
            "rate_norm_deg_s": math.degrees(vector_norm(est.omega_BN_B.tolist())),
            "bias_est_B": est.bias_B,
            "cov_trace": est.cov_trace_rad2,
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
            "st_valid": s.st_fresh,
            "imu_valid": s.imu_valid,
            "st_blind_source": _BLIND_SOURCES[min(int(s.st_blind_source), 3)],
            "exec_time_ms": exec_ms,
        }
        try:
            self.telemetry.send_channels("GNC", values, time_s=self.t_s)
        except TypeError:
            self.telemetry.send_channels("GNC", values)

    def _check_worker_lost(self, reason: str, restarts: int, dropped: bool) -> None:
        if dropped:
            self.event("CHECK_WORKER_DROPPED", restarts=min(restarts - 1, 255))
        else:
            self.event("CHECK_WORKER_LOST", reason=reason, restarts=restarts, max_restarts=MAX_RESTARTS)

    def housekeeping(self) -> None:
        """The housekeeping rate group (`fsw.housekeeping`): assumption checks, heartbeat, HK telemetry."""
        self.hk.run()

    def hk_values(self) -> dict:
        """The HK packet's channels now (`fsw.housekeeping.Housekeeping.values`)."""
        return self.hk.values()

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

        runtime.prepare_cycle_thread()
        n = self.executive.run_lockstep(self.driver.collect_tick, timeout, max_ticks, on_timeout=still_starting)
        return n

    def run_realtime(self, duration_s: float | None = None) -> int:
        """Run on the monotonic clock for ``duration_s`` (None: until stop())."""
        for severity_event, reason in runtime.enter_realtime(self.cfg.rates.realtime_priority):
            self.event(severity_event, reason=reason)
        return self.executive.run_realtime(self.driver.collect_latest, duration_s)

    def stop(self) -> None:
        self.executive.stop()

    def shutdown(self) -> None:
        self.event("FSW_STOPPED", cycles=self.cycle)
        self.checker.close()
