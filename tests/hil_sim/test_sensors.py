"""Gyro and star-tracker statistics, conventions and blinding, against their configured parameters."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from gnc.attitude import quat_conjugate, quat_multiply, quat_rotate
from hil_sim.world.params import ImuParams, SpacecraftParams, StarTrackerParams, WorldParams
from hil_sim.world.world import World, WorldBatch

QUIET_IMU = dict(bias_turn_on_std_rad_s=0.0, bias_random_walk_rad_s_per_sqrt_s=0.0,
                 angle_random_walk_rad_per_sqrt_s=0.0, quantisation_rad_s=0.0)


def _variance_in_chi2_bounds(samples: np.ndarray, sigma: float, p: float = 1e-4) -> None:
    """Sample variance of n zero-mean iid normal samples: n s^2 / sigma^2 ~ chi2(n). Two-sided test at p."""
    n = samples.size
    stat = np.sum(samples**2) / sigma**2
    lo, hi = chi2.ppf(p / 2, n), chi2.ppf(1 - p / 2, n)
    assert lo < stat < hi, f"n s^2/sigma^2 = {stat:.1f} outside [{lo:.1f}, {hi:.1f}] (s = {math.sqrt(stat / n) * sigma:.3e}, sigma = {sigma:.3e})"


def test_gyro_angle_random_walk_has_configured_std():
    arw = 1e-4  # rad/sqrt(s)
    imu = ImuParams(rate_hz=50.0, **{**QUIET_IMU, "angle_random_walk_rad_per_sqrt_s": arw})
    world = World(WorldParams(imu=imu), seed=3)  # at rest: true rate 0
    samples = np.array([world.imu_sample().omega_BN_B for _ in range(20000)])
    _variance_in_chi2_bounds(samples, arw * math.sqrt(50.0))
    # Allan deviation at tau = T is N / sqrt(T): averaging m samples divides the std by sqrt(m)
    means = samples[: 20000 // 25 * 25].reshape(-1, 25, 3).mean(axis=1)
    _variance_in_chi2_bounds(means, arw / math.sqrt(25 / 50.0))


def test_gyro_bias_random_walk_grows_as_sqrt_time():
    K = 2e-6  # rad/s/sqrt(s)
    imu = ImuParams(**{**QUIET_IMU, "bias_random_walk_rad_s_per_sqrt_s": K})
    batch = WorldBatch([WorldParams(imu=imu)] * 1000, seed=4)  # 1000 independent runs, all at rest
    first, _ = batch.imu_sample_arrays()
    first = first.copy()
    batch.step(25.0, np.zeros((1000, 4)))
    batch.imu_sample_arrays()
    batch.step(75.0, np.zeros((1000, 4)))
    last, _ = batch.imu_sample_arrays()
    # bias(100 s) - bias(first sample) over the two walks: variance K^2 * 100 s
    _variance_in_chi2_bounds(last - first, K * math.sqrt(100.0))


def test_gyro_turn_on_bias_has_configured_std_and_mean():
    imu = ImuParams(**{**QUIET_IMU, "bias_turn_on_std_rad_s": 3e-5, "bias_B_rad_s": (1e-4, -2e-4, 0.0)})
    batch = WorldBatch([WorldParams(imu=imu)] * 2000, seed=5)
    out, _ = batch.imu_sample_arrays()
    _variance_in_chi2_bounds(out - np.array([1e-4, -2e-4, 0.0]), 3e-5)


def test_gyro_scale_factor_quantisation_and_saturation():
    w0 = (0.1, -0.2, 0.3)
    imu = ImuParams(**{**QUIET_IMU, "scale_factor_ppm": (1000.0, -500.0, 0.0), "quantisation_rad_s": 1e-5,
                       "saturation_rad_s": 0.25})
    world = World(WorldParams(imu=imu, spacecraft=SpacecraftParams(omega_BN_B0_rad_s=w0)), seed=0)
    s = world.imu_sample()
    w = world.truth.omega_BN_B
    expected = np.clip(w * (1 + np.array([1e-3, -5e-4, 0.0])), -0.25, 0.25)
    np.testing.assert_allclose(s.omega_BN_B, expected, atol=0.5e-5 + 1e-15)
    np.testing.assert_allclose(s.omega_BN_B / 1e-5, np.round(s.omega_BN_B / 1e-5), atol=1e-6)
    assert s.saturated and s.omega_BN_B[2] == 0.25


def _rotvec_S(q_true_NS: np.ndarray, q_meas_NS: np.ndarray) -> np.ndarray:
    """Error rotation in the sensor frame: q_meas = q_true (x) dq."""
    dq = quat_multiply(quat_conjugate(q_true_NS), q_meas_NS)
    return Rotation.from_quat(np.r_[dq[1:], dq[0]]).as_rotvec()


def test_star_tracker_frame_and_noise_axes():
    """q_NS = q_NB (x) q_BS (checked with scipy: R_NS = R_NB R_BS), and the error is cross/about the boresight."""
    q_BS = Rotation.from_euler("xyz", [90, 20, -35], degrees=True).as_quat()
    q_BS = np.r_[q_BS[3], q_BS[:3]]
    st = StarTrackerParams(q_BS=tuple(q_BS), cross_boresight_std_arcsec=6.0, about_boresight_std_arcsec=45.0,
                           sun_exclusion_deg=0.0, moon_exclusion_deg=0.0)
    q_NB = Rotation.from_euler("zyx", [10, -40, 70], degrees=True).as_quat()
    sc = SpacecraftParams(q_NB0=(q_NB[3], *q_NB[:3]))
    world = World(WorldParams(star_tracker=st, spacecraft=sc), seed=8)
    truth_q = world.truth.q_NB
    R_NS = Rotation.from_quat(np.r_[truth_q[1:], truth_q[0]]) * Rotation.from_quat(np.r_[q_BS[1:], q_BS[0]])
    q_NS_true = np.r_[R_NS.as_quat()[3], R_NS.as_quat()[:3]]
    errs = []
    for _ in range(5000):
        s = world.star_tracker_sample()
        assert s.valid and s.blind_source == 0
        errs.append(_rotvec_S(q_NS_true, s.q_NS))
    errs = np.degrees(np.array(errs)) * 3600.0
    _variance_in_chi2_bounds(errs[:, :2], 6.0)
    _variance_in_chi2_bounds(errs[:, 2], 45.0)
    assert abs(errs.mean(axis=0)).max() < 4 * 45.0 / math.sqrt(5000)


def _world_pointing_at(direction_key: str, offset_deg: float, **st_kw) -> tuple[World, float]:
    """World whose star-tracker boresight is offset_deg away from the Sun/Moon direction at t = 0."""
    probe = World(WorldParams(), seed=0)
    target = getattr(probe.truth, direction_key)
    # body +z is the default boresight; choose q_NB so that R_NB z = target rotated by offset about a normal
    normal = np.cross(target, [0.0, 0.0, 1.0])
    normal /= np.linalg.norm(normal)
    boresight_N = Rotation.from_rotvec(np.radians(offset_deg) * normal).apply(target)
    align = Rotation.align_vectors([boresight_N], [[0.0, 0.0, 1.0]])[0]
    q = align.as_quat()
    world = World(WorldParams(spacecraft=SpacecraftParams(q_NB0=(q[3], *q[:3])),
                              star_tracker=StarTrackerParams(**st_kw)), seed=0)
    actual = math.degrees(math.acos(np.clip(quat_rotate(world.truth.q_NB, np.array([0, 0, 1.0])) @
                                            getattr(world.truth, direction_key), -1, 1)))
    return world, actual


@pytest.mark.parametrize("key,code,limit", [("sun_N", 1, 30.0), ("moon_N", 2, 25.0)])
def test_star_tracker_blinded_inside_exclusion_angle(key, code, limit):
    for offset in (0.0, limit - 0.5, limit + 0.5, 90.0):
        world, actual = _world_pointing_at(key, offset)
        s = world.star_tracker_sample()
        other = "moon_N" if key == "sun_N" else "sun_N"
        other_angle = math.degrees(math.acos(quat_rotate(world.truth.q_NB, np.array([0, 0, 1.0])) @
                                             getattr(world.truth, other)))
        other_limit = 25.0 if other == "moon_N" else 30.0
        if actual < limit:
            assert not s.valid and s.blind_source == code, (offset, actual)
        elif other_angle > other_limit:
            assert s.valid and s.blind_source == 0, (offset, actual)


def test_star_tracker_invalid_above_tracking_rate_and_holds_last_output():
    st = StarTrackerParams(max_rate_deg_s=1.0, sun_exclusion_deg=0.0, moon_exclusion_deg=0.0)
    sc = SpacecraftParams(omega_BN_B0_rad_s=(0.0, 0.0, math.radians(0.9)))
    world = World(WorldParams(spacecraft=sc, star_tracker=st), seed=0)
    good = world.star_tracker_sample()
    assert good.valid
    fast = World(WorldParams(spacecraft=SpacecraftParams(omega_BN_B0_rad_s=(0.0, math.radians(1.1), 0.0)),
                             star_tracker=st), seed=0)
    s = fast.star_tracker_sample()
    assert not s.valid and s.blind_source == 3
    np.testing.assert_array_equal(s.q_NS, [1.0, 0.0, 0.0, 0.0])  # nothing valid yet: identity


def test_noiseless_gyro_reproduces_basilisk_imu_reference():
    """Basilisk's noiseless imuSensor on the reference run (rw_reference_imu.csv): gyro = omega_BN_B at the
    sample time. Our gyro with every error source off must give the same numbers."""
    import csv
    import json

    from test_dynamics import REF_DIR, _reference_world, _torque_profile

    inputs = json.loads((REF_DIR / "rw_reference_inputs.json").read_text())
    with open(REF_DIR / "rw_reference_imu.csv") as f:
        rows = list(csv.DictReader(f))
    world = _reference_world(inputs)
    quiet = ImuParams(**{**QUIET_IMU, "saturation_rad_s": 10.0})
    world = World(WorldParams(spacecraft=world.params.spacecraft, imu=quiet, max_integration_step_s=0.01), seed=0)
    worst = 0.0
    for k, row in enumerate(rows[:1001]):  # first 100 s
        if k > 0:  # Basilisk's first IMU row is all zeros (the sensor has not run yet)
            gyro = world.imu_sample().omega_BN_B
            worst = max(worst, np.abs(gyro - [float(row[c]) for c in ("gyro_x", "gyro_y", "gyro_z")]).max())
        world.step(0.1, _torque_profile(inputs, 0.1 * k))
    assert worst < 1e-10, f"max |gyro - Basilisk gyro| = {worst:.2e} rad/s"
