"""Load-time physics checks: each bad set-up is caught with the zone names and numbers, good ones pass.

Expected numbers come from independent sources: the Sun's position from astropy (not the onboard
gnc.ephemeris the checks use), 1 - cos(delta) from the cone geometry by hand, and the wheel authority
of three orthogonal wheels in closed form.
"""
from __future__ import annotations

import copy
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import Mission
from hil_sim.mission.physics_checks import check_mission

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = ROOT / "config" / "missions"


def _data(name: str) -> dict:
    return yaml.safe_load((MISSIONS / name).read_text())


def _mission(data: dict) -> Mission:
    return Mission.model_validate(data)


def _astropy_sun_radec(epoch: str) -> tuple[float, float]:
    from astropy.coordinates import get_body, solar_system_ephemeris
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    with warnings.catch_warnings(), solar_system_ephemeris.set("builtin"):
        warnings.simplefilter("ignore")
        sun = get_body("sun", Time(epoch))
        return float(sun.ra.deg), float(sun.dec.deg)


def _offset(ra_deg: float, dec_deg: float, angle_deg: float) -> list[float]:
    """Point angle_deg north of (ra, dec) along the meridian, as [ra, dec]."""
    return [ra_deg, dec_deg + angle_deg]


def _checks(report, check: str, level: str = "error"):
    return [f for f in report.findings if f.check == check and f.level == level]


def test_demo_pointing_passes():
    report = check_mission(_mission(_data("demo-pointing.yaml")))
    assert report.ok, report.format()
    assert report.samples >= 2


def test_paper_cones_eps_interval_matches_the_geometry():
    data = _data("paper-s3-cones.yaml")
    # cones of 15 deg + 1 deg margin on axes 90 deg apart: 2 delta = 90 - 2 * 16 = 58 deg
    one_minus_cos_delta = 1.0 - math.cos(math.radians(29.0))
    assert 0.125 < one_minus_cos_delta < 0.13
    assert check_mission(_mission(data)).ok
    data["flight_software"]["law"]["eps"] = 0.13
    report = check_mission(_mission(data))
    assert not report.ok
    msgs = " ".join(f.message for f in report.errors)
    assert "eps = 0.13" in msgs and f"{one_minus_cos_delta:.4g}"[:5] in msgs


def test_target_inside_the_sun_zone_is_rejected():
    data = _data("demo-pointing.yaml")
    ra, dec = _astropy_sun_radec("2026-04-25T12:00:00")
    data["timeline"][0]["ra_dec_deg"] = [ra, dec]
    report = check_mission(_mission(data))
    errors = _checks(report, "target")
    assert errors and "timeline[0]" in errors[0].message and "inside zone 'sun'" in errors[0].message
    assert errors[0].numbers["margin_deg"] < -25  # the Sun centre is deep inside a 30..40 deg zone


@pytest.mark.parametrize("offset_deg, inside", [(31.5, False), (28.0, True)])
def test_target_near_a_sun_cone(offset_deg, inside):
    data = _data("demo-pointing.yaml")
    data["flight_software"]["pointing"]["zones"][0]["geometry"] = {"shape": "cone", "half_angle_deg": 30.0}
    ra, dec = _astropy_sun_radec("2026-04-25T12:00:00")
    data["timeline"][0]["ra_dec_deg"] = _offset(ra, dec, offset_deg)
    report = check_mission(_mission(data))
    errors = _checks(report, "target")
    assert errors, report.format()
    assert len(errors) == 1 and errors[0].loc == ("timeline", 0, "ra_dec_deg")
    msg = errors[0].message
    # the Sun's place as printed agrees with astropy to the onboard ephemeris accuracy and the rounding
    import re
    shown = re.search(r"the Sun is at RA/Dec \(([-\d.]+), ([-\d.]+)\)", msg)
    assert shown, msg
    assert float(shown[1]) == pytest.approx(ra, abs=0.1) and float(shown[2]) == pytest.approx(dec, abs=0.1)
    if inside:
        # plain words, the Sun's place and how far to move
        assert msg.startswith(f"the target from timeline[0] at RA/Dec ({ra:.1f}, {dec + offset_deg:.1f}) is 2.0 deg "
                              "inside zone 'sun' at t = 10 s: the Sun is at RA/Dec ("), msg
    else:
        assert "is only 1.49 deg outside zone 'sun' at t = 10 s, inside it as the law flies it, so the flight " \
               "software would hold short of it" in msg
    # the move: out of the zone as the law flies it (30 + 3 + 0.1 deg) and out of its eps-layer, which the
    # flight software's rule (edge_rule) floors at about 0.19 deg for a lone cone here
    from fsw.guidance.pointing import ZONE_REBUILD_TOL_DEG

    law = data["flight_software"]["law"]["margin_deg"]
    need = 30.0 + law + ZONE_REBUILD_TOL_DEG - offset_deg
    assert need + 0.1 < errors[0].numbers["move_deg"] < need + 0.3
    assert msg.endswith(f"move it at least {errors[0].numbers['move_deg']:.2f} deg further from the Sun (out of the "
                        "zone as the law flies it, inflated by law.margin_deg = 3 deg and the 0.1 deg rebuild "
                        "tolerance, and out of the law's eps-layer)"), msg
    # the reported physical margin agrees with astropy to the onboard ephemeris accuracy (0.01 deg Sun)
    assert errors[0].numbers["margin_deg"] == pytest.approx(offset_deg - 30.0, abs=0.05)


def test_sun_and_moon_zones_merge_later_in_the_run_as_the_moon_approaches_the_sun():
    """Sun-Moon separation shrinks ~12 deg/day before new moon; zones apart at t=0 overlap within a day.

    The flight software then flies them as one merged zone (fsw.guidance.ZoneGeometry.merge), so the check
    reports the merge, not an Assumption 1 violation between the zones as written."""
    from astropy.coordinates import get_body, solar_system_ephemeris
    from astropy.time import Time

    epoch = "2026-09-08T00:00:00"  # new moon on 2026-09-11
    with warnings.catch_warnings(), solar_system_ephemeris.set("builtin"):
        warnings.simplefilter("ignore")
        sep0 = float(get_body("sun", Time(epoch)).separation(get_body("moon", Time(epoch))).deg)
        sep1 = float(get_body("sun", Time(epoch) + 1.0).separation(get_body("moon", Time(epoch) + 1.0)).deg)
    assert sep0 - sep1 > 8.0
    data = _data("demo-pointing.yaml")
    data["epoch_utc"] = data["flight_software"]["epoch_utc"] = epoch + "Z"
    data["duration_s"] = 86400.0
    data["orbit"] = {"semi_major_axis_km": 7000.0, "inclination_deg": 98.0}  # LEO: Moon parallax < 1 deg
    data["flight_software"]["orbit"] = {"radius_km": 7000.0, "inclination_deg": 98.0}
    margin = data["flight_software"]["law"]["margin_deg"]
    moon_half = 10.0
    sun_half = sep0 - moon_half - 2 * margin - 8.0  # inflated zones 8 deg apart at t = 0
    zones = data["flight_software"]["pointing"]["zones"]
    zones[0]["geometry"] = {"shape": "cone", "half_angle_deg": sun_half}
    zones[1]["geometry"] = {"shape": "cone", "half_angle_deg": moon_half}
    # keep the targets well away: the anti-Sun side
    ra, dec = _astropy_sun_radec(epoch)
    data["timeline"] = [{"t_s": 10.0, "command": "SET_TARGET", "ra_dec_deg": [(ra + 180.0) % 360.0, -dec]}]
    sun = np.array([math.cos(math.radians(dec)) * math.cos(math.radians(ra)),
                    math.cos(math.radians(dec)) * math.sin(math.radians(ra)), math.sin(math.radians(dec))])
    data["flight_software"]["pointing"]["target_N"] = (-sun).tolist()
    report = check_mission(_mission(data), step_s=3600.0)
    assert report.ok, report.format()
    merges = [f for f in report.findings if f.check == "merge"]
    assert len(merges) == 1 and "zones 'sun' and 'moon'" in merges[0].message, report.format()
    # the inflated zones are 8 deg apart at t = 0 (twice the 4 deg merge gap): merged only later
    assert 0.0 < merges[0].numbers["t_s"] < 86400.0


def test_wheels_too_weak_for_the_commanded_rate_change():
    data = _data("demo-pointing.yaml")
    torque = 0.004
    data["spacecraft"]["inertia_B_kgm2"] = [[10.0, 0, 0], [0, 20.0, 0], [0, 0, 30.0]]
    wheel = {"Js_kgm2": 0.004, "max_torque_Nm": torque, "max_speed_rad_s": 628.0}
    data["spacecraft"]["wheels"] = [dict(wheel, axis_B=a) for a in ([1, 0, 0], [0, 1, 0], [0, 0, 1])]
    data["initial_state"]["wheel_speeds_rad_s"] = [0.0, 0.0, 0.0]
    fsw_wheel = {"max_torque_Nm": torque, "max_speed_rad_s": 628.0, "spin_inertia_kgm2": 0.004}
    data["flight_software"]["spacecraft"]["wheels"] = [dict(fsw_wheel, axis_B=a) for a in
                                                       ([1, 0, 0], [0, 1, 0], [0, 0, 1])]
    report = check_mission(_mission(data))
    errors = [f for f in _checks(report, "wheels") if "accelerate" in f.message]
    assert errors, report.format()
    # orthogonal wheels: along body z the torque is the one wheel's limit, J_zz = 30 is the largest
    expected = math.degrees(torque / 30.0)
    assert errors[0].numbers["accel_avail_deg_s2"] == pytest.approx(expected, rel=0.01)
    # momentum: 0.9 * 628 rad/s * 0.004 kg m^2 / 30 kg m^2 about z
    momentum = [f for f in _checks(report, "wheels", "info")][0]
    assert momentum.numbers["rate_avail_deg_s"] == pytest.approx(math.degrees(0.9 * 628.0 * 0.004 / 30.0), rel=0.01)


def test_polygon_not_containing_its_centre_is_a_kernel_error():
    data = _data("demo-pointing.yaml")
    # the centre (the Sun direction) lies on the edge from (-10, 0) to (10, 0): not strictly inside
    data["flight_software"]["pointing"]["zones"][0]["geometry"] = {
        "shape": "polygon", "vertices_deg": [[10.0, 0.0], [0.0, 10.0], [-10.0, 0.0]]}
    report = check_mission(_mission(data))
    errors = _checks(report, "kernel")
    assert errors and "zone 'sun'" in errors[0].message and "kernel" in errors[0].message


def test_initial_boresight_inside_a_zone():
    data = _data("demo-pointing.yaml")
    ra, dec = _astropy_sun_radec("2026-04-25T12:00:00")
    from scipy.spatial.transform import Rotation

    # body z (the boresight) onto the Sun: rotate z to the Sun direction
    sun = np.array([math.cos(math.radians(dec)) * math.cos(math.radians(ra)),
                    math.cos(math.radians(dec)) * math.sin(math.radians(ra)), math.sin(math.radians(dec))])
    rot, _ = Rotation.align_vectors([sun], [[0.0, 0.0, 1.0]])
    x, y, z, w = rot.as_quat()
    data["initial_state"]["q_NB"] = [w, x, y, z]
    report = check_mission(_mission(data))
    errors = _checks(report, "initial-state")
    assert errors and "deg inside zone 'sun'" in errors[0].message and errors[0].loc == ("initial_state",)


def test_kappa_at_or_below_kappa_bar_is_reported(monkeypatch):
    """Plumbing: gnc.checks decides kappa_bar (tested in tests/gnc); a report above kappa is an error."""
    import gnc.checks

    real = gnc.checks.check_assumptions

    def with_kappa_bar(*args, **kwargs):
        rep = real(*args, **kwargs)
        if kwargs.get("kappa") is not None:
            rep = copy.copy(rep)
            rep.kappa_bar = 2.5
        return rep

    monkeypatch.setattr(gnc.checks, "check_assumptions", with_kappa_bar)
    report = check_mission(_mission(_data("demo-pointing.yaml")))
    errors = _checks(report, "kappa")
    assert errors and "law.kappa = 1 is at or below kappa_bar = 2.5" in errors[0].message
    assert "raise law.kappa above 2.5" in errors[0].message and errors[0].loc == ("flight_software", "law", "kappa")
    # one root cause, one error: no second copy of it among the assumption errors
    assert len(report.errors) == 1, report.format()


def test_config_check_cli(capsys):
    from cli.main import main

    assert main(["config", "check", str(MISSIONS / "paper-s3-cones.yaml")]) == 0
    out = capsys.readouterr().out
    assert "eps upper bound 0.1254" in out and "PASS" in out


def test_validate_and_check_agree_on_a_target_inside_a_zone(tmp_path, capsys):
    """One root cause, one error, at file:line:col of the key to change, from both commands."""
    from cli.main import main

    text = (MISSIONS / "demo-pointing.yaml").read_text()
    old = "ra_dec_deg: [95.0, 30.0]"
    path = tmp_path / "sun-target.yaml"
    path.write_text(text.replace(old, "ra_dec_deg: [40.0, 25.0]", 1))
    offset = text.index(old) + len("ra_dec_deg")  # the key's position, found in the text, not by the loader
    line = text.count("\n", 0, offset) + 1
    col = text.rfind("ra_dec_deg", 0, offset) - text.rfind("\n", 0, offset)
    where = f"{path}:{line}:{col} timeline[0].ra_dec_deg: error: the target from timeline[0] at RA/Dec (40.0, 25.0) is "
    assert main(["config", "validate", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count(where) == 1 and err.count("error:") == 1, err
    assert "deg inside zone 'sun' at t = 10 s: the Sun is at RA/Dec (" in err
    assert main(["config", "check", str(path)]) == 1
    out = capsys.readouterr().out
    assert out.count(where) == 1 and out.count("error:") == 1, out
    assert "FAIL: 1 error(s)" in out


def test_every_error_names_the_key_to_change():
    data = _data("demo-pointing.yaml")
    data["flight_software"]["pointing"]["zones"][0]["geometry"] = {
        "shape": "polygon", "vertices_deg": [[10.0, 0.0], [0.0, 10.0], [-10.0, 0.0]]}
    data["flight_software"]["control"]["max_command_accel_deg_s2"] = 5.0
    report = check_mission(_mission(data))
    assert report.errors and all(f.loc for f in report.errors), report.format()
    locs = {f.loc for f in report.errors}
    assert ("flight_software", "pointing", "zones", 0, "geometry") in locs
    assert ("flight_software", "control", "max_command_accel_deg_s2") in locs


def test_a_disturbance_that_saturates_the_wheels_within_the_mission_is_refused_with_the_time():
    """A mission whose constant disturbance fills the wheels before its end used to pass `config check`; in
    flight the wheel saturated, was isolated as failed, and the boresight ended inside the Sun zone. The
    budget is checked against a hand count: the smallsat's four pyramid wheels (axes (+-1, +-1, 1)/sqrt 3,
    each 4.8e-5 kg m^2 up to 0.9 x 628 rad/s) hold 4 h / sqrt 3 along body x, all four spinning at their
    headroom with the y and z parts cancelling."""
    data = _data("smallsat-example.yaml")
    data["duration_s"] = 10_000.0
    data["spacecraft"]["disturbance"] = {"constant_B_Nm": [1.0e-5, 0.0, 0.0]}
    data["initial_state"]["wheel_speeds_rad_s"] = [0.0, 0.0, 0.0, 0.0]
    report = check_mission(_mission(data), quick=True)
    found = _checks(report, "momentum")
    assert len(found) == 1, report.format()
    h = 4.8e-5 * 0.9 * 628.0
    expected_s = (4.0 * h / math.sqrt(3.0)) / 1.0e-5
    assert found[0].numbers["exceeded_at_s"] == pytest.approx(expected_s, abs=10.0)
    assert "t = " in found[0].message and found[0].loc == ("spacecraft", "disturbance", "constant_B_Nm")
    data["duration_s"] = 0.9 * expected_s  # ends before the wheels fill: accepted
    assert not _checks(check_mission(_mission(data), quick=True), "momentum")


def test_an_initial_body_rate_beyond_the_wheels_momentum_is_refused():
    data = _data("smallsat-example.yaml")
    data["initial_state"]["omega_BN_B_rad_s"] = [0.5, 0.0, 0.0]
    found = _checks(check_mission(_mission(data), quick=True), "momentum")
    assert len(found) == 1 and found[0].loc == ("initial_state", "omega_BN_B_rad_s")
    assert found[0].numbers["momentum_Nms"] > found[0].numbers["capacity_Nms"]


def test_a_configured_rate_limit_the_star_tracker_cannot_follow_is_refused_as_onboard():
    """The configured rate limit is judged by the rules SET_GAINS meets onboard, the sensors' range included:
    a star tracker that loses its attitude above 0.5 deg/s cannot fly the demo's 1 deg/s."""
    from fsw.guidance import Guidance

    data = _data("demo-pointing.yaml")
    data["spacecraft"]["star_tracker"]["max_rate_deg_s"] = 0.5
    mission = _mission(data)
    found = [f for f in check_mission(mission, quick=True).errors if f.check == "braking"]
    assert len(found) == 1 and found[0].loc == ("flight_software", "spacecraft", "max_rate_deg_s")
    with pytest.raises(ValueError) as onboard:
        Guidance(mission.flight_software).set_gains(1.0, 1.0, "auto", mission.flight_software.spacecraft.max_rate_deg_s)
    assert onboard.value.code == "RATE_ABOVE_SENSOR_LIMIT" and str(onboard.value) in found[0].message
