"""Low-precision analytic Sun and Moon, the kind flight software carries.

Frame N: GCRS / J2000 mean equator and equinox (the ~20 mas frame bias between them is ignored).
Time: ``t`` is a Julian date in TDB (TT is the same to 2 ms, far below these models' accuracy).

Models
- Sun: Meeus, *Astronomical Algorithms* (2nd ed.) ch. 25 low-accuracy theory (mean longitude, equation of
  the centre to 3M), minus the annual aberration (20.5"), which is what a geocentric observer (GCRS) sees.
- Moon: the truncated lunar theory of Montenbruck & Gill, *Satellite Orbits* (2000) sec. 3.3.2
  (14 longitude, 8 latitude, 9 distance terms of the Brown/ELP series).
Both are evaluated in the mean ecliptic and equinox of date, rotated to the mean equator of date by the
IAU 1980 mean obliquity, then precessed back to J2000 by the IAU 1976 precession matrix (Lieske 1977;
Meeus eq. 21.3), because over 2026-2036 precession alone is 0.36-0.5 deg.

Stated accuracy (tests/gnc/test_ephemeris.py, against astropy's built-in ephemeris, 4000 epochs 2026-2036):
Sun direction max 0.0096 deg (rms 0.0038 deg; requirement < 0.01 deg), Moon geocentric direction max 0.079 deg
(rms 0.021 deg; requirement < 0.3 deg), Moon distance within 0.14 %. Onboard code should inflate keep-out
cones by at least these errors.
"""
from __future__ import annotations

import math
from datetime import datetime, timezone

import numpy as np

AU_KM = 149_597_870.7
EARTH_RADIUS_KM = 6378.137
JD_J2000 = 2451545.0
_ARCSEC = math.pi / (180.0 * 3600.0)
_DEG = math.pi / 180.0

TAI_MINUS_UTC_S = 37.0
"""Leap seconds as of 2017-01-01; no leap second has been announced since. A future one shifts the Moon by
~0.5 arcsec per second of error, irrelevant at this model's accuracy."""
TT_MINUS_TAI_S = 32.184


def parse_utc(text: str, name: str = "epoch") -> datetime:
    """ISO-8601 UTC string (``Z`` or ``+00:00`` or naive) -> aware datetime; clear error otherwise."""
    if isinstance(text, datetime):
        return text if text.tzinfo else text.replace(tzinfo=timezone.utc)
    try:
        value = datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    except ValueError as exc:
        raise ValueError(f"{name}: {text!r} is not an ISO-8601 UTC time like 2030-03-20T12:00:00Z") from exc
    if value.tzinfo is None:
        value = value.replace(tzinfo=timezone.utc)
    if value.utcoffset() != timezone.utc.utcoffset(None):
        raise ValueError(f"{name}: {text!r} must be UTC (suffix Z or +00:00)")
    return value


def julian_date(datetime_utc: datetime) -> float:
    """Julian date (UTC scale) of an aware or naive-UTC datetime."""
    dt = parse_utc(datetime_utc) if not isinstance(datetime_utc, datetime) else datetime_utc
    if dt.tzinfo is not None:
        dt = dt.astimezone(timezone.utc).replace(tzinfo=None)
    j2000 = datetime(2000, 1, 1, 12, 0, 0)
    delta = dt - j2000
    return JD_J2000 + delta.days + (delta.seconds + delta.microseconds * 1e-6) / 86400.0


def julian_date_tdb(datetime_utc: datetime | str) -> float:
    """Julian date in TDB (= TT to 2 ms) of a UTC instant, with TT - UTC = 32.184 s + 37 leap seconds."""
    dt = parse_utc(datetime_utc) if isinstance(datetime_utc, str) else datetime_utc
    return julian_date(dt) + (TAI_MINUS_UTC_S + TT_MINUS_TAI_S) / 86400.0


def _centuries(t_tdb_jd: np.ndarray | float) -> np.ndarray:
    return (np.asarray(t_tdb_jd, dtype=float) - JD_J2000) / 36525.0


def mean_obliquity_rad(t_tdb_jd: np.ndarray | float) -> np.ndarray:
    """IAU 1980 mean obliquity of the ecliptic of date (Meeus eq. 22.2), radians."""
    T = _centuries(t_tdb_jd)
    return (84381.448 - 46.8150 * T - 0.00059 * T**2 + 0.001813 * T**3) * _ARCSEC


def precession_matrix_j2000_to_date(t_tdb_jd: np.ndarray | float) -> np.ndarray:
    """IAU 1976 precession P with v_date = P v_J2000 (mean equator/equinox), shape (..., 3, 3)."""
    T = _centuries(t_tdb_jd)
    zeta = (2306.2181 * T + 0.30188 * T**2 + 0.017998 * T**3) * _ARCSEC
    z = (2306.2181 * T + 1.09468 * T**2 + 0.018203 * T**3) * _ARCSEC
    theta = (2004.3109 * T - 0.42665 * T**2 - 0.041833 * T**3) * _ARCSEC
    cz, sz = np.cos(zeta), np.sin(zeta)
    cZ, sZ = np.cos(z), np.sin(z)
    ct, st = np.cos(theta), np.sin(theta)
    # P = R3(-z) R2(theta) R3(-zeta) (coordinate rotations), written out (Lieske 1977).
    P = np.empty(np.shape(T) + (3, 3))
    P[..., 0, 0] = cZ * ct * cz - sZ * sz
    P[..., 0, 1] = -cZ * ct * sz - sZ * cz
    P[..., 0, 2] = -cZ * st
    P[..., 1, 0] = sZ * ct * cz + cZ * sz
    P[..., 1, 1] = -sZ * ct * sz + cZ * cz
    P[..., 1, 2] = -sZ * st
    P[..., 2, 0] = st * cz
    P[..., 2, 1] = -st * sz
    P[..., 2, 2] = ct
    return P


def _ecliptic_of_date_to_N(lon: np.ndarray, lat: np.ndarray, dist: np.ndarray, t_tdb_jd) -> np.ndarray:
    """Spherical mean-ecliptic-of-date coordinates -> Cartesian N (J2000 equatorial), same unit as dist."""
    cl, sl, cb, sb = np.cos(lon), np.sin(lon), np.cos(lat), np.sin(lat)
    x_ecl = np.stack([cb * cl, cb * sl, sb], axis=-1) * np.asarray(dist)[..., None]
    eps = mean_obliquity_rad(t_tdb_jd)
    ce, se = np.cos(eps), np.sin(eps)
    x_date = np.stack([x_ecl[..., 0],
                       ce * x_ecl[..., 1] - se * x_ecl[..., 2],
                       se * x_ecl[..., 1] + ce * x_ecl[..., 2]], axis=-1)
    P = precession_matrix_j2000_to_date(t_tdb_jd)
    return np.einsum("...ji,...j->...i", P, x_date)  # P^T x_date


def sun_position_N_km(t_tdb_jd: np.ndarray | float) -> np.ndarray:
    """Geocentric apparent (aberrated) Sun position in N, km, shape (..., 3)."""
    T = _centuries(t_tdb_jd)
    L0 = 280.46646 + 36000.76983 * T + 0.0003032 * T**2
    M = (357.52911 + 35999.05029 * T - 0.0001537 * T**2) * _DEG
    e = 0.016708634 - 0.000042037 * T - 0.0000001267 * T**2
    C = ((1.914602 - 0.004817 * T - 0.000014 * T**2) * np.sin(M)
         + (0.019993 - 0.000101 * T) * np.sin(2 * M) + 0.000289 * np.sin(3 * M))
    true_lon = (L0 + C) * _DEG
    nu = M + C * _DEG
    R_au = 1.000001018 * (1 - e**2) / (1 + e * np.cos(nu))
    lon = true_lon - 20.4898 * _ARCSEC / R_au  # annual aberration
    return _ecliptic_of_date_to_N(lon, np.zeros_like(lon), R_au * AU_KM, t_tdb_jd)


def sun_direction_N(t_tdb_jd: np.ndarray | float) -> np.ndarray:
    """Unit vector from the Earth's centre to the Sun in N, shape (..., 3). Within 0.01 deg, 2026-2036."""
    r = sun_position_N_km(t_tdb_jd)
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def moon_position_N_km(t_tdb_jd: np.ndarray | float) -> np.ndarray:
    """Geocentric Moon position in N, km, shape (..., 3) (Montenbruck & Gill truncated series)."""
    T = _centuries(t_tdb_jd)
    L0 = (218.31617 + 481267.88088 * T) * _DEG  # mean longitude, equinox of date
    l = (134.96292 + 477198.86753 * T) * _DEG  # Moon mean anomaly
    lp = (357.52543 + 35999.04944 * T) * _DEG  # Sun mean anomaly
    F = (93.27283 + 483202.01873 * T) * _DEG  # argument of latitude
    D = (297.85027 + 445267.11135 * T) * _DEG  # mean elongation
    s = np.sin
    dlon = (22640 * s(l) + 769 * s(2 * l) - 4586 * s(l - 2 * D) + 2370 * s(2 * D) - 668 * s(lp)
            - 412 * s(2 * F) - 212 * s(2 * l - 2 * D) - 206 * s(l + lp - 2 * D) + 192 * s(l + 2 * D)
            - 165 * s(lp - 2 * D) + 148 * s(l - lp) - 125 * s(D) - 110 * s(l + lp) - 55 * s(2 * F - 2 * D))
    lon = L0 + dlon * _ARCSEC
    lat = (18520 * s(F + lon - L0 + (412 * s(2 * F) + 541 * s(lp)) * _ARCSEC) - 526 * s(F - 2 * D)
           + 44 * s(l + F - 2 * D) - 31 * s(-l + F - 2 * D) - 25 * s(-2 * l + F) - 23 * s(lp + F - 2 * D)
           + 21 * s(-l + F) + 11 * s(-lp + F - 2 * D)) * _ARCSEC
    c = np.cos
    dist = (385000.0 - 20905 * c(l) - 3699 * c(2 * D - l) - 2956 * c(2 * D) - 570 * c(2 * l)
            + 246 * c(2 * l - 2 * D) - 205 * c(lp - 2 * D) - 171 * c(l + 2 * D) - 152 * c(l + lp - 2 * D))
    return _ecliptic_of_date_to_N(lon, lat, dist, t_tdb_jd)


def moon_direction_N(t_tdb_jd: np.ndarray | float, r_sc_N_km: np.ndarray | None = None) -> np.ndarray:
    """Unit vector to the Moon in N, shape (..., 3): from the Earth's centre, or, when the spacecraft position
    ``r_sc_N_km`` (..., 3) is given, from the spacecraft (parallax up to ~1 deg in LEO)."""
    r = moon_position_N_km(t_tdb_jd)
    if r_sc_N_km is not None:
        r = r - np.asarray(r_sc_N_km, dtype=float)
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def sun_direction_from_spacecraft_N(t_tdb_jd: np.ndarray | float, r_sc_N_km: np.ndarray) -> np.ndarray:
    """Unit vector from the spacecraft to the Sun in N (parallax < 0.003 deg even at GEO)."""
    r = sun_position_N_km(t_tdb_jd) - np.asarray(r_sc_N_km, dtype=float)
    return r / np.linalg.norm(r, axis=-1, keepdims=True)
