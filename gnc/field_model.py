"""The onboard model of the Earth's magnetic field: IGRF's centred dipole (Gauss coefficients g10, g11, h11),
turned with the Earth by its rotation angle about the inertial z axis (`gnc.earth`, UT1 taken as UTC).

    B(r) = (a / |r|)^3 (3 (m . r_hat) r_hat - m),  m = (g11, h11, g10) [T] Earth-fixed,  a = 6371.2 km

The flight software compares the magnetometer's field with it (`fsw.coarse_attitude`): a direction known to
a few degrees where the truth is the full field (IGRF to degree 13 differs from its dipole by up to ~15 deg
in direction in low orbit) and to the magnetometer's noise where the truth is this same dipole.
"""
from __future__ import annotations

import math

import numpy as np

from gnc.earth import earth_rotation_angle_rad

IGRF_REFERENCE_RADIUS_KM = 6371.2


def dipole_field_N(r_N_km: np.ndarray, dipole_T: np.ndarray, jd_utc: float) -> np.ndarray:
    """The dipole's field [T] in N at the position ``r_N_km`` [km] and the UTC Julian date ``jd_utc``;
    ``dipole_T``: (g10, g11, h11) [T]."""
    g10, g11, h11 = (float(v) for v in dipole_T)
    theta = earth_rotation_angle_rad(jd_utc)
    c, s = math.cos(theta), math.sin(theta)
    to_earth = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    r = np.asarray(r_N_km, dtype=float)
    rn = float(np.linalg.norm(r))
    u = to_earth @ (r / rn)
    m = np.array([g11, h11, g10])
    b_earth = (IGRF_REFERENCE_RADIUS_KM / rn) ** 3 * (3.0 * float(m @ u) * u - m)
    return to_earth.T @ b_earth
