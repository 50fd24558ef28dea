"""Guidance watchdog: a slew that stops making progress is reported and flown again round a new plan.

The paper's law converges from almost every start, but a slew can still stand still: at the antipode of
its target (``P(y) x_d = 0`` there: no direction is preferred), or behind a guidance defect such as the
stale aim that held fault-imu-dropout 77 deg from its target for 195 s (design note 13). Inside an
eps-layer a slow boresight is normal (the law slides it round the zone), and so is a parked one while the
target is occulted (the law holds a substitute target on purpose), so neither counts.

`ProgressWatchdog` is the pure detector: the boresight error to the commanded target has stayed above
``MIN_ERROR_DEG``, the law's rate command below ``RATE_FRACTION`` of the rate limit, the boresight
outside every eps-layer, and the error has not fallen by ``MIN_PROGRESS_DEG`` for ``law.stall_watchdog_s``
seconds. `StallRecovery` (a mixin of `fsw.guidance.Guidance`) then raises GUIDANCE_STALLED and replans
from where the boresight is: the shortest path round the zones (`path_planning`), or, when that is the
great circle itself (the antipode has every great circle as its shortest path), a detour through a
waypoint 90 deg away on the side clearest of the zones. The law still guards every zone on the new path.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.guidance.common import _norm
from fsw.guidance.path_planning import plan_path

MIN_ERROR_DEG = 1.0       # below this the slew is landing: k1 sin(error) is small by design
MIN_PROGRESS_DEG = 0.1    # an error that fell by this much in the window is progress
RATE_FRACTION = 0.05      # "near zero": 5 % of the rate limit (the law commands >= 10 % at 1 deg error)
WAYPOINT_AZIMUTHS = 24


class ProgressWatchdog:
    """Detects a slew that has stood still for ``window_s`` seconds (see the module docstring)."""

    def __init__(self, window_s: float):
        self.window_s = float(window_s)
        self.reset()

    def reset(self) -> None:
        self._since: float | None = None
        self._error0_deg = math.nan

    def update(self, t_s: float, error_deg: float, rate_rad_s: float, rate_limit_rad_s: float, in_layer: bool,
               holding: bool) -> bool:
        """One cycle; True when the slew has now stood still for the whole window (the watch restarts)."""
        idle = (self.window_s > 0.0 and not in_layer and not holding and error_deg >= MIN_ERROR_DEG
                and rate_rad_s < RATE_FRACTION * rate_limit_rad_s)
        if not idle:
            self.reset()
            return False
        if self._since is None or self._error0_deg - error_deg > MIN_PROGRESS_DEG:
            self._since, self._error0_deg = t_s, error_deg
            return False
        if t_s - self._since >= self.window_s:
            self.reset()
            return True
        return False


def detour_waypoint(y: np.ndarray, target: np.ndarray, obstacles: list, standoff_deg: float) -> np.ndarray:
    """A direction 90 deg from the boresight ``y``: of those at least ``standoff_deg`` clear of every
    obstacle, the one nearest the target; when none is clear, the one farthest from the nearest obstacle."""
    e1 = np.cross(y, [1.0, 0.0, 0.0] if abs(y[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= _norm(e1)
    e2 = np.cross(y, e1)
    az = np.linspace(0.0, 2.0 * math.pi, WAYPOINT_AZIMUTHS, endpoint=False)
    W = np.cos(az)[:, None] * e1 + np.sin(az)[:, None] * e2
    clearance = np.full(len(W), np.inf)
    for z in obstacles:
        clearance = np.minimum(clearance, z.separation_batch(W))
    free = clearance > 1.0 - math.cos(math.radians(standoff_deg))
    pick = int(np.argmax(np.where(free, W @ target, -np.inf))) if free.any() else int(np.argmax(clearance))
    return W[pick]


class StallRecovery:
    """Mixin of `fsw.guidance.Guidance`: the POINTING watchdog and its replan."""

    def _watch_progress(self, t_s: float, y: np.ndarray, error_deg: float, law_rate_rad_s: float,
                        active_zone: int) -> None:
        """Run the watchdog on this cycle's law rate (the norm of the law's rate command, after the rate
        limit and the governor); on a stall raise the event and replan from ``y``."""
        holding = self._occulted >= 0 or self._escaping
        if not self._watchdog.update(t_s, error_deg, law_rate_rad_s, self.max_rate_rad_s, active_zone >= 0,
                                     holding):
            return
        obstacles = list(self._sky_law_zones) + list(self.sky_geometry.pending)
        standoff = self.cfg.pointing.path.standoff_deg
        vertices = plan_path(y, self.target_N, obstacles, standoff, self.cfg.pointing.path.polygon_sides,
                             self._planning_polygons())
        detour = vertices is None or len(vertices) <= 2
        if detour:
            vertices = np.array([y, detour_waypoint(y, self.target_N, obstacles, standoff), self.target_N])
        self.events("GUIDANCE_STALLED", error_deg=error_deg, stalled_s=self._watchdog.window_s, detour=detour)
        self._drop_path()
        self._plan_due = False
        self._planned_t = t_s
        self._follow(vertices, y)
