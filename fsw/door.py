"""The protective aperture door: the flight software's last line in front of the instrument.

Keep-out guidance keeps the boresight out of the zones while the control can stop it; the door covers the
instrument when it cannot. Every GNC cycle `DoorController.cycle` decides from the flight software's own
view and sends DOOR_CMD (before CYCLE_DONE, so the drive takes it in the same tick):

* **close** when, for some zone, the boresight's approach would carry it within ``guard_deg`` of the
  physical zone before it stops: with approach rate v (the fall of that zone's margin since the last
  cycle, deg/s) and braking acceleration a, the reach is

      reach = v (t_close + T) + v^2 / (2 a)          (a > 0: three or more usable wheels)
      reach = v (t_close + T + coast_horizon_s)      (a = 0: the spacecraft cannot stop)

  and the door closes when margin - guard_deg <= reach (T the GNC period: the command's own delay; the
  door's closing time counts as reaction time, so the door is shut before a boresight that starts braking
  only then arrives); also when KEEP_OUT_VIOLATION is raised, while there is no attitude estimate, and
  while the mode holds it shut (``hold``: DETUMBLE, whose tumbling body cannot steer its boresight);
* **open** again only when every physical margin has been at least ``reopen_margin_deg`` (above
  ``guard_deg``: hysteresis), with no closing prediction, for ``reopen_dwell_s`` (the dwell).

DOOR_STATUS is read back: DOOR_STATE when the door reaches an end, DOOR_FAULT when the drive reports a
stall or a command timeout, when a commanded stroke is overdue (``stroke_margin`` times its known time,
plus a second), or when no status came for ``status_timeout_s``. A door failure changes nothing of the
decision: a door that does not close leaves the guidance and FDIR doing what they do anyway.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

# DOOR_STATUS.state and .fault codes (config/icd/keepout.dbc)
STATE_CLOSED, STATE_OPEN = 0, 1
FAULT_STALLED, FAULT_CMD_TIMEOUT = 1, 2
DOOR_STATE_NAMES = ("CLOSED", "OPEN", "CLOSING", "OPENING", "STOPPED")


def approach_reach_deg(v_deg_s: float, t_react_s: float, brake_deg_s2: float, coast_horizon_s: float) -> float:
    """How far [deg] a boresight approaching a zone at ``v_deg_s`` moves toward it before it stops: the
    reaction time at full rate, then braking at ``brake_deg_s2`` (0: no braking, ``coast_horizon_s`` more
    at full rate)."""
    if not v_deg_s > 0.0:
        return 0.0
    if brake_deg_s2 > 0.0:
        return v_deg_s * t_react_s + v_deg_s * v_deg_s / (2.0 * brake_deg_s2)
    return v_deg_s * (t_react_s + coast_horizon_s)


class DoorController:
    """Decides and commands the aperture door (see the module docstring).

    ``cfg``: `fsw.config.DoorConfig`; ``driver``: the bus driver (`FswBusDriver`: ``keep_latest``,
    ``latest``, ``send_frame``); ``event(name, **args)``: the flight software's event sink.
    """

    def __init__(self, cfg: Any, period_s: float, driver: Any, event: Callable[..., object]) -> None:
        self.cfg = cfg
        self.period_s = float(period_s)
        self.driver = driver
        self.event = event
        driver.keep_latest("DOOR_STATUS")
        icd = driver.icd
        self._cols = [icd.column("DOOR_STATUS", s) for s in ("position", "state", "commanded_open", "fault")]
        self.command_open: bool | None = None  # None: not decided yet (the first status tells the drive's)
        self.reason = "NONE"
        self.closes = 0
        self.opens = 0
        self._clear_since: float | None = None
        self._prev: list[float] | None = None
        self._stroke_start: float | None = None  # when the current command's stroke began
        self._state = -1
        self._faults_seen: set[str] = set()
        self.position_pct = math.nan
        self.status_t: float | None = None  # onboard time at which the newest DOOR_STATUS was first seen
        self._first_t: float | None = None  # the first cycle's time (no status yet: counted from it)
        self._status_rx = -math.inf  # its reception time as the driver stamped it (its own clock in real time)

    # ------------------------------------------------------------------------------------- decision
    def predicted_entry(self, margins_deg: Sequence[float], brake_deg_s2: float) -> tuple[int, float, float]:
        """(zone, margin [deg], reach [deg]) of the zone the boresight would come within ``guard_deg`` of
        before stopping (the smallest margin - reach), zone -1 when none. Updates the margins kept for the
        next cycle's approach rates."""
        cfg, dt = self.cfg, self.period_s
        prev = self._prev
        if prev is not None and len(prev) != len(margins_deg):
            prev = None
        margins = [float(m) for m in margins_deg]
        self._prev = margins
        t_react = cfg.close_time_s + dt
        worst, worst_k, worst_m, worst_reach = math.inf, -1, math.nan, math.nan
        for k, m in enumerate(margins):
            if m != m:  # NaN: no margin for this zone this cycle
                continue
            p = prev[k] if prev is not None else math.nan
            v = (p - m) / dt if p == p else 0.0
            reach = approach_reach_deg(v, t_react, brake_deg_s2, cfg.coast_horizon_s)
            slack = m - cfg.guard_deg - reach
            if slack <= 0.0 and slack < worst:
                worst, worst_k, worst_m, worst_reach = slack, k, m, reach
        return worst_k, worst_m, worst_reach

    def cycle(self, t_s: float, tick: int, margins_deg: Sequence[float], zone_bodies: Sequence[str],
              attitude_known: bool, brake_deg_s2: float, violation: bool, hold: str | None = None) -> bool:
        """One GNC cycle: read the status, decide, send DOOR_CMD. ``margins_deg``: the boresight's signed
        physical margins to the sky zones [deg] (NaN: unknown); ``brake_deg_s2``: the braking acceleration
        the control can give (0 with fewer than three usable wheels); ``violation``: KEEP_OUT_VIOLATION is
        raised; ``hold``: a reason to keep the door shut whatever the margins (the mode's: DETUMBLE). Returns
        the command sent (True: open)."""
        if self._first_t is None:
            self._first_t = t_s
        self._read_status(t_s)
        if self.command_open is None:  # no status yet: the door is taken as closed
            self._command(False, t_s, "NONE")
        zone, margin, reach = self.predicted_entry(margins_deg, brake_deg_s2)
        if hold is not None:
            reason = hold
        elif not attitude_known:
            reason = "NO_ATTITUDE"
        elif violation:
            reason = "KEEP_OUT_VIOLATION"
        elif zone >= 0:
            reason = "PREDICTED_ENTRY"
        else:
            reason = None
        if reason is not None:
            self._clear_since = None
            if self.command_open:
                body = zone_bodies[zone] if 0 <= zone < len(zone_bodies) else "INERTIAL"
                self.event("DOOR_CLOSING", reason=reason, zone=zone, body=body,
                           margin_deg=margin if zone >= 0 else _finite_min(margins_deg),
                           reach_deg=reach if zone >= 0 else math.nan)
                self.closes += 1
            self._command(False, t_s, reason)
        else:
            finite = [float(m) for m in margins_deg if m == m]
            clear = all(m >= self.cfg.reopen_margin_deg for m in finite)
            if not clear:
                self._clear_since = None
            elif self._clear_since is None:
                self._clear_since = t_s
            if not self.command_open and clear and t_s - self._clear_since >= self.cfg.reopen_dwell_s - 1e-9:
                self.event("DOOR_OPENING", margin_deg=min(finite) if finite else math.nan,
                           dwell_s=t_s - self._clear_since)
                self.opens += 1
                self._command(True, t_s, "NONE")
        # in the wheel commands' burst, ahead of them (before CYCLE_DONE in lockstep)
        self.driver.send_frame("DOOR_CMD", {"open": 1 if self.command_open else 0, "tick_lsb": tick & 0xFFFF},
                               with_commands=True)
        self._check_faults(t_s)
        return bool(self.command_open)

    def _command(self, open_door: bool, t_s: float, reason: str) -> None:
        if self.command_open != open_door:
            self._stroke_start = t_s
        self.command_open = open_door
        self.reason = reason

    # ------------------------------------------------------------------------------------- status
    def _read_status(self, t_s: float) -> None:
        latest = self.driver.latest("DOOR_STATUS")
        if latest is None:
            return
        row, t_rx = latest
        if t_rx <= self._status_rx:
            return
        self._status_rx = t_rx
        self.status_t = t_s
        c_pos, c_state, c_cmd, c_fault = self._cols
        self.position_pct = float(row[c_pos])
        state = int(row[c_state])
        fault = int(row[c_fault])
        if self.command_open is None:
            # the drive's own command at start-up (the door as it was launched): kept until decided
            self.command_open = bool(row[c_cmd])
            self._stroke_start = t_s
        if state != self._state:
            self._state = state
            if state in (STATE_CLOSED, STATE_OPEN):
                self.event("DOOR_STATE", state=DOOR_STATE_NAMES[state], position_pct=self.position_pct)
        self._fault("STALLED", bool(fault & FAULT_STALLED))
        self._fault("COMMAND_TIMEOUT", bool(fault & FAULT_CMD_TIMEOUT))

    def _check_faults(self, t_s: float) -> None:
        cfg = self.cfg
        last = self.status_t if self.status_t is not None else self._first_t
        self._fault("NO_STATUS", t_s - last > cfg.status_timeout_s + 1e-9)
        if self._stroke_start is None or self.command_open is None:
            return
        stroke = cfg.open_time_s if self.command_open else cfg.close_time_s
        at_end = (self._state == STATE_OPEN) if self.command_open else (self._state == STATE_CLOSED)
        overdue = not at_end and t_s - self._stroke_start > cfg.stroke_margin * stroke + 1.0
        self._fault("NOT_OPEN" if self.command_open else "NOT_CLOSED", overdue)
        self._fault("NOT_CLOSED" if self.command_open else "NOT_OPEN", False)

    def _fault(self, name: str, present: bool) -> None:
        """DOOR_FAULT once per episode of ``name`` (again after it cleared)."""
        if present and name not in self._faults_seen:
            self._faults_seen.add(name)
            self.event("DOOR_FAULT", fault=name, position_pct=self.position_pct)
        elif not present:
            self._faults_seen.discard(name)


def _finite_min(values: Sequence[float]) -> float:
    finite = [float(v) for v in values if v == v]
    return min(finite) if finite else math.nan
