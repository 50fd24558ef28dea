"""Compiled backend of `gnc.eclipse`: the sunlit fraction of the Sun's disc for one geometry (the truth's
environment kernels inline it at every integration stage) and for rows of geometries."""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
def sunlit_rows_nb(r, sun, earth_radius_km, sun_radius_km, out):
    """`sunlit_fraction_at` for each row: ``r`` (n, 3) the spacecraft and ``sun`` (n, 3) the Sun, both from
    the Earth's centre [km]; into ``out`` (n,)."""
    for k in range(r.shape[0]):
        out[k] = sunlit_fraction_at(r[k, 0], r[k, 1], r[k, 2], sun[k, 0] - r[k, 0], sun[k, 1] - r[k, 1],
                                    sun[k, 2] - r[k, 2], earth_radius_km, sun_radius_km)


@njit(cache=True, error_model="numpy", inline="always")
def sunlit_fraction_at(rx, ry, rz, sx, sy, sz, earth_radius_km, sun_radius_km):
    """The sunlit fraction for one geometry: r the spacecraft from the Earth's centre, s the Sun from the
    spacecraft [km]."""
    rn = math.sqrt(rx * rx + ry * ry + rz * rz)
    sn = math.sqrt(sx * sx + sy * sy + sz * sz)
    a = math.asin(min(sun_radius_km / sn, 1.0))
    b = math.asin(min(earth_radius_km / rn, 1.0))
    c = math.acos(min(max(-(rx * sx + ry * sy + rz * sz) / (rn * sn), -1.0), 1.0))
    if c >= a + b:
        return 1.0
    if c <= b - a:
        return 0.0
    if c <= a - b:
        return 1.0 - (b * b) / (a * a)
    x = (c * c + a * a - b * b) / (2.0 * c)
    y = math.sqrt(max(a * a - x * x, 0.0))
    overlap = (a * a * math.acos(min(max(x / a, -1.0), 1.0)) + b * b * math.acos(min(max((c - x) / b, -1.0), 1.0))
               - c * y)
    return 1.0 - overlap / (math.pi * a * a)
