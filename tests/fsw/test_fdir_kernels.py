"""FDIR's compiled pass against the Python it replaced: the limit monitors as they were (one object, one
``update`` per monitor and cycle), ``Fdir.evaluate`` as it was, and the application's per-wheel loop that
built the wheel monitors' values. Random cycles with trips and clearings of every monitor; the events
(names, arguments, order), the actions, the states and the counters must be equal."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest

from fsw.config import FswConfig
from fsw.fdir import _ACTION_CODES, Fdir, FdirAction, WheelSpeedResidual

WHEEL_OVERSPEED, WHEEL_FAULT_MASK = 0x01, 0x02 | 0x04


@dataclass
class FdirInputs:
    """What FDIR looks at in one GNC cycle (None = not applicable this cycle), as the flight code gathered
    it before `Fdir.evaluate_cycle`."""

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
    wheel_flags: list[int] = field(default_factory=list)  # status fault bits this cycle, -1: no status


def _evaluate(fdir: Fdir, x: FdirInputs) -> list[FdirAction]:
    """`Fdir`'s compiled pass on an `FdirInputs` (the flight code's ``Fdir.evaluate`` before
    `Fdir.evaluate_cycle`): wheels past the inputs' lists are not evaluated, None is no innovation."""
    n = fdir.n_wheels
    fault = np.zeros(n, dtype=np.bool_)
    ratio = np.full(n, np.nan)
    evaluated = np.zeros(n, dtype=np.bool_)
    for i, v in enumerate(x.wheel_fault[:n]):
        fault[i] = bool(v)
        evaluated[i] = True
    for i, v in enumerate(x.wheel_speed_ratio[:n]):
        ratio[i] = v
    innovation = x.innovation_deg if x.innovation_deg is not None else np.nan
    return fdir._evaluate(x.imu_missing, x.imu_corrupt_frames, x.st_missing, x.st_corrupt_frames, innovation,
                          fault, evaluated, ratio, x.wheel_speed_rad_s, x.margins_deg, x.zone_bodies, x.slipped)
_STATE_RANK = {"DISABLED": 0, "NOMINAL": 1, "PERSISTING": 2, "TRIPPED": 3}


class _RefMonitor:
    def __init__(self, monitor, rule, below=False):
        self.monitor, self.rule, self.below = monitor, rule, below
        self.count, self.trips, self.last_value = 0, 0, float("nan")
        self.state = "NOMINAL" if rule.enabled else "DISABLED"

    def update(self, value):
        if self.state == "DISABLED" or value is None:
            return None
        self.last_value = float(value)
        limit = self.rule.limit
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


class _RefFdir:
    """`Fdir` as it was before the compiled pass (commit e02f598)."""

    def __init__(self, cfg, n_wheels, event):
        f = cfg.fdir
        self.event = event
        self.imu_stale = _RefMonitor("IMU_STALE", f.imu_stale)
        self.imu_corrupt = _RefMonitor("IMU_CORRUPT", f.imu_corrupt)
        self.st_stale = _RefMonitor("ST_STALE", f.star_tracker_stale)
        self.st_corrupt = _RefMonitor("ST_CORRUPT", f.star_tracker_corrupt)
        self.innovation = _RefMonitor("INNOVATION", f.innovation)
        self.wheel_fault = [_RefMonitor("WHEEL_FAULT", f.wheel_fault) for _ in range(n_wheels)]
        self.wheel_speed = [_RefMonitor("WHEEL_SPEED", f.wheel_speed) for _ in range(n_wheels)]
        self.keepout_yellow = _RefMonitor("KEEP_OUT_MARGIN", f.keepout_yellow, below=True)
        self.keepout_red = _RefMonitor("KEEP_OUT_MARGIN", f.keepout_red, below=True)
        self.cycle_slip = _RefMonitor("CYCLE_SLIP", f.cycle_slip)
        self.stale_counts = {"IMU": 0, "STAR_TRACKER": 0}

    def all_monitors(self):
        return [self.imu_stale, self.imu_corrupt, self.st_stale, self.st_corrupt, self.innovation,
                *self.wheel_fault, *self.wheel_speed, self.keepout_yellow, self.keepout_red, self.cycle_slip]

    def states(self):
        out = {}
        for m in self.all_monitors():
            cur = out.get(m.monitor)
            if cur is None or _STATE_RANK[m.state] > _STATE_RANK[cur]:
                out[m.monitor] = m.state
        return out

    def _run(self, mon, value, actions, wheel=None):
        res = mon.update(value)
        if res == "tripped":
            self.event("FDIR_TRIPPED", monitor=mon.monitor, action=_ACTION_CODES[mon.rule.action], value=float(value))
            if mon.rule.action != "none":
                actions.append(FdirAction(mon.rule.action, mon.monitor, wheel))
        elif res == "cleared":
            self.event("FDIR_CLEARED", monitor=mon.monitor)
        return res

    def evaluate(self, x):
        actions = []
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
        if x.innovation_deg is not None and x.innovation_deg == x.innovation_deg:
            if self._run(self.innovation, x.innovation_deg, actions) == "tripped":
                self.event("INNOVATION_HIGH", innovation_deg=x.innovation_deg)
        for i, faulty in enumerate(x.wheel_fault):
            if self._run(self.wheel_fault[i], 1.0 if faulty else 0.0, actions, i) == "tripped":
                if i < len(x.wheel_flags):
                    flags = x.wheel_flags[i]
                    self.event("WHEEL_FAULT", wheel=i + 1, fault=flags & 0xFF, cause=_REF_CAUSE(flags))
                else:
                    self.event("WHEEL_FAULT", wheel=i + 1, fault=0, cause="wheel monitor tripped")
        for i, ratio in enumerate(x.wheel_speed_ratio):
            if ratio != ratio:
                continue
            if self._run(self.wheel_speed[i], ratio, actions, i) == "tripped":
                self.event("WHEEL_SPEED_LIMIT", wheel=i + 1, speed_rad_s=x.wheel_speed_rad_s[i])
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


def _REF_CAUSE(flags: int) -> str:
    """The words the DBC's fault-bit comment gives each flag (drive fault first)."""
    if flags < 0:
        return "status lost: no speed report from the wheel"
    if flags & 4:
        return "drive fault reported by the wheel"
    if flags & 2:
        return "command timeout: the wheel's torque commands stopped arriving"
    return "speed does not follow the commanded torque"


def _ref_wheel_values(wheels, speed_list, residual_off, max_speed, seen, cmd):
    """The application's per-wheel loop before `WheelSpeedResidual.monitor_values`, with saturation: a
    wheel at 98 % of its limit (or flagged overspeed) pushed further is not failing to follow."""
    wheel_fault, wheel_ratio = [], []
    for i, (w, s, m) in enumerate(zip(wheels, speed_list, max_speed)):
        if w is None:
            wheel_fault.append(seen[i] or residual_off[i])
            wheel_ratio.append(abs(s) / m if math.isfinite(s) else math.nan)
            continue
        seen[i] = True
        fault = int(w[1])
        saturated = (bool(fault & WHEEL_OVERSPEED) or abs(s) >= 0.98 * m) and cmd[i] * s > 0.0
        wheel_fault.append(bool(fault & WHEEL_FAULT_MASK) or (residual_off[i] and not saturated))
        wheel_ratio.append(max(abs(s) / m, 1.0 if fault & WHEEL_OVERSPEED else 0.0) if math.isfinite(s) else math.nan)
    return wheel_fault, wheel_ratio


def _config():
    rule = lambda limit, n, action: {"limit": limit, "persistence_cycles": n, "action": action}  # noqa: E731
    return FswConfig(fdir={
        "imu_stale": rule(0.5, 2, "safe"), "imu_corrupt": rule(0.5, 2, "none"),
        "star_tracker_stale": rule(0.5, 3, "none"), "star_tracker_corrupt": rule(1.5, 1, "none"),
        "innovation": rule(1.0, 2, "reset_estimator"), "wheel_fault": rule(0.5, 2, "isolate_wheel"),
        "wheel_speed": rule(0.95, 2, "safe"), "keepout_yellow": rule(1.0, 1, "none"),
        "keepout_red": rule(0.0, 2, "safe"),
        "cycle_slip": {"enabled": False, "limit": 0.5, "persistence_cycles": 2, "action": "none"},
    })


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_compiled_fdir_matches_the_python_monitors(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cfg = _config()
    n = 4
    events, ref_events = [], []
    fdir = Fdir(cfg, n, event=lambda name, **a: events.append((name, a)))
    ref = _RefFdir(cfg, n, event=lambda name, **a: ref_events.append((name, a)))
    Js = np.full(n, 1e-3)
    res, ref_res = WheelSpeedResidual(Js), WheelSpeedResidual(Js)
    max_speed = np.array([600.0, 500.0, 600.0, 550.0])
    seen, ref_seen = np.zeros(n, dtype=bool), [False] * n
    active = np.ones(n, dtype=bool)
    speed = rng.normal(scale=300.0, size=n)
    bodies = ["SUN", "MOON", "EARTH"]
    for k in range(1500):
        if k == 700:
            active[2] = False
        phase = (k // 50) % 4  # calm and rough stretches, so that monitors trip and clear
        rough = phase in (1, 3)
        speed = speed + rng.normal(scale=40.0 if rough else 2.0, size=n)
        if rng.random() < 0.05:
            speed[rng.integers(n)] = max_speed[0] * (0.97 if rng.random() < 0.5 else -1.0)
        wheels = []
        for i in range(n):
            if rng.random() < (0.3 if rough else 0.02):
                wheels.append(None)
            else:
                flags = int(rng.choice([0, 0, 0, 1, 2, 4, 5])) if rough else 0
                wheels.append((float(speed[i]), flags))
        speed_list = [w[0] if w is not None else math.nan for w in wheels]
        speeds = np.array(speed_list, dtype=float)
        faults = np.array([w[1] if w is not None else -1 for w in wheels], dtype=np.int64)
        cmd = rng.normal(scale=0.05, size=n)
        imu_missing = bool(rng.random() < (0.6 if rough else 0.02))
        st_missing = bool(rng.random() < (0.7 if rough else 0.05))
        imu_corrupt = int(rng.integers(0, 3)) if rough and rng.random() < 0.5 else 0
        st_corrupt = int(rng.integers(0, 4)) if rough and rng.random() < 0.5 else 0
        innovation = (float("nan"), float(rng.uniform(0.0, 0.5)), float(rng.uniform(0.5, 3.0)))[
            int(rng.integers(0, 3)) if rough else int(rng.integers(0, 2))]
        nz = int(rng.integers(0, 4))
        margins = [float(x) for x in rng.normal(loc=0.5 if rough else 5.0, scale=1.5, size=nz)]
        if nz and rng.random() < 0.2:
            margins[int(rng.integers(nz))] = float("nan")
        if nz > 1 and rng.random() < 0.1:
            margins[-1] = margins[0]  # a tie: the first zone is reported
        zone_bodies = bodies[:max(0, nz - 1)]  # one zone without a body: INERTIAL
        slipped = bool(rng.random() < 0.1)

        actions = fdir.evaluate_cycle(res, 0.1, speeds, faults, cmd, active, seen, max_speed, WHEEL_FAULT_MASK,
                                      WHEEL_OVERSPEED, imu_missing, imu_corrupt, st_missing, st_corrupt, innovation,
                                      margins, zone_bodies, slipped)
        off = (ref_res.update(0.1, speeds, cmd) & active).tolist()
        wheel_fault, wheel_ratio = _ref_wheel_values(wheels, speed_list, off, max_speed.tolist(), ref_seen,
                                                     cmd.tolist())
        ref_actions = ref.evaluate(FdirInputs(
            imu_missing=imu_missing, imu_corrupt_frames=imu_corrupt, st_missing=st_missing,
            st_corrupt_frames=st_corrupt, innovation_deg=innovation, wheel_fault=wheel_fault,
            wheel_speed_ratio=wheel_ratio, wheel_speed_rad_s=speed_list, margins_deg=margins,
            zone_bodies=zone_bodies, slipped=slipped, wheel_flags=faults.tolist()))
        assert actions == ref_actions, k
        assert events == ref_events, k
        assert [type(v) for _, a in events for v in a.values()] == [type(v) for _, a in ref_events for v in a.values()]
        assert seen.tolist() == ref_seen
        assert fdir.states() == ref.states() and fdir.stale_counts == ref.stale_counts
        for m, r in zip(fdir.all_monitors(), ref.all_monitors()):
            assert (m.state, m.count, m.trips) == (r.state, r.count, r.trips), (k, m.monitor)
            assert str(m.last_value) == str(r.last_value)
    names = {name for name, _ in ref_events}
    assert {"FDIR_TRIPPED", "FDIR_CLEARED", "SENSOR_STALE", "SENSOR_CORRUPT", "INNOVATION_HIGH", "WHEEL_FAULT",
            "WHEEL_SPEED_LIMIT", "KEEP_OUT_MARGIN_LOW", "KEEP_OUT_VIOLATION"} <= names, names
    assert fdir.trips == sum(m.trips for m in ref.all_monitors()) > 20


def test_evaluate_of_fdir_inputs_matches_the_python_monitors() -> None:
    """The pass on `FdirInputs` (lists, None for no innovation) against the Python monitors."""
    rng = np.random.default_rng(5)
    cfg = _config()
    events, ref_events = [], []
    fdir = Fdir(cfg, 2, event=lambda name, **a: events.append((name, a)))
    ref = _RefFdir(cfg, 2, event=lambda name, **a: ref_events.append((name, a)))
    for k in range(600):
        x = FdirInputs(imu_missing=bool(rng.random() < 0.3), imu_corrupt_frames=int(rng.integers(0, 2)),
                       st_missing=bool(rng.random() < 0.4), st_corrupt_frames=int(rng.integers(0, 3)),
                       innovation_deg=None if rng.random() < 0.3 else float(rng.uniform(0, 2)),
                       wheel_fault=[bool(rng.random() < 0.4) for _ in range(2)],
                       wheel_speed_ratio=[float(rng.uniform(0.8, 1.1)) if rng.random() < 0.8 else math.nan
                                          for _ in range(2)],
                       wheel_speed_rad_s=[float(rng.normal(scale=100.0)) for _ in range(2)],
                       margins_deg=[float(v) for v in rng.normal(loc=1.0, scale=1.0, size=int(rng.integers(0, 3)))],
                       zone_bodies=["SUN"], slipped=bool(rng.random() < 0.5))
        assert _evaluate(fdir, x) == ref.evaluate(x), k
        assert events == ref_events and fdir.states() == ref.states()


@pytest.mark.parametrize("speed_fraction, expect_isolation", [(0.99, False), (0.5, True)])
def test_a_wheel_held_at_its_speed_limit_is_saturated_not_failed(speed_fraction: float,
                                                                  expect_isolation: bool) -> None:
    """A wheel pushed further at its speed limit does not speed up: that is what the wheel model does at the
    limit, so it is saturation (WHEEL_SPEED), never an isolation for a speed that does not follow its torque.
    The same wheel ignoring its torque at half speed is failing, and is isolated."""
    cfg = _config()
    n = 4
    events: list = []
    fdir = Fdir(cfg, n, event=lambda name, **a: events.append((name, a)))
    Js = np.full(n, 1e-3)
    res = WheelSpeedResidual(Js)
    max_speed = np.full(n, 600.0)
    seen, active = np.zeros(n, dtype=bool), np.ones(n, dtype=bool)
    speeds = np.array([speed_fraction * 600.0, 10.0, -20.0, 30.0])
    cmd = np.array([0.05, 0.0, 0.0, 0.0])  # wheel 1 pushed further up: 50 rad/s^2 it does not follow
    flags = np.zeros(n, dtype=np.int64)
    actions = []
    for _ in range(100):
        actions += fdir.evaluate_cycle(res, 0.1, speeds.copy(), flags, cmd, active, seen, max_speed,
                                       WHEEL_FAULT_MASK, WHEEL_OVERSPEED, False, 0, False, 0, float("nan"),
                                       [5.0], ["SUN"], False)
    isolated = [a for a in actions if a.action == "isolate_wheel"]
    assert bool(isolated) == expect_isolation, (actions, events)
    faults = [a for name, a in events if name == "WHEEL_FAULT"]
    if expect_isolation:
        assert faults and faults[0]["cause"] == "speed does not follow the commanded torque"
    else:
        assert not faults and any(name == "WHEEL_SPEED_LIMIT" for name, _ in events)
