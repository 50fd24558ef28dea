"""Two-body Keplerian orbit of the spacecraft about the Earth, position in N (GCRS), km.

Enough for what the attitude simulation needs from the orbit: the Earth direction from the spacecraft
and the Moon's parallax (up to ~1 deg in LEO). No perturbations (J2 would move the node ~1 deg/day).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from hil_sim.world.params import OrbitParams


def perifocal_to_N(params: OrbitParams) -> np.ndarray:
    """Rotation matrix R_NP (columns: perigee direction, semi-latus direction, orbit normal in N)."""
    O, i, w = (math.radians(params.raan_deg), math.radians(params.inclination_deg),
               math.radians(params.arg_perigee_deg))
    cO, sO, ci, si, cw, sw = math.cos(O), math.sin(O), math.cos(i), math.sin(i), math.cos(w), math.sin(w)
    return np.array([
        [cO * cw - sO * sw * ci, -cO * sw - sO * cw * ci, sO * si],
        [sO * cw + cO * sw * ci, -sO * sw + cO * cw * ci, -cO * si],
        [sw * si, cw * si, ci],
    ])


def orbit_elements_array(params: OrbitParams) -> np.ndarray:
    """Packed float64[14] for the numba kernel: a, e, n, M0, R_NP (9), mu."""
    a = params.semi_major_axis_km
    n = math.sqrt(params.mu_km3_s2 / a**3)
    out = np.empty(14)
    out[0] = a
    out[1] = params.eccentricity
    out[2] = n
    out[3] = math.radians(params.mean_anomaly_deg)
    out[4:13] = perifocal_to_N(params).reshape(-1)
    out[13] = params.mu_km3_s2
    return out


@njit(cache=True, error_model="numpy")
def orbit_position_N_km(elements, t_s, out):
    """Position at t (s since epoch) into out[0:3] for one packed element set (see orbit_elements_array)."""
    orbit_position_row_N_km(elements.reshape(1, elements.shape[0]), 0, t_s, out)


@njit(cache=True, error_model="numpy", inline="always")
def _eccentric_anomaly(ORB, m, t_s):
    """Run m's eccentric anomaly at t: Kepler's equation by Newton to 1e-14 rad (skipped for a circular
    orbit, where E = M)."""
    e = ORB[m, 1]
    M = ORB[m, 3] + ORB[m, 2] * t_s
    M -= 2.0 * math.pi * math.floor(M / (2.0 * math.pi))
    E = M if e < 0.8 else math.pi
    for _ in range(30 if e > 0.0 else 0):
        f = E - e * math.sin(E) - M
        dE = f / (1.0 - e * math.cos(E))
        E -= dE
        if abs(dE) < 1e-14:
            break
    return E


@njit(cache=True, error_model="numpy", inline="always")
def orbit_velocity_row_N_km_s(ORB, m, t_s):
    """Velocity (vx, vy, vz) of run m (row m of the packed elements ORB) at t, km/s (a tuple: no allocation
    at every integration stage)."""
    a = ORB[m, 0]
    e = ORB[m, 1]
    E = _eccentric_anomaly(ORB, m, t_s)
    E_dot = ORB[m, 2] / (1.0 - e * math.cos(E))
    xp = -a * math.sin(E) * E_dot
    yp = a * math.sqrt(1.0 - e * e) * math.cos(E) * E_dot
    return (ORB[m, 4] * xp + ORB[m, 5] * yp, ORB[m, 7] * xp + ORB[m, 8] * yp, ORB[m, 10] * xp + ORB[m, 11] * yp)


@njit(cache=True, error_model="numpy", inline="always")
def orbit_position_row_N_km(ORB, m, t_s, out):
    """Position of run m (row m of the packed elements ORB) at t into out[0:3]; Kepler's equation by Newton
    to 1e-14 rad (skipped for a circular orbit, where E = M)."""
    a = ORB[m, 0]
    e = ORB[m, 1]
    E = _eccentric_anomaly(ORB, m, t_s)
    xp = a * (math.cos(E) - e)
    yp = a * math.sqrt(1.0 - e * e) * math.sin(E)
    for j in range(3):
        out[j] = ORB[m, 4 + 3 * j] * xp + ORB[m, 4 + 3 * j + 1] * yp


class KeplerOrbit:
    """Convenience wrapper: ``position_N_km(t)`` and ``velocity_N_km_s(t)`` (numerical derivative-free)."""

    def __init__(self, params: OrbitParams) -> None:
        self.params = params
        self.elements = orbit_elements_array(params)

    @property
    def period_s(self) -> float:
        return 2.0 * math.pi / self.elements[2]

    def position_N_km(self, t_s: np.ndarray | float) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        flat = t.reshape(-1)
        out = np.empty((flat.size, 3))
        for k in range(flat.size):
            orbit_position_N_km(self.elements, flat[k], out[k])
        return out.reshape(t.shape + (3,))

    def velocity_N_km_s(self, t_s: float) -> np.ndarray:
        """Analytic two-body velocity at t."""
        return np.array(orbit_velocity_row_N_km_s(self.elements.reshape(1, -1), 0, float(t_s)))
