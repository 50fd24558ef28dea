"""Path following for POINTING slews: the law's aim moved along the planned path (`path_planning`),
a look-ahead beyond the boresight, and the path replanned when a moving zone comes onto it. The paper's
law still guards every zone; the path only chooses which way round (design note 10).
"""
from __future__ import annotations

import math

import numpy as np

from fsw.guidance.common import angle_deg
from fsw.guidance.path_planning import PathFollower, advance_aim, path_length_deg, plan_path


class PathFollowing:
    """Mixin of `fsw.guidance.Guidance`: the planned path and the law's aim on it."""

    # ----------------------------------------------------------------------------- path guidance
    def _drop_path(self) -> None:
        """Forget the planned path and the law built for its aim; the next cycle plans from the boresight.

        The law is rebuilt only when its key is cleared (or a zone moved, or the aim advanced). Dropping
        the path without clearing it left the law steering to the old path point: a mode change back to
        POINTING during a planned slew (fault-imu-dropout: SAFE at 60 s, POINTING again at 80 s) brought
        the boresight to the point the path had reached and held it there, 77 deg from the target, until
        the Moon had moved far enough to force a rebuild 195 s later (design note 13)."""
        self._follower = None
        self._aim, self._aim_k = self.target_N, -1
        self._plan_due = True
        self._sky_law_key = None

    def _plan(self, t_s: float, y: np.ndarray, obstacles: list) -> None:
        """Plan the slew from the boresight ``y`` round ``obstacles`` (the law's zones after merging, and
        the shapes of pairs about to merge); follow it only when the great circle is blocked. A plan that
        fails keeps the path being followed (if any), to be checked again a replan period later: the law
        keeps every zone safe either way."""
        self._plan_due = False
        cfg = self.cfg.pointing.path
        if not cfg.enabled:
            return
        self._planned_t = t_s
        vertices = plan_path(y, self.target_N, obstacles, cfg.standoff_deg, cfg.polygon_sides, self._planning_polygons())
        if vertices is None:
            return
        if len(vertices) <= 2:
            self._follower, self._aim, self._aim_k = None, self.target_N, -1
            return
        replanned = self._follower is not None
        self._follow(vertices, y)
        if not replanned:
            length = path_length_deg(vertices)
            self.events("PATH_PLANNED", length_deg=length, detour_deg=length - angle_deg(y, self.target_N),
                        legs=len(vertices) - 1)

    def _planning_polygons(self) -> dict:
        """The planner's polygons of the zones planned round so far (`plan_path`'s ``kept``): a replan
        round the same zone objects does not rebuild them."""
        kept = getattr(self, "_planning_polygons_kept", None)
        if kept is None:
            kept = self._planning_polygons_kept = {}
        return kept

    def _follow(self, vertices: np.ndarray, y: np.ndarray) -> None:
        """Fly the path ``vertices`` (boresight ``y`` at its start): the law's aim moves along it."""
        # far enough ahead that the law's rate, k1 sin(angle to its target), stays at the rate limit
        saturating = math.degrees(math.asin(min(1.0, 1.25 * self.max_rate_rad_s / self.k1)))
        self._follower = PathFollower(vertices, max(self.cfg.pointing.path.lookahead_deg, saturating))
        self._aim_k = -1
        self._advance_aim(y)

    def _path_blocked(self, t_s: float, obstacles: list) -> bool:
        """Every replan_period_s: does a zone (they move) now come within half the standoff of the rest
        of the path? Then it is planned again from the boresight. A path that is still clear is kept: a
        plan from a boresight that has cut a corner towards a zone would hug that zone."""
        f, cfg = self._follower, self.cfg.pointing.path
        if f is None or t_s - self._planned_t < cfg.replan_period_s:
            return False
        self._planned_t = t_s
        rest = f.path[f.index:]
        d = 1.0 - math.cos(math.radians(0.5 * cfg.standoff_deg))
        return any(bool(np.any(z.separation_batch(rest) <= d)) for z in obstacles)

    def _aim_moved(self, t_s: float, y: np.ndarray) -> bool:
        """True when the law must be rebuilt: the aim moved along the path, the path ended, or it is time
        to check the path against the moved zones."""
        f = self._follower
        if f is None:
            return False
        if t_s - self._planned_t >= self.cfg.pointing.path.replan_period_s:
            return True  # time to check the path against the zones as they are now (`_path_blocked`)
        return self._advance_aim(y)

    def _advance_aim(self, y: np.ndarray) -> bool:
        """Move the law's aim to the path point ahead of the boresight ``y``; True if it moved."""
        moved, self._follower, aim, self._aim_k = advance_aim(self._follower, y, self._aim_k, self.target_N)
        if moved:
            self._aim = aim
        return moved
