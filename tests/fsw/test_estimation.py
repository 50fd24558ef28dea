"""MEKF against the hil_sim truth models: accuracy, gyro-bias estimation, mounting, coasting, gating."""
from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from scipy.spatial.transform import Rotation

from reference.mekf import mekf_propagate

from fsw.config import EstimatorConfig
from fsw.estimation import AttitudeEstimator, _mekf_fuse


def _err_deg(q_a, q_b) -> float:
    """Attitude difference by scipy (scalar-last there), independent of gnc.attitude."""
    ra = Rotation.from_quat(np.roll(q_a, -1))
    rb = Rotation.from_quat(np.roll(q_b, -1))
    return math.degrees((ra.inv() * rb).magnitude())


def _world(bias=(0.0, 0.0, 0.0), q_BS=(1.0, 0.0, 0.0, 0.0), omega0=(0.01, -0.02, 0.015)):
    from hil_sim.world.params import ImuParams, SpacecraftParams, StarTrackerParams, WorldParams
    from hil_sim.world.world import World

    wp = WorldParams(
        spacecraft=SpacecraftParams(omega_BN_B0_rad_s=omega0),
        imu=ImuParams(bias_B_rad_s=bias, bias_turn_on_std_rad_s=0.0, bias_random_walk_rad_s_per_sqrt_s=1e-8),
        star_tracker=StarTrackerParams(q_BS=q_BS, sun_exclusion_deg=0.0, moon_exclusion_deg=0.0, max_rate_deg_s=10.0),
    )
    return World(wp, seed=4), wp


def _estimator(wp, **over):
    cfg = EstimatorConfig(
        gyro_arw_rad_s_sqrt_hz=wp.imu.angle_random_walk_rad_per_sqrt_s,
        gyro_bias_rw_rad_s2_sqrt_hz=1e-6,
        star_tracker_sigma_arcsec=max(wp.star_tracker.cross_boresight_std_arcsec, wp.star_tracker.about_boresight_std_arcsec),
        **over,
    )
    return AttitudeEstimator(cfg, np.asarray(wp.star_tracker.q_BS))


def _run(world, est, seconds, st_on=lambda t: True, dt=0.1, n_imu=10):
    """Lockstep feed: 10 gyro samples per 0.1 s cycle, star tracker every cycle when st_on(t)."""
    log = []
    for k in range(int(round(seconds / dt))):
        omegas = []
        for _ in range(n_imu):
            world.step(dt / n_imu, np.zeros(world.n_wheels))
            omegas.append(world.imu_sample().omega_BN_B)
        st = world.star_tracker_sample()
        q = st.q_NS if (st.valid and st_on(world.t)) else None
        status = est.step_samples(dt, np.array(omegas), q)
        log.append((world.t, _err_deg(est.q_NB, world.truth.q_NB), status))
    return log


def test_tracks_truth_and_estimates_the_gyro_bias() -> None:
    bias = np.radians([0.05, -0.03, 0.04])  # deg/s class biases, far above the noise
    world, wp = _world(bias=tuple(bias))
    est = _estimator(wp)
    log = _run(world, est, 200.0)
    errs = np.array([e for _, e, _ in log[-500:]])
    sigma_st_deg = wp.star_tracker.about_boresight_std_arcsec / 3600
    assert np.median(errs) < 1.5 * sigma_st_deg  # filtered below the single-shot noise
    np.testing.assert_allclose(est.bias_B, bias, atol=math.radians(0.002))
    assert all(s.star_tracker_used for _, _, s in log[-100:])


def test_star_tracker_mounting_is_applied() -> None:
    q_BS = Rotation.from_euler("zyx", [30, -50, 70], degrees=True).as_quat()
    q_BS = tuple(np.roll(q_BS, 1))  # scalar first
    world, wp = _world(q_BS=q_BS)
    est = _estimator(wp)
    log = _run(world, est, 20.0)
    assert log[-1][1] < 0.02  # the estimate is the body attitude, not the sensor's


def test_coasting_grows_the_covariance_and_stays_consistent() -> None:
    world, wp = _world(bias=tuple(np.radians([0.02, 0.01, -0.02])))
    est = _estimator(wp)
    _run(world, est, 100.0)
    cov_before = est.cov_trace_deg2
    log = _run(world, est, 60.0, st_on=lambda t: False)
    covs = [s.cov_trace_deg2 for _, _, s in log]
    assert all(b > a for a, b in zip(covs, covs[1:]))  # grows every cycle while blind
    assert covs[-1] > 10 * cov_before
    assert log[-1][2].coasting_s == pytest.approx(60.0, abs=0.11)
    # the actual error stays within 3 sigma of the filter's own uncertainty
    assert log[-1][1] < 3 * math.sqrt(covs[-1])
    # back in view: the covariance collapses again
    log = _run(world, est, 5.0)
    assert log[-1][2].cov_trace_deg2 < 0.1 * covs[-1] and log[-1][2].coasting_s == 0.0


def test_outlier_is_gated_and_reported() -> None:
    world, wp = _world()
    est = _estimator(wp, innovation_gate_deg=1.0)
    _run(world, est, 30.0)
    q_before = est.q_NB.copy()
    st = world.star_tracker_sample()
    bad = Rotation.from_quat(np.roll(st.q_NS, -1)) * Rotation.from_rotvec([0, 0, math.radians(10)])
    status = est.step(0.1, world.imu_sample().omega_BN_B, np.roll(bad.as_quat(), 1))
    assert status.innovation_rejected and not status.star_tracker_used
    assert status.innovation_deg == pytest.approx(10.0, abs=0.2)
    assert _err_deg(est.q_NB, q_before) < 0.5  # propagated only, not pulled by 10 deg


def test_latency_compensation_uses_the_gyro_rate() -> None:
    world, wp = _world(omega0=(0.0, 0.0, math.radians(2.0)))
    st_old = world.star_tracker_sample()  # exposure at t = 0
    for _ in range(5):
        world.step(0.01, np.zeros(world.n_wheels))
    omega = world.imu_sample().omega_BN_B
    errors = {}
    for latency in (0.0, 0.05):
        est = _estimator(wp)
        est.step(1e-6, omega, st_old.q_NS, st_latency_s=latency)  # initialises from the sample
        errors[latency] = _err_deg(est.q_NB, world.truth.q_NB)
    assert errors[0.0] == pytest.approx(0.1, abs=0.02)  # 2 deg/s x 50 ms uncompensated
    assert errors[0.05] < 0.02


class _ReferenceMekf:
    """The estimator's cycle written out in Python around the numba pieces (to compare the one-call
    kernel against): trapezoidal propagation between gyro samples, latency bridged with the mean rate
    over the latency, the star tracker's body-frame noise matrix."""

    def __init__(self, est: AttitudeEstimator) -> None:
        self.e = est
        self.prev = None

    def step(self, dt, omega_meas, q_NS, lat=0.0):
        return self.step_samples(dt, np.zeros((0, 3)) if omega_meas is None else np.reshape(omega_meas, (1, 3)), q_NS, lat)

    def step_samples(self, dt, omegas, q_NS, lat=0.0):
        from fsw.estimation import _rotvec_quat, mekf_innovation, mekf_update_lagged
        from gnc.attitude import quat_multiply_nb

        e = self.e
        n = len(omegas)
        if n:
            sub = dt / n
            rates = [omegas[i] if (i == 0 and self.prev is None) else 0.5 * ((omegas[i - 1] if i else self.prev) + omegas[i])
                     for i in range(n)]
            self.prev = np.array(omegas[-1], dtype=float)
            m = min(n, max(1, round(lat / sub)))
            bridge, bridge_var = np.mean(rates[n - m:], axis=0), e.sig_v ** 2 / (m * sub)
            last, steps = np.asarray(omegas[-1], dtype=float), [(r, sub) for r in rates]
        else:
            self.prev = None
            last = e.omega_BN_B + e.bias_B
            bridge, bridge_var, steps = last, e.sig_v ** 2 / dt, [(last, dt)]
        if e.initialized:
            for r, h in steps:
                e.q_NB, e.P = mekf_propagate(e.q_NB, e.bias_B, e.P, np.asarray(r, dtype=float), h, e.sig_v, e.sig_u)
        e.omega_BN_B = last - e.bias_B
        used = rejected = False
        innov = float("nan")
        if q_NS is not None:
            q_meas = quat_multiply_nb(np.asarray(q_NS, dtype=float), e.q_SB)
            R = e.R_st_B.copy()
            lag = 0.0
            if 0.0 < lat < e.cfg.star_tracker_max_age_s:
                lag = lat
                q_meas = quat_multiply_nb(q_meas, _rotvec_quat((bridge - e.bias_B) * lat))
                R += np.eye(3) * bridge_var * lat ** 2
            if not e.initialized:
                e.q_NB, e.P, e.initialized, used, innov = q_meas / np.linalg.norm(q_meas), e._initial_P(), True, True, 0.0
            else:
                dtheta = mekf_innovation(e.q_NB, q_meas)
                innov = math.degrees(math.sqrt(float(dtheta @ dtheta)))
                sigma_pred = math.degrees(math.sqrt(float(np.trace(e.P[0:3, 0:3]) + np.trace(R))))
                if innov > max(e.cfg.innovation_gate_deg, 4.0 * sigma_pred):
                    rejected = True
                else:
                    e.q_NB, e.bias_B, e.P = mekf_update_lagged(e.q_NB, e.bias_B, e.P, dtheta, R, lag)
                    used = True
        e.coasting_s = 0.0 if used else e.coasting_s + dt
        return used, rejected, innov


def test_compiled_cycle_matches_the_python_reference_on_random_inputs() -> None:
    rng = np.random.default_rng(11)
    cfg = EstimatorConfig(gyro_arw_rad_s_sqrt_hz=1e-4, gyro_bias_rw_rad_s2_sqrt_hz=1e-6, star_tracker_cross_sigma_arcsec=5.0,
                          star_tracker_about_sigma_arcsec=40.0)
    q_BS = Rotation.random(random_state=3).as_quat()[[3, 0, 1, 2]]
    est, ref_est = AttitudeEstimator(cfg, q_BS), AttitudeEstimator(cfg, q_BS)
    ref = _ReferenceMekf(ref_est)
    q_true = np.array([1.0, 0.0, 0.0, 0.0])
    kinds = {"used": 0, "rejected": 0, "coast": 0}
    for k in range(400):
        n = int(rng.integers(0, 11))
        omegas = rng.normal(scale=0.02, size=(n, 3))
        q_true = Rotation.from_quat(np.roll(q_true, -1)) * Rotation.from_rotvec(rng.normal(scale=1e-3, size=3))
        q_true = np.roll(q_true.as_quat(), 1)
        q_NS = None
        if k % 4:
            noise = rng.normal(scale=1e-4 if k % 17 else 0.5, size=3)  # now and then an outlier for the gate
            q_NS = np.roll((Rotation.from_quat(np.roll(q_true, -1)) * Rotation.from_rotvec(noise)
                            * Rotation.from_quat(np.roll(q_BS, -1))).as_quat(), 1)
        lat = float(rng.uniform(0.0, 0.3)) if k % 3 else 0.0
        status = est.step_samples(0.1, omegas, q_NS, lat) if k % 5 else est.step(0.1, omegas[0] if n else None, q_NS, lat)
        used, rejected, innov = ref.step_samples(0.1, omegas, q_NS, lat) if k % 5 else ref.step(
            0.1, omegas[0] if n else None, q_NS, lat)
        assert (status.star_tracker_used, status.innovation_rejected) == (used, rejected)
        if math.isnan(innov):
            assert math.isnan(status.innovation_deg)
        else:
            assert status.innovation_deg == pytest.approx(innov, rel=1e-10, abs=1e-12)
        for name in ("q_NB", "bias_B", "P", "omega_BN_B"):
            np.testing.assert_allclose(getattr(est, name), getattr(ref_est, name), rtol=1e-9, atol=1e-15, err_msg=name)
        assert est.coasting_s == pytest.approx(ref_est.coasting_s, abs=1e-12)
        assert est.initialized == ref_est.initialized
        kinds["used" if used else "rejected" if rejected else "coast"] += 1
    assert min(kinds.values()) > 5, kinds  # fusing, gating and coasting were all compared


def test_structured_propagation_matches_the_dense_matrix_form() -> None:
    """mekf_propagate writes Phi P Phi^T + Q out on Phi's block structure; the dense numpy form
    (Crassidis & Junkins' discrete model, as the filter had it) must give the same covariance."""

    rng = np.random.default_rng(5)
    for _ in range(200):
        L = rng.normal(scale=1e-3, size=(6, 6))
        P = L @ L.T + np.eye(6) * 1e-9
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        bias, omega = rng.normal(scale=1e-3, size=3), rng.normal(scale=0.05, size=3)
        dt, sig_v, sig_u = float(rng.uniform(0.005, 0.2)), 1e-4, 1e-6
        _, Pn = mekf_propagate(q, bias, P, omega, dt, sig_v, sig_u)
        w = omega - bias
        Phi = np.eye(6)
        Phi[0:3, 0:3] -= np.array(
            [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) * dt
        Phi[0:3, 3:6] = -dt * np.eye(3)
        Q = np.zeros((6, 6))
        Q[0:3, 0:3] = (sig_v ** 2 * dt + sig_u ** 2 * dt ** 3 / 3.0) * np.eye(3)
        Q[0:3, 3:6] = Q[3:6, 0:3] = -sig_u ** 2 * dt ** 2 / 2.0 * np.eye(3)
        Q[3:6, 3:6] = sig_u ** 2 * dt * np.eye(3)
        ref = Phi @ P @ Phi.T + Q
        ref = 0.5 * (ref + ref.T)
        np.testing.assert_allclose(Pn, ref, rtol=1e-12, atol=1e-24)
        assert np.array_equal(Pn, Pn.T)


@njit
def _mekf_propagate_many(q, bias, P, omegas, dt, sig_v, sig_u):
    """Propagate through consecutive gyro samples omegas (n, 3), each held for ``dt`` [s]."""
    for k in range(omegas.shape[0]):
        q, P = mekf_propagate(q, bias, P, omegas[k], dt, sig_v, sig_u)
    return q, P


@njit("Tuple((f8[::1], f8[::1], f8[:, ::1], f8[::1], b1, b1, b1, f8))(f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], f8,"
      " f8[::1], f8, f8[::1], f8[::1], f8, f8, f8, b1, b1, f8[::1], f8[::1], f8, f8, f8, f8[:, ::1], f8[:, ::1])")
def _mekf_cycle(q, bias, P, prior, prior_dt, omega_prop, dt, omega_last, omega_bridge, bridge_var, sig_v, sig_u,
                initialized, has_st, q_NS, q_SB, st_latency, max_age, gate_deg, R_st, P0):
    """The estimator cycle as one compiled call before `_estimator_cycle` (the flight code until then):
    propagate through the gyro rates ``prior`` (k, 3), each held ``prior_dt``, then ``omega_prop`` held
    ``dt`` (`mekf_propagate`, allocating); fuse the star tracker (`_mekf_fuse`).
    Returns (q, bias, P, omega, initialized, used, rejected, innovation_deg)."""
    if initialized and prior.shape[0] > 0:
        q, P = _mekf_propagate_many(q, bias, P, prior, prior_dt, sig_v, sig_u)
    if initialized:
        q, P = mekf_propagate(q, bias, P, omega_prop, dt, sig_v, sig_u)
    return _mekf_fuse(q, bias, P, omega_last, omega_bridge, bridge_var, initialized, has_st, q_NS, q_SB, st_latency,
                      max_age, gate_deg, R_st, P0)


def _numpy_cycle(est, dt_s, samples, q_NS, st_latency_s):
    """The estimator cycle as it was written in numpy around `_mekf_cycle` (before `_estimator_cycle`
    fused it into one compiled call): the reference the fused kernel must match bit for bit."""
    from fsw.estimation import _NO_QUATERNION, _NO_SAMPLES

    n = samples.shape[0]
    if n:
        samples = np.ascontiguousarray(samples, dtype=float)
        sub = dt_s / n
        prev = samples[0] if est._prev_sample is None else est._prev_sample
        rates = 0.5 * (np.vstack((prev[None, :], samples[:-1])) + samples)
        est._prev_sample = samples[-1].copy()
        m = min(n, max(1, round(st_latency_s / sub)))
        bridge = rates[n - m:].mean(axis=0)
        bridge_var = est.sig_v * est.sig_v / (m * sub)
        prior, omega_prop, dt_prop, omega_last = rates[:-1], rates[-1], sub, samples[-1]
    else:
        est._prev_sample = None
        omega_last = est.omega_BN_B + est.bias_B
        prior, omega_prop, dt_prop, bridge = _NO_SAMPLES, omega_last, dt_s, omega_last
        bridge_var = est.sig_v * est.sig_v / dt_s
    has_st = q_NS is not None
    P0 = est._initial_P() if has_st and not est.initialized else est.P
    (est.q_NB, est.bias_B, est.P, est.omega_BN_B, est.initialized, used, rejected, innov_deg) = _mekf_cycle(
        est.q_NB, est.bias_B, est.P, np.ascontiguousarray(prior), float(dt_prop), omega_prop, float(dt_prop),
        omega_last, bridge, float(bridge_var), est.sig_v, est.sig_u,
        est.initialized, has_st, np.ascontiguousarray(q_NS, dtype=float) if has_st else _NO_QUATERNION,
        np.ascontiguousarray(est.q_SB, dtype=float), float(st_latency_s), est.cfg.star_tracker_max_age_s,
        est.cfg.innovation_gate_deg, est.R_st_B, P0)
    est.coasting_s = 0.0 if used else est.coasting_s + dt_s
    # the gyro-less rate (`AttitudeEstimator._gyroless_rate`) is Python after the compiled cycle, the same
    # code on both sides: what this compares is the cycle
    if n == 0:
        est._gyroless_rate(dt_s, used)
    else:
        est._fix_prev = None
    return used, rejected, innov_deg


def test_fused_cycle_is_bit_identical_to_the_numpy_cycle() -> None:
    """`_estimator_cycle` (trapezoid rates, latency bridge and `_mekf_cycle` in one call) against the numpy
    code it replaced: every output equal to the last bit, over random sample counts (0 to 12), latencies
    (ties of the rounding included: 0.05 s over 0.01 s intervals and half-interval multiples), gaps in
    the gyro and the star tracker, and outliers for the gate."""
    rng = np.random.default_rng(23)
    cfg = EstimatorConfig(gyro_arw_rad_s_sqrt_hz=1e-4, gyro_bias_rw_rad_s2_sqrt_hz=1e-6, star_tracker_cross_sigma_arcsec=5.0,
                          star_tracker_about_sigma_arcsec=40.0)
    q_BS = Rotation.random(random_state=5).as_quat()[[3, 0, 1, 2]]
    est, ref = AttitudeEstimator(cfg, q_BS), AttitudeEstimator(cfg, q_BS)
    q_true = np.array([1.0, 0.0, 0.0, 0.0])
    kinds = {"used": 0, "rejected": 0, "coast": 0}
    for k in range(600):
        n = int(rng.integers(0, 13)) if k % 7 else 0
        omegas = rng.normal(scale=0.02, size=(n, 3)) + rng.normal(scale=1e-3, size=3)
        q_true = Rotation.from_quat(np.roll(q_true, -1)) * Rotation.from_rotvec(rng.normal(scale=1e-3, size=3))
        q_true = np.roll(q_true.as_quat(), 1)
        q_NS = None
        if k % 4:
            noise = rng.normal(scale=1e-4 if k % 17 else 0.5, size=3)
            q_NS = np.roll((Rotation.from_quat(np.roll(q_true, -1)) * Rotation.from_rotvec(noise)
                            * Rotation.from_quat(np.roll(q_BS, -1))).as_quat(), 1)
        lat = (0.0, 0.05, 0.015, 0.025, float(rng.uniform(0.0, 0.3)), 0.1 / max(n, 1) * (int(rng.integers(0, 8)) + 0.5))[k % 6]
        status = est.step_samples(0.1, omegas, q_NS, lat)
        used, rejected, innov = _numpy_cycle(ref, 0.1, omegas, q_NS, lat)
        assert (status.star_tracker_used, status.innovation_rejected) == (used, rejected)
        assert str(status.innovation_deg) == str(innov)
        for name in ("q_NB", "bias_B", "P", "omega_BN_B"):
            assert np.array_equal(getattr(est, name), getattr(ref, name)), name
        assert (est._prev_sample is None) == (ref._prev_sample is None)
        if est._prev_sample is not None:
            assert np.array_equal(est._prev_sample, ref._prev_sample)
        assert est.coasting_s == ref.coasting_s and est.initialized == ref.initialized
        kinds["used" if used else "rejected" if rejected else "coast"] += 1
    assert min(kinds.values()) > 5, kinds


def test_round_half_even_is_pythons_round() -> None:
    from fsw.estimation import _round_half_even

    xs = [0.0, 0.5, 1.5, 2.5, 3.5, 0.49999999999999994, 2.5000000000000004, 1e-300, 7.0, 12.5, 1e15 + 0.5]
    xs += list(np.random.default_rng(1).uniform(0.0, 40.0, 500)) + [i / 2 for i in range(60)]
    for x in xs:
        assert _round_half_even(float(x)) == round(float(x)), x


def test_in_place_propagation_is_bit_identical_to_mekf_propagate() -> None:
    """`_propagate_in_place` (no allocation) against `mekf_propagate`, equal to the last bit, including
    rates equal to the bias (the small-angle branch of the rotation vector) and zero rates."""
    from fsw.estimation import _propagate_in_place

    rng = np.random.default_rng(9)
    PP = np.empty((6, 6))
    for k in range(400):
        L = rng.normal(scale=1e-3, size=(6, 6))
        P = L @ L.T + np.eye(6) * 1e-9
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        bias = rng.normal(scale=1e-3, size=3)
        omega = (bias.copy(), np.zeros(3), bias + 1e-14, rng.normal(scale=0.05, size=3))[k % 4]
        dt = (0.01, float(rng.uniform(0.001, 0.2)))[k % 2]
        qn, Pn = mekf_propagate(q, bias, P, omega, dt, 1e-4, 1e-6)
        q2, P2 = q.copy(), P.copy()
        _propagate_in_place(q2, bias, P2, omega, dt, 1e-4, 1e-6, PP)
        assert np.array_equal(q2, qn) and np.array_equal(P2, Pn), k


def test_estimator_tick_is_estimator_cycle_in_place() -> None:
    """`_estimator_tick` (bias, P and the previous sample overwritten, the tracker sample divided by its
    norm inside) against `_estimator_cycle` on the numpy-normalised sample: every output equal to the last
    bit, over random sample counts, tracker gaps, norms off one, outliers and a (re)initialisation."""
    from fsw.estimation import _NO_QUATERNION, _estimator_cycle, _estimator_tick

    rng = np.random.default_rng(31)
    cfg = EstimatorConfig(gyro_arw_rad_s_sqrt_hz=1e-4, gyro_bias_rw_rad_s2_sqrt_hz=1e-6)
    est = AttitudeEstimator(cfg, np.array([1.0, 0.0, 0.0, 0.0]))
    consts = np.array([est.sig_v, est.sig_u, cfg.star_tracker_max_age_s, cfg.innovation_gate_deg])
    q, bias, P, omega = est.q_NB, est.bias_B, est.P, est.omega_BN_B
    prev, has_prev, initialized = np.full(3, np.nan), False, False
    kinds = set()
    for k in range(400):
        n = int(rng.integers(0, 12)) if k % 9 else 0
        samples = rng.normal(scale=0.02, size=(n, 3))
        has_st = bool(k % 3)
        q_raw = rng.normal(size=4) if k % 50 == 0 else np.array([1.0, 0.0, 0.0, 0.0]) + rng.normal(scale=1e-4, size=4)
        q_raw *= rng.uniform(0.95, 1.05) / np.linalg.norm(q_raw)
        nq = float(np.linalg.norm(q_raw)) if has_st else 1.0
        lat = float(rng.uniform(0.0, 0.2))
        P0 = est._initial_P() if has_st and not initialized else P
        ref = _estimator_cycle(q, bias, P, omega, samples, prev, has_prev, 0.1, est.sig_v, est.sig_u, initialized,
                               has_st, q_raw / nq if has_st else _NO_QUATERNION, est.q_SB, lat,
                               cfg.star_tracker_max_age_s, cfg.innovation_gate_deg, est.R_st_B, P0)
        bias2, P2, prev2 = bias.copy(), P.copy(), prev.copy()
        out = _estimator_tick(q, bias2, P2, omega, prev2, samples, q_raw if has_st else _NO_QUATERNION, est.q_SB,
                              est.R_st_B, P0, consts, 0.1, lat, nq, has_prev, initialized, has_st)
        q_r, bias_r, P_r, omega_r, prev_r, init_r, used_r, rej_r, innov_r = ref
        assert np.array_equal(out[0], q_r) and np.array_equal(out[1], omega_r)
        assert np.array_equal(bias2, bias_r) and np.array_equal(P2, P_r), k
        assert np.array_equal(prev2, prev_r, equal_nan=True)
        assert out[2:5] == (init_r, used_r, rej_r) and str(out[5]) == str(innov_r)
        kinds.add("used" if used_r else "rejected" if rej_r else "coast")
        q, bias, P, omega, prev, has_prev, initialized = q_r, bias_r, P_r, omega_r, prev_r, n > 0, init_r
        if k == 200:  # forget the attitude: the next fix initialises again
            initialized = False
    assert kinds == {"used", "rejected", "coast"}, kinds


def test_without_gyro_the_rate_follows_the_star_tracker_fixes() -> None:
    """No gyro sample, a fused fix every cycle: the rate estimate converges to the body's true rate (low-pass
    of the attitude's change between fixes), instead of staying at its last value."""
    from fsw.estimation import GYROLESS_TAU_S

    cfg = EstimatorConfig(gyro_arw_rad_s_sqrt_hz=1e-4, gyro_bias_rw_rad_s2_sqrt_hz=1e-6, star_tracker_sigma_arcsec=1.0)
    q_BS = np.array([1.0, 0.0, 0.0, 0.0])
    est = AttitudeEstimator(cfg, q_BS)
    w_true = np.array([0.004, -0.002, 0.003])
    rot = Rotation.identity()
    est.step(0.1, w_true, np.roll(rot.as_quat(), 1))  # initialised with a gyro
    est.omega_BN_B = np.array([0.02, 0.0, 0.0])  # a stale rate, as at the start of an outage
    for _ in range(int(10 * GYROLESS_TAU_S / 0.1)):
        rot = rot * Rotation.from_rotvec(w_true * 0.1)
        est.step(0.1, None, np.roll(rot.as_quat(), 1))
    np.testing.assert_allclose(est.omega_BN_B, w_true, atol=2e-4)
