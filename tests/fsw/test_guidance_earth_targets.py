"""POINTING targets on the rotating Earth (nadir, a ground point): the direction the guidance follows is
the one astropy gives for the same spacecraft position and ground point; the boresight follows it in a
kinematic closed loop; a fixed target commanded later ends the tracking; the zones keep it out as they
keep out a fixed target; the Earth zone reaches the top of the atmosphere when a mission asks for it."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig, GroundTargetConfig
from fsw.guidance import Guidance, SkyEphemeris
from gnc.ephemeris import EARTH_RADIUS_KM

EPOCH = "2026-11-29T10:00:00+00:00"
LEO = {"radius_km": 6978.0, "inclination_deg": 51.6, "raan_deg": 30.0, "arg_latitude_at_epoch_deg": 10.0}


def _cfg(pointing: dict, **extra) -> FswConfig:
    return FswConfig.model_validate({"epoch_utc": EPOCH, "initial_mode": "POINTING", "orbit": LEO,
                                     "law": {"k1": 0.2}, "spacecraft": {"max_rate_deg_s": 3.0},
                                     "pointing": {"roll_gain_1_s": 0.0, **pointing}, **extra})


def _q_with_boresight(y: np.ndarray) -> np.ndarray:
    """An attitude q_NB turning body +z (the default boresight) onto ``y``."""
    rot, _ = Rotation.align_vectors([y], [[0.0, 0.0, 1.0]])
    return np.roll(rot.as_quat(), 1)


def _step(q: np.ndarray, omega_B: np.ndarray, dt: float) -> np.ndarray:
    r = Rotation.from_quat(np.roll(q, -1)) * Rotation.from_rotvec(omega_B * dt)
    return np.roll(r.as_quat(), 1)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b) / float(np.linalg.norm(a) * np.linalg.norm(b))))))


def _unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v, dtype=float) / np.linalg.norm(v)


def _sub_satellite(eph: SkyEphemeris, t_s: float) -> dict:
    """The ground point (geocentric latitude, longitude; close enough) under the spacecraft at ``t_s``."""
    from gnc.earth import earth_fixed_to_inertial

    r_E = earth_fixed_to_inertial(eph.jd0_utc + t_s / 86400.0).T @ eph.position_N_km(t_s)
    return {"latitude_deg": math.degrees(math.asin(r_E[2] / np.linalg.norm(r_E))),
            "longitude_deg": math.degrees(math.atan2(r_E[1], r_E[0])), "altitude_m": 0.0}


def _fly(g: Guidance, q: np.ndarray, t0: float, seconds: float, dt: float = 0.1):
    errors, margins = [], []
    for k in range(int(round(seconds / dt))):
        out = g.step(t0 + k * dt, dt, q, np.zeros(3))
        errors.append(out.pointing_error_deg)
        margins.append(out.margin_min_deg)
        q = _step(q, out.omega_cmd_BN_B, dt)
    return q, out, np.array(errors), np.array(margins)


def test_ground_target_direction_matches_astropy() -> None:
    """The direction `SkyEphemeris` gives from its own orbit position to a ground point, against astropy's
    GCRS position of the same WGS-84 point (UT1 = UTC): within 0.01 deg over 10 minutes."""
    import astropy.units as u
    from astropy.coordinates import GCRS, EarthLocation
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    ground = GroundTargetConfig(latitude_deg=43.6, longitude_deg=1.44, altitude_m=150.0)
    eph = SkyEphemeris(_cfg({"target_kind": "ground", "target_ground": ground.model_dump()}))
    point = SkyEphemeris.ground_point_E_km(ground)
    loc = EarthLocation.from_geodetic(1.44 * u.deg, 43.6 * u.deg, 150.0 * u.m)
    worst = 0.0
    for t_s in np.linspace(0.0, 600.0, 7):
        t = Time(EPOCH[:19], format="isot", scale="utc") + t_s * u.s
        t.delta_ut1_utc = 0.0
        truth = np.asarray(loc.get_itrs(obstime=t).transform_to(GCRS(obstime=t)).cartesian.xyz.to_value(u.km))
        want = truth - eph.position_N_km(t_s)
        worst = max(worst, _angle_deg(eph.target_direction_N(t_s, point), want))
    assert worst < 0.01


def test_nadir_target_is_followed_every_cycle() -> None:
    """Nadir turns at the orbit rate (0.064 deg/s in a 600 km orbit): the boresight stays on it within the
    law's lag (rate / k1 = 0.32 deg) once it has caught up, and the reported target is nadir each cycle."""
    g = Guidance(_cfg({"target_kind": "nadir"}))
    eph = g.ephem
    q = _q_with_boresight(-eph.position_N_km(0.0) / np.linalg.norm(eph.position_N_km(0.0)))
    q, out, errors, _ = _fly(g, q, 0.0, 120.0)
    r = eph.position_N_km(119.9)
    assert np.allclose(out.target_N, _unit(-r), atol=1e-12)
    assert np.max(errors[200:]) < 0.4
    assert np.max(errors[200:]) > 0.05  # it does move: a fixed target would be reached exactly


def test_ground_target_is_followed_and_a_fixed_target_ends_it() -> None:
    """A point the spacecraft flies over at t = 75 s: its direction sweeps ~60 deg in a minute, up to 0.72
    deg/s overhead; the boresight follows it with the proportional law's lag, rate / k1 (3.6 deg at
    k1 = 0.2 1/s), and no more."""
    ground = _sub_satellite(SkyEphemeris(_cfg({})), 75.0)
    g = Guidance(_cfg({"target_kind": "ground", "target_ground": ground}))
    q = _q_with_boresight(g.target_on_earth_N("ground", GroundTargetConfig(**ground), 0.0))
    q, out, _, _ = _fly(g, q, 0.0, 30.0)
    first = out.target_N.copy()
    targets = []
    for k in range(600):
        out = g.step(30.0 + 0.1 * k, 0.1, q, np.zeros(3))
        targets.append(out.target_N.copy())
        lag_bound = 1.1 * math.radians(_angle_deg(targets[-2], targets[-1]) / 0.1) / 0.2 if k else 90.0
        assert out.pointing_error_deg < math.degrees(lag_bound) + 0.3
        q = _step(q, out.omega_cmd_BN_B, 0.1)
    assert _angle_deg(first, out.target_N) > 30.0  # the target swept across the sky
    g.set_target_direction(np.array([0.0, 0.0, 1.0]))
    q, out, _, _ = _fly(g, q, 90.0, 1.0)
    assert np.allclose(out.target_N, [0.0, 0.0, 1.0])
    g.set_target_on_earth("nadir")
    q, out, _, _ = _fly(g, q, 91.0, 1.0)
    assert np.allclose(out.target_N, _unit(-g.ephem.position_N_km(91.9)), atol=1e-12)


def test_tracking_survives_safe_and_resumes() -> None:
    g = Guidance(_cfg({"target_kind": "nadir"}))
    q = _q_with_boresight(-g.ephem.position_N_km(0.0))
    q, out, _, _ = _fly(g, q, 0.0, 5.0)
    g.set_mode("SAFE")
    g.step(5.0, 0.1, q, np.zeros(3))
    g.set_mode("POINTING")
    q, out, _, _ = _fly(g, q, 30.0, 1.0)
    assert np.allclose(out.target_N, _unit(-g.ephem.position_N_km(30.9)), atol=1e-12)


def test_a_zone_keeps_a_moving_target_out() -> None:
    """A fixed inertial zone that nadir sweeps into: the boresight stays out of it (margin > 0) while the
    target passes through it, as for a fixed target a zone moves over."""
    g0 = Guidance(_cfg({"target_kind": "nadir"}))
    ahead = -g0.ephem.position_N_km(60.0)
    zone = {"name": "no", "body": "inertial", "direction_N": list(ahead / np.linalg.norm(ahead)),
            "geometry": {"shape": "cone", "half_angle_deg": 1.5}}
    g = Guidance(_cfg({"target_kind": "nadir", "zones": [zone]}, law={"k1": 0.2, "margin_deg": 1.0}))
    q = _q_with_boresight(-g.ephem.position_N_km(0.0))
    q, out, errors, margins = _fly(g, q, 0.0, 120.0)
    assert np.min(margins) > 0.0
    assert np.max(errors) > 2.0  # it did hold short of the target while the zone covered it
    assert errors[-1] < 0.5  # and caught up once it had passed


@pytest.mark.parametrize("height_km", [None, 0.0, 100.0])
def test_earth_zone_reaches_the_top_of_the_atmosphere(height_km) -> None:
    zone = {"name": "earth", "body": "earth", "geometry": {"shape": "cone", "half_angle_deg": 5.0}}
    if height_km is not None:
        zone["atmosphere_height_km"] = height_km
    eph = SkyEphemeris(_cfg({"zones": [zone]}))
    limb = EARTH_RADIUS_KM + (height_km or 0.0)
    assert eph.earth_angular_radius_deg == pytest.approx(math.degrees(math.asin(limb / LEO["radius_km"])), abs=1e-12)
    if height_km == 100.0:  # 1.47 deg beyond the solid Earth's limb seen from 600 km
        assert eph.earth_angular_radius_deg - math.degrees(math.asin(EARTH_RADIUS_KM / LEO["radius_km"])) > 1.4


def test_atmosphere_height_only_on_earth_zones() -> None:
    sun = {"name": "sun", "body": "sun", "geometry": {"shape": "cone", "half_angle_deg": 5.0},
           "atmosphere_height_km": 100.0}
    with pytest.raises(ValueError, match="atmosphere_height_km"):
        _cfg({"zones": [sun]})
    with pytest.raises(ValueError, match="target_ground"):
        _cfg({"target_kind": "ground"})
