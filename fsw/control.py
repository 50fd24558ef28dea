"""Rate loop and reaction-wheel allocation.

Rigid body with wheels (body frame B, Basilisk convention): ``J omega_dot = -omega x (J omega + h_w) - G tau_w
+ tau_ext``, where ``G`` (3 x n) holds the wheel spin axes, ``tau_w`` the wheel motor torques [N m]
(the torque the motor applies to its wheel; the body feels the reaction ``-G tau_w``) and
``h_w = G (Js * Omega)`` the wheels' spin momentum (wheel speeds relative to the body).

Rate loop (computed torque on the body):

    tau_B = J (kp (omega_cmd - omega) + omega_cmd_dot) + omega x (J omega + h_w)

``omega_cmd`` is first shaped to what the wheels can deliver: its acceleration is at most
``max_command_accel_deg_s2`` and changes by at most ``max_command_jerk_deg_s3`` (the jerk); the shaped
command's acceleration is the feed-forward ``omega_cmd_dot``. Without the jerk limit the law's command,
which can swing by ten degrees of direction from one cycle to the next inside an eps-layer, made the
acceleration reverse every cycle and the feed-forward J omega_cmd_dot threw the wheels from one torque
limit to the other (design note 13); with it the torque command changes by at most
J max_jerk dt plus the feedback's share a cycle. Allocation: ``tau_w = -G^+ tau_B`` with the
minimum-norm pseudo-inverse of the active (non-isolated) wheels; if any wheel exceeds its torque limit the
whole vector is scaled down by the worst ratio, which keeps the torque direction (the loop slows down
rather than turning the wrong way).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fsw.records import ControlOutput


def allocation_matrix(G: np.ndarray, active: np.ndarray) -> np.ndarray:
    """(n, 3) map from body torque to wheel motor torques: -pinv(G_active), zero rows for isolated wheels."""
    M = np.zeros((G.shape[1], 3))
    idx = np.flatnonzero(active)
    if idx.size:
        M[idx] = -np.linalg.pinv(G[:, idx])
    return M


def allocate_min_norm(G: np.ndarray, active: np.ndarray, torque_B_Nm: np.ndarray, max_torque_Nm: np.ndarray,
                      M: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Wheel motor torques that produce body torque ``torque_B_Nm`` (reaction, -G tau_w), min norm,
    uniformly scaled into the limits. Returns (tau_w (n,), scale in (0, 1])."""
    if not np.any(active):
        return np.zeros(G.shape[1]), 0.0
    if M is None:
        M = allocation_matrix(G, active)
    tau = M @ torque_B_Nm
    ratio = float(np.max(np.abs(tau) / max_torque_Nm))
    scale = 1.0 if ratio <= 1.0 else 1.0 / ratio
    return tau * scale, scale


@njit("Tuple((f8[::1], f8[::1], f8, f8[::1]))(f8, f8[::1], f8[::1], f8[::1], f8[::1], b1, f8, f8, f8,"
      " b1, f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], b1)", cache=True)
def _rate_loop(dt_s, cmd, prev, accel_prev, w, has_prev, max_accel, max_jerk, kp, ff, J, G, Js, measured_speed,
               last_speed, max_torque, M, any_active):
    """``RateController.step``'s arithmetic (one compiled call per cycle: the numpy version cost ~40 us of
    small-array calls). ``measured_speed``: this cycle's wheel speeds, NaN where none was reported (the
    last known, ``last_speed``, is kept for it). Returns (torque_B, tau_w, scale, shaped); the controller's
    state is updated in place (fewer arrays to hand back): ``accel_prev`` becomes the shaped command's
    acceleration, ``last_speed`` the wheel speeds used. The expressions and summation orders are those of
    the numpy reference (tests/fsw/test_control.py).

    ``max_jerk`` 0: the shaped command steps towards ``cmd`` by at most ``max_accel dt`` (its acceleration
    may reverse from one cycle to the next). ``max_jerk`` > 0: its acceleration heads for
    ``kp (cmd - shaped)`` (at most ``max_accel``) and changes by at most ``max_jerk dt`` a cycle."""
    if max_jerk > 0.0:
        a_des = kp * (cmd - prev)
        na = math.sqrt(a_des[0] * a_des[0] + a_des[1] * a_des[1] + a_des[2] * a_des[2])
        if na > max_accel:
            a_des *= max_accel / na
        da = a_des - accel_prev
        nd = math.sqrt(da[0] * da[0] + da[1] * da[1] + da[2] * da[2])
        if nd > max_jerk * dt_s:
            da *= max_jerk * dt_s / nd
        step = (accel_prev + da) * dt_s
    else:
        step = cmd - prev
        max_step = max_accel * dt_s
        norm = math.sqrt(step[0] * step[0] + step[1] * step[1] + step[2] * step[2])
        if norm > max_step:
            step *= max_step / norm
    shaped = prev + step
    accel = step / dt_s
    for i in range(3):
        accel_prev[i] = accel[i]  # read above (jerk limit) before it is overwritten here
    wheel_speed = last_speed
    for i in range(wheel_speed.shape[0]):
        s = measured_speed[i]
        if math.isfinite(s):
            wheel_speed[i] = s
    cmd_dot = accel if (ff and has_prev) else np.zeros(3)
    h_w = G @ (Js * wheel_speed)
    h = J @ w + h_w
    gyro = np.array([w[1] * h[2] - w[2] * h[1], w[2] * h[0] - w[0] * h[2], w[0] * h[1] - w[1] * h[0]])
    torque = J @ (kp * (shaped - w) + cmd_dot) + gyro
    if not any_active:
        return torque, np.zeros(G.shape[1]), 0.0, shaped
    tau = M @ torque
    ratio = np.max(np.abs(tau) / max_torque)
    scale = 1.0 if ratio <= 1.0 else 1.0 / ratio
    return torque, tau * scale, scale, shaped


class RateController:
    """Rate loop + allocation for the configured wheels; `step` once per GNC cycle."""

    def __init__(self, cfg):
        sc = cfg.spacecraft
        # C order: the compiled rate loop takes contiguous arrays
        self.J = np.ascontiguousarray(sc.inertia_B_kgm2, dtype=float)
        self.G = np.ascontiguousarray(np.array([w.axis_B for w in sc.wheels], dtype=float).T)
        self.Js = np.array([w.spin_inertia_kgm2 for w in sc.wheels])
        self.max_torque = np.array([w.max_torque_Nm for w in sc.wheels])
        self.max_speed = np.array([w.max_speed_rad_s for w in sc.wheels])
        self.n = self.G.shape[1]
        self.kp = cfg.control.rate_bandwidth_rad_s
        self.ff = cfg.control.feedforward_command_rate
        self.max_accel = math.radians(cfg.control.max_command_accel_deg_s2)
        jerk = cfg.control.max_command_jerk_deg_s3
        # auto: the commanded acceleration changes no faster than the loop follows it (full scale in 1 / kp)
        self.max_jerk = self.kp * self.max_accel if jerk == "auto" else math.radians(float(jerk))
        self.active = np.ones(self.n, dtype=bool)
        self.M = allocation_matrix(self.G, self.active)
        self._any_active = True
        self.reset()

    def reset(self) -> None:
        self._omega_cmd_prev: np.ndarray | None = None
        self._accel_prev = np.zeros(3)
        self.wheel_speed = np.zeros(self.n)

    def isolate(self, wheel: int) -> bool:
        """Remove a wheel from allocation; refuses (False) if the rest could not span 3-D."""
        if not self.active[wheel]:
            return True
        trial = self.active.copy()
        trial[wheel] = False
        if np.linalg.matrix_rank(self.G[:, trial], tol=1e-6) < 3:
            return False
        self.active = trial
        self.M = allocation_matrix(self.G, self.active)
        self._any_active = bool(self.active.any())
        return True

    def restore(self, wheel: int, active: bool = True) -> None:
        """Put an isolated wheel back into allocation (flown open loop when its status is lost), or with
        ``active`` False take it out whatever the rest can span (undoing a restore)."""
        self.active[wheel] = active
        self.M = allocation_matrix(self.G, self.active)
        self._any_active = bool(self.active.any())

    # share of the worst-axis torque the slew may use: the rest is for feedback, gyroscopic terms and
    # disturbances (the default spacecraft's 0.15 deg/s^2 is 0.79 of its four wheels' 0.19)
    AUTHORITY_FRACTION = 0.8
    # wheel speed the slews may use, as a fraction of the limit (the rest is FDIR's WHEEL_SPEED margin)
    MOMENTUM_FRACTION = 0.9

    def slew_authority(self) -> tuple[float, float]:
        """(angular acceleration [deg/s^2], body rate [deg/s]) the active wheels can give about the worst
        body axis, less the reserves: the torque share AUTHORITY_FRACTION, and the momentum left between
        each wheel's present speed and MOMENTUM_FRACTION of its limit."""
        from gnc.wheels import worst_axis_authority

        a = self.active
        headroom = self.Js[a] * np.maximum(0.0, self.MOMENTUM_FRACTION * self.max_speed[a] - np.abs(self.wheel_speed[a]))
        accel, rate = worst_axis_authority(self.J, self.G[:, a].T, self.max_torque[a], headroom)
        return math.degrees(self.AUTHORITY_FRACTION * accel), math.degrees(rate)

    @property
    def isolated_mask(self) -> int:
        return sum(1 << i for i, active in enumerate(self.active.tolist()) if not active)

    def step(self, dt_s: float, omega_cmd_BN_B: np.ndarray, omega_BN_B: np.ndarray, wheel_speed_rad_s: np.ndarray | None = None) -> ControlOutput:
        """One cycle of the rate loop; ``wheel_speed_rad_s`` (NaN for a wheel without a report, None: no
        reports at all) keeps the last known speed where there is none."""
        ws = self.wheel_speed if wheel_speed_rad_s is None else np.ascontiguousarray(wheel_speed_rad_s, dtype=float)
        cmd = np.ascontiguousarray(omega_cmd_BN_B, dtype=float)
        w = np.ascontiguousarray(omega_BN_B, dtype=float)
        has_prev = self._omega_cmd_prev is not None
        prev = self._omega_cmd_prev if has_prev else w
        torque, tau_w, scale, shaped = _rate_loop(
            float(dt_s), cmd, prev, self._accel_prev, w, has_prev, self.max_accel, float(self.max_jerk), float(self.kp),
            bool(self.ff), self.J, self.G, self.Js, ws, self.wheel_speed, self.max_torque, self.M, self._any_active)
        self._omega_cmd_prev = shaped
        return ControlOutput(torque, tau_w, scale, shaped)

    def hold(self, wheel_speed_rad_s: np.ndarray | None = None) -> ControlOutput:
        """A cycle without the rate loop (DETUMBLE): zero torque to every wheel, the speeds they report kept
        as `step` keeps them; the next `step` shapes its command from the measured rate again."""
        if wheel_speed_rad_s is not None:
            ws = np.asarray(wheel_speed_rad_s, dtype=float)
            known = np.isfinite(ws)
            self.wheel_speed[known] = ws[known]
        self._omega_cmd_prev = None
        self._accel_prev = np.zeros(3)
        zero = np.zeros(3)
        return ControlOutput(zero, np.zeros(self.n), 1.0, zero)
