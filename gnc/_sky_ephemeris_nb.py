"""Compiled backend of `gnc.sky_ephemeris`: the onboard Sun, Moon and Earth directions in one call (the
guidance's steady-state cycle, `fsw.guidance._kernels.pointing_step_nb`, calls it inside its own kernel)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def sky_directions_nb(t_s, u0, n_rad_s, radius_km, p_hat, q_hat, f, s0, s1, m0, m1):
    """Rows: unit vectors spacecraft -> Sun, -> Moon, -> Earth centre (N), with the geocentric Sun and Moon
    positions interpolated between two nodes (``f`` in [0, 1)) and the circular orbit's position at t."""
    u = u0 + n_rad_s * t_s
    cu, su = math.cos(u), math.sin(u)
    out = np.empty((3, 3))
    r = np.empty(3)
    for i in range(3):
        r[i] = radius_km * (cu * p_hat[i] + su * q_hat[i])
        out[0, i] = s0[i] + f * (s1[i] - s0[i]) - r[i]
        out[1, i] = m0[i] + f * (m1[i] - m0[i]) - r[i]
        out[2, i] = -r[i]
    for k in range(2):
        n = math.sqrt(_dot3(out[k], out[k]))
        for i in range(3):
            out[k, i] = out[k, i] / n
    n = math.sqrt(_dot3(r, r))
    for i in range(3):
        out[2, i] = out[2, i] / n
    return out
