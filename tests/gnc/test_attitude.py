"""gnc.attitude against scipy.spatial.transform.Rotation (scalar-LAST) and against the paper's maps.

The closed-loop tests integrate the *attitude* (quaternion or rotation matrix) driven by the body-rate
command, and compare the resulting x (boresight or quaternion) with an independent integration of
xdot = P(x) u(x) on the sphere.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from gnc import attitude as att


def to_scipy(q_sf: np.ndarray) -> Rotation:
    """Scalar-first -> scipy (scalar-last)."""
    return Rotation.from_quat(np.roll(q_sf, -1, axis=-1))


def from_scipy(rot: Rotation) -> np.ndarray:
    return np.roll(rot.as_quat(), 1, axis=-1)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


def random_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_dcm_matches_scipy(rng):
    q = random_quats(rng, 200)
    np.testing.assert_allclose(att.quat_to_dcm(q), to_scipy(q).as_matrix(), atol=1e-14)


def test_rotate_matches_scipy_and_dcm(rng):
    q = random_quats(rng, 200)
    v = rng.normal(size=(200, 3))
    expected = to_scipy(q).apply(v)
    np.testing.assert_allclose(att.quat_rotate(q, v), expected, atol=1e-13)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", att.quat_to_dcm(q), v), expected, atol=1e-13)


def test_multiply_is_composition(rng):
    # q_AC = q_AB (x) q_BC  <=>  R_AC = R_AB R_BC  (scipy: r1 * r2 applies r2 first)
    p = random_quats(rng, 100)
    q = random_quats(rng, 100)
    composed = att.quat_multiply(p, q)
    np.testing.assert_allclose(att.quat_to_dcm(composed), (to_scipy(p) * to_scipy(q)).as_matrix(), atol=1e-13)


def test_conjugate_is_inverse(rng):
    q = random_quats(rng, 50)
    np.testing.assert_allclose(att.quat_to_dcm(att.quat_conjugate(q)), to_scipy(q).inv().as_matrix(), atol=1e-14)
    ident = att.quat_multiply(q, att.quat_conjugate(q))
    np.testing.assert_allclose(ident, np.tile([1.0, 0, 0, 0], (50, 1)), atol=1e-14)


def test_dcm_to_quat_roundtrip_including_near_pi(rng):
    q = random_quats(rng, 300)
    # rotations by ~pi about each axis stress the branch choice of Shepperd's method
    near_pi = att.quat_from_axis_angle(np.eye(3), np.full(3, np.pi - 1e-9))
    q = np.vstack([q, near_pi, att.quat_from_axis_angle(np.eye(3), np.full(3, np.pi))])
    R = to_scipy(q).as_matrix()
    q_back = att.dcm_to_quat(R)
    assert np.all(q_back[:, 0] >= 0.0)
    sign = np.sign(np.sum(q_back * q, axis=1))
    np.testing.assert_allclose(q_back, q * sign[:, None], atol=1e-12)
    # single matrix in, single quaternion out
    assert att.dcm_to_quat(R[0]).shape == (4,)


def test_axis_angle_matches_scipy_rotvec(rng):
    axis = rng.normal(size=(50, 3))
    angle = rng.uniform(-np.pi, np.pi, size=50)
    unit = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    expected = Rotation.from_rotvec(unit * angle[:, None]).as_matrix()
    np.testing.assert_allclose(att.quat_to_dcm(att.quat_from_axis_angle(axis, angle)), expected, atol=1e-14)


def test_error_angle_sign_invariant_and_matches_scipy(rng):
    q1 = random_quats(rng, 100)
    q2 = random_quats(rng, 100)
    expected = (to_scipy(q1).inv() * to_scipy(q2)).magnitude()
    np.testing.assert_allclose(att.attitude_error_angle(q1, q2), expected, atol=1e-12)
    np.testing.assert_allclose(att.attitude_error_angle(q1, -q2), expected, atol=1e-12)
    tiny = att.quat_from_axis_angle([0.0, 0.0, 1.0], 1e-10)
    assert att.attitude_error_angle([1.0, 0, 0, 0], tiny) == pytest.approx(1e-10, rel=1e-6)


def test_kinematics_matrix_identities(rng):
    # the paper uses A^T A = I_3 and A A^T = P(x) on S^3
    for q in random_quats(rng, 20):
        A = att.kinematics_matrix(q)
        np.testing.assert_allclose(A.T @ A, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(A @ A.T, np.eye(4) - np.outer(q, q), atol=1e-14)


def test_quat_derivative_matches_rotation_derivative(rng):
    # qdot = 0.5 q (x) [0, w] for body rates: compare against a finite difference of scipy's
    # R(t+h) = R(t) exp(w^x h)
    q = random_quats(rng, 20)
    w = rng.normal(size=(20, 3))
    h = 1e-6
    r_plus = to_scipy(q) * Rotation.from_rotvec(w * h)
    r_minus = to_scipy(q) * Rotation.from_rotvec(-w * h)
    q_plus = from_scipy(r_plus)
    q_minus = from_scipy(r_minus)
    q_plus *= np.sign(np.sum(q_plus * q, axis=1))[:, None]
    q_minus *= np.sign(np.sum(q_minus * q, axis=1))[:, None]
    fd = (q_plus - q_minus) / (2 * h)
    np.testing.assert_allclose(att.quat_derivative(q, w), fd, atol=1e-8)
    np.testing.assert_allclose(att.quat_derivative(q, w), np.einsum("nij,nj->ni", att.kinematics_matrix(q), w) / 2, atol=1e-15)


def test_numba_kernels_match(rng):
    for q, p, w, u4, b in zip(random_quats(rng, 10), random_quats(rng, 10), rng.normal(size=(10, 3)), rng.normal(size=(10, 4)), rng.normal(size=(10, 3))):
        np.testing.assert_allclose(att.quat_multiply_nb(p, q), att.quat_multiply(p, q), atol=1e-15)
        np.testing.assert_allclose(att.quat_derivative_nb(q, w), att.quat_derivative(q, w), atol=1e-15)
        np.testing.assert_allclose(att.quat_to_dcm_nb(q), att.quat_to_dcm(q), atol=1e-15)
        np.testing.assert_allclose(att.quaternion_rate_command_nb(q, u4), att.quaternion_rate_command(q, u4), atol=1e-14)
        np.testing.assert_allclose(att.pointing_rate_command_nb(q, b, w), att.pointing_rate_command(q, b, w), atol=1e-14)


def test_bad_shapes_are_rejected():
    with pytest.raises(ValueError, match="last dimension 4"):
        att.quat_to_dcm([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="zero"):
        att.quat_normalize([0.0, 0.0, 0.0, 0.0])


# --- closed loop: integrate the attitude, watch x follow xdot = P(x) u -------------------------------

def _u_field(x: np.ndarray, x_d: np.ndarray, a: np.ndarray) -> np.ndarray:
    """A smooth nonlinear input field (not tangent, so the projection P(x) matters)."""
    return x_d - 0.7 * np.dot(x, a) * a + 0.3 * x


def _sphere_flow(x_d, a):
    def f(_t, x):
        u = _u_field(x, x_d, a)
        return u - x * np.dot(x, u)

    return f


def test_pointing_map_integrated_on_so3():
    b_B = np.array([0.0, 0.6, 0.8])
    q0 = att.quat_from_axis_angle([1.0, 2.0, -0.5], 2.1)
    x_d = np.array([0.0, 0.0, 1.0])
    a = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)

    def attitude_rhs(_t, q):
        q = q / np.linalg.norm(q)
        y = att.quat_rotate(q, b_B)
        omega = att.pointing_rate_command(q, b_B, _u_field(y, x_d, a))
        return att.quat_derivative(q, omega)

    t_eval = np.linspace(0.0, 6.0, 31)
    sol_q = solve_ivp(attitude_rhs, (0, 6), q0, t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")
    y0 = to_scipy(q0).apply(b_B)
    sol_x = solve_ivp(_sphere_flow(x_d, a), (0, 6), y0, t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")
    q_traj = sol_q.y.T / np.linalg.norm(sol_q.y.T, axis=1, keepdims=True)
    y_traj = to_scipy(q_traj).apply(b_B)  # boresight from the attitude, via scipy
    np.testing.assert_allclose(y_traj, sol_x.y.T, atol=1e-8)
    assert np.linalg.norm(y_traj[-1] - y_traj[0]) > 0.5  # it actually moved


def test_pointing_map_with_rotation_matrix_kinematics():
    # Independent of the quaternion code path: integrate Rdot = R omega^x directly.
    b_B = np.array([1.0, 0.0, 0.0])
    R0 = Rotation.from_rotvec([0.3, -1.2, 0.7]).as_matrix()
    x_d = np.array([0.0, 1.0, 0.0])
    a = np.array([0.0, 0.0, 1.0])

    def rhs(_t, r):
        R = r.reshape(3, 3)
        u = _u_field(R @ b_B, x_d, a)
        q = att.dcm_to_quat(R)
        w = att.pointing_rate_command(q, b_B, u)
        return (R @ att.skew(w)).ravel()

    t_eval = np.linspace(0, 4, 21)
    sol_R = solve_ivp(rhs, (0, 4), R0.ravel(), t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")
    sol_x = solve_ivp(_sphere_flow(x_d, a), (0, 4), R0 @ b_B, t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")
    y = np.einsum("nij,j->ni", sol_R.y.T.reshape(-1, 3, 3), b_B)
    np.testing.assert_allclose(y, sol_x.y.T, atol=1e-8)


def test_quaternion_map_integrated_on_so3():
    # Integrate the rotation matrix with the body rate omega = 2 A(q)^T u(q), then read q back via scipy:
    # it must match xdot = P(x) u(x) on S^3 (up to the quaternion sign).
    q0 = att.quat_normalize(np.array([0.2, -0.7, 0.4, 0.5]))
    x_d = np.array([1.0, 0.0, 0.0, 0.0])
    a = np.array([0.0, 0.5, 0.5, np.sqrt(0.5)])

    def u4(x):
        return x_d - 0.7 * np.dot(x, a) * a + 0.3 * x

    # u4 is not sign-symmetric (u4(-q) != -u4(q)), so propagate q alongside R to keep the branch that
    # defines omega; R itself is integrated independently and read back through scipy.
    def rhs(_t, s):
        R = s[:9].reshape(3, 3)
        q = s[9:] / np.linalg.norm(s[9:])
        w = att.quaternion_rate_command(q, u4(q))
        return np.concatenate(((R @ att.skew(w)).ravel(), att.quat_derivative(q, w)))

    t_eval = np.linspace(0, 5, 26)
    R0 = att.quat_to_dcm(q0)
    sol = solve_ivp(rhs, (0, 5), np.concatenate((R0.ravel(), q0)), t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")
    sol_x = solve_ivp(lambda t, x: u4(x) - x * np.dot(x, u4(x)), (0, 5), q0, t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")
    R_traj = sol.y[:9].T.reshape(-1, 3, 3)
    q_from_R = from_scipy(Rotation.from_matrix(R_traj))
    x = sol_x.y.T
    q_from_R *= np.sign(np.sum(q_from_R * x, axis=1))[:, None]
    np.testing.assert_allclose(q_from_R, x, atol=1e-8)
    np.testing.assert_allclose(sol.y[9:].T, x, atol=1e-8)
    assert att.attitude_error_angle(x[0], x[-1]) > 0.5
