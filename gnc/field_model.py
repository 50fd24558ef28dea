"""The Earth's magnetic field as the flight software models it onboard: IGRF's main field to degree N from the
Gauss coefficients at the epoch (degree 1: the centred dipole), synthesised by the kernel the simulator's truth
uses (`gnc._geomagnetic_nb`), in the Earth-fixed frame turned by the Earth rotation angle about the inertial
z axis (`gnc.earth`, UT1 taken as UTC; precession, nutation and polar motion neglected as in the truth).

The flight software compares the magnetometer's field with it (`fsw.coarse_attitude`). The degree matters:
IGRF-14's dipole is up to 35 deg off the full field's direction in low orbit (docs/environment.md), so an
onboard dipole under a truth of degree 13 is a few degrees' measurement at best; the same degree as the truth
leaves the magnetometer's noise and the spacecraft's own field.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from gnc._geomagnetic_nb import field_E
from gnc.earth import earth_rotation_angle_rad

IGRF_MAX_DEGREE = 13  # IGRF-14's main field


def degree_of(pairs: int) -> int:
    """The degree N of an expansion of ``pairs`` (g, h) pairs (N (N + 3) / 2), ValueError if none fits."""
    for n in range(1, IGRF_MAX_DEGREE + 1):
        if n * (n + 3) // 2 == pairs:
            return n
    raise ValueError(f"{pairs} (g, h) pairs are no expansion of degree 1 to {IGRF_MAX_DEGREE} (N (N + 3) / 2)")


def unnormalised_rows(gauss_T: Sequence[Sequence[float]]) -> np.ndarray:
    """The (C_nm, S_nm) rows `gnc._geomagnetic_nb.field_E` reads, from Schmidt semi-normalised pairs in the
    order n = 1..N, m = 0..n: times sqrt(2 (n - m)! / (n + m)!) for m > 0 (the Schmidt functions are that
    multiple of the unnormalised ones, neither with the Condon-Shortley phase)."""
    degree = degree_of(len(gauss_T))
    out = np.empty(2 * len(gauss_T))
    k = 0
    for n in range(1, degree + 1):
        for m in range(n + 1):
            s = 1.0 if m == 0 else math.sqrt(2.0 * math.factorial(n - m) / math.factorial(n + m))
            out[2 * k], out[2 * k + 1] = s * gauss_T[k][0], s * gauss_T[k][1]
            k += 1
    return out


class FieldModel:
    """IGRF to the degree of ``gauss_T`` ((g, h) pairs [T], n = 1..N, m = 0..n); `field_N` evaluates it."""

    def __init__(self, gauss_T: Sequence[Sequence[float]]) -> None:
        self.degree = degree_of(len(gauss_T))
        self._rows = np.ascontiguousarray(unnormalised_rows(gauss_T)[:, None])

    def field_N(self, r_N_km: np.ndarray, jd_utc: float) -> np.ndarray:
        """The field [T] in N at the position ``r_N_km`` [km] and the UTC Julian date ``jd_utc``."""
        theta = earth_rotation_angle_rad(jd_utc)
        c, s = math.cos(theta), math.sin(theta)
        x, y, z = (float(v) for v in r_N_km)
        bx, by, bz = field_E(self._rows, 0, 0, self.degree, c * x + s * y, c * y - s * x, z)
        return np.array([c * bx - s * by, s * bx + c * by, bz])
