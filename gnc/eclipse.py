"""Eclipses: how much of the Sun's disc the spacecraft sees past the Earth (a conical shadow: umbra,
penumbra and, in principle, the annular case). One geometry for both ends: the truth evaluates it on its
ephemeris and orbit (`hil_sim.world.eclipse`, solar radiation pressure, the sun sensors), the flight
software on its own (`gnc.sky_ephemeris.SkyEphemeris.sunlit_fraction`).

The Sun and the Earth are discs of apparent radii a = asin(R_sun / |s|) and b = asin(R_earth / |r|) seen
from the spacecraft (s: Sun from the spacecraft, r: spacecraft from the Earth's centre), c the angle
between their centres. The sunlit fraction is 1 when c >= a + b, 0 when the Earth's disc covers the Sun's
(c <= b - a), 1 - b^2/a^2 when the Sun's covers the Earth's (c <= a - b), and otherwise 1 - A / (pi a^2)
with A the area of the discs' overlap (the lens of two circles, in the small-angle plane). This is the
conical model of Montenbruck and Gill, Satellite Orbits (2000), section 3.4.2, as Basilisk's eclipse module
computes it too (`tests/hil_sim/test_eclipse.py` compares the two on a Basilisk 2.12.1 reference).
"""
from __future__ import annotations

import numpy as np

from gnc._eclipse_nb import sunlit_fraction_at, sunlit_rows_nb
from gnc.ephemeris import EARTH_RADIUS_KM

SUN_RADIUS_KM = 695_700.0  # IAU 2015 nominal solar radius

__all__ = ["SUN_RADIUS_KM", "sunlit_fraction", "sunlit_fraction_at"]


def sunlit_fraction(r_sc_N_km: np.ndarray, r_sun_N_km: np.ndarray, earth_radius_km: float = EARTH_RADIUS_KM,
                    sun_radius_km: float = SUN_RADIUS_KM) -> np.ndarray:
    """Fraction of the Sun's disc visible from the spacecraft, 0 (umbra) .. 1 (full Sun): (n,) for
    geocentric positions (n, 3) [km] of the spacecraft and of the Sun (or (3,) each, a scalar array)."""
    r, sun = np.broadcast_arrays(np.asarray(r_sc_N_km, dtype=float), np.asarray(r_sun_N_km, dtype=float))
    rows_r, rows_s = np.ascontiguousarray(r.reshape(-1, 3)), np.ascontiguousarray(sun.reshape(-1, 3))
    out = np.empty(rows_r.shape[0])
    sunlit_rows_nb(rows_r, rows_s, float(earth_radius_km), float(sun_radius_km), out)
    return out.reshape(r.shape[:-1])
