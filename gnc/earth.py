"""The rotating Earth for pointing at it: Earth rotation, WGS-84 geodetic positions in the inertial frame,
the direction from the spacecraft to a ground target, nadir, and a target's elevation.

Frames: N is GCRS / J2000 mean equator and equinox (as `gnc.ephemeris`; the ~20 mas frame bias is
ignored); E is the Earth-fixed ITRS (WGS-84 realised on it; polar motion, < 0.5 arcsec, is ignored).

Time: ``jd_utc`` is a Julian date on the UTC scale. UT1 is taken equal to UTC (|UT1 - UTC| < 0.9 s by
the IERS's own rule, at most 0.42 km at the equator) and TT = UTC + 69.184 s (`gnc.ephemeris`' leap
seconds).

Models (IERS Conventions 2010, ch. 5, the CIO-based transformation r_N = Q(X, Y) R3(-ERA) r_E):
- Earth rotation angle ERA (IAU 2000, eq. 5.15):
  ERA = 2 pi (0.7790572732640 + 1.00273781191135448 (JD_UT1 - 2451545.0)).
- CIP coordinates X, Y: the IAU 2006/2000A polynomial parts (Table 5.2a/b, ``tab5.2a.txt``) and the
  two largest nutation terms: the 18.6-year one of the Moon's node (-6.844 arcsec sin Omega in X, +9.205
  arcsec cos Omega in Y) and the half-year one (-0.524, +0.573 arcsec); the terms left out add up to
  less than 0.3 arcsec over 2026-2036 (checked against ERFA's xy06). The CIO locator s (< 0.1 arcsec
  until 2050) is ignored.
Stated accuracy (tests/gnc/test_earth.py, against astropy's ITRS -> GCRS with UT1 = UTC, 2026-2036): an
Earth-fixed point's inertial position within 0.03 km (1 arcsec at the Earth's radius); from low orbit
the direction to a ground target within 0.005 deg.
"""
from __future__ import annotations

import math

import numpy as np

from gnc.ephemeris import JD_J2000, TAI_MINUS_UTC_S, TT_MINUS_TAI_S

WGS84_A_KM = 6378.137  # equatorial radius
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared
_ARCSEC = math.pi / (180.0 * 3600.0)
_TT_MINUS_UTC_DAYS = (TAI_MINUS_UTC_S + TT_MINUS_TAI_S) / 86400.0


def earth_rotation_angle_rad(jd_utc: float) -> float:
    """Earth rotation angle [rad] in [0, 2 pi) (IAU 2000; UT1 = UTC). The fraction of the day is split off
    first, so a Julian date near 2.46e6 keeps its ~10 us resolution."""
    d = jd_utc - JD_J2000
    frac = math.fmod(d, 1.0)
    turns = frac + 0.7790572732640 + 0.00273781191135448 * d
    return 2.0 * math.pi * (turns % 1.0)


def cip_xy_rad(jd_utc: float) -> tuple[float, float]:
    """CIP coordinates X, Y [rad] in GCRS (IAU 2006/2000A polynomials, the 18.6-year and half-year nutation
    terms)."""
    t = (jd_utc + _TT_MINUS_UTC_DAYS - JD_J2000) / 36525.0
    # mean longitude of the Moon's ascending node (IERS 2010 eq. 5.43)
    # fundamental arguments (IERS 2010 eq. 5.43): the Moon's node, and 2(F - D + Omega) of the half-year term
    omega = math.radians((450160.398036 - 6962890.5431 * t) / 3600.0)
    semi = 2.0 * omega + math.radians(((335779.526232 - 1072260.70369) + (1739527262.8478 - 1602961601.2090) * t) / 1800.0)
    x = (-0.016617 + t * (2004.191898 + t * (-0.4297829 + t * (-0.19861834)))
         - 6.844318 * math.sin(omega) - 0.523908 * math.sin(semi))
    y = (-0.006951 + t * (-0.025896 + t * (-22.4072747 + t * 0.00190059))
         + 9.205236 * math.cos(omega) + 0.573033 * math.cos(semi))
    return x * _ARCSEC, y * _ARCSEC


def earth_fixed_to_inertial(jd_utc: float) -> np.ndarray:
    """Rotation matrix C_NE (3x3): r_N = C_NE @ r_E at ``jd_utc``."""
    x, y = cip_xy_rad(jd_utc)
    a = 0.5 + 0.125 * (x * x + y * y)  # 1 / (1 + Z) to second order
    q = np.array([[1.0 - a * x * x, -a * x * y, x],
                  [-a * x * y, 1.0 - a * y * y, y],
                  [-x, -y, 1.0 - a * (x * x + y * y)]])
    era = earth_rotation_angle_rad(jd_utc)
    c, s = math.cos(era), math.sin(era)
    r3 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # R3(-ERA)
    return q @ r3


def geodetic_to_earth_fixed_km(latitude_deg: float, longitude_deg: float, altitude_m: float = 0.0) -> np.ndarray:
    """Earth-fixed position [km] of a WGS-84 geodetic latitude, longitude (east positive) [deg] and
    height above the ellipsoid [m]."""
    lat, lon = math.radians(latitude_deg), math.radians(longitude_deg)
    h = altitude_m / 1000.0
    sl, cl = math.sin(lat), math.cos(lat)
    n = WGS84_A_KM / math.sqrt(1.0 - WGS84_E2 * sl * sl)  # prime-vertical radius of curvature
    return np.array([(n + h) * cl * math.cos(lon), (n + h) * cl * math.sin(lon), (n * (1.0 - WGS84_E2) + h) * sl])


def geodetic_up_earth_fixed(latitude_deg: float, longitude_deg: float) -> np.ndarray:
    """Unit normal to the WGS-84 ellipsoid (local vertical, up) at a geodetic latitude, longitude [deg]."""
    lat, lon = math.radians(latitude_deg), math.radians(longitude_deg)
    return np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])


def geodetic_to_inertial_km(latitude_deg: float, longitude_deg: float, altitude_m: float, jd_utc: float) -> np.ndarray:
    """Inertial (N) position [km] of a WGS-84 geodetic point at ``jd_utc``."""
    return earth_fixed_to_inertial(jd_utc) @ geodetic_to_earth_fixed_km(latitude_deg, longitude_deg, altitude_m)


def direction_to_point_N(r_sc_N_km: np.ndarray, r_point_N_km: np.ndarray) -> np.ndarray:
    """Unit vector in N from the spacecraft at ``r_sc_N_km`` to a point at ``r_point_N_km`` (both [km])."""
    d = np.asarray(r_point_N_km, dtype=float) - np.asarray(r_sc_N_km, dtype=float)
    n = math.sqrt(float(d @ d))
    if not n > 0.0:
        raise ValueError("the spacecraft is at the target point: no direction")
    return d / n


def nadir_N(r_sc_N_km: np.ndarray) -> np.ndarray:
    """Geocentric nadir: unit vector in N from the spacecraft to the Earth's centre (the geodetic nadir
    differs from it by at most 0.19 deg, at mid latitudes)."""
    r = np.asarray(r_sc_N_km, dtype=float)
    n = math.sqrt(float(r @ r))
    if not n > 0.0:
        raise ValueError("the spacecraft position is zero: no nadir")
    return -r / n


def elevation_deg(latitude_deg: float, longitude_deg: float, altitude_m: float, r_sc_E_km: np.ndarray) -> float:
    """Elevation [deg] of the spacecraft at Earth-fixed ``r_sc_E_km`` above a ground target's local
    horizon (the plane normal to the ellipsoid's vertical there): below 0, the target cannot see it."""
    up = geodetic_up_earth_fixed(latitude_deg, longitude_deg)
    d = np.asarray(r_sc_E_km, dtype=float) - geodetic_to_earth_fixed_km(latitude_deg, longitude_deg, altitude_m)
    vertical = float(d @ up)
    horizontal = d - vertical * up
    return math.degrees(math.atan2(vertical, math.sqrt(float(horizontal @ horizontal))))
