"""Mission checks of targets on the rotating Earth: a ground target commanded while it is below its
horizon (or its min_elevation_deg) for the whole dwell is an error at the key to change, with the time it
next rises; a visible one passes with its window; nadir and ground targets are checked against the zones
where they are at each sampled time. The example mission earth-observation.yaml passes."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import Mission
from hil_sim.mission.physics_checks import check_mission, schedule, target_at

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "config" / "missions" / "earth-observation.yaml"
DELHI = {"latitude_deg": 28.61, "longitude_deg": 77.21, "altitude_m": 216.0, "min_elevation_deg": 10.0}


def _data() -> dict:
    return yaml.safe_load(EXAMPLE.read_text())


def _findings(report, check: str, level: str):
    return [f for f in report.findings if f.check == check and f.level == level]


def _elevation_deg(mission: Mission, ground: dict, t_s: float) -> float:
    """Elevation from the truth orbit (circular here), by gnc.earth (itself checked against astropy)."""
    from gnc.sky_ephemeris import SkyEphemeris
    from gnc.earth import earth_fixed_to_inertial, elevation_deg

    eph = SkyEphemeris(mission.flight_software)
    r_E = earth_fixed_to_inertial(eph.jd0_utc + t_s / 86400.0).T @ eph.position_N_km(t_s)
    return elevation_deg(ground["latitude_deg"], ground["longitude_deg"], ground["altitude_m"], r_E)


def test_example_passes_with_its_visibility_window():
    report = check_mission(Mission.model_validate(_data()), quick=True)
    assert report.ok, report.format()
    first, second = _findings(report, "visibility", "info")
    assert first.loc == ("flight_software", "pointing", "target_ground") and second.loc == ("timeline", 0, "ground")
    assert 24.0 < first.numbers["max_elevation_deg"] < 26.0  # at t = 150 s, when Karachi takes over
    assert 32.0 < second.numbers["max_elevation_deg"] < 34.0


def test_ground_target_below_the_horizon_for_its_dwell_is_an_error_with_its_next_rise():
    """Delhi is -1 to 8 deg above the horizon over t = 0-100 s, under the 10 deg asked for; it rises past 10
    deg at t ~ 150 s."""
    data = _data()
    data["timeline"] = [{"t_s": 0.0, "command": "SET_TARGET", "ground": dict(DELHI)},
                        {"t_s": 100.0, "command": "SET_TARGET", "nadir": True}]
    mission = Mission.model_validate(data)
    assert max(_elevation_deg(mission, DELHI, t) for t in np.arange(0.0, 101.0, 5.0)) < 10.0
    report = check_mission(mission, quick=True)
    (error,) = _findings(report, "visibility", "error")
    assert error.loc == ("timeline", 0, "ground")
    rise = float(error.message.split("next rises above 10 deg at t = ")[1].split(" s")[0])
    assert _elevation_deg(mission, DELHI, rise) >= 10.0 > _elevation_deg(mission, DELHI, rise - 5.0)
    assert f"command it at t_s >= {rise:.0f}" in error.message
    # commanded at its rise it passes
    data["timeline"][0]["t_s"], data["timeline"][1]["t_s"] = rise, rise + 100.0
    assert not _findings(check_mission(Mission.model_validate(data), quick=True), "visibility", "error")


def test_visibility_error_is_reported_at_the_key(tmp_path, capsys):
    from cli.main import main

    example = EXAMPLE.read_text()
    start, end = example.index("timeline:\n"), example.index("requirements:")
    text = example[:start] + (
        "timeline:\n"
        "  - t_s: 0.0\n"
        "    command: SET_TARGET\n"
        "    ground: {latitude_deg: -33.87, longitude_deg: 151.21}   # Sydney: the other side of the Earth\n\n"
    ) + example[end:]
    path = tmp_path / "sydney.yaml"
    path.write_text(text)
    line = text[:text.index("    ground: {latitude_deg: -33.87")].count("\n") + 1
    assert main(["config", "validate", str(path)]) == 1
    err = capsys.readouterr().err
    assert f"{path}:{line}:5 timeline[0].ground: error: the ground target from timeline[0]" in err, err
    assert "the spacecraft is below its horizon" in err


def test_schedule_and_zone_checks_follow_the_moving_target():
    """A nadir target's segment starts at nadir, and it is checked against a zone where it is later: a fixed
    zone on the nadir direction at t = 300 s is found by the target check."""
    data = _data()
    data["timeline"] = [{"t_s": 200.0, "command": "SET_TARGET", "nadir": True}]
    mission = Mission.model_validate(data)
    segments = schedule(mission)
    assert [s.earth[0] for s in segments] == ["ground", "nadir"]
    from gnc.sky_ephemeris import SkyEphemeris

    eph = SkyEphemeris(mission.flight_software)
    r0 = eph.position_N_km(200.0)
    assert np.allclose(segments[1].target, -r0 / np.linalg.norm(r0))
    r = eph.position_N_km(300.0)
    later = copy.deepcopy(data)
    later["flight_software"]["pointing"]["zones"].append(
        {"name": "ahead", "body": "inertial", "direction_N": list(-r / np.linalg.norm(r)),
         "geometry": {"shape": "cone", "half_angle_deg": 2.0}})
    report = check_mission(Mission.model_validate(later), quick=True)
    held = [f for f in report.findings if f.check == "target" and "zone 'ahead'" in f.message]
    assert held and held[0].loc == ("timeline", 0, "nadir")
    assert np.allclose(target_at(segments[1], eph, 300.0), -r / np.linalg.norm(r))


@pytest.mark.parametrize("keys", [{"nadir": True, "ra_dec_deg": [1.0, 2.0]}, {}])
def test_set_target_takes_exactly_one_target(keys):
    data = _data()
    data["timeline"] = [{"t_s": 10.0, "command": "SET_TARGET", **keys}]
    problems = Mission.model_validate(data)._timeline_entry_problems(0, Mission.model_validate(data).timeline[0])
    assert problems and "exactly one of target_N, ra_dec_deg, nadir, ground, q_target_NB" in problems[0][1]


def test_judge_measures_the_error_to_where_the_ground_target_truly_is():
    """Truth with a boresight exactly on the ground point (astropy's GCRS position, from a true spacecraft
    orbit that is not the onboard one): the judge's error is ~0; against the target frozen at its first
    direction it would grow to degrees."""
    import astropy.units as u
    from astropy.coordinates import GCRS, EarthLocation
    from astropy.time import Time
    from astropy.utils import iers

    from hil_sim.sil.judge import error_series

    iers.conf.auto_download = False
    mission = Mission.model_validate(_data())
    g = mission.flight_software.pointing.target_ground
    t = np.linspace(0.0, 140.0, 7)  # the initial target's dwell
    r_sc = np.array([[7000.0 * np.cos(0.001 * s), 7000.0 * np.sin(0.001 * s), 500.0] for s in t])
    loc = EarthLocation.from_geodetic(g.longitude_deg * u.deg, g.latitude_deg * u.deg, g.altitude_m * u.m)
    when = Time("2026-06-25T10:00:00", format="isot", scale="utc") + t * u.s
    when.delta_ut1_utc = np.zeros(len(t))
    p = np.asarray(loc.get_itrs(obstime=when).transform_to(GCRS(obstime=when)).cartesian.xyz.to_value(u.km)).T
    y = (p - r_sc) / np.linalg.norm(p - r_sc, axis=1, keepdims=True)
    err, _ = error_series(mission, {"t_s": t, "r_sc_N_km": r_sc, "q_NB": np.zeros((len(t), 4))}, y)
    assert np.max(err) < 0.01
    frozen = np.degrees(np.arccos(np.clip(y @ y[0], -1.0, 1.0)))
    assert frozen[-1] > 2.0


@pytest.mark.parametrize("height_km", [None, 100.0])
def test_earth_zone_with_its_atmosphere_in_the_judge_and_the_check(height_km):
    """The judge (truth) and the mission check (onboard orbit) both widen an Earth zone to the top of the
    atmosphere: asin((6378.137 + h) / r) more than its own half-angle."""
    import math

    from fsw.config import SkyZoneConfig
    from hil_sim.mission.physics_checks import SkyZones
    from hil_sim.sil.judge import _zone_centers

    zone = {"name": "earth", "body": "earth", "geometry": {"shape": "cone", "half_angle_deg": 5.0}}
    if height_km is not None:
        zone["atmosphere_height_km"] = height_km
    want = math.degrees(math.asin((6378.137 + (height_km or 0.0)) / 6978.0))
    truth = {"earth_N": np.array([[1.0, 0.0, 0.0]]), "r_sc_N_km": np.array([[-6978.0, 0.0, 0.0]])}
    _, extra = _zone_centers(SkyZoneConfig(**zone), truth, np.array([0.0]))
    assert extra == pytest.approx(want, abs=1e-12)
    data = _data()
    data["flight_software"]["pointing"]["zones"] = [zone]
    data["flight_software"]["pointing"]["target_kind"] = "inertial"
    data["flight_software"]["pointing"].pop("target_ground")
    sky = SkyZones(Mission.model_validate(data))
    centre = sky.centers(0.0)[0]
    side = np.cross(centre, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)

    def off(angle_deg: float) -> np.ndarray:
        return np.cos(np.radians(angle_deg)) * centre + np.sin(np.radians(angle_deg)) * side

    phys = sky.physical(0.0)[0]
    assert phys.contains(off(want + 5.0 - 0.01)) and not phys.contains(off(want + 5.0 + 0.01))
