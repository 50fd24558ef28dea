"""Slew limits that keep the keep-out promise on the real spacecraft, not only on the paper's kinematics.

The paper's law keeps ``ydot = P(y) u`` outside the inflated zones; the real boresight lags the command.
Stopping from the rate ``w`` takes the braking distance

    b(w) = w^2 / (2 a) + 1.5 w / k_p        [angle]

with ``a`` the angular acceleration the rate loop may command (`control.max_command_accel_deg_s2`, or
less when the remaining wheels give less), ``1 / k_p`` the rate loop's lag (``k_p`` its bandwidth) and
``w / (2 k_p)`` the command's own jerk-limited start of the braking (`fsw.control`: the acceleration
reaches ``a`` in ``a / j = 1 / k_p`` with the automatic jerk limit, which costs ``w a / (2 j)``).
Two rules use it, one function each, shared by the flight software and the ground's `config check`:

* `braking_problem` (command and load-time rule): a rate limit whose braking distance exceeds what the
  inflated margin and the law's eps-layer leave (``margin - reserve + layer(eps)``) is refused, with the
  reason code ``BRAKING_DISTANCE``. The law turns the boresight across its eps-layer, so a loop that can
  stop within layer + margin follows it out of the zone. k1 does not enter: past saturation the law's
  speed is the rate limit whatever k1 is, below it the law is slower.
* `rate_for_distance_deg_s` (per-cycle governor): the commanded body rate is scaled down, as a whole, to
  the largest rate whose braking distance fits in the boresight's physical margin minus the reserve.
  A positive scalar factor is a time scaling: it changes the speed along the law's path, never the path,
  so the paper's invariance and convergence carry over (as for the rate limit itself). It covers what the
  command rule cannot see: an eps-layer thinner than the one it assumed (auto eps near close zones), a
  wheel lost mid-slew, SAFE mode and recovery manoeuvres.

The reserve (``BRAKING_RESERVE_DEG``) is the part of the physical margin the loop must not consume:
the onboard Moon ephemeris error (0.3 deg) and the attitude estimate's (3 sigma ~0.01 deg with a star
tracker), rounded up. Design note 12 in docs/design-notes.md.
"""
from __future__ import annotations

import math

import numpy as np

BRAKING_RESERVE_DEG = 0.5
BRAKING_REASON = "BRAKING_DISTANCE"
# the rate loop's lag (1 / k_p) and the jerk-limited command's (1 / (2 k_p)), in loop time constants
LAG_TIME_CONSTANTS = 1.5


def braking_distance_deg(rate_deg_s: float, accel_deg_s2: float, bandwidth_rad_s: float) -> float:
    """Angle [deg] the body turns while stopping from ``rate_deg_s`` at ``accel_deg_s2`` after the rate
    loop's and the jerk limit's lag ``1.5 / bandwidth_rad_s`` [s]."""
    return rate_deg_s * rate_deg_s / (2.0 * accel_deg_s2) + LAG_TIME_CONSTANTS * rate_deg_s / bandwidth_rad_s


def armable(law_margin_deg, closing_deg_s, margin_deg: float, accel_deg_s2: float, bandwidth_rad_s: float):
    """Whether a zone kept for inertial targets may be armed (scalars or arrays alike): the boresight
    ``law_margin_deg`` outside the zone as the law sees it (inflated by ``margin_deg``), and able to stop
    from the rate it closes on it within the inflation less the braking reserve. The flight software's
    rule (`PointingGuidance.armable`) and the judge's on the truth (`hil_sim.sil.judge`)."""
    stop = braking_distance_deg(np.maximum(closing_deg_s, 0.0), accel_deg_s2, bandwidth_rad_s)
    return (law_margin_deg > 0.0) & (stop <= law_margin_deg + margin_deg - BRAKING_RESERVE_DEG)


def rate_for_distance_deg_s(distance_deg: float, accel_deg_s2: float, bandwidth_rad_s: float) -> float:
    """Largest rate [deg/s] whose braking distance is at most ``distance_deg`` (0 when it is not positive):
    the positive root of w^2 / (2 a) + w / k_p = d."""
    if not distance_deg > 0.0 or not accel_deg_s2 > 0.0:
        return 0.0
    lag = LAG_TIME_CONSTANTS / bandwidth_rad_s
    return accel_deg_s2 * (math.sqrt(lag * lag + 2.0 * distance_deg / accel_deg_s2) - lag)


def layer_angle_deg(eps: float) -> float:
    """Angular depth [deg] of an eps-layer (d_s = 1 - cos angle)."""
    return math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - eps))))


def allowed_braking_deg(margin_deg: float, eps: float) -> float:
    """Braking distance [deg] a slew may need: the inflation margin less the reserve, plus the eps-layer."""
    return margin_deg - BRAKING_RESERVE_DEG + layer_angle_deg(eps)


def braking_problem(rate_limit_deg_s: float, accel_deg_s2: float, bandwidth_rad_s: float, margin_deg: float,
                    eps: float) -> str | None:
    """None when stopping from ``rate_limit_deg_s`` fits in the inflated margin and the eps-layer, else the
    rejection reason, starting with the reason code ``BRAKING_DISTANCE``."""
    need = braking_distance_deg(rate_limit_deg_s, accel_deg_s2, bandwidth_rad_s)
    allowed = allowed_braking_deg(margin_deg, eps)
    if need <= allowed:
        return None
    fits = rate_for_distance_deg_s(allowed, accel_deg_s2, bandwidth_rad_s)
    return (f"{BRAKING_REASON}: braking from {rate_limit_deg_s:g} deg/s at {accel_deg_s2:.3g} deg/s^2 takes "
            f"{need:.2f} deg, margin and eps-layer allow {allowed:.2f} deg (rate limit <= {fits:.3g} deg/s)")


def rule_eps(eps_setting: float | str, eps_max_used: float) -> float:
    """The eps-layer the braking rule may credit: the cap of the automatic eps, and never more for a fixed
    one (eps 0.99 would credit an 89 deg layer: SET_GAINS with 4 deg/s was accepted and the true body rate
    reached 3.33 deg/s, 333 % of the configured limit)."""
    return eps_max_used if eps_setting == "auto" else min(float(eps_setting), eps_max_used)


SENSOR_REASON = "RATE_ABOVE_SENSOR_LIMIT"


def sensor_rate_problem(rate_limit_deg_s: float, star_tracker_max_rate_deg_s: float,
                        imu_range_rad_s: float) -> str | None:
    """None when the sensors follow ``rate_limit_deg_s`` (the star tracker still gives an attitude, the
    gyro stays in range), else the rejection reason, starting with ``RATE_ABOVE_SENSOR_LIMIT``."""
    gyro_deg_s = math.degrees(imu_range_rad_s)
    if rate_limit_deg_s <= min(star_tracker_max_rate_deg_s, gyro_deg_s):
        return None
    return (f"{SENSOR_REASON}: {rate_limit_deg_s:g} deg/s is above what the sensors follow (star tracker "
            f"{star_tracker_max_rate_deg_s:g} deg/s, gyro range {gyro_deg_s:.3g} deg/s)")


def rate_limit_problem(rate_limit_deg_s: float, eps: float | str, cfg, accel_deg_s2: float) -> tuple[str, str] | None:
    """The onboard rules for a rate limit, with the flight software's configuration ``cfg`` (FswConfig) and
    the command acceleration in force (``cfg.control.max_command_accel_deg_s2`` until a wheel is lost):
    None when it may be flown, else (reason code, reason). One function for SET_GAINS onboard and for
    `keepout config check`, which applies it to the configured limit and to every SET_GAINS of the timeline."""
    problem = braking_problem(rate_limit_deg_s, accel_deg_s2, cfg.control.rate_bandwidth_rad_s, cfg.law.margin_deg,
                              rule_eps(eps, cfg.law.eps_max_used))
    if problem is not None:
        return BRAKING_REASON, problem
    sc = cfg.spacecraft
    problem = sensor_rate_problem(rate_limit_deg_s, sc.star_tracker_max_rate_deg_s, sc.imu_range_rad_s)
    return None if problem is None else (SENSOR_REASON, problem)


class GainsRefused(ValueError):
    """SET_GAINS refused: ``code`` is the acknowledgement's reason code (comms.dictionary.TC_REASONS)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message if message.startswith(code) else f"{code}: {message}")
        self.code = code
