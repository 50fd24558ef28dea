"""The attitude held on the coarse sun sensors while the star tracker is lost (fsw.sun_fix, gnc.magnetic.css_sun_fix)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fsw.config import FswConfig, SunSensorFixConfig
from fsw.estimation import AttitudeEstimator
from fsw.sun_fix import SunSensorFix, sun_vector_update
from gnc.attitude import quat_from_axis_angle, quat_multiply, quat_to_dcm
from gnc.magnetic import css_sun_direction, css_sun_fix

CUBE = np.vstack([np.eye(3), -np.eye(3)])


def _cells(sun_B, fraction=1.0, noise=0.0, rng=None):
    out = fraction * np.maximum(CUBE @ sun_B, 0.0)
    if noise:
        out = np.maximum(out + rng.normal(0.0, noise, len(out)), 0.0)
    return out


def _angle_deg(a, b):
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b)))))


def test_a_sun_pointed_face_is_fixed_where_three_lit_cells_are_not_needed():
    sun = np.array([1.0, 0.0, 0.0])  # one cell lit: the Sun-pointed attitude SAFE holds
    assert css_sun_direction(CUBE, _cells(sun)) is None
    np.testing.assert_allclose(css_sun_fix(CUBE, _cells(sun)), sun, atol=1e-12)


def test_every_direction_is_fixed_within_the_dark_cells_bound_plus_noise():
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(3000):
        s = rng.normal(size=3)
        s /= np.linalg.norm(s)
        fix = css_sun_fix(CUBE, _cells(s, noise=0.005, rng=rng))
        assert fix is not None
        worst = max(worst, _angle_deg(fix, s))
    assert worst < math.degrees(math.asin(0.05)) + 1.5


def test_no_fix_in_the_shadow_or_the_penumbra():
    s = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    assert css_sun_fix(CUBE, _cells(s, fraction=0.0)) is None
    assert css_sun_fix(CUBE, _cells(s, fraction=0.5)) is None  # dimmed: a dark cell bounds nothing
    assert css_sun_fix(CUBE, _cells(s, fraction=1.0)) is not None


def _rotated(q, axis, deg):
    return quat_multiply(q, quat_from_axis_angle(np.asarray(axis, dtype=float), math.radians(deg)))


def test_the_update_corrects_across_the_sun_line_and_leaves_the_roll_about_it():
    q_true = np.array([1.0, 0.0, 0.0, 0.0])
    sun_N = np.array([1.0, 0.0, 0.0])
    sun_B = quat_to_dcm(q_true).T @ sun_N
    P = np.diag([math.radians(5.0) ** 2] * 3 + [1e-8] * 3)
    across = _rotated(q_true, [0.0, 0.0, 1.0], 4.0)  # 4 deg off across the Sun line
    q, bias = across, np.zeros(3)
    for _ in range(20):
        q, bias, P, innov, sigma = sun_vector_update(q, bias, P, sun_B, sun_N, math.radians(2.0))
    assert _angle_deg(quat_to_dcm(q).T @ sun_N, sun_B) < 0.5
    about = _rotated(q_true, [1.0, 0.0, 0.0], 4.0)  # 4 deg off about the Sun line: not observable
    q2, _, P2, innov2, _ = sun_vector_update(about, np.zeros(3), np.diag([math.radians(5.0) ** 2] * 3 + [1e-8] * 3),
                                             sun_B, sun_N, math.radians(2.0))
    assert innov2 < 1e-9
    np.testing.assert_allclose(q2, about, atol=1e-12)
    # the variance across the line is held at the measurement's, never below
    e = np.array([0.0, 1.0, 0.0])
    assert float(e @ P[0:3, 0:3] @ e) >= math.radians(2.0) ** 2 * (1 - 1e-9)
    assert np.all(np.linalg.eigvalsh(P) > 0.0)


class _Events(list):
    def __call__(self, name, **args):
        self.append((name, args))


def _estimator():
    est = AttitudeEstimator(FswConfig().estimator, np.array([1.0, 0.0, 0.0, 0.0]))
    est.initialized = True
    est.P = np.diag([math.radians(3.0) ** 2] * 3 + [1e-8] * 3)
    return est


def test_the_fix_starts_after_the_star_tracker_has_been_silent_and_stops_when_it_is_back():
    events = _Events()
    fix = SunSensorFix(SunSensorFixConfig(after_s=10.0), events)
    est = _estimator()
    sun_N = np.array([0.0, 0.0, -1.0])
    off = _rotated(np.array([1.0, 0.0, 0.0, 0.0]), [1.0, 0.0, 0.0], 3.0)
    est.q_NB = off
    cells = _cells(np.array([0.0, 0.0, -1.0]))  # the truth: identity attitude
    est.coasting_s, est.star_tracker_used = 5.0, False
    assert not fix.cycle(est, cells, lambda: sun_N) and events == []
    est.coasting_s = 10.0
    for _ in range(30):
        fix.cycle(est, cells, lambda: sun_N)
    assert events[0][0] == "SUN_SENSOR_FIX_ON" and fix.fused == 30
    assert _angle_deg(quat_to_dcm(est.q_NB).T @ sun_N, np.array([0.0, 0.0, -1.0])) < 0.5
    assert not fix.cycle(est, np.zeros(6), lambda: sun_N) and fix.dark == 1  # the shadow: nothing to fuse
    est.star_tracker_used, est.coasting_s = True, 0.0
    fix.cycle(est, cells, lambda: sun_N)
    assert events[-1] == ("SUN_SENSOR_FIX_OFF", {"fused": 30, "rejected": 0})


def test_a_sun_far_from_the_estimate_is_gated_out():
    fix = SunSensorFix(SunSensorFixConfig(after_s=1.0, gate_deg=10.0), _Events())
    est = _estimator()
    est.coasting_s, est.star_tracker_used = 2.0, False
    q_before = est.q_NB.copy()
    far = np.array([math.sin(math.radians(40.0)), 0.0, -math.cos(math.radians(40.0))])
    assert not fix.cycle(est, _cells(far), lambda: np.array([0.0, 0.0, -1.0]))
    assert fix.rejected == 1
    np.testing.assert_array_equal(est.q_NB, q_before)


def test_the_fix_needs_the_sun_sensors_and_cells_that_see_the_hemisphere():
    with pytest.raises(ValueError, match="sun_sensor_fix needs magnetic_devices with sun_sensors"):
        FswConfig(sun_sensor_fix={})
    FswConfig(sun_sensor_fix={}, magnetic_devices={"sun_sensors": True})
    with pytest.raises(ValueError, match="whole hemisphere"):
        SunSensorFixConfig(field_of_view_half_angle_deg=60.0)
