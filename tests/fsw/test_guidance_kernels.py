"""The guidance's compiled per-cycle kernels (fsw.guidance._kernels) against the numpy expressions they
replaced: the same numbers up to the last bit or two of a 3-term dot product."""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from fsw.guidance._kernels import aim_index_nb, boresight_nb, pointing_command_nb
from gnc._sky_ephemeris_nb import sky_directions_nb
from fsw.guidance.common import _saturate
from gnc.attitude import pointing_rate_command_nb

TOL = 1e-14


def _unit(v):
    return v / np.linalg.norm(v)


def _q_NB(rng) -> np.ndarray:
    xyzw = Rotation.random(random_state=rng).as_quat()
    return np.array([xyzw[3], *xyzw[:3]])


def _reference_command(q, y, b, u_law, k1, max_rate, governor_rate, target, roll_axis, roll_ref, roll_gain):
    """POINTING's command as the guidance computed it with numpy (scipy's Rotation for R_NB)."""
    R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
    omega = _saturate(np.asarray(pointing_rate_command_nb(q, b, k1 * u_law)), max_rate)
    if governor_rate >= 0.0:
        omega = _saturate(omega, governor_rate)
    error = math.degrees(math.acos(max(-1.0, min(1.0, float(y @ target)))))
    ref = roll_ref
    if abs(float(ref @ y)) > 0.95:
        ref = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    r_B = R.T @ ref
    a = roll_axis - (roll_axis @ b) * b
    r = r_B - (r_B @ b) * b
    roll = math.atan2(float(b @ np.cross(a, r)), float(a @ r))
    room = math.sqrt(max(0.0, max_rate ** 2 - float(omega @ omega)))
    total = omega + _saturate(roll_gain * roll * b, min(room, 0.5 * max_rate))
    return total, float(np.linalg.norm(omega)), error, roll


def test_boresight_and_pointing_command_match_the_numpy_reference() -> None:
    rng = np.random.default_rng(11)
    b = np.array([0.0, 0.0, 1.0])
    roll_axis = np.array([1.0, 0.0, 0.0])
    governed = limited = 0
    for k in range(400):
        q = _q_NB(rng)
        y = boresight_nb(q, b)
        R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
        np.testing.assert_allclose(y, R @ b, rtol=0, atol=TOL)
        u_law = rng.standard_normal(3)
        target = _unit(rng.standard_normal(3))
        # every fourth case: the roll reference near the boresight (the fallback axis)
        roll_ref = _unit(y + 0.05 * rng.standard_normal(3)) if k % 4 == 0 else _unit(rng.standard_normal(3))
        governor = -1.0 if k % 3 == 0 else float(rng.uniform(0.0, 0.02))
        args = (q, y, b, u_law, 0.3, math.radians(1.0), governor, target, roll_axis, roll_ref, 0.2)
        got = pointing_command_nb(*args)
        omega, rate, error, roll = _reference_command(*args)
        # at the rate limit the roll's room, sqrt(max_rate^2 - |omega|^2), is the root of a rounding
        # difference: up to sqrt(2.2e-16) max_rate = 2.6e-10 rad/s apart, whichever way the sum is rounded
        np.testing.assert_allclose(got[:3], omega, rtol=0, atol=1e-9)
        assert abs(got[3] - rate) < TOL and abs(got[4] - error) < 1e-9 and abs(got[5] - roll) < 1e-12
        assert np.linalg.norm(got[:3]) <= math.radians(1.0) * (1 + 1e-12)  # the body rate stays in the limit
        governed += governor >= 0.0 and rate <= governor + 1e-15
        limited += abs(rate - math.radians(1.0)) < 1e-15
    assert governed > 100 and limited > 50  # both limits were exercised


def test_sky_directions_are_the_interpolated_unit_vectors() -> None:
    rng = np.random.default_rng(5)
    p_hat, q_hat = np.array([1.0, 0.0, 0.0]), _unit(np.array([0.0, 0.9, 0.1]))
    for _ in range(100):
        s0, s1, m0, m1 = (rng.standard_normal(3) * scale for scale in (1.5e8, 1.5e8, 3.8e5, 3.8e5))
        t, f = float(rng.uniform(0.0, 1e5)), float(rng.uniform(0.0, 1.0))
        d = sky_directions_nb(t, 0.3, 7.3e-5, 42164.0, p_hat, q_hat, f, s0, s1, m0, m1)
        u = 0.3 + 7.3e-5 * t
        r = 42164.0 * (math.cos(u) * p_hat + math.sin(u) * q_hat)
        for row, v in zip(d, (s0 + f * (s1 - s0) - r, m0 + f * (m1 - m0) - r, -r)):
            np.testing.assert_allclose(row, v / np.linalg.norm(v), rtol=0, atol=1e-15)


def test_aim_index_is_argmax_then_first_point_beyond_the_look_ahead() -> None:
    rng = np.random.default_rng(2)
    for k in range(400):
        dim = 3 if k % 2 else 4  # boresight paths on S^2, attitude paths on S^3
        path = np.ascontiguousarray(sample_path(rng, dim))
        y = _unit(rng.standard_normal(dim))
        start = int(rng.integers(0, len(path)))
        cos_ahead = math.cos(math.radians(rng.uniform(1.0, 30.0)))
        nearest = start + int(np.argmax(path[start:] @ y))
        ahead = np.flatnonzero(path[nearest:] @ y < cos_ahead)
        aim = len(path) - 1 if ahead.size == 0 else nearest + int(ahead[0])
        assert tuple(aim_index_nb(path, start, y, cos_ahead)) == (nearest, aim)


def sample_path(rng, dim: int) -> np.ndarray:
    """A random great-circle path on S^(dim-1) of 40-200 points, 0.5 deg apart."""
    a = _unit(rng.standard_normal(dim))
    v = rng.standard_normal(dim)
    e = _unit(v - (v @ a) * a)
    s = np.radians(0.5) * np.arange(int(rng.integers(40, 200)))
    return np.cos(s)[:, None] * a + np.sin(s)[:, None] * e
