"""The compiled magnetic-device and sun-sensor kernels (hil_sim.world._magnetic_devices_nb) against the numpy
expressions they replace (tests/reference/magnetic.py), on random geometries and the edge cases."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference import magnetic as ref

from comms.bus import Icd
from gnc.attitude import quat_to_dcm
from hil_sim.devices.magnetic import MagneticNodes, MagneticParams
from hil_sim.world import _magnetic_devices_nb as nb
from hil_sim.world.magnetic_devices import MagnetometerParams, MagnetorquerParams
from hil_sim.world.sun_sensors import CUBE_FACES_B, SunSensorParams, SunSensorModel

N = 5000
EMPTY = np.zeros(0)


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=n)
    return v / np.linalg.norm(v)


def _close(a: np.ndarray, b: np.ndarray, rtol: float = 1e-15) -> None:
    """Equal to within ``rtol`` of the vector's largest element (the kernels sum small products in their own
    order, numpy's BLAS in its own: a last-bit difference)."""
    assert np.max(np.abs(a - b)) <= rtol * np.max(np.abs(b)), (a, b)


def test_an_inertial_vector_turned_into_body_axes_as_the_rotation_matrix_does():
    rng = np.random.default_rng(10)
    for _ in range(N):
        q, v = _unit(rng, 4), rng.normal(size=3) * 3e-5
        _close(nb.to_body_nb(q, *v), ref.to_body(q, v))  # the reference is a matrix product (BLAS order)


def test_rod_commands_clipped_to_each_rods_saturation_nan_as_zero_inf_saturated():
    rng = np.random.default_rng(11)
    for _ in range(N):
        cmd, lim = rng.normal(size=3) * 12.0, rng.uniform(0.5, 10.0, 3)
        cmd[rng.integers(0, 3)] = rng.choice([np.nan, np.inf, -np.inf, cmd[0]])
        assert np.array_equal(nb.clip_rods_nb(cmd, lim, np.empty(3)), ref.rod_dipoles(cmd, lim))


@pytest.mark.parametrize("live", [True, False])
def test_held_rods_and_their_body_dipole(live):
    rng = np.random.default_rng(12)
    for _ in range(200):
        cmd, lim, axes = rng.normal(size=3) * 12.0, rng.uniform(0.5, 10.0, 3), rng.normal(size=(3, 3))
        held, body = np.empty(3), np.empty(3)
        nb.held_rods_nb(live, cmd, lim, np.ascontiguousarray(axes.T), held, body)
        expected = ref.rod_dipoles(cmd, lim) if live else np.zeros(3)
        assert np.array_equal(held, expected)
        if live:
            _close(body, axes.T @ expected)
        else:
            np.testing.assert_array_equal(body, 0.0)


def test_the_magnetometer_reading_with_the_rods_field_bias_noise_and_range():
    rng = np.random.default_rng(13)
    for k in range(N):
        b, R = rng.normal(size=3) * 3e-5, quat_to_dcm(_unit(rng, 4))
        C, rods = rng.normal(size=(3, 3)) * 1e-7, rng.normal(size=3) * 10.0
        bias, noise = rng.normal(size=3) * 1e-7, rng.normal(size=3) * 5e-8
        full = 1e-4 if k % 2 else 2e-5  # every other sample clipped at the range on some axis
        got = nb.magnetometer_nb(b, C, rods, R, bias, noise, 0.0, full, np.empty(3))
        _close(got, ref.magnetometer_reading(b, C, rods, R, bias, noise, 0.0, full))
        bare = nb.magnetometer_nb(b, C, EMPTY, R, bias, EMPTY, 0.0, full, np.empty(3))
        _close(bare, ref.magnetometer_reading(b, C, None, R, bias, None, 0.0, full))


def test_the_magnetometer_quantises_half_steps_to_even_as_numpy():
    # identity mounting, no rods: the reading is the field itself, so only the rounding can differ
    res = 1e-6
    b = np.array([2.5e-6, -3.5e-6, 0.49e-6])
    got = nb.magnetometer_nb(b, np.zeros((3, 0)), EMPTY, np.eye(3), np.zeros(3), EMPTY, res, 1e-4, np.empty(3))
    expected = ref.magnetometer_reading(b, None, None, np.eye(3), np.zeros(3), None, res, 1e-4)
    assert np.array_equal(got, expected)


def test_sun_cells_follow_the_cosine_law_field_of_view_noise_and_zero_floor():
    rng = np.random.default_rng(14)
    for k in range(N):
        normals = rng.normal(size=(6, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        sun, half, frac = _unit(rng, 3), rng.uniform(20.0, 90.0), rng.choice([0.0, 0.4, 1.0])
        noise = rng.normal(size=6) * 0.05 if k % 2 else None
        got = nb.sun_cells_nb(normals, sun, math.cos(math.radians(half)), 2.0 * frac,
                              EMPTY if noise is None else noise, np.empty(6))
        expected = ref.sun_cells(normals, sun, half, 2.0, frac, noise)
        assert np.max(np.abs(got - expected)) <= 1e-15 * 2.0, (got, expected)


def test_the_models_draw_the_same_noise_as_before():
    """SunSensorModel and the nodes draw from their generator exactly what the numpy models drew."""
    params = SunSensorParams(normals_B=CUBE_FACES_B, noise_std=0.01)
    sun = np.array([0.6, 0.0, 0.8])
    got = SunSensorModel(params).outputs(sun, 1.0, np.random.default_rng(3))
    noise = np.random.default_rng(3).normal(0.0, 0.01, (6,))
    _close(got, ref.sun_cells(np.array(CUBE_FACES_B), sun, 90.0, 1.0, 1.0, noise))


def test_the_nodes_hold_and_sum_the_rods_as_the_truth_model():
    rods = MagnetorquerParams(axes_B=((0.6, 0.8, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)), max_dipole_Am2=(1.0, 2.0, 3.0))
    nodes = MagneticNodes(Icd(), MagneticParams(magnetometer=MagnetometerParams(), magnetorquers=rods))
    np.testing.assert_array_equal(nodes.held_Am2(0.0), 0.0)  # no command yet
    nodes.on_command([5.0, -0.5, np.nan], 1.0)
    np.testing.assert_array_equal(nodes.held_Am2(1.1), [1.0, -0.5, 0.0])
    np.testing.assert_allclose(nodes.rods_dipole_B(1.1), [0.6, 0.8, -0.5], atol=1e-15)
    np.testing.assert_array_equal(nodes.rods_dipole_B(1.0 + nodes.params.mtq_cmd_timeout_s + 0.01), 0.0)
