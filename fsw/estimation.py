"""Attitude determination: a multiplicative extended Kalman filter (MEKF).

State: the attitude estimate ``q_NB`` (scalar-first unit quaternion) and the gyro bias ``bias_B``
[rad/s]. The filter's error state is ``dx = [dtheta_B (3), dbias_B (3)]`` with the true attitude
``q_NB = q_est (x) [1, dtheta/2]`` (body-frame small rotation) and ``bias = bias_est + dbias``.

Gyro model: ``omega_meas = omega_true + bias + eta_v`` with bias random walk ``bias_dot = eta_u``;
``eta_v`` is the angle random walk density (rad/s/sqrt(Hz)), ``eta_u`` the bias random walk density
(rad/s^2/sqrt(Hz)) (Crassidis & Junkins, Optimal Estimation of Dynamic Systems, ch. 7; Markley &
Crassidis, Fundamentals of Spacecraft Attitude Determination and Control, sec. 6.2).

Star tracker: it reports ``q_NS``; with the configured mounting ``q_BS`` the measured body attitude is
``q_NB,meas = q_NS (x) q_BS^*``. The sample's own time stamp is used to bring it to the filter time with
the gyro rate (latency compensation). Without a valid, fresh sample the filter coasts on the gyro and its
covariance grows (``cov_trace_deg2``, the attitude part, is telemetered).

The numeric kernels are numba-compiled (the GNC cycle must stay well under 2 ms).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from fsw.records import AttitudeEstimate, SensorSnapshot, new_record
from gnc.attitude import quat_multiply_nb


@njit(cache=True)
def _rotvec_quat(phi):
    """Exact quaternion of the rotation vector phi (body frame)."""
    ang = math.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    out = np.empty(4)
    if ang < 1e-12:
        out[0] = 1.0
        out[1] = 0.5 * phi[0]
        out[2] = 0.5 * phi[1]
        out[3] = 0.5 * phi[2]
    else:
        s = math.sin(0.5 * ang) / ang
        out[0] = math.cos(0.5 * ang)
        out[1] = s * phi[0]
        out[2] = s * phi[1]
        out[3] = s * phi[2]
    n = math.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2 + out[3] ** 2)
    return out / n


@njit(cache=True)
def _propagate_in_place(q, bias, P, omega_meas, dt, sig_v, sig_u, PP):
    """Propagate attitude, bias and covariance over ``dt`` [s] with the gyro sample (held constant),
    overwriting ``q`` (4,) and ``P`` (6, 6), ``PP`` (6, 6) scratch: no array is allocated (ten samples a cycle
    made some hundred small allocations). The Kalman equations written plainly with numpy,
    tests/reference/mekf.py's `mekf_propagate`, give the same results to the last bit
    (tests/fsw/test_estimation.py)."""
    w0 = omega_meas[0] - bias[0]
    w1 = omega_meas[1] - bias[1]
    w2 = omega_meas[2] - bias[2]
    # _rotvec_quat(w * dt)
    p0 = w0 * dt
    p1 = w1 * dt
    p2 = w2 * dt
    ang = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    if ang < 1e-12:
        r0 = 1.0
        r1 = 0.5 * p0
        r2 = 0.5 * p1
        r3 = 0.5 * p2
    else:
        s = math.sin(0.5 * ang) / ang
        r0 = math.cos(0.5 * ang)
        r1 = s * p0
        r2 = s * p1
        r3 = s * p2
    n = math.sqrt(r0 ** 2 + r1 ** 2 + r2 ** 2 + r3 ** 2)
    r0 = r0 / n
    r1 = r1 / n
    r2 = r2 / n
    r3 = r3 / n
    # quat_multiply_nb(q, r), then normalised
    a0 = q[0] * r0 - q[1] * r1 - q[2] * r2 - q[3] * r3
    a1 = q[0] * r1 + q[1] * r0 + q[2] * r3 - q[3] * r2
    a2 = q[0] * r2 - q[1] * r3 + q[2] * r0 + q[3] * r1
    a3 = q[0] * r3 + q[1] * r2 - q[2] * r1 + q[3] * r0
    nq = math.sqrt(a0 ** 2 + a1 ** 2 + a2 ** 2 + a3 ** 2)
    q[0] = a0 / nq
    q[1] = a1 / nq
    q[2] = a2 / nq
    q[3] = a3 / nq
    # A = I - [w x] dt, element by element as np.eye(3) - skew(w) * dt
    A00 = 1.0 - 0.0 * dt
    A01 = 0.0 - (-w2) * dt
    A02 = 0.0 - w1 * dt
    A10 = 0.0 - w2 * dt
    A11 = 1.0 - 0.0 * dt
    A12 = 0.0 - (-w0) * dt
    A20 = 0.0 - (-w1) * dt
    A21 = 0.0 - w0 * dt
    A22 = 1.0 - 0.0 * dt
    for j in range(6):
        PP[0, j] = A00 * P[0, j] + A01 * P[1, j] + A02 * P[2, j] - dt * P[3, j]
        PP[1, j] = A10 * P[0, j] + A11 * P[1, j] + A12 * P[2, j] - dt * P[4, j]
        PP[2, j] = A20 * P[0, j] + A21 * P[1, j] + A22 * P[2, j] - dt * P[5, j]
        PP[3, j] = P[3, j]
        PP[4, j] = P[4, j]
        PP[5, j] = P[5, j]
    for i in range(6):
        P[i, 0] = PP[i, 0] * A00 + PP[i, 1] * A01 + PP[i, 2] * A02 - dt * PP[i, 3]
        P[i, 1] = PP[i, 0] * A10 + PP[i, 1] * A11 + PP[i, 2] * A12 - dt * PP[i, 4]
        P[i, 2] = PP[i, 0] * A20 + PP[i, 1] * A21 + PP[i, 2] * A22 - dt * PP[i, 5]
        P[i, 3] = PP[i, 3]
        P[i, 4] = PP[i, 4]
        P[i, 5] = PP[i, 5]
    qa = sig_v * sig_v * dt + sig_u * sig_u * dt ** 3 / 3.0
    qc = -sig_u * sig_u * dt * dt / 2.0
    qb = sig_u * sig_u * dt
    for i in range(3):
        P[i, i] += qa
        P[i, 3 + i] += qc
        P[3 + i, i] += qc
        P[3 + i, 3 + i] += qb
    for i in range(6):
        for j in range(i + 1, 6):
            P[i, j] = P[j, i] = 0.5 * (P[i, j] + P[j, i])


@njit(cache=True)
def mekf_innovation(q, q_meas):
    """Small-angle innovation dtheta_B [rad] = 2 vec(q_est^* (x) q_meas), sign-fixed (double cover)."""
    qc = q.copy()
    qc[1:] = -qc[1:]
    dq = quat_multiply_nb(qc, q_meas)
    if dq[0] < 0.0:
        dq = -dq
    # exact rotation vector of dq (robust for large innovations too)
    vn = math.sqrt(dq[1] ** 2 + dq[2] ** 2 + dq[3] ** 2)
    out = np.empty(3)
    if vn < 1e-12:
        out[:] = 2.0 * dq[1:]
    else:
        ang = 2.0 * math.atan2(vn, dq[0])
        out[:] = dq[1:] * (ang / vn)
    return out


@njit(cache=True)
def mekf_update_lagged(q, bias, P, dtheta, R, lag):
    """Fuse an attitude measurement taken ``lag`` [s] ago and brought to the filter time with the
    bias-corrected gyro rate: H = [I, lag I].

    Bridging the sample with (omega_meas - bias_est) over the lag rotates it by the bias error times
    the lag as well: the innovation is dtheta + dbias lag + noise. Right after a (re)initialisation the
    bias is uncertain to ~1e-3 rad/s, and 0.1 s of it is ~20 arcsec, four times the tracker's
    cross-boresight noise: with H = [I 0] the filter took that for attitude error and left start-up
    with a bias error outside its covariance (design note 13)."""
    H = np.zeros((3, 6))
    for i in range(3):
        H[i, i] = 1.0
        H[i, 3 + i] = lag
    PHt = P @ H.T
    S = H @ PHt + R
    K = PHt @ np.linalg.inv(S)
    dx = K @ dtheta
    IKH = np.eye(6) - K @ H
    # Joseph form keeps P symmetric positive definite in single steps with large gains.
    Pn = IKH @ P @ IKH.T + K @ R @ K.T
    Pn = 0.5 * (Pn + Pn.T)
    qn = quat_multiply_nb(q, _rotvec_quat(dx[0:3]))
    qn /= math.sqrt(qn[0] ** 2 + qn[1] ** 2 + qn[2] ** 2 + qn[3] ** 2)
    return qn, bias + dx[3:6], Pn


@njit(cache=True)
def _mekf_fuse(q, bias, P, omega_last, omega_bridge, bridge_var, initialized, has_st, q_NS, q_SB, st_latency, max_age,
               gate_deg, R_st, P0):
    """The estimator cycle after the propagation: the rate estimate (``omega_last`` minus the bias) and the
    star tracker's fusion. ``omega_bridge``: the mean measured rate over the star tracker's latency, which
    brings its sample to the filter time, and ``bridge_var`` the variance of that mean's white noise per
    axis [rad^2/s^2]; ``R_st``: the star tracker's noise covariance in body axes [rad^2]
    (`star_tracker_noise_B`); ``P0``: the covariance a first star-tracker fix initialises.
    Returns (q, bias, P, omega, initialized, used, rejected, innovation_deg)."""
    used = False
    rejected = False
    innov_deg = np.nan
    omega = omega_last - bias
    if has_st:
        q_meas = quat_multiply_nb(q_NS, q_SB)
        R = R_st.copy()
        lag = 0.0
        if 0.0 < st_latency < max_age:
            lag = st_latency
            q_meas = quat_multiply_nb(q_meas, _rotvec_quat((omega_bridge - bias) * st_latency))
            # the bridge rate's white noise times the latency adds to the measurement noise on every axis
            lat_var = bridge_var * st_latency * st_latency
            for i in range(3):
                R[i, i] += lat_var
        if not initialized:
            q = q_meas / math.sqrt(q_meas[0] ** 2 + q_meas[1] ** 2 + q_meas[2] ** 2 + q_meas[3] ** 2)
            P = P0.copy()
            initialized = True
            used = True
            innov_deg = 0.0
        else:
            dtheta = mekf_innovation(q, q_meas)
            innov_deg = math.degrees(math.sqrt(dtheta[0] * dtheta[0] + dtheta[1] * dtheta[1] + dtheta[2] * dtheta[2]))
            trace = P[0, 0] + P[1, 1] + P[2, 2] + R[0, 0] + R[1, 1] + R[2, 2]
            sigma_pred_deg = math.degrees(math.sqrt(trace))
            if innov_deg > max(gate_deg, 4.0 * sigma_pred_deg):
                rejected = True
            else:
                q, bias, P = mekf_update_lagged(q, bias, P, dtheta, R, lag)
                used = True
    return q, bias, P, omega, initialized, used, rejected, innov_deg


@njit(cache=True)
def _round_half_even(x):
    """Python's ``round(x)`` of a float (ties to even) as an integer."""
    r = math.floor(x)
    d = x - r
    if d > 0.5 or (d == 0.5 and r % 2.0 != 0.0):
        r += 1.0
    return int(r)


@njit("Tuple((f8[::1], f8[::1], f8[:, ::1], f8[::1], f8[::1], b1, b1, b1, f8))(f8[::1], f8[::1], f8[:, ::1], f8[::1],"
      " f8[:, ::1], f8[::1], b1, f8, f8, f8, b1, b1, f8[::1], f8[::1], f8, f8, f8, f8[:, ::1], f8[:, ::1])", cache=True)
def _estimator_cycle(q, bias, P, omega, samples, prev_sample, has_prev, dt_s, sig_v, sig_u, initialized, has_st, q_NS,
                     q_SB, st_latency, max_age, gate_deg, R_st, P0):
    """`AttitudeEstimator._cycle` in one compiled call: the trapezoid rates of the gyro ``samples`` (n, 3),
    the bridge over the star tracker's latency, the propagation, then `_mekf_fuse`; the expressions and
    summation orders of the numpy version it replaces (tests/fsw/test_estimation.py). ``omega``: the last rate estimate;
    ``prev_sample``: the last gyro sample of the previous cycle (``has_prev`` False: none).
    Returns (q, bias, P, omega, the new previous sample, initialized, used, rejected, innovation_deg); the
    new previous sample is NaN when this cycle had no gyro sample."""
    n = samples.shape[0]
    if n:
        sub = dt_s / n
        rates = np.empty((n, 3))
        for j in range(3):
            # no earlier sample: hold the first
            p0 = prev_sample[j] if has_prev else samples[0, j]
            rates[0, j] = 0.5 * (p0 + samples[0, j])
            for k in range(1, n):
                rates[k, j] = 0.5 * (samples[k - 1, j] + samples[k, j])
        new_prev = samples[n - 1].copy()
        m = min(n, max(1, _round_half_even(st_latency / sub)))  # the intervals that the latency spans
        bridge = np.empty(3)
        for j in range(3):
            # numpy's mean over axis 0: the rows added in order, then divided by their count
            acc = rates[n - m, j]
            for k in range(n - m + 1, n):
                acc += rates[k, j]
            bridge[j] = acc / m
        bridge_var = sig_v * sig_v / (m * sub)
        if initialized:
            q = q.copy()
            P = P.copy()
            PP = np.empty((6, 6))
            for k in range(n):
                _propagate_in_place(q, bias, P, rates[k], sub, sig_v, sig_u, PP)
        q, bias, P, omega, initialized, used, rejected, innov = _mekf_fuse(
            q, bias, P, new_prev, bridge, bridge_var, initialized, has_st, q_NS, q_SB, st_latency, max_age, gate_deg,
            R_st, P0)
        return q, bias, P, omega, new_prev, initialized, used, rejected, innov
    # no valid gyro sample: hold the last bias-corrected rate over the whole cycle
    omega_last = omega + bias
    bridge_var = sig_v * sig_v / dt_s
    if initialized:
        q = q.copy()
        P = P.copy()
        _propagate_in_place(q, bias, P, omega_last, dt_s, sig_v, sig_u, np.empty((6, 6)))
    q, bias, P, omega, initialized, used, rejected, innov = _mekf_fuse(
        q, bias, P, omega_last, omega_last, bridge_var, initialized, has_st, q_NS, q_SB, st_latency, max_age, gate_deg,
        R_st, P0)
    return q, bias, P, omega, np.full(3, np.nan), initialized, used, rejected, innov


@njit("Tuple((f8[::1], f8[::1], b1, b1, b1, f8))(f8[::1], f8[::1], f8[:, ::1], f8[::1], f8[::1], f8[:, ::1], f8[::1],"
      " f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], f8, f8, f8, b1, b1, b1)", cache=True)
def _estimator_tick(q, bias, P, omega, prev_sample, samples, q_NS, q_SB, R_st, P0, consts, dt_s, st_latency, q_norm,
                    has_prev, initialized, has_st):
    """`_estimator_cycle` with fewer arguments and results, for `AttitudeEstimator.update`: handing five new
    arrays back to Python cost more than the dispatch of the call (~0.5 us each). ``consts``: (sig_v, sig_u,
    star tracker max age, innovation gate [deg]). ``bias`` (3,), ``P`` (6, 6) and ``prev_sample`` (3,) are
    overwritten with the new ones (NaN: this cycle had no gyro sample); they are the estimator's own, which
    nothing else keeps. The attitude and the rate, which guidance keeps from one cycle to the next, come
    back as new arrays. ``q_NS`` is divided by ``q_norm`` first (numpy's ``q_NS / q_norm``, element by
    element), so the caller need not build the unit quaternion. Returns (q, omega, initialized, used,
    rejected, innovation_deg)."""
    q_unit = np.empty(4)
    for i in range(4):
        q_unit[i] = q_NS[i] / q_norm
    q, bias_n, P_n, omega, new_prev, initialized, used, rejected, innov = _estimator_cycle(
        q, bias, P, omega, samples, prev_sample, has_prev, dt_s, consts[0], consts[1], initialized, has_st, q_unit, q_SB,
        st_latency, consts[2], consts[3], R_st, P0)
    for i in range(3):
        bias[i] = bias_n[i]
        prev_sample[i] = new_prev[i]
    for i in range(6):
        for j in range(6):
            P[i, j] = P_n[i, j]
    return q, omega, initialized, used, rejected, innov


def star_tracker_noise_B(cfg, q_BS: np.ndarray) -> np.ndarray:
    """The star tracker's attitude noise covariance in body axes [rad^2] (3, 3).

    A tracker measures its cross-boresight axes (sensor x, y) much better than the roll about its
    boresight (sensor z): hil_sim's model draws a small rotation e_S = (sx n1, sx n2, sz n3) in the sensor
    frame, which is e_B = C_BS e_S in body axes. So R_B = C_BS diag(sx^2, sx^2, sz^2) C_BS^T, with sx, sz
    the configured cross- and about-boresight sigmas (each falls back to ``star_tracker_sigma_arcsec``).
    An isotropic R equal to the roll noise let the filter believe the cross axes it barely knew less well
    than they were measured, and the reverse for the roll axis (design note 13).
    """
    from gnc.attitude import quat_to_dcm

    arcsec = math.pi / (180.0 * 3600.0)
    cross = cfg.star_tracker_cross_sigma_arcsec or cfg.star_tracker_sigma_arcsec
    about = cfg.star_tracker_about_sigma_arcsec or cfg.star_tracker_sigma_arcsec
    C_BS = quat_to_dcm(np.asarray(q_BS, dtype=float) / np.linalg.norm(q_BS))
    R = C_BS @ np.diag([(cross * arcsec) ** 2, (cross * arcsec) ** 2, (about * arcsec) ** 2]) @ C_BS.T
    return np.ascontiguousarray(0.5 * (R + R.T))


_NO_SAMPLES = np.zeros((0, 3))
_CONJUGATE = np.array([1.0, -1.0, -1.0, -1.0])
# low-pass time constant of the rate taken from star-tracker fixes while the gyro is silent [s]
GYROLESS_TAU_S = 1.0
_NO_QUATERNION = np.array([1.0, 0.0, 0.0, 0.0])


@dataclass
class EstimatorStatus:
    initialized: bool
    star_tracker_used: bool
    innovation_deg: float  # last innovation angle (nan when none this cycle)
    innovation_rejected: bool
    coasting_s: float  # time since the last fused star-tracker sample [s]
    cov_trace_deg2: float


class AttitudeEstimator:
    """MEKF for q_NB and the gyro bias. The GNC cycle calls `update` once per cycle with its
    `SensorSnapshot`; `step` and `step_samples` take the measurements one by one (tests, studies)."""

    def __init__(self, cfg, q_BS: np.ndarray):
        self.cfg = cfg
        self.q_SB = np.asarray(q_BS, dtype=float) * np.array([1.0, -1.0, -1.0, -1.0])
        self.sig_v = cfg.gyro_arw_rad_s_sqrt_hz
        self.sig_u = cfg.gyro_bias_rw_rad_s2_sqrt_hz
        self.R_st_B = star_tracker_noise_B(cfg, q_BS)
        # the compiled cycle's scalar constants in one array (one argument instead of four)
        self._consts = np.array([self.sig_v, self.sig_u, cfg.star_tracker_max_age_s, cfg.innovation_gate_deg],
                                dtype=float)
        self.reset()

    def reset(self) -> None:
        """Forget the attitude: the next valid star-tracker sample re-initialises (bias kept at 0)."""
        self.q_NB = np.array([1.0, 0.0, 0.0, 0.0])
        self.bias_B = np.zeros(3)
        self.P = np.eye(6)
        self.initialized = False
        self.coasting_s = 0.0
        self.omega_BN_B = np.zeros(3)
        self.last_innovation_deg = float("nan")
        self.resets = 0
        self.star_tracker_used = False  # this cycle's star-tracker sample was fused
        self.innovation_rejected = False  # this cycle's star-tracker sample was gated out
        # the last gyro sample, start of the next interval (`_prev_sample`): overwritten by the compiled cycle
        self._prev_buf = np.full(3, np.nan)
        self._has_prev = False
        self._fix_prev: np.ndarray | None = None  # the last fused attitude of a cycle without gyro samples

    @property
    def _prev_sample(self) -> np.ndarray | None:
        """The last gyro sample (a copy), start of the next interval; None when the last cycle had none."""
        return self._prev_buf.copy() if self._has_prev else None

    @_prev_sample.setter
    def _prev_sample(self, sample: np.ndarray | None) -> None:
        self._has_prev = sample is not None
        self._prev_buf = np.full(3, np.nan) if sample is None else np.array(sample, dtype=float).reshape(3)

    def _initial_P(self) -> np.ndarray:
        sa = math.radians(self.cfg.initial_attitude_sigma_deg)
        sb = math.radians(self.cfg.initial_bias_sigma_deg_s)
        return np.diag([sa * sa] * 3 + [sb * sb] * 3)

    def measured_q_NB(self, q_NS: np.ndarray) -> np.ndarray:
        return quat_multiply_nb(np.ascontiguousarray(q_NS, dtype=float), self.q_SB)

    def update(self, sensors: SensorSnapshot) -> AttitudeEstimate:
        """One GNC cycle on ``sensors``: propagate through its gyro samples over the cycle, then fuse its
        star-tracker fix when it has a fresh one. The estimate's innovation is NaN without a fix.

        One compiled call (`_estimator_tick`) and the attribute sets: the snapshot's gyro rows are a
        C-contiguous float (n, 3) array and its fix a contiguous float quaternion (4,), divided by its norm
        in the compiled call."""
        dt_s, samples, q_NS = sensors.dt_s, sensors.gyro_B, sensors.q_NS
        has_st = q_NS is not None
        P = self.P
        P0 = self._initial_P() if has_st and not self.initialized else P
        # bias_B, P and the previous sample are updated in place (`_estimator_tick`)
        self.q_NB, self.omega_BN_B, self.initialized, used, self.innovation_rejected, innov_deg = _estimator_tick(
            self.q_NB, self.bias_B, P, self.omega_BN_B, self._prev_buf, samples, q_NS if has_st else _NO_QUATERNION,
            self.q_SB, self.R_st_B, P0, self._consts, dt_s, sensors.st_latency_s, sensors.q_NS_norm, self._has_prev,
            self.initialized, has_st)
        self._has_prev = samples.shape[0] > 0
        self.star_tracker_used = used
        if samples.shape[0] == 0:
            self._gyroless_rate(dt_s, used)
        else:
            self._fix_prev = None
        self.coasting_s = 0.0 if used else self.coasting_s + dt_s
        self.last_innovation_deg = innov_deg
        return new_record(AttitudeEstimate, (self.q_NB, self.omega_BN_B, self.initialized, innov_deg))

    def step(self, dt_s: float, omega_meas_B: np.ndarray | None, q_NS: np.ndarray | None, st_latency_s: float = 0.0) -> EstimatorStatus:
        """One cycle: propagate with the gyro over ``dt_s`` then fuse the star tracker if given.

        ``omega_meas_B`` None (no valid IMU sample) propagates with the last bias-corrected rate;
        ``q_NS`` None (blinded, stale, invalid) coasts. ``st_latency_s`` is how old the star-tracker
        sample is with respect to the end of the propagation.
        """
        omegas = _NO_SAMPLES if omega_meas_B is None else np.asarray(omega_meas_B, dtype=float).reshape(1, 3)
        return self._cycle(dt_s, omegas, q_NS, st_latency_s)

    def step_samples(self, dt_s: float, omegas_B: np.ndarray, q_NS: np.ndarray | None, st_latency_s: float = 0.0) -> EstimatorStatus:
        """Like `step` for a tick with several gyro samples (n, 3), evenly spaced, the last at the end."""
        return self._cycle(dt_s, np.asarray(omegas_B, dtype=float).reshape(-1, 3), q_NS, st_latency_s)

    def _cycle(self, dt_s: float, samples: np.ndarray, q_NS: np.ndarray | None, st_latency_s: float) -> EstimatorStatus:
        """Propagate over ``dt_s`` through the gyro ``samples`` (n, 3), taken every dt_s / n, the last one
        now; then fuse the star tracker.

        The gyro gives the rate at sampling instants. Held from one sample to the next (the rate at the
        end of an interval standing for all of it), every interval is off by half the angular acceleration
        times its length: 1e-5 rad/s at the demo's 2e-3 rad/s^2 wheel authority, five times the gyro bias
        and always in the direction of the acceleration, so the bias estimate chased it and the attitude
        error left its covariance on every slew (design note 13). Each interval is propagated with the
        mean of the samples at its two ends instead (the trapezoid rule; error second order in the
        interval). Their noise is shared by two neighbouring intervals with half weight, so the angle
        random walk over the cycle, and the process noise, are unchanged. The star tracker's latency is
        bridged the same way, with the mean rate over the latency.
        """
        self.update(SensorSnapshot.of_measurements(float(dt_s), np.ascontiguousarray(samples, dtype=float),
                                                   None if q_NS is None else np.ascontiguousarray(q_NS, dtype=float),
                                                   float(st_latency_s)))
        return EstimatorStatus(
            initialized=self.initialized,
            star_tracker_used=self.star_tracker_used,
            innovation_deg=self.last_innovation_deg,
            innovation_rejected=self.innovation_rejected,
            coasting_s=self.coasting_s,
            cov_trace_deg2=self.cov_trace_deg2,
        )

    def _gyroless_rate(self, dt_s: float, used: bool) -> None:
        """A cycle without a gyro sample: the rate estimate follows the change of the attitude between two
        consecutive fused star-tracker fixes, low-passed over GYROLESS_TAU_S (the tracker's noise,
        differentiated at 10 Hz, is ~0.2 deg/s about its boresight). Held as it was, the last rate went on
        steering the rate loop for the whole outage: SAFE damped a rate that was no longer there and spun
        the body up to several times its limit (a 30 s IMU silence in the release campaign). Without a fix
        either, the rate is held, as before."""
        if not (used and self.initialized):
            self._fix_prev = None
            return
        prev, self._fix_prev = self._fix_prev, self.q_NB.copy()
        if prev is None:
            return
        # q_NB(t + dt) = q_NB(t) (x) dq with dq the body's rotation over dt: dq = conj(q_prev) (x) q_now
        dq = quat_multiply_nb(prev * _CONJUGATE, np.ascontiguousarray(self.q_NB))
        if dq[0] < 0.0:
            dq = -dq
        v = dq[1:]
        sin_half = float(np.linalg.norm(v))
        if sin_half > 0.0:
            rate = (2.0 * math.atan2(sin_half, float(dq[0])) / (sin_half * dt_s)) * v
            a = dt_s / (GYROLESS_TAU_S + dt_s)
            self.omega_BN_B = self.omega_BN_B + a * (rate - self.omega_BN_B)

    def _attitude_trace(self) -> float:
        # = float(np.trace(self.P[0:3, 0:3])) (same summation order), without numpy's call overhead
        # (item: the element as a Python float, no numpy scalar in between)
        P = self.P
        return P.item(0, 0) + P.item(1, 1) + P.item(2, 2)

    @property
    def cov_trace_rad2(self) -> float:
        """Trace of the attitude error covariance [rad^2]; NaN before the first fix."""
        return self._attitude_trace() if self.initialized else math.nan

    @property
    def cov_trace_deg2(self) -> float:
        # math.degrees is np.degrees (x * (180 / pi), the same constant) for a float
        return math.degrees(math.degrees(self._attitude_trace())) if self.initialized else float("nan")
