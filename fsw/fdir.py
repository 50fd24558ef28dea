"""Fault detection, isolation and recovery: limit checks with persistence.

Every monitor follows the classic limit-check pattern: a monitored value, a limit, a persistence count
(consecutive GNC cycles beyond the limit), an event when it trips and an action, taken once per trip.
A monitor clears (event FDIR_CLEARED) when its value is back within the limit; it can then trip again.

Monitors (dictionary names) and their configuration keys (`fsw.config.FdirConfig`):

==================  ======================  =================================================
IMU_STALE           imu_stale               1 when no valid IMU sample arrived this cycle
IMU_CORRUPT         imu_corrupt             IMU frames rejected by E2E this cycle (count)
ST_STALE            star_tracker_stale      1 when no valid fresh star-tracker sample this cycle
ST_CORRUPT          star_tracker_corrupt    star-tracker frames rejected by E2E this cycle
INNOVATION          innovation              star-tracker innovation [deg]
WHEEL_FAULT         wheel_fault             per wheel: 1 when fault flags set, status missing, or the
                                            measured speed disagrees with the commanded torque
                                            (`WheelSpeedResidual`)
WHEEL_SPEED         wheel_speed             per wheel: |speed| / max_speed
KEEP_OUT_MARGIN     keepout_yellow/_red     smallest signed physical margin [deg] (below limit)
CYCLE_SLIP          cycle_slip              1 when the GNC cycle slipped
==================  ======================  =================================================

Actions are returned to the application (`FlightSoftware`), which executes them: ``safe`` (enter SAFE),
``reset_estimator``, ``isolate_wheel`` (remove it from allocation and fly on with the others, within
slew limits recomputed for them; SAFE only when they cannot control three axes or a wheel was already
lost), ``isolate_wheel_safe`` (isolate and enter SAFE).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

_ACTION_CODES = {
    "none": "EVENT_ONLY",
    "safe": "ENTER_SAFE",
    "reset_estimator": "RESET_ESTIMATOR",
    "isolate_wheel": "ISOLATE_WHEEL",
    "isolate_wheel_safe": "ISOLATE_WHEEL",
}


SATURATED_FRACTION = 0.98  # |speed| / max_speed from which a wheel counts as at its limit (not a failure)


@dataclass
class FdirAction:
    action: str  # safe | reset_estimator | isolate_wheel | isolate_wheel_safe
    monitor: str
    wheel: int | None = None


# monitor states as the compiled pass keeps them (index = code)
_STATES = ("DISABLED", "NOMINAL", "PERSISTING", "TRIPPED")
_DISABLED, _NOMINAL, _PERSISTING, _TRIPPED = 0, 1, 2, 3
# `_monitor_pass` results per monitor
_NO_CHANGE, _TRIPPED_NOW, _CLEARED_NOW = 0, 1, 2


# rows of MonitorBank.f (floats) and MonitorBank.i (integers): two arrays cross into the compiled pass,
# not nine
_F_LIMIT, _F_LAST, _F_VALUE = 0, 1, 2
_I_PERSIST, _I_BELOW, _I_STATE, _I_COUNT, _I_TRIPS, _I_RESULT = 0, 1, 2, 3, 4, 5


class MonitorBank:
    """The state of a set of limit monitors as arrays, so that one compiled call (`_monitor_pass`) runs
    them all each cycle; each `LimitMonitor` is a view of one index. ``f`` (3, n): limit, last value,
    this cycle's value (NaN: not evaluated); ``i`` (6, n): persistence, below (1: trips below the limit),
    state code, count, trips, this cycle's result (0 no change, 1 tripped, 2 cleared)."""

    def __init__(self, rules, below) -> None:
        n = len(rules)
        self.f = np.full((3, n), np.nan)
        self.f[_F_LIMIT] = [float(r.limit) for r in rules]
        self.i = np.zeros((6, n), dtype=np.int64)
        self.i[_I_PERSIST] = [int(r.persistence_cycles) for r in rules]
        self.i[_I_BELOW] = [1 if b else 0 for b in below]
        self.i[_I_STATE] = [_NOMINAL if r.enabled else _DISABLED for r in rules]
        # row views, for reading (and LimitMonitor's Python update)
        self.limit, self.last_value, self.values = self.f[_F_LIMIT], self.f[_F_LAST], self.f[_F_VALUE]
        self.persistence, self.state, self.count, self.trips, self.result = (
            self.i[_I_PERSIST], self.i[_I_STATE], self.i[_I_COUNT], self.i[_I_TRIPS], self.i[_I_RESULT])

    def run(self, values: np.ndarray) -> np.ndarray:
        """One cycle's values (NaN: not evaluated this cycle); returns the result per monitor
        (0 no change, 1 tripped, 2 cleared), an array reused every cycle."""
        self.values[:] = values
        _monitor_pass(self.f, self.i)
        return self.result


@njit("void(f8[:, ::1], i8[:, ::1])", cache=True)
def _monitor_pass(f, ints):
    """`LimitMonitor.update` for every monitor of a bank (`MonitorBank`'s ``f`` and ``i``) on the values
    in ``f[_F_VALUE]``, in one call: the same comparisons and transitions. A NaN value is 'not evaluated
    this cycle' (no monitor is fed a NaN value otherwise)."""
    limit, last_value, values = f[_F_LIMIT], f[_F_LAST], f[_F_VALUE]
    persistence, below, state, count, trips, result = (ints[_I_PERSIST], ints[_I_BELOW], ints[_I_STATE],
                                                       ints[_I_COUNT], ints[_I_TRIPS], ints[_I_RESULT])
    for i in range(values.shape[0]):
        result[i] = _NO_CHANGE
        value = values[i]
        if state[i] == _DISABLED or value != value:
            continue
        last_value[i] = value
        if (value < limit[i]) if below[i] != 0 else (value > limit[i]):
            count[i] += 1
            if state[i] == _TRIPPED:
                continue
            if count[i] >= persistence[i]:
                state[i] = _TRIPPED
                trips[i] += 1
                result[i] = _TRIPPED_NOW
                continue
            state[i] = _PERSISTING
            continue
        was = state[i]
        count[i] = 0
        state[i] = _NOMINAL
        if was == _TRIPPED:
            result[i] = _CLEARED_NOW


class LimitMonitor:
    """One limit check. ``below=True`` trips when the value is *below* the limit (margins).

    Its count, state, trips and last value live at index ``index`` of ``bank`` (a `MonitorBank`; one of
    its own when none is given), where `Fdir` runs all monitors in one compiled pass."""

    def __init__(self, monitor: str, rule, below: bool = False, bank: MonitorBank | None = None, index: int = 0):
        self.monitor = monitor
        self.rule = rule
        self.below = below
        self._bank = bank if bank is not None else MonitorBank([rule], [below])
        self._i = index

    @property
    def count(self) -> int:
        return int(self._bank.count[self._i])

    @count.setter
    def count(self, value: int) -> None:
        self._bank.count[self._i] = value

    @property
    def state(self) -> str:
        return _STATES[self._bank.state[self._i]]

    @state.setter
    def state(self, value: str) -> None:
        self._bank.state[self._i] = _STATES.index(value)

    @property
    def trips(self) -> int:
        return int(self._bank.trips[self._i])

    @trips.setter
    def trips(self, value: int) -> None:
        self._bank.trips[self._i] = value

    @property
    def last_value(self) -> float:
        return float(self._bank.last_value[self._i])

    def beyond(self, value: float) -> bool:
        return value < self.rule.limit if self.below else value > self.rule.limit

    def update(self, value: float | None) -> str | None:
        """Feed one cycle's value (None: not evaluated this cycle). Returns 'tripped', 'cleared' or None."""
        if self.state == "DISABLED" or value is None:
            return None
        b, i = self._bank, self._i
        b.last_value[i] = float(value)
        if self.beyond(value):
            b.count[i] += 1
            if b.state[i] == _TRIPPED:
                return None
            if b.count[i] >= self.rule.persistence_cycles:
                b.state[i] = _TRIPPED
                b.trips[i] += 1
                return "tripped"
            b.state[i] = _PERSISTING
            return None
        was = b.state[i]
        b.count[i] = 0
        b.state[i] = _NOMINAL
        return "cleared" if was == _TRIPPED else None

    def reset(self) -> None:
        self.count = 0
        if self.state != "DISABLED":
            self.state = "NOMINAL"


class WheelSpeedResidual:
    """Commanded-versus-measured wheel speed: a wheel whose speed does not follow its torque commands.

    Over the last ``window`` cycles the speed change the commands predict, ``sum(tau_cmd dt) / Js`` (the
    command of cycle k acts until the speed read at k + 1), is compared with the change measured. A dead
    motor (no torque) leaves the speed to friction, a seized bearing drops it to zero, a driver that
    ignores its commands keeps it: each leaves a residual that friction (~0.2 rad/s per second here) and
    the speed quantisation (0.04 rad/s) do not reach. Flags what a wheel's own status does not report.
    """

    def __init__(self, spin_inertia_kgm2: np.ndarray, window: int = 10, abs_limit_rad_s: float = 2.0,
                 rel_limit: float = 0.5):
        self.Js = np.ascontiguousarray(spin_inertia_kgm2, dtype=float)
        self.window = window
        self.abs_limit = float(abs_limit_rad_s)
        self.rel_limit = float(rel_limit)
        n = len(self.Js)
        # the window as a ring of rows (measured change, predicted change); state[0] the next row to
        # write, state[1] the rows held
        self._measured = np.zeros((window, n))
        self._predicted = np.zeros((window, n))
        self._state = np.zeros(2, dtype=np.int64)
        self._prev_speed = np.zeros(n)
        self._prev_cmd = np.zeros(n)
        self._started = False

    def update(self, dt_s: float, speed_rad_s: np.ndarray, torque_cmd_Nm: np.ndarray) -> np.ndarray:
        """Feed this cycle's measured speeds (NaN: no status) and the torques just commanded; returns the
        wheels whose residual over the window is beyond limit (bool per wheel)."""
        speed = np.ascontiguousarray(speed_rad_s, dtype=float)
        cmd = np.ascontiguousarray(torque_cmd_Nm, dtype=float)
        off = _residual_step(float(dt_s), speed, cmd, self._started, self._prev_speed, self._prev_cmd, self.Js,
                             self._measured, self._predicted, self._state, self.abs_limit, self.rel_limit)
        self._started = True
        return off

    def monitor_values(self, dt_s: float, speed_rad_s: np.ndarray, fault_flags: np.ndarray, torque_cmd_Nm: np.ndarray,
                       active: np.ndarray, seen: np.ndarray, max_speed_rad_s: np.ndarray, fault_mask: int,
                       overspeed_bit: int) -> tuple[np.ndarray, np.ndarray]:
        """`update` and, in the same compiled call, the per-wheel values of FDIR's WHEEL_FAULT and
        WHEEL_SPEED monitors: (fault (bool), |speed| / max_speed (NaN: not evaluated)).

        ``speed_rad_s``: this cycle's measured speeds, NaN where no status arrived; ``fault_flags``: the
        status's fault bits, -1 where no status arrived; ``active``: the wheels in the allocation (an
        isolated wheel's residual is not its fault any more); ``seen``: the wheels heard from at least once,
        updated here (a wheel never heard from is not faulty for its silence). A wheel is faulty when its
        flags have a bit of ``fault_mask``, when it was heard from before and is silent now, or when its
        residual is beyond limit (and it is active); its speed ratio is at least 1 when it reports
        ``overspeed_bit``."""
        fault, ratio = _wheel_monitor_values(
            float(dt_s), speed_rad_s, fault_flags, torque_cmd_Nm, active, seen, max_speed_rad_s, self._started,
            self._prev_speed, self._prev_cmd, self.Js, self._measured, self._predicted, self._state,
            self.abs_limit, self.rel_limit, int(fault_mask), int(overspeed_bit))
        self._started = True
        return fault, ratio

    def forget(self) -> None:
        """Start the window again (after an isolation the other wheels' commands change abruptly)."""
        self._state[:] = 0


@njit(cache=True)
def _residual_step(dt_s, speed, cmd, started, prev_speed, prev_cmd, Js, measured, predicted, state, abs_limit,
                   rel_limit):
    """`WheelSpeedResidual.update` in one compiled call: append this cycle's row to the ring, keep the
    speeds and commands for the next, and compare the window's sums (oldest row first, as numpy summed
    the rows of the window it kept) with the limits."""
    window, n = measured.shape
    if started:
        k = state[0]
        for j in range(n):
            measured[k, j] = speed[j] - prev_speed[j]
            predicted[k, j] = prev_cmd[j] * dt_s / Js[j]
        state[0] = (k + 1) % window
        state[1] = min(state[1] + 1, window)
    for j in range(n):
        prev_speed[j] = speed[j]
        prev_cmd[j] = cmd[j]
    off = np.zeros(n, dtype=np.bool_)
    if state[1] < window:
        return off
    first = state[0]  # the oldest row: the ring is full
    for j in range(n):
        m = measured[first, j]
        p = predicted[first, j]
        for r in range(1, window):
            k = (first + r) % window
            m += measured[k, j]
            p += predicted[k, j]
        # NaN (a missing status) compares False: the missing status is its own fault
        off[j] = abs(m - p) > abs_limit + rel_limit * abs(p)
    return off


@njit("Tuple((b1[::1], f8[::1]))(f8, f8[::1], i8[::1], f8[::1], b1[::1], b1[::1], f8[::1], b1, f8[::1], f8[::1],"
      " f8[::1], f8[:, ::1], f8[:, ::1], i8[::1], f8, f8, i8, i8)", cache=True)
def _wheel_monitor_values(dt_s, speed, fault_flags, cmd, active, seen, max_speed, started, prev_speed, prev_cmd, Js,
                          measured, predicted, state, abs_limit, rel_limit, fault_mask, overspeed_bit):
    """`WheelSpeedResidual.monitor_values` in one compiled call: the residual step, then per wheel the
    expressions the application's per-wheel Python loop had (tests/fsw/test_fdir_kernels.py)."""
    off = _residual_step(dt_s, speed, cmd, started, prev_speed, prev_cmd, Js, measured, predicted, state, abs_limit,
                         rel_limit)
    n = speed.shape[0]
    fault = np.zeros(n, dtype=np.bool_)
    ratio = np.empty(n)
    for i in range(n):
        s = speed[i]
        # A wheel at its speed limit cannot follow a torque that pushes it further: its speed is held there,
        # as the model says it is. That is saturation (WHEEL_SPEED), not a failure to isolate. A torque back
        # from the limit must still be followed.
        at_limit = fault_flags[i] >= 0 and ((fault_flags[i] & overspeed_bit) != 0
                                            or (math.isfinite(s) and abs(s) >= SATURATED_FRACTION * max_speed[i]))
        residual_off = off[i] and active[i] and not (at_limit and cmd[i] * s > 0.0)
        if fault_flags[i] < 0:  # no status this cycle (speed NaN): its silence is a fault once heard from
            fault[i] = seen[i] or residual_off
            ratio[i] = np.nan
            continue
        seen[i] = True
        f = fault_flags[i]
        fault[i] = (f & fault_mask) != 0 or residual_off
        if math.isfinite(s):
            r = abs(s) / max_speed[i]
            o = 1.0 if (f & overspeed_bit) != 0 else 0.0
            ratio[i] = o if o > r else r  # max(r, o): the first unless the second is larger
        else:
            ratio[i] = np.nan
    return fault, ratio


# the wheel status's fault bits (config/icd/keepout.dbc, RWn_STATUS.fault)
_WHEEL_BITS = ((0x04, "drive fault reported by the wheel"),
               (0x02, "command timeout: the wheel's torque commands stopped arriving"))
STATUS_LOST = "status lost"  # a wheel isolated for this alone may still obey its commands


def wheel_fault_cause(flags: int) -> str:
    """A WHEEL_FAULT's cause in words, from the wheel's status flags this cycle (-1: no status came)."""
    if flags < 0:
        return f"{STATUS_LOST}: no speed report from the wheel"
    for bit, words in _WHEEL_BITS:
        if flags & bit:
            return words
    return "speed does not follow the commanded torque"


class Fdir:
    """All monitors; `evaluate_cycle` (or `evaluate_arrays`) once per GNC cycle returns the actions to take.

    The monitors' states are arrays of one `MonitorBank`, in the order they are evaluated: IMU_STALE,
    ST_STALE, IMU_CORRUPT, ST_CORRUPT, INNOVATION, WHEEL_FAULT per wheel, WHEEL_SPEED per wheel,
    KEEP_OUT_MARGIN yellow and red, CYCLE_SLIP. One compiled call (`_fdir_pass`) feeds them all; the events
    and actions are then issued in Python, in that order, and only in a cycle where one is due.
    """

    def __init__(self, cfg, n_wheels: int, event: Callable[..., object] | None = None):
        f = cfg.fdir
        self.event = event or (lambda name, **args: None)
        self.n_wheels = n_wheels
        rules = ([f.imu_stale, f.star_tracker_stale, f.imu_corrupt, f.star_tracker_corrupt, f.innovation]
                 + [f.wheel_fault] * n_wheels + [f.wheel_speed] * n_wheels
                 + [f.keepout_yellow, f.keepout_red, f.cycle_slip])
        below = [False] * (5 + 2 * n_wheels) + [True, True, False]
        self._bank = bank = MonitorBank(rules, below)
        self.imu_stale = LimitMonitor("IMU_STALE", f.imu_stale, bank=bank, index=0)
        self.st_stale = LimitMonitor("ST_STALE", f.star_tracker_stale, bank=bank, index=1)
        self.imu_corrupt = LimitMonitor("IMU_CORRUPT", f.imu_corrupt, bank=bank, index=2)
        self.st_corrupt = LimitMonitor("ST_CORRUPT", f.star_tracker_corrupt, bank=bank, index=3)
        self.innovation = LimitMonitor("INNOVATION", f.innovation, bank=bank, index=4)
        self.wheel_fault = [LimitMonitor("WHEEL_FAULT", f.wheel_fault, bank=bank, index=5 + i) for i in range(n_wheels)]
        self.wheel_speed = [LimitMonitor("WHEEL_SPEED", f.wheel_speed, bank=bank, index=5 + n_wheels + i)
                            for i in range(n_wheels)]
        k = 5 + 2 * n_wheels
        self.keepout_yellow = LimitMonitor("KEEP_OUT_MARGIN", f.keepout_yellow, below=True, bank=bank, index=k)
        self.keepout_red = LimitMonitor("KEEP_OUT_MARGIN", f.keepout_red, below=True, bank=bank, index=k + 1)
        self.cycle_slip = LimitMonitor("CYCLE_SLIP", f.cycle_slip, bank=bank, index=k + 2)
        self._all_wheels = np.ones(n_wheels, dtype=np.bool_)  # evaluate_arrays: every wheel is evaluated
        self.stale_counts = {"IMU": 0, "STAR_TRACKER": 0}
        # the symptom of each wheel's last WHEEL_FAULT trip (STATUS_LOST or `wheel_fault_cause`), "" before
        # any: a wheel isolated only because its status is lost still obeys its commands and can be used again
        self.wheel_fault_reasons = [""] * n_wheels
        # (dictionary name, bank indices of its monitors) in all_monitors() order of first appearance, for states()
        groups: dict[str, list[int]] = {}
        for m in self.all_monitors():
            groups.setdefault(m.monitor, []).append(m._i)
        self._monitor_groups = list(groups.items())

    def all_monitors(self) -> list[LimitMonitor]:
        return [self.imu_stale, self.imu_corrupt, self.st_stale, self.st_corrupt, self.innovation,
                *self.wheel_fault, *self.wheel_speed, self.keepout_yellow, self.keepout_red, self.cycle_slip]

    @property
    def trips(self) -> int:
        return sum(self._bank.trips.tolist())  # Python ints: numpy's reduction costs more on a few values

    def reset_counters(self) -> None:
        self._bank.trips[:] = 0

    def states(self) -> dict[str, str]:
        """Worst state per dictionary monitor (HK channels fdir_<monitor>)."""
        codes = self._bank.state.tolist()
        # a state's code is its rank (_STATES runs from DISABLED to TRIPPED): the worst is the largest code
        return {monitor: _STATES[max(map(codes.__getitem__, indices))] for monitor, indices in self._monitor_groups}

    def _trip(self, mon: LimitMonitor, value: float, actions: list[FdirAction], wheel: int | None = None) -> None:
        rule = mon.rule
        self.event("FDIR_TRIPPED", monitor=mon.monitor, action=_ACTION_CODES[rule.action], value=float(value))
        if rule.action != "none":
            actions.append(FdirAction(rule.action, mon.monitor, wheel))

    def _changed(self, mon: LimitMonitor, value: float | None, actions: list[FdirAction], wheel: int | None = None,
                 res: int = _NO_CHANGE) -> int:
        """The trip's event and action, or the clearing's event, for the pass's result ``res``."""
        if res == _TRIPPED_NOW:
            self._trip(mon, value, actions, wheel)
        elif res == _CLEARED_NOW:
            self.event("FDIR_CLEARED", monitor=mon.monitor)
        return res

    def evaluate_arrays(self, imu_missing: bool, imu_corrupt_frames: int, st_missing: bool, st_corrupt_frames: int,
                        innovation_deg: float, wheel_fault: np.ndarray, wheel_speed_ratio: np.ndarray,
                        wheel_speed_rad_s: np.ndarray, margins_deg, zone_bodies: list[str],
                        slipped: bool) -> list[FdirAction]:
        """One cycle of every monitor (per-wheel values as arrays of ``n_wheels``: ``wheel_fault`` bool, ``wheel_speed_ratio`` NaN where not evaluated;
        ``innovation_deg`` NaN when none this cycle). Returns the actions to take."""
        return self._evaluate(imu_missing, imu_corrupt_frames, st_missing, st_corrupt_frames, innovation_deg,
                              wheel_fault, self._all_wheels, wheel_speed_ratio, wheel_speed_rad_s, margins_deg,
                              zone_bodies, slipped)

    def evaluate_cycle(self, residual: WheelSpeedResidual, dt_s: float, wheel_speed_rad_s: np.ndarray,
                       wheel_fault_flags: np.ndarray, wheel_torque_cmd_Nm: np.ndarray, wheel_active: np.ndarray,
                       wheel_seen: np.ndarray, max_speed_rad_s: np.ndarray, fault_mask: int, overspeed_bit: int,
                       imu_missing: bool, imu_corrupt_frames: int, st_missing: bool, st_corrupt_frames: int,
                       innovation_deg: float, margins_deg, zone_bodies: list[str], slipped: bool) -> list[FdirAction]:
        """`WheelSpeedResidual.monitor_values` then `evaluate_arrays` on its values, in one compiled call
        (`_fdir_cycle`): the GNC cycle's FDIR. Arguments as theirs. Returns the actions to take."""
        self._count_stale(imu_missing, st_missing)
        r = residual
        worst_k, changed = _fdir_cycle(
            float(dt_s), wheel_speed_rad_s, wheel_fault_flags, wheel_torque_cmd_Nm, wheel_active, wheel_seen,
            max_speed_rad_s, r._started, r._prev_speed, r._prev_cmd, r.Js, r._measured, r._predicted, r._state,
            r.abs_limit, r.rel_limit, int(fault_mask), int(overspeed_bit), bool(imu_missing), bool(st_missing),
            float(imu_corrupt_frames), float(st_corrupt_frames), float(innovation_deg), _margins_array(margins_deg),
            bool(slipped), self._bank.f, self._bank.i)
        r._started = True
        if not changed and not imu_corrupt_frames and not st_corrupt_frames:
            return []  # the usual cycle: no monitor changed state, nothing to report
        return self._report(imu_corrupt_frames, st_corrupt_frames, innovation_deg, wheel_speed_rad_s, margins_deg,
                            zone_bodies, worst_k, wheel_fault_flags)

    def _count_stale(self, imu_missing: bool, st_missing: bool) -> None:
        stale = self.stale_counts
        stale["IMU"] = stale["IMU"] + 1 if imu_missing else 0
        stale["STAR_TRACKER"] = stale["STAR_TRACKER"] + 1 if st_missing else 0

    def _evaluate(self, imu_missing, imu_corrupt_frames, st_missing, st_corrupt_frames, innovation_deg, wheel_fault,
                  wheel_evaluated, wheel_speed_ratio, wheel_speed_rad_s, margins_deg, zone_bodies, slipped):
        self._count_stale(imu_missing, st_missing)
        b = self._bank
        worst_k, changed = _fdir_pass(
            bool(imu_missing), bool(st_missing), float(imu_corrupt_frames), float(st_corrupt_frames),
            float(innovation_deg), np.ascontiguousarray(wheel_fault, dtype=np.bool_), wheel_evaluated,
            np.ascontiguousarray(wheel_speed_ratio, dtype=float), _margins_array(margins_deg), bool(slipped), b.f, b.i)
        if not changed and not imu_corrupt_frames and not st_corrupt_frames:
            return []  # the usual cycle: no monitor changed state, nothing to report
        return self._report(imu_corrupt_frames, st_corrupt_frames, innovation_deg, wheel_speed_rad_s, margins_deg,
                            zone_bodies, worst_k)

    def _report(self, imu_corrupt_frames, st_corrupt_frames, innovation_deg, wheel_speed_rad_s, margins_deg,
                zone_bodies, worst_k, wheel_fault_flags=None) -> list[FdirAction]:
        """The events and actions of the monitors that changed state this cycle, in evaluation order."""
        actions: list[FdirAction] = []
        res = self._bank.result.tolist()
        values = self._bank.values.tolist()
        stale = self.stale_counts
        if self._changed(self.imu_stale, values[0], actions, None, res[0]) == _TRIPPED_NOW:
            self.event("SENSOR_STALE", sensor="IMU", cycles=stale["IMU"])
        if self._changed(self.st_stale, values[1], actions, None, res[1]) == _TRIPPED_NOW:
            self.event("SENSOR_STALE", sensor="STAR_TRACKER", cycles=stale["STAR_TRACKER"])
        if imu_corrupt_frames:
            self.event("SENSOR_CORRUPT", sensor="IMU", count=imu_corrupt_frames)
        if st_corrupt_frames:
            self.event("SENSOR_CORRUPT", sensor="STAR_TRACKER", count=st_corrupt_frames)
        self._changed(self.imu_corrupt, values[2], actions, None, res[2])
        self._changed(self.st_corrupt, values[3], actions, None, res[3])
        if self._changed(self.innovation, innovation_deg, actions, None, res[4]) == _TRIPPED_NOW:
            self.event("INNOVATION_HIGH", innovation_deg=innovation_deg)
        n = self.n_wheels
        for i, mon in enumerate(self.wheel_fault):
            if self._changed(mon, values[5 + i], actions, i, res[5 + i]) == _TRIPPED_NOW:
                if wheel_fault_flags is not None and i < len(wheel_fault_flags):
                    flags = int(wheel_fault_flags[i])
                    cause = wheel_fault_cause(flags)
                    self.event("WHEEL_FAULT", wheel=i + 1, fault=flags & 0xFF, cause=cause)
                else:  # evaluated from fault values alone (evaluate_arrays): the flags are not known here
                    flags, cause = 0, "wheel monitor tripped"
                    self.event("WHEEL_FAULT", wheel=i + 1, fault=0, cause=cause)
                # what the application asks when a later fault would leave fewer than three wheels
                self.wheel_fault_reasons[i] = STATUS_LOST if flags < 0 else cause
        for i, mon in enumerate(self.wheel_speed):
            r = res[5 + n + i]
            if r == _NO_CHANGE:
                continue
            ratio = values[5 + n + i]
            if self._changed(mon, ratio, actions, i, r) == _TRIPPED_NOW:
                speed = float(wheel_speed_rad_s[i]) if i < len(wheel_speed_rad_s) else ratio
                self.event("WHEEL_SPEED_LIMIT", wheel=i + 1, speed_rad_s=speed)
        if worst_k >= 0:
            k = 5 + 2 * n
            worst = margins_deg[worst_k]
            body = zone_bodies[worst_k] if worst_k < len(zone_bodies) else "INERTIAL"
            if res[k] == _TRIPPED_NOW:  # the yellow limit warns only: no FDIR_TRIPPED, nothing on clearing
                self.event("KEEP_OUT_MARGIN_LOW", zone=worst_k, body=body, margin_deg=worst)
            if self._changed(self.keepout_red, worst, actions, None, res[k + 1]) == _TRIPPED_NOW:
                self.event("KEEP_OUT_VIOLATION", zone=worst_k, body=body, margin_deg=worst)
        self._changed(self.cycle_slip, values[-1], actions, None, res[-1])
        return actions


def _margins_array(margins_deg) -> np.ndarray:
    """The guidance's margins (a list, or already an array) as a contiguous float array."""
    if type(margins_deg) is np.ndarray and margins_deg.dtype == np.float64 and margins_deg.flags.c_contiguous:
        return margins_deg
    return np.array(margins_deg, dtype=float)


@njit("Tuple((i8, i8))(b1, b1, f8, f8, f8, b1[::1], b1[::1], f8[::1], f8[::1], b1, f8[:, ::1], i8[:, ::1])", cache=True)
def _fdir_pass(imu_missing, st_missing, imu_corrupt, st_corrupt, innovation_deg, wheel_fault, wheel_evaluated,
               wheel_ratio, margins_deg, slipped, f, ints):
    """`Fdir`'s monitored values for one cycle, written into the bank's value row (NaN: not evaluated),
    and the monitors run on them (`_monitor_pass`). Returns (the zone of the smallest finite margin, -1
    when there is none; the number of monitors that tripped or cleared)."""
    values = f[_F_VALUE]
    n = wheel_fault.shape[0]
    values[0] = 1.0 if imu_missing else 0.0
    values[1] = 1.0 if st_missing else 0.0
    values[2] = imu_corrupt
    values[3] = st_corrupt
    values[4] = innovation_deg  # NaN: no innovation this cycle
    for i in range(n):
        values[5 + i] = (1.0 if wheel_fault[i] else 0.0) if wheel_evaluated[i] else np.nan
        values[5 + n + i] = wheel_ratio[i]  # NaN: no status, not evaluated
    # the smallest finite margin, the first zone that has it (min over (margin, zone) pairs)
    worst_k = -1
    worst = np.nan
    for k in range(margins_deg.shape[0]):
        m = margins_deg[k]
        if m == m and (worst_k < 0 or m < worst):
            worst, worst_k = m, k
    values[5 + 2 * n] = worst
    values[6 + 2 * n] = worst
    values[7 + 2 * n] = 1.0 if slipped else 0.0
    _monitor_pass(f, ints)
    result = ints[_I_RESULT]
    changed = 0
    for i in range(result.shape[0]):
        if result[i] != _NO_CHANGE:
            changed += 1
    return worst_k, changed


@njit("Tuple((i8, i8))(f8, f8[::1], i8[::1], f8[::1], b1[::1], b1[::1], f8[::1], b1, f8[::1], f8[::1], f8[::1],"
      " f8[:, ::1], f8[:, ::1], i8[::1], f8, f8, i8, i8, b1, b1, f8, f8, f8, f8[::1], b1, f8[:, ::1], i8[:, ::1])",
      cache=True)
def _fdir_cycle(dt_s, speed, fault_flags, cmd, active, seen, max_speed, started, prev_speed, prev_cmd, Js, measured,
                predicted, state, abs_limit, rel_limit, fault_mask, overspeed_bit, imu_missing, st_missing, imu_corrupt,
                st_corrupt, innovation_deg, margins_deg, slipped, f, ints):
    """`Fdir.evaluate_cycle`: `_wheel_monitor_values` and `_fdir_pass` in one compiled call."""
    fault, ratio = _wheel_monitor_values(dt_s, speed, fault_flags, cmd, active, seen, max_speed, started, prev_speed,
                                         prev_cmd, Js, measured, predicted, state, abs_limit, rel_limit, fault_mask,
                                         overspeed_bit)
    return _fdir_pass(imu_missing, st_missing, imu_corrupt, st_corrupt, innovation_deg, fault,
                      np.ones(fault.shape[0], dtype=np.bool_), ratio, margins_deg, slipped, f, ints)
