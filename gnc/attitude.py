"""Attitude kinematics: scalar-first Hamilton quaternions and the maps from the paper's u to omega.

Conventions (checked against ``scipy.spatial.transform.Rotation`` in the tests; scipy is scalar-LAST):

* A quaternion is ``q = [eta, q1, q2, q3]`` (scalar first), Hamilton product, unit norm.
* ``q_NB`` rotates body vectors into the inertial frame N: ``v_N = q_NB (x) [0, v_B] (x) q_NB^*``,
  equivalently ``v_N = R_NB v_B`` with ``R_NB = quat_to_dcm(q_NB)``.
* ``omega_BN_B`` is the angular velocity of B relative to N, in B components [rad/s].
* Kinematics (the paper's eq. quaternion_kinematics): ``qdot = 0.5 A(q) omega`` with
  ``A(q) = [-qv^T; eta I + qv^x]``, i.e. ``qdot = 0.5 q (x) [0, omega]``.

The two maps from the paper's control input ``u`` to a body-rate command:

* pointing (S^2): boresight ``b_B`` fixed in the body, ``y_N = R_NB b_B``. With
  ``omega = b^x R^T u`` the boresight obeys ``ydot = P(y) u`` (paper's Section on reduced attitude,
  written here for y = R b instead of the paper's x = R^T e3).
* quaternion (S^3): ``omega = 2 A(q)^T u`` gives ``qdot = P(q) u`` since ``A^T A = I_3`` and
  ``A A^T = P(q)`` on S^3.

Every public function accepts a single quaternion/vector or a stack with leading batch dimensions
(``(..., 4)``, ``(..., 3)``) and broadcasts. Scalar numba kernels (suffix ``_nb``) are provided for
hot loops (the flight GNC cycle, the truth dynamics step) where numpy's per-call overhead dominates.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "quat_multiply",
    "quat_conjugate",
    "quat_normalize",
    "quat_to_dcm",
    "dcm_to_quat",
    "quat_from_axis_angle",
    "quat_rotate",
    "kinematics_matrix",
    "quat_derivative",
    "pointing_rate_command",
    "quaternion_rate_command",
    "attitude_error_angle",
    "skew",
    "quat_multiply_nb",
    "quat_derivative_nb",
    "quat_to_dcm_nb",
    "quaternion_rate_command_nb",
    "pointing_rate_command_nb",
]


def _as_quat(q: np.ndarray, name: str = "q") -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"{name} must have last dimension 4 (scalar-first [eta, q1, q2, q3]); got shape {q.shape}")
    return q


def _as_vec3(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name} must have last dimension 3; got shape {v.shape}")
    return v


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix v^x with ``v^x w = v x w``; v of shape (..., 3) -> (..., 3, 3)."""
    v = _as_vec3(v, "v")
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p (x) q (scalar first). ``q_AC = quat_multiply(q_AB, q_BC)``."""
    p = _as_quat(p, "p")
    q = _as_quat(q, "q")
    p0, p1, p2, p3 = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        (
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ),
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate [eta, -qv]; for a unit quaternion the inverse rotation (q_BN from q_NB)."""
    q = _as_quat(q)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Scale to unit norm. Raises on a zero quaternion (no attitude can be recovered from it)."""
    q = _as_quat(q)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm == 0.0) or not np.all(np.isfinite(norm)):
        raise ValueError("cannot normalize a zero or non-finite quaternion")
    return q / norm


def quat_to_dcm(q_NB: np.ndarray) -> np.ndarray:
    """Rotation matrix R_NB (v_N = R_NB v_B) of a unit quaternion q_NB; shape (..., 3, 3)."""
    q = _as_quat(q_NB, "q_NB")
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[..., 0, 1] = 2.0 * (x * y - w * z)
    R[..., 0, 2] = 2.0 * (x * z + w * y)
    R[..., 1, 0] = 2.0 * (x * y + w * z)
    R[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[..., 1, 2] = 2.0 * (y * z - w * x)
    R[..., 2, 0] = 2.0 * (x * z - w * y)
    R[..., 2, 1] = 2.0 * (y * z + w * x)
    R[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


def dcm_to_quat(R_NB: np.ndarray) -> np.ndarray:
    """Unit quaternion q_NB (eta >= 0) of a rotation matrix R_NB, by Shepperd's method.

    Shepperd picks the largest of the four squared components to divide by, so the result stays
    accurate for every rotation (no division by a small eta near 180 deg).
    """
    R = np.asarray(R_NB, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R_NB must have shape (..., 3, 3); got {R.shape}")
    batch = R.shape[:-2]
    Rf = R.reshape(-1, 3, 3)
    tr = Rf[:, 0, 0] + Rf[:, 1, 1] + Rf[:, 2, 2]
    # 4*[eta^2, q1^2, q2^2, q3^2] candidates
    cand = np.stack((1.0 + tr, 1.0 + 2.0 * Rf[:, 0, 0] - tr, 1.0 + 2.0 * Rf[:, 1, 1] - tr, 1.0 + 2.0 * Rf[:, 2, 2] - tr), axis=-1)
    k = np.argmax(cand, axis=-1)
    s = 2.0 * np.sqrt(np.maximum(cand[np.arange(len(k)), k], 0.0))  # = 4*|component k|
    q = np.empty((len(k), 4))
    d21 = Rf[:, 2, 1] - Rf[:, 1, 2]
    d02 = Rf[:, 0, 2] - Rf[:, 2, 0]
    d10 = Rf[:, 1, 0] - Rf[:, 0, 1]
    s01 = Rf[:, 0, 1] + Rf[:, 1, 0]
    s02 = Rf[:, 0, 2] + Rf[:, 2, 0]
    s12 = Rf[:, 1, 2] + Rf[:, 2, 1]
    rows = (
        np.stack((s / 4.0, d21 / s, d02 / s, d10 / s), axis=-1),
        np.stack((d21 / s, s / 4.0, s01 / s, s02 / s), axis=-1),
        np.stack((d02 / s, s01 / s, s / 4.0, s12 / s), axis=-1),
        np.stack((d10 / s, s02 / s, s12 / s, s / 4.0), axis=-1),
    )
    for idx in range(4):
        mask = k == idx
        q[mask] = rows[idx][mask]
    q *= np.where(q[:, :1] < 0.0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q.reshape(batch + (4,))


def quat_from_axis_angle(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Quaternion of a right-handed rotation by ``angle`` [rad] about the unit ``axis`` (normalized here)."""
    axis = _as_vec3(axis, "axis")
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(n == 0.0):
        raise ValueError("rotation axis must be non-zero")
    half = 0.5 * np.asarray(angle, dtype=float)[..., None]
    return np.concatenate((np.cos(half), np.sin(half) * axis / n), axis=-1)


def quat_rotate(q_NB: np.ndarray, v_B: np.ndarray) -> np.ndarray:
    """v_N = R_NB v_B, without forming the matrix: v + 2 eta (qv x v) + 2 qv x (qv x v)."""
    q = _as_quat(q_NB, "q_NB")
    v = _as_vec3(v_B, "v_B")
    eta = q[..., :1]
    qv = q[..., 1:]
    t = 2.0 * np.cross(qv, v)
    return v + eta * t + np.cross(qv, t)


def kinematics_matrix(q: np.ndarray) -> np.ndarray:
    """A(q) = [-qv^T; eta I + qv^x], shape (..., 4, 3), so that qdot = 0.5 A(q) omega_BN_B."""
    q = _as_quat(q)
    eta = q[..., 0]
    qv = q[..., 1:]
    A = np.empty(q.shape[:-1] + (4, 3))
    A[..., 0, :] = -qv
    A[..., 1:, :] = eta[..., None, None] * np.eye(3) + skew(qv)
    return A


def quat_derivative(q_NB: np.ndarray, omega_BN_B: np.ndarray) -> np.ndarray:
    """qdot = 0.5 A(q) omega = 0.5 q (x) [0, omega]  [1/s], omega in rad/s."""
    q = _as_quat(q_NB, "q_NB")
    w = _as_vec3(omega_BN_B, "omega_BN_B")
    eta = q[..., :1]
    qv = q[..., 1:]
    return 0.5 * np.concatenate((-np.sum(qv * w, axis=-1, keepdims=True), eta * w + np.cross(qv, w)), axis=-1)


def pointing_rate_command(q_NB: np.ndarray, b_B: np.ndarray, u_N: np.ndarray) -> np.ndarray:
    """omega_BN_B = b^x R_NB^T u_N [rad/s]: makes the boresight y_N = R_NB b_B obey ydot = P(y) u.

    b_B must be a unit vector (the boresight); u_N is the law's output in N.
    """
    q = _as_quat(q_NB, "q_NB")
    b = _as_vec3(b_B, "b_B")
    u = _as_vec3(u_N, "u_N")
    u_B = quat_rotate(quat_conjugate(q), u)
    return np.cross(b, u_B)


def quaternion_rate_command(q_NB: np.ndarray, u: np.ndarray) -> np.ndarray:
    """omega_BN_B = 2 A(q)^T u [rad/s]: makes the quaternion obey qdot = P(q) u on S^3."""
    q = _as_quat(q_NB, "q_NB")
    u = _as_quat(u, "u")
    eta = q[..., :1]
    qv = q[..., 1:]
    u0 = u[..., :1]
    uv = u[..., 1:]
    # A^T u = -qv u0 + (eta I + qv^x)^T uv = -u0 qv + eta uv - qv x uv
    return 2.0 * (-u0 * qv + eta * uv - np.cross(qv, uv))


def attitude_error_angle(q1: np.ndarray, q2: np.ndarray) -> np.ndarray | float:
    """Rotation angle [rad, in [0, pi]] between two attitudes; invariant to the sign of either quaternion.

    Uses atan2 of the vector and scalar parts of q1^* (x) q2, accurate for tiny and near-pi angles
    (unlike 2 acos|q1.q2|, which loses half the digits near zero).
    """
    dq = quat_multiply(quat_conjugate(q1), q2)
    ang = 2.0 * np.arctan2(np.linalg.norm(dq[..., 1:], axis=-1), np.abs(dq[..., 0]))
    return float(ang) if np.ndim(ang) == 0 else ang


# ---------------------------------------------------------------------------------------------
# Scalar numba kernels for hot loops (same conventions; inputs are contiguous float64 arrays).
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def quat_multiply_nb(p, q):
    out = np.empty(4)
    out[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3]
    out[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2]
    out[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1]
    out[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0]
    return out


@njit(cache=True)
def quat_derivative_nb(q, w):
    out = np.empty(4)
    out[0] = -0.5 * (q[1] * w[0] + q[2] * w[1] + q[3] * w[2])
    out[1] = 0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1])
    out[2] = 0.5 * (q[0] * w[1] + q[3] * w[0] - q[1] * w[2])
    out[3] = 0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0])
    return out


@njit(cache=True)
def quat_to_dcm_nb(q):
    w, x, y, z = q[0], q[1], q[2], q[3]
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[0, 1] = 2.0 * (x * y - w * z)
    R[0, 2] = 2.0 * (x * z + w * y)
    R[1, 0] = 2.0 * (x * y + w * z)
    R[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[1, 2] = 2.0 * (y * z - w * x)
    R[2, 0] = 2.0 * (x * z - w * y)
    R[2, 1] = 2.0 * (y * z + w * x)
    R[2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


@njit(cache=True)
def quaternion_rate_command_nb(q, u):
    out = np.empty(3)
    # 2 (-u0 qv + eta uv - qv x uv)
    out[0] = 2.0 * (-u[0] * q[1] + q[0] * u[1] - (q[2] * u[3] - q[3] * u[2]))
    out[1] = 2.0 * (-u[0] * q[2] + q[0] * u[2] - (q[3] * u[1] - q[1] * u[3]))
    out[2] = 2.0 * (-u[0] * q[3] + q[0] * u[3] - (q[1] * u[2] - q[2] * u[1]))
    return out


@njit(cache=True)
def pointing_rate_command_nb(q, b, u):
    R = quat_to_dcm_nb(q)
    uB0 = R[0, 0] * u[0] + R[1, 0] * u[1] + R[2, 0] * u[2]
    uB1 = R[0, 1] * u[0] + R[1, 1] * u[1] + R[2, 1] * u[2]
    uB2 = R[0, 2] * u[0] + R[1, 2] * u[1] + R[2, 2] * u[2]
    out = np.empty(3)
    out[0] = b[1] * uB2 - b[2] * uB1
    out[1] = b[2] * uB0 - b[0] * uB2
    out[2] = b[0] * uB1 - b[1] * uB0
    return out
