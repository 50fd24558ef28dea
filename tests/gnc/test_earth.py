"""gnc.earth (Earth rotation, WGS-84 geodetic points in N, direction to a ground target, nadir, elevation)
against astropy: `EarthLocation` for WGS-84 and its ITRS -> GCRS transformation (full IAU 2006/2000A
precession-nutation, with UT1 = UTC as gnc.earth assumes), 2026-2036.

Bounds (gnc.earth's stated accuracy): an Earth-fixed point's inertial position within 0.03 km; from a
low orbit (radius 7000 km) the direction to a ground target within 0.005 deg."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gnc import earth
from gnc.ephemeris import JD_J2000

astropy = pytest.importorskip("astropy")


@pytest.fixture(scope="module")
def astropy_points():
    """(jd_utc, lat, lon, alt, GCRS position [km]) for 60 epochs x random points, by astropy."""
    import astropy.units as u
    from astropy.coordinates import GCRS, EarthLocation
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    rng = np.random.default_rng(7)
    n = 60
    jd = 2461041.5 + rng.uniform(0.0, 3650.0, n)  # 2026-01-01 .. 2036
    lat = np.degrees(np.arcsin(rng.uniform(-1.0, 1.0, n)))
    lon = rng.uniform(-180.0, 180.0, n)
    alt = rng.uniform(-100.0, 5000.0, n)
    loc = EarthLocation.from_geodetic(lon * u.deg, lat * u.deg, alt * u.m, ellipsoid="WGS84")
    t = Time(jd, format="jd", scale="utc")
    t.delta_ut1_utc = np.zeros(n)
    itrs = loc.get_itrs(obstime=t)
    gcrs = itrs.transform_to(GCRS(obstime=t))
    pos = np.asarray(gcrs.cartesian.xyz.to_value(u.km)).T
    ecef = np.asarray(itrs.cartesian.xyz.to_value(u.km)).T
    return jd, lat, lon, alt, pos, ecef


def test_geodetic_earth_fixed_matches_astropy_wgs84(astropy_points):
    jd, lat, lon, alt, _, ecef = astropy_points
    mine = np.array([earth.geodetic_to_earth_fixed_km(a, b, c) for a, b, c in zip(lat, lon, alt)])
    assert np.max(np.linalg.norm(mine - ecef, axis=1)) < 1e-6  # 1 mm: the same closed form


def test_inertial_position_within_0p03_km(astropy_points):
    jd, lat, lon, alt, pos, _ = astropy_points
    mine = np.array([earth.geodetic_to_inertial_km(a, b, c, d) for a, b, c, d in zip(lat, lon, alt, jd)])
    err = np.linalg.norm(mine - pos, axis=1)
    assert np.max(err) < 0.03, f"max {np.max(err):.4f} km"


def test_direction_from_low_orbit_within_0p005_deg(astropy_points):
    """The target seen from a spacecraft 700 km above it, 30 deg off its vertical (a slant range of ~1000 km)."""
    jd, lat, lon, alt, pos, _ = astropy_points
    worst = 0.0
    for a, b, c, d, truth in zip(lat, lon, alt, jd, pos):
        p = earth.geodetic_to_inertial_km(a, b, c, d)
        up = p / np.linalg.norm(p)
        side = np.cross(up, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        r_sc = p + 700.0 * up + 400.0 * side
        got = earth.direction_to_point_N(r_sc, p)
        want = (truth - r_sc) / np.linalg.norm(truth - r_sc)
        worst = max(worst, math.degrees(math.acos(min(1.0, float(got @ want)))))
    assert worst < 0.005, f"max {worst:.5f} deg"


def test_earth_rotation_rate_is_sidereal():
    """ERA makes one turn per stellar day, 86164.0989 s of UT1 (IERS Conventions 2010, sec. 1.2)."""
    a = earth.earth_rotation_angle_rad(JD_J2000 + 9000.0)
    b = earth.earth_rotation_angle_rad(JD_J2000 + 9000.0 + 86164.0989 / 86400.0)
    assert abs(((b - a + math.pi) % (2 * math.pi)) - math.pi) < 1e-8  # 0.0001 s of rotation


def test_nadir_and_elevation():
    r = np.array([0.0, 7000.0, 0.0])
    assert np.allclose(earth.nadir_N(r), [0.0, -1.0, 0.0])
    # a spacecraft straight above the target is at 90 deg elevation; one on the far side is below the horizon
    up_E = earth.geodetic_to_earth_fixed_km(45.0, 10.0, 0.0)
    above = earth.geodetic_to_earth_fixed_km(45.0, 10.0, 700e3)
    assert earth.elevation_deg(45.0, 10.0, 0.0, above) == pytest.approx(90.0, abs=1e-9)
    assert earth.elevation_deg(45.0, 10.0, 0.0, -up_E * 1.1) < -80.0
    with pytest.raises(ValueError):
        earth.direction_to_point_N(up_E, up_E)
