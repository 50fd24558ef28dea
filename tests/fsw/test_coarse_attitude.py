"""The coarse attitude: the Sun sensors and the magnetometer while the star tracker is lost (fsw.coarse_attitude,
gnc.magnetic.css_sun_fix, gnc.field_model)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fsw.config import CoarseAttitudeConfig, FswConfig
from fsw.estimation import AttitudeEstimator
from fsw.coarse_attitude import CoarseAttitude, triad_q_NB, vector_update
from gnc.field_model import FieldModel
from gnc.attitude import quat_from_axis_angle, quat_multiply, quat_to_dcm
from gnc.magnetic import css_sun_direction, css_sun_fix

CUBE = np.array(CoarseAttitudeConfig().normals_B)  # +x, -x, +y, -y, +z, -z: CSS_CURRENTS order


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
    q = across
    for _ in range(20):
        q, P, innov, sigma = vector_update(q, P, sun_B, sun_N, math.radians(2.0))
    assert _angle_deg(quat_to_dcm(q).T @ sun_N, sun_B) < 0.5
    about = _rotated(q_true, [1.0, 0.0, 0.0], 4.0)  # 4 deg off about the Sun line: not observable
    q2, P2, innov2, _ = vector_update(about, np.diag([math.radians(5.0) ** 2] * 3 + [1e-8] * 3),
                                             sun_B, sun_N, math.radians(2.0))
    assert innov2 < 1e-9
    np.testing.assert_allclose(q2, about, atol=1e-12)
    # the variance across the line is held at the measurement's, never below
    e = np.array([0.0, 1.0, 0.0])
    assert float(e @ P[0:3, 0:3] @ e) >= math.radians(2.0) ** 2 * (1 - 1e-9)
    assert np.all(np.linalg.eigvalsh(P) > 0.0)


def test_a_coarse_direction_never_moves_the_gyro_bias():
    """The bias is considered, not estimated: a Sun direction 3 deg off, fused 600 times into an estimator
    with a strong attitude-bias correlation, corrects the attitude and leaves the bias where it was (an
    estimated bias had walked to 370 deg/h on the cells' slowly changing error)."""
    est = _estimator()
    est.P = np.diag([math.radians(5.0) ** 2] * 3 + [math.radians(0.1) ** 2] * 3)
    est.P[0, 3] = est.P[3, 0] = 0.9 * math.sqrt(est.P[0, 0] * est.P[3, 3])
    est.bias_B[:] = [1e-5, -2e-5, 3e-6]
    start = est.bias_B.copy()
    est.q_NB = _rotated(np.array([1.0, 0.0, 0.0, 0.0]), [1.0, 0.0, 0.0], 3.0)  # the truth: identity
    est.coasting_s, est.star_tracker_used = 10.0, False
    sky = _Sky([0.0, 0.6, 0.8])
    fix = _coarse(CoarseAttitudeConfig(after_s=1.0), _Events())
    for _ in range(600):
        fix.cycle(est, _cells(sky.sun_N), NO_FIELD, True, 0.0, sky)
    assert fix.fused == 600
    np.testing.assert_array_equal(est.bias_B, start)
    assert _angle_deg(quat_to_dcm(est.q_NB).T @ sky.sun_N, sky.sun_N) < 0.5
    assert np.all(np.linalg.eigvalsh(0.5 * (est.P + est.P.T)) > 0.0)


class _Events(list):
    def __call__(self, name, **args):
        self.append((name, args))


class _Sky:
    """The onboard ephemeris as the coarse attitude asks it: the Sun's direction and the spacecraft's position."""

    def __init__(self, sun_N, r_N_km=(6928.0, 0.0, 0.0)):
        self.sun_N, self.r_N_km = np.asarray(sun_N, dtype=float), np.asarray(r_N_km, dtype=float)

    def directions(self, t_s):
        return {"sun": self.sun_N}

    def position_N_km(self, t_s):
        return self.r_N_km


GAUSS_T = [[-29.35e-6, 0.0], [-1.41e-6, 4.55e-6]]  # IGRF-14's dipole (g10; g11, h11) about 2026
JD0 = 2461156.0


def _coarse(cfg, events):
    return CoarseAttitude(cfg, events, JD0)


def _estimator(initialized=True):
    est = AttitudeEstimator(FswConfig().estimator, np.array([1.0, 0.0, 0.0, 0.0]))
    est.initialized = initialized
    est.P = np.diag([math.radians(3.0) ** 2] * 3 + [1e-8] * 3)
    return est


NO_FIELD = np.full(3, np.nan)


def test_the_fix_starts_after_the_star_tracker_has_been_silent_and_stops_when_it_is_back():
    events = _Events()
    fix = _coarse(CoarseAttitudeConfig(after_s=10.0), events)
    est = _estimator()
    sky = _Sky([0.0, 0.0, -1.0])
    est.q_NB = _rotated(np.array([1.0, 0.0, 0.0, 0.0]), [1.0, 0.0, 0.0], 3.0)
    cells = _cells(np.array([0.0, 0.0, -1.0]))  # the truth: identity attitude
    est.coasting_s, est.star_tracker_used = 5.0, False
    assert not fix.cycle(est, cells, NO_FIELD, True, 0.0, sky) and events == []
    est.coasting_s = 10.0
    for _ in range(30):
        fix.cycle(est, cells, NO_FIELD, True, 0.0, sky)
    assert events[0][0] == "COARSE_ATTITUDE_ON" and fix.fused == 30
    assert _angle_deg(quat_to_dcm(est.q_NB).T @ sky.sun_N, np.array([0.0, 0.0, -1.0])) < 0.5
    assert not fix.cycle(est, np.zeros(6), NO_FIELD, True, 0.0, sky)  # the shadow, no field: nothing to fuse
    est.star_tracker_used, est.coasting_s = True, 0.0
    fix.cycle(est, cells, NO_FIELD, True, 0.0, sky)
    assert events[-1] == ("COARSE_ATTITUDE_OFF", {"fused": 30, "rejected": 0})


def test_a_good_estimate_is_barely_moved_by_a_coarse_direction():
    """Just after the star tracker is lost the estimate is far better than the cells: a Sun direction 3 deg
    off (the dark cells' bound) must not drag it there, nor inflate its covariance."""
    est = _estimator()
    est.P = np.diag([math.radians(0.01) ** 2] * 3 + [1e-12] * 3)
    fix = _coarse(CoarseAttitudeConfig(after_s=1.0), _Events())
    est.coasting_s, est.star_tracker_used = 2.0, False
    off = np.array([math.sin(math.radians(3.0)), 0.0, -math.cos(math.radians(3.0))])
    for _ in range(100):
        fix.cycle(est, _cells(off), NO_FIELD, True, 0.0, _Sky([0.0, 0.0, -1.0]))
    assert math.degrees(2.0 * math.acos(min(1.0, abs(est.q_NB[0])))) < 0.1
    assert np.trace(est.P[0:3, 0:3]) <= 3 * math.radians(0.01) ** 2 * 1.0001


def test_a_direction_far_from_the_estimate_is_gated_out():
    fix = _coarse(CoarseAttitudeConfig(after_s=1.0, gate_deg=10.0), _Events())
    est = _estimator()
    est.coasting_s, est.star_tracker_used = 2.0, False
    q_before = est.q_NB.copy()
    far = np.array([math.sin(math.radians(40.0)), 0.0, -math.cos(math.radians(40.0))])
    assert not fix.cycle(est, _cells(far), NO_FIELD, True, 0.0, _Sky([0.0, 0.0, -1.0]))
    assert fix.rejected == 1
    np.testing.assert_array_equal(est.q_NB, q_before)


def _field_cfg(**kw):
    return CoarseAttitudeConfig(after_s=1.0, field_sigma_deg=1.0, geomagnetic_gauss_T=GAUSS_T, **kw)


def test_never_a_star_tracker_fix_the_sun_and_the_field_find_the_attitude():
    q_true = _rotated(_rotated(np.array([1.0, 0.0, 0.0, 0.0]), [0.0, 1.0, 0.0], 70.0), [1.0, 0.0, 0.0], -35.0)
    R = quat_to_dcm(q_true)
    sky = _Sky(np.array([0.6, 0.7, 0.2]) / np.linalg.norm([0.6, 0.7, 0.2]), r_N_km=(3000.0, -5500.0, 3000.0))
    field_N = FieldModel(GAUSS_T).field_N(sky.r_N_km, JD0 + 20.0 / 86400.0)
    events = _Events()
    fix = _coarse(_field_cfg(), events)
    est = _estimator(initialized=False)
    est.coasting_s, est.star_tracker_used = 20.0, False
    assert not fix.cycle(est, _cells(R.T @ sky.sun_N), NO_FIELD, True, 20.0, sky)  # the Sun alone: not yet
    assert fix.cycle(est, _cells(R.T @ sky.sun_N), R.T @ field_N, True, 20.0, sky)
    assert est.initialized and events[-1][0] == "COARSE_ATTITUDE_FOUND"
    err = math.degrees(2.0 * math.acos(min(1.0, abs(float(est.q_NB @ q_true)))))
    assert err < math.degrees(math.asin(0.05))  # exact cells and field: only the dark cells' bound (2.9 deg)
    assert fix.cycle(est, np.zeros(6), R.T @ field_N, True, 20.0, sky)  # in the shadow, the field alone
    assert not fix.cycle(est, np.zeros(6), R.T @ field_N, False, 20.0, sky)  # the rods drive: no field


def test_the_field_fixes_the_rotation_about_the_sun_line():
    sky = _Sky([1.0, 0.0, 0.0], r_N_km=(0.0, 6928.0, 0.0))
    field_N = FieldModel(GAUSS_T).field_N(sky.r_N_km, JD0)
    est = _estimator()
    q_true = np.array([1.0, 0.0, 0.0, 0.0])
    est.q_NB = _rotated(q_true, [1.0, 0.0, 0.0], 5.0)  # 5 deg about the Sun line: the cells cannot see it
    fix = _coarse(_field_cfg(), _Events())
    est.coasting_s, est.star_tracker_used = 2.0, False
    for _ in range(50):
        fix.cycle(est, _cells(sky.sun_N), field_N, True, 0.0, sky)
    err = math.degrees(2.0 * math.acos(min(1.0, abs(float(est.q_NB @ q_true)))))
    assert err < 1.5


def test_triad_puts_the_first_vector_exactly_and_the_second_in_its_plane():
    rng = np.random.default_rng(5)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    R = quat_to_dcm(q)
    a_N, b_N = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
    got = triad_q_NB(R.T @ a_N, a_N, R.T @ b_N, b_N)
    assert abs(abs(float(got @ q)) - 1.0) < 1e-12


@pytest.mark.parametrize("degree", [1, 13])
def test_the_onboard_field_is_the_truths_field(degree):
    """gnc.field_model against the simulator's kernel (hil_sim.world.environment.earth_field_N: its own dipole at
    degree 1, IGRF at 13) with IGRF-14's coefficients at one epoch and the same rotation angle."""
    import datetime as dt

    from hil_sim.world import environment as env
    from hil_sim.world.geomagnetic import dipole_coefficients_T, earth_rotation_angle_rad, gauss_coefficients_T

    epoch = dt.datetime(2026, 4, 25, 12, tzinfo=dt.timezone.utc)
    gauss = gauss_coefficients_T(epoch, degree)
    jd0 = epoch.timestamp() / 86400.0 + 2440587.5
    rows = np.zeros((env.ENV_FIELD_FIRST + 1 + 2 * len(gauss), 1))
    g10, g11, h11 = dipole_coefficients_T(epoch)
    rows[env.ENV_EARTH_DIPOLE:env.ENV_EARTH_DIPOLE + 3, 0] = (g11, h11, g10)
    rows[env.ENV_ERA0, 0] = earth_rotation_angle_rad(epoch)
    rows[env.ENV_OMEGA_E, 0] = 7.292115146706979e-5
    if degree > 1:
        rows[env.ENV_FIELD_DEGREE, 0], rows[env.ENV_FIELD_FIRST, 0] = degree, env.ENV_FIELD_FIRST + 1
        rows[env.ENV_FIELD_FIRST + 1:, 0] = FieldModel(gauss)._rows[:, 0]
    onboard = FieldModel(gauss)
    assert onboard.degree == degree
    for r, t in (((6928.0, 0.0, 0.0), 0.0), ((1000.0, -4000.0, 5500.0), 1234.5), ((-300.0, 200.0, -6900.0), 5000.0)):
        truth = np.array(env.earth_field_N(rows, 0, *r, t))
        got = onboard.field_N(np.array(r), jd0 + t / 86400.0)
        # the Earth's turning over t as a rate (truth) or a Julian date (onboard): 1e-9 of the field
        assert np.linalg.norm(got - truth) < 1e-7 * np.linalg.norm(truth)


def test_the_coarse_attitude_needs_its_sensors_and_cells_that_see_the_hemisphere():
    with pytest.raises(ValueError, match="coarse_attitude needs magnetic_devices with sun_sensors"):
        FswConfig(coarse_attitude={})
    FswConfig(coarse_attitude={}, magnetic_devices={"sun_sensors": True})
    with pytest.raises(ValueError, match="needs magnetic_devices with magnetometer"):
        FswConfig(coarse_attitude=_field_cfg().model_dump(), magnetic_devices={"sun_sensors": True})
    with pytest.raises(ValueError, match="whole hemisphere"):
        CoarseAttitudeConfig(field_of_view_half_angle_deg=60.0)
    with pytest.raises(ValueError, match="geomagnetic_gauss_T"):
        CoarseAttitudeConfig(field_sigma_deg=2.0)
    with pytest.raises(ValueError, match="degree 2 takes 5"):
        CoarseAttitudeConfig(field_sigma_deg=2.0, field_degree=2, geomagnetic_gauss_T=GAUSS_T)


def _coarse_fsw(**coarse) -> FswConfig:
    return FswConfig(coarse_attitude=coarse, magnetic_devices={"sun_sensors": True}, law={"margin_deg": 3.0},
                     pointing={"zones": [{"name": "sun", "body": "sun", "geometry": {"shape": "cone",
                                                                                    "half_angle_deg": 40.0}}]})


def test_the_coarse_margin_covers_the_coarse_error_or_the_mission_is_refused():
    """Default: law.margin_deg + 3 sun_sigma_deg; a margin below law.margin_deg + 3 sigma of the better
    direction is refused with the figure it needs."""
    assert _coarse_fsw(sun_sigma_deg=2.0).coarse_margin_deg() == pytest.approx(9.0)
    assert _coarse_fsw(sun_sigma_deg=1.0, margin_deg=6.5).coarse_margin_deg() == 6.5
    assert FswConfig().coarse_margin_deg() is None
    with pytest.raises(ValueError, match=r"coarse_attitude.margin_deg 5 does not cover .* at least .* 9"):
        _coarse_fsw(sun_sigma_deg=2.0, margin_deg=5.0)
    field = _field_cfg().model_dump() | {"field_sigma_deg": 1.0, "margin_deg": 6.0}  # the field's 1 deg: 3 + 3
    FswConfig(coarse_attitude=field, magnetic_devices={"sun_sensors": True, "magnetometer": True},
              law={"margin_deg": 3.0})


def test_the_laws_zones_grow_to_the_coarse_margin_and_back():
    """While the coarse attitude flies, the law avoids each zone by its margin (9 deg here), not the star
    tracker's 3 deg; the physical zones, which the margins and the door judge, stay as they are."""
    from fsw.guidance import Guidance
    from fsw.guidance.common import signed_margin_deg

    g = Guidance(_coarse_fsw(sun_sigma_deg=2.0))
    g.sky_margins_at(0.0, np.array([1.0, 0.0, 0.0]))  # builds the zones
    slot = g.slots[0]
    probe = slot.center_N.copy()
    axis = np.cross(probe, [0.0, 0.0, 1.0])
    probe = quat_to_dcm(quat_from_axis_angle(axis / np.linalg.norm(axis), math.radians(55.0))) @ probe
    fine, phys = signed_margin_deg(slot.law, probe), signed_margin_deg(slot.phys, probe)
    g.use_coarse_margin(True)
    assert signed_margin_deg(slot.law, probe) == pytest.approx(fine - 6.0, abs=0.05)
    assert signed_margin_deg(slot.phys, probe) == phys
    g.use_coarse_margin(False)
    assert signed_margin_deg(slot.law, probe) == pytest.approx(fine, abs=1e-9)


def test_a_boresight_the_grown_zone_catches_is_pushed_straight_out():
    """The star tracker lost 5 deg from the Sun cone: the law's zone grows to 9 deg over the boresight, and
    the law turns it straight out of the zone (at the rate limit), not on through the zone to a target
    beyond it."""
    from fsw.guidance import Guidance
    from fsw.guidance.common import signed_margin_deg
    from gnc.attitude import dcm_to_quat

    cfg = FswConfig(initial_mode="POINTING", coarse_attitude={}, magnetic_devices={"sun_sensors": True},
                    law={"margin_deg": 3.0}, pointing={"boresight_B": [0.0, 0.0, 1.0], "zones": [
                        {"name": "sun", "body": "sun", "geometry": {"shape": "cone", "half_angle_deg": 40.0}}]})
    g = Guidance(cfg)
    g.sky_margins_at(0.0, np.array([1.0, 0.0, 0.0]))
    sun = g.slots[0].center_N
    across = np.cross(sun, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)

    def from_sun(deg):
        return math.cos(math.radians(deg)) * sun + math.sin(math.radians(deg)) * across

    y = from_sun(45.0)
    g.set_target_direction(from_sun(-60.0))  # beyond the Sun: the way to it runs through the zone
    x_B = np.cross([0.0, 0.0, 1.0], y)
    x_B /= np.linalg.norm(x_B)
    q = dcm_to_quat(np.column_stack([x_B, np.cross(y, x_B), y]))
    g.use_coarse_margin(True)
    assert signed_margin_deg(g.slots[0].law, y) < -4.0 < 4.9 < signed_margin_deg(g.slots[0].phys, y)
    out = g.step(0.0, 0.1, q, np.zeros(3))
    y_dot = np.cross(quat_to_dcm(q) @ out.omega_cmd_BN_B, y)
    outward = y * float(y @ sun) - sun  # away from the Sun, along the sphere at y
    outward /= np.linalg.norm(outward)
    assert float(y_dot @ outward) / np.linalg.norm(y_dot) > 0.99
