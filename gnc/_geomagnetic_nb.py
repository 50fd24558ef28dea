"""The spherical-harmonic synthesis of the Earth's main field (IGRF to degree N) at one Earth-fixed position:
the truth's kernels call it at every integration stage (`hil_sim.world.environment`), the flight software's
field model once a cycle (`gnc.field_model`), so both evaluate one formula.

The field is B = -grad V, V = a sum_n sum_m (C_nm V_nm + S_nm W_nm) with the solid harmonics
V_nm + i W_nm = (a / r)^(n+1) P_nm(cos theta) exp(i m phi) (P_nm unnormalised, without the Condon-Shortley
phase) built by Cunningham's recursions in Cartesian coordinates, and the gradient of each term from
V_(n+1), W_(n+1) (Montenbruck & Gill, Satellite Orbits, 3.2.4-3.2.5, eqs. 3.29-3.33, with GM / R^2 -> 1 and R
-> a, the potential a sum ... of the magnetic field instead of GM / R sum ... of gravity). Cartesian all
through: no colatitude, no division by sin(theta), so the poles need no special case, unlike the
(r, theta, phi) form ppigrf evaluates. (C_nm, S_nm) are IGRF's Schmidt semi-normalised (g, h) times
sqrt(2 (n - m)! / (n + m)!) for m > 0 (`gnc.field_model.unnormalised_rows`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

IGRF_REFERENCE_RADIUS_KM = 6371.2  # IGRF's (and WMM's) reference radius a


@njit(cache=True, error_model="numpy")
def _solid_harmonics(x, y, z, top):
    """(V, W), each (top + 1, top + 1): V[n, m], W[n, m] for 0 <= m <= n <= top at (x, y, z) [km]."""
    a = IGRF_REFERENCE_RADIUS_KM
    r2 = x * x + y * y + z * z
    rho = a * a / r2
    x0, y0, z0 = a * x / r2, a * y / r2, a * z / r2
    VW = np.empty((2, top + 1, top + 1))  # only 0 <= m <= n is written, and read
    V, W = VW[0], VW[1]
    V[0, 0] = a / math.sqrt(r2)
    W[0, 0] = 0.0
    for m in range(top + 1):
        if m > 0:  # the diagonal from the one before
            V[m, m] = (2 * m - 1) * (x0 * V[m - 1, m - 1] - y0 * W[m - 1, m - 1])
            W[m, m] = (2 * m - 1) * (x0 * W[m - 1, m - 1] + y0 * V[m - 1, m - 1])
        if m + 1 <= top:
            V[m + 1, m] = (2 * m + 1) * z0 * V[m, m]
            W[m + 1, m] = (2 * m + 1) * z0 * W[m, m]
        for n in range(m + 2, top + 1):
            f1 = (2 * n - 1) * z0 / (n - m)
            f2 = (n + m - 1) * rho / (n - m)
            V[n, m] = f1 * V[n - 1, m] - f2 * V[n - 2, m]
            W[n, m] = f1 * W[n - 1, m] - f2 * W[n - 2, m]
    return V, W


@njit(cache=True, error_model="numpy")
def field_E(B, m, first, degree, x, y, z):
    """The main field (bx, by, bz) in the Earth-fixed frame at (x, y, z) [km, from the Earth's centre], in the
    coefficients' unit: degree ``degree``, (C_nm, S_nm) of run m in rows first, first + 1, ... of B, pairs in
    the order n = 1..degree, m = 0..n."""
    V, W = _solid_harmonics(x, y, z, degree + 1)
    gx = gy = gz = 0.0
    k = first
    for n in range(1, degree + 1):
        for j in range(n + 1):
            C, S = B[k, m], B[k + 1, m]
            k += 2
            if j == 0:
                gx -= C * V[n + 1, 1]
                gy -= C * W[n + 1, 1]
            else:
                f = (n - j + 2) * (n - j + 1)
                gx += 0.5 * ((-C * V[n + 1, j + 1] - S * W[n + 1, j + 1]) + f * (C * V[n + 1, j - 1] + S * W[n + 1, j - 1]))
                gy += 0.5 * ((-C * W[n + 1, j + 1] + S * V[n + 1, j + 1]) + f * (-C * W[n + 1, j - 1] + S * V[n + 1, j - 1]))
            gz += (n - j + 1) * (-C * V[n + 1, j] - S * W[n + 1, j])
    return -gx, -gy, -gz  # B = -grad V
