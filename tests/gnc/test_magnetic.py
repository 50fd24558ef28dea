"""gnc.magnetic: B-dot detumbling, cross-product unloading, rod saturation and coarse Sun sensing."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hil_sim.world.sun_sensors import SunSensorParams, sun_sensor_outputs

from gnc.magnetic import (bdot_dipole, css_sun_direction, dipole_for_torque, magnetic_torque,
                          saturate_dipole, unloading_dipole)

MU_EARTH = 3.986004418e14  # m^3/s^2
R_ORBIT = 6_921e3  # m, a 550 km circular orbit
B0 = 3.12e-5 * (6_371.2e3 / R_ORBIT) ** 3  # T, the dipole's equatorial field at the orbit's radius


def css_currents(normals_B: np.ndarray, sun_B: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """The truth model's cosine-law cells (no noise, full Sun, a 90 deg field of view): what the flight law reads."""
    cells = SunSensorParams(normals_B=tuple(map(tuple, np.asarray(normals_B, dtype=float))), full_scale=scale)
    return sun_sensor_outputs(cells, np.asarray(sun_B, dtype=float), 1.0, np.random.default_rng(0))


def _field_N(t_s: float, inclination_deg: float = 97.6) -> np.ndarray:
    """A centred, aligned dipole's field along a circular orbit (enough to turn B the way an orbit does)."""
    n = math.sqrt(MU_EARTH / R_ORBIT**3)
    u = n * t_s
    i = math.radians(inclination_deg)
    r_hat = np.array([math.cos(u), math.sin(u) * math.cos(i), math.sin(u) * math.sin(i)])
    m_hat = np.array([0.0, 0.0, -1.0])
    return B0 * (3.0 * r_hat * float(m_hat @ r_hat) - m_hat)


def test_saturation_keeps_the_direction_and_every_rod_within_its_limit():
    rng = np.random.default_rng(3)
    limits = np.array([0.2, 0.2, 0.1])
    for _ in range(200):
        m = rng.normal(scale=0.5, size=3)
        s = saturate_dipole(m, limits)
        assert np.all(np.abs(s) <= limits + 1e-15)
        assert np.linalg.norm(np.cross(s, m)) <= 1e-12 * np.linalg.norm(m) ** 2
        assert float(s @ m) > 0.0
    inside = np.array([0.05, -0.1, 0.02])
    assert np.array_equal(saturate_dipole(inside, limits), inside)


def test_a_dipole_gives_the_part_of_a_torque_normal_to_the_field():
    rng = np.random.default_rng(4)
    for _ in range(100):
        tau, b = rng.normal(size=3), rng.normal(size=3) * 3e-5
        got = magnetic_torque(dipole_for_torque(tau, b), b)
        b_hat = b / np.linalg.norm(b)
        np.testing.assert_allclose(got, tau - (tau @ b_hat) * b_hat, rtol=1e-10, atol=1e-14)
    assert np.array_equal(dipole_for_torque(np.ones(3), np.zeros(3)), np.zeros(3))


def test_unloading_never_adds_wheel_momentum():
    rng = np.random.default_rng(5)
    for _ in range(200):
        dh, b = rng.normal(scale=0.01, size=3), rng.normal(size=3) * 3e-5
        m = unloading_dipole(dh, b, gain_1_s=0.01, max_Am2=np.full(3, 0.2))
        assert float(dh @ magnetic_torque(m, b)) <= 1e-18


def test_cross_product_unloading_dumps_the_momentum_of_an_inertially_held_spacecraft():
    """Attitude held (the wheels absorb m x B), the wheels' excess falls as the orbit turns the field."""
    period = 2 * math.pi / math.sqrt(MU_EARTH / R_ORBIT**3)
    dt = 5.0
    h0 = np.array([0.02, -0.015, 0.01])  # N m s, above the bias
    h = h0.copy()
    for k in range(int(3 * period / dt)):
        b = _field_N(k * dt)  # body = N: the attitude is held
        h = h + dt * magnetic_torque(unloading_dipole(h, b, gain_1_s=2e-3, max_Am2=np.full(3, 0.2)), b)
    assert np.linalg.norm(h) < 0.05 * np.linalg.norm(h0)


def _field_rate_N(t_s: float) -> np.ndarray:
    return (_field_N(t_s + 0.5) - _field_N(t_s - 0.5)) / 1.0


def _detumble(gain: float, orbits: float, rate0_deg_s: float = 5.0) -> tuple[float, list[float]]:
    """(final rate [deg/s], rotational energy [J] every tenth of an orbit) of a B-dot detumble.

    The law sees dB/dt in body axes as a magnetometer differencing its samples would: the body's turning
    of the field plus the orbit's (``R^T dB_N/dt - w x B_B``)."""
    J = np.diag([0.12, 0.10, 0.08])  # kg m^2, a 12U cubesat
    J_inv = np.linalg.inv(J)
    limits = np.full(3, 0.2)

    def rates(t, y):
        q, w = y[:4] / np.linalg.norm(y[:4]), y[4:]
        q0, qv = q[0], q[1:]
        R_NB = (q0**2 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) + 2 * q0 * np.array(
            [[0, -qv[2], qv[1]], [qv[2], 0, -qv[0]], [-qv[1], qv[0], 0]])
        b = R_NB.T @ _field_N(t)
        m = bdot_dipole(R_NB.T @ _field_rate_N(t) - np.cross(w, b), gain, limits)
        w0, w1, w2 = w
        q_dot = 0.5 * np.array([[0, -w0, -w1, -w2], [w0, 0, w2, -w1], [w1, -w2, 0, w0], [w2, w1, -w0, 0]]) @ q
        return np.concatenate([q_dot, J_inv @ (magnetic_torque(m, b) - np.cross(w, J @ w))])

    y0 = np.concatenate([[1.0, 0.0, 0.0, 0.0], np.radians(np.full(3, rate0_deg_s))])
    t_end = orbits * 5_730.0
    sol = solve_ivp(rates, (0.0, t_end), y0, rtol=1e-8, atol=1e-10, t_eval=np.linspace(0.0, t_end, int(orbits * 10) + 1))
    energy = [0.5 * float(w @ J @ w) for w in sol.y[4:].T]
    return math.degrees(float(np.linalg.norm(sol.y[4:, -1]))), energy


def test_bdot_detumbles_from_separation_rates():
    n = 2 * math.pi / 5_730.0
    gain = 2 * n * (1 + math.sin(math.radians(97.6 - 90.0))) * 0.08 / B0**2  # Avanzini and Giulietti's sizing
    rate_end, energy = _detumble(gain, orbits=3.0)
    assert rate_end < 0.5, rate_end
    assert all(b < a for a, b in zip(energy[:10], energy[1:11]))  # while it tumbles, every tenth of an orbit takes energy out


def test_without_bdot_the_body_keeps_tumbling():
    rate_end, energy = _detumble(0.0, orbits=0.1)
    assert rate_end > 8.0
    assert energy[-1] == pytest.approx(energy[0], rel=1e-5)


@pytest.mark.parametrize("sun", [[1, 0, 0], [0.3, -0.5, 0.81], [-0.6, -0.6, -0.53]])
def test_six_cells_on_the_cube_faces_give_the_sun_direction(sun):
    normals = np.vstack([np.eye(3), -np.eye(3)])
    s = np.asarray(sun, dtype=float) / np.linalg.norm(sun)
    got = css_sun_direction(normals, css_currents(normals, s, 2.5), 2.5, lit_fraction=-1.0)
    np.testing.assert_allclose(got, s, atol=1e-12)


def test_cells_that_do_not_fix_the_sun_give_none():
    normals = np.vstack([np.eye(3), -np.eye(3)])
    s = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)  # two faces lit: the Sun is only known on a circle
    assert css_sun_direction(normals, css_currents(normals, s)) is None
    assert css_sun_direction(normals, np.zeros(6)) is None  # eclipse
    pyramid = np.array([[0.5, 0.5, 0.707], [-0.5, 0.5, 0.707], [0.0, -0.7, 0.714], [0.0, 0.0, -1.0]])
    pyramid /= np.linalg.norm(pyramid, axis=1)[:, None]
    s2 = np.array([0.1, 0.2, 0.97]) / np.linalg.norm([0.1, 0.2, 0.97])
    np.testing.assert_allclose(css_sun_direction(pyramid, css_currents(pyramid, s2)), s2, atol=1e-12)
