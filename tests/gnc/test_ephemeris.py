"""Onboard low-precision Sun/Moon (gnc.ephemeris) against astropy's built-in ephemeris, 2026-2036.

Measured (this test's grid of 4000 epochs): Sun max ~0.0096 deg, Moon max ~0.08 deg (rms ~0.02 deg),
Moon distance within 0.15 %. Requirement: Sun < 0.01 deg, Moon < 0.3 deg.
"""
from __future__ import annotations

import warnings
from datetime import datetime, timezone

import numpy as np
import pytest

from gnc import ephemeris as eph


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


@pytest.fixture(scope="module")
def astropy_truth():
    from hil_sim.world.ephemeris import astropy_sun_moon_N_km

    start = eph.julian_date_tdb("2026-01-01T00:00:00Z")
    end = eph.julian_date_tdb("2036-12-31T00:00:00Z")
    # irregular spacing so the grid does not alias with the lunar month
    jd = np.sort(np.random.default_rng(0).uniform(start, end, 4000))
    sun, moon = astropy_sun_moon_N_km(jd)
    return jd, sun, moon


def test_sun_direction_within_0p01_deg(astropy_truth):
    jd, sun, _ = astropy_truth
    err = _angle_deg(eph.sun_direction_N(jd), sun)
    assert err.max() < 0.01, f"Sun direction error max {err.max():.5f} deg"


def test_moon_direction_within_0p3_deg(astropy_truth):
    jd, _, moon = astropy_truth
    err = _angle_deg(eph.moon_direction_N(jd), moon)
    assert err.max() < 0.3, f"Moon direction error max {err.max():.4f} deg"
    assert np.sqrt(np.mean(err**2)) < 0.05
    dist = np.linalg.norm(eph.moon_position_N_km(jd), axis=1) / np.linalg.norm(moon, axis=1)
    assert np.abs(dist - 1).max() < 0.005


def test_moon_parallax_from_spacecraft(astropy_truth):
    """From a spacecraft the Moon direction moves by up to asin(r_sc / r_moon) ~ 1 deg in LEO; the function
    must subtract positions (checked against astropy's Moon minus the same spacecraft position)."""
    jd, _, moon = astropy_truth
    jd, moon = jd[:200], moon[:200]
    rng = np.random.default_rng(1)
    r_sc = rng.normal(size=(200, 3))
    r_sc *= 6928.0 / np.linalg.norm(r_sc, axis=1, keepdims=True)
    err = _angle_deg(eph.moon_direction_N(jd, r_sc), moon - r_sc)
    shift = _angle_deg(moon - r_sc, moon)
    assert shift.max() > 0.5  # the parallax is real and large...
    assert err.max() < 0.3  # ...and modelled
    # Sun parallax is negligible but the function still subtracts the spacecraft position
    err_sun = _angle_deg(eph.sun_direction_from_spacecraft_N(jd, r_sc), eph.sun_position_N_km(jd) - r_sc)
    assert err_sun.max() < 1e-9


def test_precession_matrix_matches_erfa():
    import erfa

    for jd in (2461041.5, 2463000.25, 2465000.0):
        np.testing.assert_allclose(eph.precession_matrix_j2000_to_date(jd), erfa.pmat76(jd, 0.0), atol=1e-15)


def test_julian_date_against_astropy():
    from astropy.time import Time

    dt = datetime(2031, 7, 4, 17, 30, 12, 250000, tzinfo=timezone.utc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = Time(dt, scale="utc")
        assert eph.julian_date(dt) == pytest.approx(t.jd, abs=1e-9)
        # TDB: astropy uses its own leap-second table (may warn 'dubious year' past its last update)
        assert eph.julian_date_tdb(dt) == pytest.approx(t.tdb.jd, abs=3e-8)  # TDB - TT < 1.7 ms


def test_vectorised_and_scalar_calls_agree():
    jd = np.array([2461500.1, 2462500.7])
    np.testing.assert_allclose(eph.sun_direction_N(jd)[1], eph.sun_direction_N(jd[1]), atol=0)
    np.testing.assert_allclose(eph.moon_direction_N(jd)[0], eph.moon_direction_N(jd[0]), atol=0)
    assert eph.sun_direction_N(jd[0]).shape == (3,)


def test_parse_utc_rejects_bad_epochs():
    with pytest.raises(ValueError, match="ISO-8601"):
        eph.parse_utc("next tuesday", "epoch_utc")
    with pytest.raises(ValueError, match="UTC"):
        eph.parse_utc("2030-01-01T00:00:00+02:00", "epoch_utc")
