"""The flight software's aperture door (fsw.door): the closing prediction against braking kinematics, the
reasons to close, the hysteresis and dwell before it opens again, the faults it reads from DOOR_STATUS."""
from __future__ import annotations

import math

import pytest

from comms.bus import Icd
from fsw.config import DoorConfig
from fsw.door import DoorController, approach_reach_deg

T = 0.1


class _Driver:
    """The bus driver as the door sees it: DOOR_STATUS rows it is handed, DOOR_CMD frames it records."""

    def __init__(self) -> None:
        self.icd = Icd()
        self.sent: list[dict] = []
        self.kept: list[str] = []
        self.status = None

    def keep_latest(self, name: str) -> None:
        self.kept.append(name)

    def latest(self, name: str):
        return self.status

    def send_frame(self, name: str, signals: dict, with_commands: bool = False) -> None:
        assert name == "DOOR_CMD" and with_commands
        self.icd.encode(name, signals, 0)  # a valid frame of the ICD
        self.sent.append(dict(signals))

    def report(self, t: float, position: float, state: int, commanded_open: int, fault: int = 0) -> None:
        row = [0.0] * self.icd.table.start.shape[1]
        for sig, v in (("position", position), ("state", state), ("commanded_open", commanded_open), ("fault", fault)):
            row[self.icd.column("DOOR_STATUS", sig)] = float(v)
        self.status = (row, t)


def _door(**cfg):
    events: list[tuple[str, dict]] = []
    driver = _Driver()
    door = DoorController(DoorConfig(**{"close_time_s": 1.0, "open_time_s": 2.0, **cfg}), T, driver,
                          lambda name, **a: events.append((name, a)))
    return door, driver, events


def _names(events) -> list[str]:
    return [n for n, _ in events]


def test_reach_matches_the_stopping_kinematics() -> None:
    # independent: integrate a boresight at v that reacts after t_r then brakes at a until it stops
    v, t_r, a = 0.8, 1.1, 0.15
    x, w, dt = 0.0, v, 1e-4
    t = 0.0
    while w > 0.0:
        x += w * dt
        if t >= t_r:
            w -= a * dt
        t += dt
    assert approach_reach_deg(v, t_r, a, 60.0) == pytest.approx(x, rel=1e-3)
    # no braking: it coasts through the horizon; moving away or still: nothing to reach
    assert approach_reach_deg(v, t_r, 0.0, 60.0) == pytest.approx(v * 61.1)
    assert approach_reach_deg(-0.5, t_r, a, 60.0) == 0.0 and approach_reach_deg(0.0, t_r, 0.0, 60.0) == 0.0


def _fly(door, driver, margins_of_t, t0, t1, *, brake=0.15, known=True, violation=False, status=None):
    """Cycles from t0 to t1 with margins_of_t(t) (one zone, SUN); the door as ``status(t, open)`` reports it."""
    n = round((t1 - t0) / T)
    for k in range(n):
        t = t0 + k * T
        if status is not None:
            status(t)
        door.cycle(t, int(round(t / T)), [margins_of_t(t)], ["SUN"], known, brake, violation)
    return driver.sent[-1]["open"]


def _ideal(driver, door):
    """A door that is where it was last commanded."""
    def status(t):
        open_ = bool(door.command_open)
        driver.report(t, 100.0 if open_ else 0.0, 1 if open_ else 0, int(open_))
    return status


def test_opens_after_the_dwell_and_stays_open_along_a_zone() -> None:
    door, driver, events = _door()
    status = _ideal(driver, door)
    # a boresight holding 3 deg out of a zone: closed until the dwell is over, then open
    assert _fly(door, driver, lambda t: 3.0, 0.0, 9.95, status=status) == 0
    assert _fly(door, driver, lambda t: 3.0, 10.0, 10.3, status=status) == 1
    assert _names(events).count("DOOR_OPENING") == 1
    # a slew that skirts the zone at 3 deg (margin not falling) or leaves it never closes the door
    assert _fly(door, driver, lambda t: 3.0, 10.3, 60.0, status=status) == 1
    assert _fly(door, driver, lambda t: 3.0 + (t - 60.0), 60.0, 80.0, status=status) == 1
    assert "DOOR_CLOSING" not in _names(events)


def test_closes_when_the_wheels_cannot_stop_the_approach_in_time() -> None:
    door, driver, events = _door(reopen_dwell_s=0.0)
    status = _ideal(driver, door)
    _fly(door, driver, lambda t: 30.0, 0.0, 1.0, status=status)
    # approaching at 1 deg/s from 30 deg with 0.15 deg/s^2: the reach is 1.1 + 3.33 = 4.43 deg, so the
    # door must close when the margin falls to 0.5 + 4.43 deg, and not before
    margin = lambda t: 30.0 - (t - 1.0)  # noqa: E731
    _fly(door, driver, margin, 1.0, 30.0, status=status)
    closing = [a for n, a in events if n == "DOOR_CLOSING"]
    assert len(closing) == 1 and closing[0]["reason"] == "PREDICTED_ENTRY" and closing[0]["body"] == "SUN"
    assert closing[0]["reach_deg"] == pytest.approx(1.1 + 1.0 / 0.3, rel=1e-6)
    assert 0.5 + 4.43 - 0.1 <= closing[0]["margin_deg"] <= 0.5 + 4.44
    # the same approach with the braking the wheels can give never closing in time: the guidance's job
    door2, driver2, events2 = _door(reopen_dwell_s=0.0)
    _fly(door2, driver2, lambda t: 30.0, 0.0, 1.0, status=_ideal(driver2, door2))
    _fly(door2, driver2, lambda t: max(10.0, 30.0 - (t - 1.0)), 1.0, 30.0, status=_ideal(driver2, door2))
    assert "DOOR_CLOSING" not in _names(events2)


def test_without_braking_a_slow_drift_closes_it_long_before_the_zone() -> None:
    door, driver, events = _door(reopen_dwell_s=0.0)
    status = _ideal(driver, door)
    _fly(door, driver, lambda t: 40.0, 0.0, 1.0, status=status, brake=0.0)
    assert _fly(door, driver, lambda t: 40.0 - 0.2 * (t - 1.0), 1.0, 3.0, status=status, brake=0.0) == 1
    # 0.2 deg/s for 1.1 + 60 s reaches 12.2 deg: it closes once the margin is down to 12.7 deg
    assert _fly(door, driver, lambda t: 40.0 - 0.2 * (t - 1.0), 3.0, 200.0, status=status, brake=0.0) == 0
    closing = [a for n, a in events if n == "DOOR_CLOSING"][0]
    assert closing["margin_deg"] == pytest.approx(0.5 + 0.2 * 61.1, abs=0.03)


def test_violation_and_lost_attitude_close_it_and_hysteresis_holds_it() -> None:
    door, driver, events = _door(reopen_margin_deg=2.0, reopen_dwell_s=5.0)
    status = _ideal(driver, door)
    _fly(door, driver, lambda t: 20.0, 0.0, 5.5, status=status)
    assert driver.sent[-1]["open"] == 1
    assert _fly(door, driver, lambda t: 20.0, 5.5, 5.7, status=status, violation=True) == 0
    assert _fly(door, driver, lambda t: 20.0, 5.7, 11.0, status=status) == 1  # reopened after the dwell
    assert _fly(door, driver, lambda t: 20.0, 11.0, 11.2, status=status, known=False) == 0
    reasons = [a["reason"] for n, a in events if n == "DOOR_CLOSING"]
    assert reasons == ["KEEP_OUT_VIOLATION", "NO_ATTITUDE"]
    # out by 1.5 deg (above the guard, below the reopen margin): stays shut however long
    assert _fly(door, driver, lambda t: 1.5, 11.2, 60.0, status=status) == 0
    # 2 deg and more, but for less than the dwell at a time: still shut
    assert _fly(door, driver, lambda t: 2.5 if (t % 4.0) < 3.0 else 1.9, 60.0, 100.0, status=status) == 0
    assert _fly(door, driver, lambda t: 2.5, 100.0, 106.0, status=status) == 1


def test_commands_every_cycle_with_its_tick() -> None:
    door, driver, _ = _door()
    _fly(door, driver, lambda t: 30.0, 0.0, 1.0)
    assert len(driver.sent) == 10 and [s["tick_lsb"] for s in driver.sent] == list(range(10))
    assert driver.kept == ["DOOR_STATUS"]


def test_faults_from_the_status() -> None:
    door, driver, events = _door(reopen_dwell_s=0.0, status_timeout_s=1.0)
    # no status at all: NO_STATUS once, after the timeout
    _fly(door, driver, lambda t: 30.0, 0.0, 2.0)
    faults = [a["fault"] for n, a in events if n == "DOOR_FAULT"]
    assert faults == ["NO_STATUS"]
    # a door that reports it is stuck closed (stalled, never open): STALLED, then the stroke is overdue
    events.clear()
    stuck = lambda t: driver.report(t, 0.0, 0, 1, fault=1)  # noqa: E731
    _fly(door, driver, lambda t: 30.0, 2.0, 8.0, status=stuck)
    faults = [a["fault"] for n, a in events if n == "DOOR_FAULT"]
    assert faults[0] == "STALLED" and "NOT_OPEN" in faults and "NO_STATUS" not in faults
    # the 2 s stroke is overdue after 1.5 x 2 + 1 = 4 s
    t_overdue = [e for e in events if e[0] == "DOOR_FAULT" and e[1]["fault"] == "NOT_OPEN"]
    assert len(t_overdue) == 1


def test_config_refuses_a_reopen_margin_below_the_guard() -> None:
    with pytest.raises(ValueError, match="reopen_margin_deg"):
        DoorConfig(close_time_s=1.0, open_time_s=1.0, guard_deg=3.0, reopen_margin_deg=2.0)
    assert math.isfinite(DoorConfig(close_time_s=1.0, open_time_s=1.0).coast_horizon_s)


def test_status_on_the_drivers_own_clock_and_a_late_first_status() -> None:
    # real time: the driver stamps frames on its monotonic clock, far from onboard time, and the first
    # status may come a few cycles after the first cycle (the devices start later): no fault from either
    door, driver, events = _door()
    for k in range(40):
        t = k * T
        if k >= 5:
            driver.report(5000.0 + 1.3 * t, 0.0, 0, 0)
        door.cycle(t, k, [30.0], ["SUN"], True, 0.15, False)
    assert "DOOR_FAULT" not in _names(events)
    # then it falls silent: NO_STATUS after status_timeout_s of onboard time
    for k in range(40, 60):
        door.cycle(k * T, k, [30.0], ["SUN"], True, 0.15, False)
    faults = [a["fault"] for n, a in events if n == "DOOR_FAULT"]
    assert faults == ["NO_STATUS"]
