"""keepout's watch over a plug-in (`fsw.plugins`): the plug-in proposes, keepout's keep-out protection decides.

`GuardedGuidance` is keepout's `Guidance` (mode logic, zones, margins, SAFE) with the plug-in's law in
place of keepout's in POINTING and QUATERNION. Every cycle keepout's own step runs first, so the keep-out
margins the FDIR watches are keepout's, computed on the estimate; then the plug-in's command, limited to
keepout's rate limit and braking rule, replaces keepout's. The braking rule is keepout's governor
(`fsw.guidance.slew_limits`): while a zone comes closer the command is held to the rate from which the rate
loop can still stop before that zone's physical boundary, so what takes over at the guard limit can stop
outside the zone. The guard stops the plug-in for the rest of the run when

* a keep-out margin falls below the guard limit, ``max(law.margin_deg, fdir.keepout_yellow.limit)``, and
  is still falling: keepout's own law never takes the boresight into that layer;
* the plug-in raises, or returns anything but three finite numbers.

Then POINTING enters SAFE (rate damping first); QUATERNION flies on with keepout's own law, because SAFE's
Sun acquisition knows no forbidden-attitude zone (a plug-in stopped 2 deg from one in demo-quaternion was
turned through it by SAFE, 0.13 deg deep; keepout's law kept 0.8 deg).

`GuardedEstimator` runs keepout's MEKF beside the plug-in estimator every cycle; FDIR keeps reading the
MEKF's innovation. The plug-in's attitude is flown while it stays within ``estimator.innovation_gate_deg``
of the MEKF's (the angle beyond which keepout distrusts a star-tracker fix); past it, or on an exception or
a malformed estimate, the plug-in is stopped and the MEKF's estimate is flown from that cycle on.

A stop raises PLUGIN_STOPPED with the reason; PLUGIN_STARTED tells at start-up which plug-in flies.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

import numpy as np

from fsw import records
from fsw.estimation import AttitudeEstimator
from fsw.guidance import Guidance, GuidanceOutput
from fsw.guidance.common import _saturate
from fsw.guidance.slew_limits import BRAKING_RESERVE_DEG, rate_for_distance_deg_s
from fsw.plugins import AttitudeEstimate, EstimatorInput, GuidanceInput, Plugin
from fsw.records import SensorSnapshot

_NAN3, _NAN4 = np.full(3, np.nan), np.full(4, np.nan)


def _fault_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


class GuardedGuidance(Guidance):
    """keepout's guidance flying a plug-in's law in POINTING and QUATERNION, under the guard above.

    ``request_safe``: the flight software's way into SAFE (it reports the mode change)."""

    def __init__(self, cfg: Any, plugin: Plugin, request_safe: Callable[[], None],
                 events: Callable[..., Any] | None = None):
        super().__init__(cfg, events=events)
        self.plugin = plugin
        self._request_safe = request_safe
        self.guard_limit_deg = max(cfg.law.margin_deg, cfg.fdir.keepout_yellow.limit)
        self.armed = False  # off during the start-up warm-up, which steps every mode on a made-up state
        self.stopped = False
        self.commands = 0  # cycles flown on the plug-in's command
        self._last_margins: list[float] = []

    def arm(self) -> None:
        self.armed = True

    def step(self, t_s: float, dt_s: float, q_NB: np.ndarray | None, omega_BN_B: np.ndarray) -> GuidanceOutput:
        out = super().step(t_s, dt_s, q_NB, omega_BN_B)
        if not self.armed or self.stopped or q_NB is None or self.mode in ("SAFE", "DETUMBLE"):
            self._last_margins = []
            return out
        nearest = self._nearest_closing_deg(out.margins_deg)
        if nearest < self.guard_limit_deg:
            return self._stop(f"margin {nearest:.2f} deg below the guard limit {self.guard_limit_deg:.2f} "
                              "deg and falling", t_s, dt_s, q_NB, omega_BN_B, out)
        try:
            cmd = np.asarray(self.plugin.impl.command(self._input(out, t_s, dt_s, q_NB, omega_BN_B)), dtype=float)
        except Exception as exc:  # noqa: BLE001 - a user's law that fails is stopped, not the flight software
            return self._stop(_fault_text(exc), t_s, dt_s, q_NB, omega_BN_B, out)
        if cmd.shape != (3,) or not np.isfinite(cmd).all():
            return self._stop(f"command {cmd.tolist()!r} is not three finite numbers", t_s, dt_s, q_NB, omega_BN_B, out)
        self.commands += 1
        return dataclasses.replace(out, omega_cmd_BN_B=_saturate(cmd, min(self.max_rate_rad_s, self._braking_rate(nearest))))

    def _nearest_closing_deg(self, margins_deg) -> float:
        """The smallest margin [deg] that fell since the last cycle (inf when none did)."""
        margins = list(margins_deg)
        prev, self._last_margins = self._last_margins, margins
        if len(prev) != len(margins):
            return math.inf
        return min((m for m, p in zip(margins, prev) if m < p), default=math.inf)

    def _braking_rate(self, nearest_deg: float) -> float:
        """The rate [rad/s] from which the rate loop stops within ``nearest_deg`` of margin, less keepout's
        braking reserve (a margin on S^3 is half the body rotation)."""
        if nearest_deg == math.inf:
            return math.inf
        per_deg = 2.0 if self.mode == "QUATERNION" else 1.0
        room = per_deg * nearest_deg - BRAKING_RESERVE_DEG
        return math.radians(rate_for_distance_deg_s(room, self.accel_deg_s2, self.bandwidth_rad_s))

    def _input(self, out: GuidanceOutput, t_s: float, dt_s: float, q_NB: np.ndarray, omega: np.ndarray) -> GuidanceInput:
        pointing = self.mode == "POINTING"
        if pointing:
            self._settle_sky()
            zones = tuple(s.law for s in self.slots if s.law is not None)
        else:
            zones = tuple(self.s3_law_zones)
        sun, moon = out.sun_N, out.moon_N
        if not np.isfinite(sun).all():  # QUATERNION's output carries no sky: the plug-in gets it all the same
            sky = self.ephem.directions(t_s)
            sun, moon = sky["sun"], sky["moon"]
        return GuidanceInput(
            t_s=t_s, dt_s=dt_s, mode=self.mode, q_NB=np.array(q_NB, dtype=float), omega_BN_B=np.array(omega, dtype=float),
            boresight_B=self.b_B.copy(), target_N=self.target_N.copy() if pointing else _NAN3.copy(),
            q_target_NB=_NAN4.copy() if pointing else self.q_target.copy(), zones=zones,
            sun_N=np.array(sun, dtype=float), moon_N=np.array(moon, dtype=float),
            max_rate_rad_s=self.max_rate_rad_s)

    def _stop(self, reason: str, t_s: float, dt_s: float, q_NB: np.ndarray, omega: np.ndarray,
              own: GuidanceOutput) -> GuidanceOutput:
        """Stop the plug-in. POINTING enters SAFE (this cycle already SAFE's command). QUATERNION flies on
        with keepout's own law (``own``, this cycle's): SAFE's Sun acquisition knows no forbidden-attitude
        zone and can turn the spacecraft through one, while the law steers round them and its governor brakes."""
        self.stopped = True
        self.events("PLUGIN_STOPPED", kind="GUIDANCE", name=self.plugin.name[:40], reason=reason[:110])
        if self.mode == "QUATERNION":
            return own
        self._request_safe()
        return super().step(t_s, dt_s, q_NB, omega)


class GuardedEstimator:
    """The attitude estimate the GNC cycle reads (`AttitudeEstimator`'s attributes), from a plug-in watched
    by keepout's MEKF (``reference``), which runs every cycle whatever the plug-in does."""

    def __init__(self, cfg: Any, q_BS: np.ndarray, plugin: Plugin, event: Callable[..., Any]):
        self.reference = AttitudeEstimator(cfg, q_BS)
        self.plugin = plugin
        self._event = event
        self._q_BS = np.asarray(q_BS, dtype=float).copy()
        self.limit_deg = cfg.innovation_gate_deg
        self.stopped = False
        self.updates = 0  # cycles flown on the plug-in's estimate
        self.initialized = False
        self.q_NB = np.array([1.0, 0.0, 0.0, 0.0])
        self.omega_BN_B = np.zeros(3)

    # the MEKF's own figures: bias, covariance and coasting time are not part of the plug-in interface
    @property
    def bias_B(self) -> np.ndarray:
        return self.reference.bias_B

    @property
    def P(self) -> np.ndarray:
        return self.reference.P

    @property
    def coasting_s(self) -> float:
        return self.reference.coasting_s

    @property
    def cov_trace_rad2(self) -> float:
        return self.reference.cov_trace_rad2

    def reset(self) -> None:
        self.reference.reset()
        self.initialized = False
        if not self.stopped:
            try:
                self.plugin.impl.reset()
            except Exception as exc:  # noqa: BLE001
                self._stop(_fault_text(exc))

    def update(self, sensors: SensorSnapshot) -> records.AttitudeEstimate:
        """`AttitudeEstimator.update`'s contract: the plug-in's attitude and rate (the MEKF's once it is
        stopped), with the MEKF's innovation [deg] for FDIR."""
        ref = self.reference
        innovation_deg = ref.update(sensors).innovation_deg
        if not self.stopped:
            self._plugin_update(sensors)
        if self.stopped:
            self.q_NB, self.omega_BN_B, self.initialized = ref.q_NB, ref.omega_BN_B, ref.initialized
        return records.AttitudeEstimate(self.q_NB, self.omega_BN_B, self.initialized, innovation_deg)

    def _plugin_update(self, sensors: SensorSnapshot) -> None:
        q_NS = sensors.q_NS
        sample = EstimatorInput(dt_s=sensors.dt_s, gyro_B=np.array(sensors.gyro_B, dtype=float).reshape(-1, 3),
                                q_NS=None if q_NS is None else np.asarray(q_NS, dtype=float) / sensors.q_NS_norm,
                                star_tracker_latency_s=sensors.st_latency_s, q_BS=self._q_BS.copy())
        try:
            est = self.plugin.impl.update(sample)
        except Exception as exc:  # noqa: BLE001 - a user's estimator that fails is stopped, not the flight software
            self._stop(_fault_text(exc))
            return
        problem = _estimate_problem(est)
        if problem is None and est.q_NB is not None and self.reference.initialized:
            q = np.asarray(est.q_NB, dtype=float)
            angle = math.degrees(2.0 * math.acos(min(1.0, abs(float(q @ self.reference.q_NB)) / float(np.linalg.norm(q)))))
            if angle > self.limit_deg:
                problem = f"estimate {angle:.2f} deg from keepout's MEKF (limit {self.limit_deg:.2f} deg)"
        if problem is not None:
            self._stop(problem)
            return
        self.updates += 1
        self.initialized = est.q_NB is not None
        if self.initialized:
            q = np.asarray(est.q_NB, dtype=float)
            self.q_NB = q / float(np.linalg.norm(q))
        self.omega_BN_B = np.asarray(est.omega_BN_B, dtype=float).copy()

    def _stop(self, reason: str) -> None:
        self.stopped = True
        self._event("PLUGIN_STOPPED", kind="ESTIMATOR", name=self.plugin.name[:40], reason=reason[:110])


def _estimate_problem(est: Any) -> str | None:
    """Why ``est`` is not a usable `AttitudeEstimate`, or None."""
    if not isinstance(est, AttitudeEstimate):
        return f"update() returned a {type(est).__name__}, not an AttitudeEstimate"
    omega = np.asarray(est.omega_BN_B, dtype=float)
    if omega.shape != (3,) or not np.isfinite(omega).all():
        return "omega_BN_B is not three finite numbers"
    if est.q_NB is not None:
        q = np.asarray(est.q_NB, dtype=float)
        if q.shape != (4,) or not np.isfinite(q).all() or not 0.5 < float(np.linalg.norm(q)) < 2.0:
            return "q_NB is not a finite quaternion near unit norm"
    return None
