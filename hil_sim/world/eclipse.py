"""Eclipses: how much of the Sun's disc the spacecraft sees past the Earth (a conical shadow: umbra,
penumbra and, in principle, the annular case), from the truth ephemeris.

The Sun and the Earth are discs of apparent radii a = asin(R_sun / |s|) and b = asin(R_earth / |r|) seen
from the spacecraft (s: Sun from the spacecraft, r: spacecraft from the Earth's centre), c the angle
between their centres. The sunlit fraction is 1 when c >= a + b, 0 when the Earth's disc covers the Sun's
(c <= b - a), 1 - b^2/a^2 when the Sun's covers the Earth's (c <= a - b), and otherwise 1 - A / (pi a^2)
with A the area of the discs' overlap (the lens of two circles, in the small-angle plane). This is the
conical model of Montenbruck and Gill, Satellite Orbits (2000), section 3.4.2, as Basilisk's eclipse module
computes it too (`tests/hil_sim/test_eclipse.py` compares the two on a Basilisk 2.12.1 reference).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gnc.ephemeris import AU_KM, EARTH_RADIUS_KM

SUN_RADIUS_KM = 695_700.0  # IAU 2015 nominal solar radius


def sunlit_fraction(r_sc_N_km: np.ndarray, r_sun_N_km: np.ndarray, earth_radius_km: float = EARTH_RADIUS_KM,
                    sun_radius_km: float = SUN_RADIUS_KM) -> np.ndarray:
    """Fraction of the Sun's disc visible from the spacecraft, 0 (umbra) .. 1 (full Sun): (n,) for
    geocentric positions (n, 3) [km] of the spacecraft and of the Sun (or (3,) each, a scalar array)."""
    r, sun = np.broadcast_arrays(np.asarray(r_sc_N_km, dtype=float), np.asarray(r_sun_N_km, dtype=float))
    rows_r, rows_s = np.ascontiguousarray(r.reshape(-1, 3)), np.ascontiguousarray(sun.reshape(-1, 3))
    out = np.empty(rows_r.shape[0])
    _sunlit_rows(rows_r, rows_s, float(earth_radius_km), float(sun_radius_km), out)
    return out.reshape(r.shape[:-1])


@njit(cache=True, error_model="numpy")
def _sunlit_rows(r, sun, earth_radius_km, sun_radius_km, out):
    for k in range(r.shape[0]):
        out[k] = sunlit_fraction_at(r[k, 0], r[k, 1], r[k, 2], sun[k, 0] - r[k, 0], sun[k, 1] - r[k, 1],
                                    sun[k, 2] - r[k, 2], earth_radius_km, sun_radius_km)


@njit(cache=True, error_model="numpy", inline="always")
def sunlit_fraction_at(rx, ry, rz, sx, sy, sz, earth_radius_km, sun_radius_km):
    """The sunlit fraction for one geometry: r the spacecraft from the Earth's centre, s the Sun from the
    spacecraft [km]. The kernel the truth models call at every integration stage (solar radiation pressure)."""
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


def eclipse_spans(t_s: np.ndarray, r_sc_N_km: np.ndarray, sun_N: np.ndarray) -> list[tuple[float, float, float]]:
    """Each stretch of a recorded run in the Earth's shadow: (start [s], end [s], least sunlit fraction).

    From what a run records (spacecraft position, unit Sun direction): the Sun is placed 1 AU along that
    direction, which moves the shadow's edge by far less than a recording interval. A run without an
    orbit (positions at the Earth's centre) has no eclipses."""
    t = np.asarray(t_s, dtype=float)
    r = np.asarray(r_sc_N_km, dtype=float)
    if len(t) == 0 or r.ndim != 2 or float(np.min(np.linalg.norm(r, axis=1))) <= EARTH_RADIUS_KM:
        return []
    lit = sunlit_fraction(r, r + AU_KM * np.asarray(sun_N, dtype=float))
    shaded = np.concatenate([[False], lit < 1.0, [False]])
    starts = np.flatnonzero(~shaded[:-1] & shaded[1:])
    ends = np.flatnonzero(shaded[:-1] & ~shaded[1:]) - 1
    return [(float(t[a]), float(t[b]), float(np.min(lit[a:b + 1]))) for a, b in zip(starts, ends)]
