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

import numpy as np

from gnc.ephemeris import EARTH_RADIUS_KM

SUN_RADIUS_KM = 695_700.0  # IAU 2015 nominal solar radius


def sunlit_fraction(r_sc_N_km: np.ndarray, r_sun_N_km: np.ndarray, earth_radius_km: float = EARTH_RADIUS_KM,
                    sun_radius_km: float = SUN_RADIUS_KM) -> np.ndarray:
    """Fraction of the Sun's disc visible from the spacecraft, 0 (umbra) .. 1 (full Sun): (n,) for
    geocentric positions (n, 3) [km] of the spacecraft and of the Sun (or (3,) each, a scalar array)."""
    r = np.asarray(r_sc_N_km, dtype=float)
    s = np.asarray(r_sun_N_km, dtype=float) - r  # the Sun from the spacecraft
    rn = np.linalg.norm(r, axis=-1)
    sn = np.linalg.norm(s, axis=-1)
    a = np.arcsin(np.clip(sun_radius_km / sn, -1.0, 1.0))
    b = np.arcsin(np.clip(earth_radius_km / rn, -1.0, 1.0))
    c = np.arccos(np.clip(np.sum(-r * s, axis=-1) / (rn * sn), -1.0, 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (c * c + a * a - b * b) / (2.0 * c)
        y = np.sqrt(np.maximum(a * a - x * x, 0.0))
        overlap = (a * a * np.arccos(np.clip(x / a, -1.0, 1.0)) + b * b * np.arccos(np.clip((c - x) / b, -1.0, 1.0))
                   - c * y)
    partial = 1.0 - overlap / (np.pi * a * a)
    annular = 1.0 - (b * b) / (a * a)
    return np.where(c >= a + b, 1.0, np.where(c <= b - a, 0.0, np.where(c <= a - b, annular, partial)))
