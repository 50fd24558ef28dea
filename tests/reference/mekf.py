"""The MEKF's covariance propagation written with numpy arrays, a test oracle: fsw.estimation propagates in
place with every product written out (`_propagate_in_place`), and must give these results to the last bit.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fsw.estimation import _rotvec_quat
from gnc.attitude import quat_multiply_nb


@njit(cache=True)
def _skew(v):
    S = np.zeros((3, 3))
    S[0, 1] = -v[2]
    S[0, 2] = v[1]
    S[1, 0] = v[2]
    S[1, 2] = -v[0]
    S[2, 0] = -v[1]
    S[2, 1] = v[0]
    return S


@njit(cache=True)
def mekf_propagate(q, bias, P, omega_meas, dt, sig_v, sig_u):
    """Propagate attitude, bias and covariance over ``dt`` [s] with the gyro sample (held constant)."""
    w = omega_meas - bias
    qn = quat_multiply_nb(q, _rotvec_quat(w * dt))
    qn /= math.sqrt(qn[0] ** 2 + qn[1] ** 2 + qn[2] ** 2 + qn[3] ** 2)
    # Discrete transition of the error state (first order in dt for the attitude block):
    # Phi = [[I - [w x] dt, -dt I], [0, I]]; Pn = Phi P Phi^T + Q written out on that structure (the
    # general 6x6 products went through BLAS: ~3 us a sample, ten samples a cycle).
    A = np.eye(3) - _skew(w) * dt
    # Phi P: rows 0..2 = A P[0:3] - dt P[3:6]; rows 3..5 = P[3:6]
    PP = np.empty((6, 6))
    for i in range(3):
        for j in range(6):
            PP[i, j] = A[i, 0] * P[0, j] + A[i, 1] * P[1, j] + A[i, 2] * P[2, j] - dt * P[3 + i, j]
            PP[3 + i, j] = P[3 + i, j]
    # (Phi P) Phi^T: columns 0..2 = (Phi P)[:, 0:3] A^T - dt (Phi P)[:, 3:6]; columns 3..5 unchanged
    Pn = np.empty((6, 6))
    for i in range(6):
        for j in range(3):
            Pn[i, j] = PP[i, 0] * A[j, 0] + PP[i, 1] * A[j, 1] + PP[i, 2] * A[j, 2] - dt * PP[i, 3 + j]
            Pn[i, 3 + j] = PP[i, 3 + j]
    qa = sig_v * sig_v * dt + sig_u * sig_u * dt ** 3 / 3.0
    qc = -sig_u * sig_u * dt * dt / 2.0
    qb = sig_u * sig_u * dt
    for i in range(3):
        Pn[i, i] += qa
        Pn[i, 3 + i] += qc
        Pn[3 + i, i] += qc
        Pn[3 + i, 3 + i] += qb
    for i in range(6):
        for j in range(i + 1, 6):
            Pn[i, j] = Pn[j, i] = 0.5 * (Pn[i, j] + Pn[j, i])
    return qn, Pn
