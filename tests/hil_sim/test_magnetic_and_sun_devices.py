"""Truth models of the magnetorquer rods, the magnetometer and the coarse sun sensors."""
import math

import numpy as np
import pytest

from gnc.attitude import quat_to_dcm
from gnc.magnetic import css_sun_direction
from hil_sim.world.magnetic_devices import (MagnetometerParams, MagnetorquerParams, body_dipole,
                                             magnetometer_sample, magnetorquer_torque_B, rod_dipoles)
from hil_sim.world.sun_sensors import SunSensorParams, sun_sensor_outputs

B_B = np.array([2.1e-5, -1.3e-5, 3.4e-5])


def test_each_rod_saturates_on_its_own():
    rods = MagnetorquerParams(max_dipole_Am2=(0.2, 0.1, 0.3))
    np.testing.assert_array_equal(rod_dipoles(rods, np.array([0.5, -0.5, 0.1])), [0.2, -0.1, 0.1])
    np.testing.assert_array_equal(rod_dipoles(rods, np.array([np.nan, 0.05, -1.0])), [0.0, 0.05, -0.3])


def test_the_rods_torque_is_their_body_dipole_cross_the_field():
    s = math.sqrt(0.5)
    rods = MagnetorquerParams(axes_B=((s, s, 0.0), (-s, s, 0.0), (0.0, 0.0, 1.0)), max_dipole_Am2=(1.0, 1.0, 1.0))
    cmd = np.array([0.3, -0.2, 0.1])
    m_B = body_dipole(rods, cmd)
    np.testing.assert_allclose(m_B, [s * 0.5, s * 0.1, 0.1], atol=1e-15)
    np.testing.assert_allclose(magnetorquer_torque_B(rods, cmd, B_B), np.cross(m_B, B_B), atol=1e-20)


@pytest.mark.parametrize("bad", [dict(axes_B=((1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, 1.0))),
                                 dict(max_dipole_Am2=(0.2, 0.0, 0.2)), dict(max_dipole_Am2=(0.2, 0.2))])
def test_rods_that_cannot_be_built_are_refused(bad):
    with pytest.raises(ValueError, match="magnetorquers"):
        MagnetorquerParams(**bad)


def test_the_magnetometer_reads_the_field_in_its_own_axes_with_bias_and_the_rods_field():
    q_BS = np.array([math.cos(0.3), 0.0, math.sin(0.3), 0.0])
    mag = MagnetometerParams(q_BS=tuple(q_BS), bias_S_T=(1e-7, -2e-7, 0.0))
    rng = np.random.default_rng(0)
    expected = quat_to_dcm(q_BS).T @ B_B + np.array([1e-7, -2e-7, 0.0])
    np.testing.assert_allclose(magnetometer_sample(mag, B_B, None, None, rng), expected, atol=1e-18)
    coupling = ((2e-6, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1e-6))
    rods = MagnetorquerParams(magnetometer_coupling_T_per_Am2=coupling)
    on = magnetometer_sample(mag, B_B, rods, np.array([0.2, 0.0, -0.1]), rng)
    off = magnetometer_sample(mag, B_B, rods, np.zeros(3), rng)
    np.testing.assert_allclose(off, expected, atol=1e-18)
    np.testing.assert_allclose(quat_to_dcm(q_BS) @ (on - off), [4e-7, 0.0, -1e-7], atol=1e-18)


def test_magnetometer_noise_quantisation_and_range():
    rng = np.random.default_rng(1)
    noisy = MagnetometerParams(noise_std_T=50e-9)
    samples = np.array([magnetometer_sample(noisy, B_B, None, None, rng) for _ in range(20_000)])
    assert np.std(samples - B_B, axis=0) == pytest.approx(np.full(3, 50e-9), rel=0.05)
    coarse = MagnetometerParams(resolution_T=1e-6, full_scale_T=3e-5)
    np.testing.assert_allclose(magnetometer_sample(coarse, B_B, None, None, rng), [2.1e-5, -1.3e-5, 3.0e-5], atol=1e-15)


def test_cells_follow_the_cosine_law_inside_their_field_of_view():
    css = SunSensorParams(field_of_view_half_angle_deg=60.0, full_scale=2.0)
    rng = np.random.default_rng(2)
    sun = np.array([math.cos(math.radians(50)), math.sin(math.radians(50)), 0.0])
    out = sun_sensor_outputs(css, sun, 1.0, rng)
    np.testing.assert_allclose(out, [2.0 * math.cos(math.radians(50)), 0.0, 2.0 * math.cos(math.radians(40)), 0.0, 0.0, 0.0])
    sun_70 = np.array([math.cos(math.radians(70)), 0.0, math.sin(math.radians(70))])
    assert sun_sensor_outputs(css, sun_70, 1.0, rng)[0] == 0.0  # beyond the +x cell's 60 deg field of view


def test_cells_are_dark_in_eclipse_and_dimmed_in_penumbra():
    css = SunSensorParams(noise_std=0.0)
    rng = np.random.default_rng(3)
    sun = np.array([0.6, 0.0, 0.8])
    assert np.all(sun_sensor_outputs(css, sun, 0.0, rng) == 0.0)
    np.testing.assert_allclose(sun_sensor_outputs(css, sun, 0.4, rng), 0.4 * sun_sensor_outputs(css, sun, 1.0, rng))


def test_the_onboard_estimate_recovers_the_sun_from_noisy_cells():
    """Truth cells -> gnc.magnetic.css_sun_direction: within a few degrees at 1 % noise, None in eclipse."""
    css = SunSensorParams(noise_std=0.01)
    rng = np.random.default_rng(4)
    normals = np.asarray(css.normals_B)
    worst = 0.0
    for _ in range(300):
        sun = rng.normal(size=3)
        sun /= np.linalg.norm(sun)
        if np.sum(normals @ sun > 0.2) < 3:
            continue  # fewer than three well-lit faces: no fix is expected
        est = css_sun_direction(normals, sun_sensor_outputs(css, sun, 1.0, rng))
        worst = max(worst, math.degrees(math.acos(min(1.0, float(est @ sun)))))
    assert 0.0 < worst < 5.0
    assert css_sun_direction(normals, sun_sensor_outputs(SunSensorParams(), np.array([0.0, 0.0, 1.0]), 0.0, rng)) is None


@pytest.mark.parametrize("bad", [dict(normals_B=((1.0, 1.0, 0.0),)), dict(field_of_view_half_angle_deg=95.0),
                                 dict(full_scale=0.0)])
def test_cells_that_cannot_be_built_are_refused(bad):
    with pytest.raises(ValueError, match="sun sensors"):
        SunSensorParams(**bad)
