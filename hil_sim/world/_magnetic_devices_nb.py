"""Compiled backend of `hil_sim.world.magnetic_devices` and `hil_sim.world.sun_sensors`: the rods' clipping,
the magnetometer's reading and the coarse sun sensors' cells, sampled once per GNC tick. On 3-vectors numpy's
per-call overhead (nan_to_num, clip, cross, small products) cost more than the arithmetic; these kernels do
the same sums on scalars, in the order the numpy expressions they replace write them
(tests/hil_sim/test_magnetic_kernels.py holds them equal). ``to_body_nb`` turns an inertial vector (the
field, the Sun) into body axes."""
from __future__ import annotations

import numpy as np
from numba import njit

from gnc.attitude import quat_to_dcm_nb


@njit(cache=True)
def to_body_nb(q_NB, x, y, z):
    """``R_NB^T v`` for v = (x, y, z) in N and the unit quaternion ``q_NB``: v in body axes (a new array),
    as ``quat_to_dcm(q_NB).T @ v``."""
    R = quat_to_dcm_nb(q_NB)
    out = np.empty(3)
    for j in range(3):
        out[j] = R[0, j] * x + R[1, j] * y + R[2, j] * z
    return out


@njit(cache=True)
def clip_rods_nb(command, limit, out):
    """Each rod's dipole [A m^2] into ``out``: ``command`` clipped to +-``limit`` per rod, NaN as 0 (an
    infinite command saturates, as np.nan_to_num then np.clip give)."""
    for i in range(command.shape[0]):
        c = command[i]
        if c != c:
            c = 0.0
        lo = -limit[i]
        out[i] = min(max(c, lo), limit[i])
    return out


@njit(cache=True)
def held_rods_nb(live, command, limit, axes_T, held, body):
    """The rods' held dipoles into ``held`` (rod order) and their sum in body axes into ``body`` [A m^2]:
    clipped commands when ``live`` (a valid command within the timeout), zero otherwise. ``axes_T`` (3, n):
    the rod axes as columns."""
    if live:
        clip_rods_nb(command, limit, held)
    else:
        held[:] = 0.0
    for r in range(3):
        s = 0.0
        for i in range(held.shape[0]):
            s += axes_T[r, i] * held[i]
        body[r] = s


@njit(cache=True)
def magnetometer_nb(b_B, coupling, rods, R_BS, bias, noise, resolution, full_scale, out):
    """The magnetometer's reading [T] in sensor axes into ``out``: ``R_BS^T (b_B + coupling rods) + bias
    + noise``, quantised to ``resolution`` (0: not) and clipped at +-``full_scale``. ``rods`` and ``noise``
    of length 0: no rods' field, no noise (nothing added, as the numpy model skips the sum)."""
    b = np.empty(3)
    for r in range(3):
        b[r] = b_B[r]
    if rods.shape[0] > 0:
        for r in range(3):
            s = 0.0
            for i in range(rods.shape[0]):
                s += coupling[r, i] * rods[i]
            b[r] = b[r] + s
    for r in range(3):
        v = R_BS[0, r] * b[0] + R_BS[1, r] * b[1] + R_BS[2, r] * b[2] + bias[r]
        if noise.shape[0] > 0:
            v = v + noise[r]
        if resolution > 0.0:
            v = np.round(v / resolution) * resolution
        out[r] = min(max(v, -full_scale), full_scale)
    return out


@njit(cache=True)
def sun_cells_nb(normals, sun_B, cos_fov, full_scale_fraction, noise, out):
    """Every coarse sun sensor cell's output into ``out``: ``full_scale f cos(theta)`` where the Sun is in
    the cell's field of view (``cos(theta) >= cos_fov``), else 0, plus ``noise`` (length 0: none), clipped
    at 0. ``full_scale_fraction``: full scale times the sunlit fraction."""
    for i in range(normals.shape[0]):
        c = normals[i, 0] * sun_B[0] + normals[i, 1] * sun_B[1] + normals[i, 2] * sun_B[2]
        v = full_scale_fraction * (c if c >= cos_fov else 0.0)
        if noise.shape[0] > 0:
            v = v + noise[i]
        out[i] = max(v, 0.0)
    return out
