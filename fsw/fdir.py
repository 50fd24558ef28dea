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

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

_ACTION_CODES = {
    "none": "EVENT_ONLY",
    "safe": "ENTER_SAFE",
    "reset_estimator": "RESET_ESTIMATOR",
    "isolate_wheel": "ISOLATE_WHEEL",
    "isolate_wheel_safe": "ISOLATE_WHEEL",
}
_STATE_RANK = {"DISABLED": 0, "NOMINAL": 1, "PERSISTING": 2, "TRIPPED": 3}


@dataclass
class FdirAction:
    action: str  # safe | reset_estimator | isolate_wheel | isolate_wheel_safe
    monitor: str
    wheel: int | None = None


class LimitMonitor:
    """One limit check. ``below=True`` trips when the value is *below* the limit (margins)."""

    def __init__(self, monitor: str, rule, below: bool = False):
        self.monitor = monitor
        self.rule = rule
        self.below = below
        self.count = 0
        self.state = "NOMINAL" if rule.enabled else "DISABLED"
        self.trips = 0
        self.last_value = float("nan")

    def beyond(self, value: float) -> bool:
        return value < self.rule.limit if self.below else value > self.rule.limit

    def update(self, value: float | None) -> str | None:
        """Feed one cycle's value (None: not evaluated this cycle). Returns 'tripped', 'cleared' or None."""
        if self.state == "DISABLED" or value is None:
            return None
        self.last_value = float(value)
        limit = self.rule.limit  # `beyond`, inline: fifteen monitors run every cycle
        if (value < limit) if self.below else (value > limit):
            self.count += 1
            if self.state == "TRIPPED":
                return None
            if self.count >= self.rule.persistence_cycles:
                self.state = "TRIPPED"
                self.trips += 1
                return "tripped"
            self.state = "PERSISTING"
            return None
        was = self.state
        self.count = 0
        self.state = "NOMINAL"
        return "cleared" if was == "TRIPPED" else None

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


@dataclass
class FdirInputs:
    """What FDIR looks at in one GNC cycle (None = not applicable this cycle)."""

    imu_missing: bool
    imu_corrupt_frames: int
    st_missing: bool
    st_corrupt_frames: int
    innovation_deg: float | None
    wheel_fault: list[bool] = field(default_factory=list)
    wheel_speed_ratio: list[float] = field(default_factory=list)
    wheel_speed_rad_s: list[float] = field(default_factory=list)
    margins_deg: list[float] = field(default_factory=list)
    zone_bodies: list[str] = field(default_factory=list)
    slipped: bool = False


class Fdir:
    """All monitors; `evaluate` once per GNC cycle returns the actions to take."""

    def __init__(self, cfg, n_wheels: int, event: Callable[..., object] | None = None):
        f = cfg.fdir
        self.event = event or (lambda name, **args: None)
        self.imu_stale = LimitMonitor("IMU_STALE", f.imu_stale)
        self.imu_corrupt = LimitMonitor("IMU_CORRUPT", f.imu_corrupt)
        self.st_stale = LimitMonitor("ST_STALE", f.star_tracker_stale)
        self.st_corrupt = LimitMonitor("ST_CORRUPT", f.star_tracker_corrupt)
        self.innovation = LimitMonitor("INNOVATION", f.innovation)
        self.wheel_fault = [LimitMonitor("WHEEL_FAULT", f.wheel_fault) for _ in range(n_wheels)]
        self.wheel_speed = [LimitMonitor("WHEEL_SPEED", f.wheel_speed) for _ in range(n_wheels)]
        self.keepout_yellow = LimitMonitor("KEEP_OUT_MARGIN", f.keepout_yellow, below=True)
        self.keepout_red = LimitMonitor("KEEP_OUT_MARGIN", f.keepout_red, below=True)
        self.cycle_slip = LimitMonitor("CYCLE_SLIP", f.cycle_slip)
        self.stale_counts = {"IMU": 0, "STAR_TRACKER": 0}

    def all_monitors(self) -> list[LimitMonitor]:
        return [self.imu_stale, self.imu_corrupt, self.st_stale, self.st_corrupt, self.innovation,
                *self.wheel_fault, *self.wheel_speed, self.keepout_yellow, self.keepout_red, self.cycle_slip]

    @property
    def trips(self) -> int:
        return sum(m.trips for m in self.all_monitors())

    def reset_counters(self) -> None:
        for m in self.all_monitors():
            m.trips = 0

    def states(self) -> dict[str, str]:
        """Worst state per dictionary monitor (HK channels fdir_<monitor>)."""
        out: dict[str, str] = {}
        for m in self.all_monitors():
            cur = out.get(m.monitor)
            if cur is None or _STATE_RANK[m.state] > _STATE_RANK[cur]:
                out[m.monitor] = m.state
        return out

    def _trip(self, mon: LimitMonitor, value: float, actions: list[FdirAction], wheel: int | None = None) -> None:
        rule = mon.rule
        self.event("FDIR_TRIPPED", monitor=mon.monitor, action=_ACTION_CODES[rule.action], value=float(value))
        if rule.action != "none":
            actions.append(FdirAction(rule.action, mon.monitor, wheel))

    def _run(self, mon: LimitMonitor, value: float | None, actions: list[FdirAction], wheel: int | None = None) -> str | None:
        return self._changed(mon, value, actions, wheel, mon.update(value))

    def _changed(self, mon: LimitMonitor, value: float | None, actions: list[FdirAction], wheel: int | None = None,
                 res: str | None = None) -> str | None:
        """The trip's event and action, or the clearing's event, for ``res`` = ``mon.update(value)``."""
        if res == "tripped":
            self._trip(mon, value, actions, wheel)
        elif res == "cleared":
            self.event("FDIR_CLEARED", monitor=mon.monitor)
        return res

    def evaluate(self, x: FdirInputs) -> list[FdirAction]:
        # `_run` only where a monitor changed state: fifteen monitors run every cycle and almost never do
        actions: list[FdirAction] = []
        stale = self.stale_counts
        stale["IMU"] = stale["IMU"] + 1 if x.imu_missing else 0
        stale["STAR_TRACKER"] = stale["STAR_TRACKER"] + 1 if x.st_missing else 0
        if self._run(self.imu_stale, 1.0 if x.imu_missing else 0.0, actions) == "tripped":
            self.event("SENSOR_STALE", sensor="IMU", cycles=stale["IMU"])
        if self._run(self.st_stale, 1.0 if x.st_missing else 0.0, actions) == "tripped":
            self.event("SENSOR_STALE", sensor="STAR_TRACKER", cycles=stale["STAR_TRACKER"])
        if x.imu_corrupt_frames:
            self.event("SENSOR_CORRUPT", sensor="IMU", count=x.imu_corrupt_frames)
        if x.st_corrupt_frames:
            self.event("SENSOR_CORRUPT", sensor="STAR_TRACKER", count=x.st_corrupt_frames)
        self._run(self.imu_corrupt, float(x.imu_corrupt_frames), actions)
        self._run(self.st_corrupt, float(x.st_corrupt_frames), actions)
        if x.innovation_deg is not None and x.innovation_deg == x.innovation_deg:  # not NaN
            if self._run(self.innovation, x.innovation_deg, actions) == "tripped":
                self.event("INNOVATION_HIGH", innovation_deg=x.innovation_deg)
        monitors = self.wheel_fault
        for i, faulty in enumerate(x.wheel_fault):
            value = 1.0 if faulty else 0.0
            res = monitors[i].update(value)
            if res is not None and self._changed(monitors[i], value, actions, i, res) == "tripped":
                self.event("WHEEL_FAULT", wheel=i + 1, fault=1)
        monitors = self.wheel_speed
        for i, ratio in enumerate(x.wheel_speed_ratio):
            if ratio != ratio:
                continue
            res = monitors[i].update(ratio)
            if res is not None and self._changed(monitors[i], ratio, actions, i, res) == "tripped":
                self.event("WHEEL_SPEED_LIMIT", wheel=i + 1, speed_rad_s=x.wheel_speed_rad_s[i] if i < len(x.wheel_speed_rad_s) else ratio)
        if x.margins_deg:
            finite = [(m, k) for k, m in enumerate(x.margins_deg) if m == m]
            if finite:
                worst, k = min(finite)
                body = x.zone_bodies[k] if k < len(x.zone_bodies) else "INERTIAL"
                if self.keepout_yellow.update(worst) == "tripped":
                    self.event("KEEP_OUT_MARGIN_LOW", zone=k, body=body, margin_deg=worst)
                if self._run(self.keepout_red, worst, actions) == "tripped":
                    self.event("KEEP_OUT_VIOLATION", zone=k, body=body, margin_deg=worst)
        self._run(self.cycle_slip, 1.0 if x.slipped else 0.0, actions)
        return actions
