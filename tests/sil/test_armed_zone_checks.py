"""`keepout config check` of a sky zone with ``armed: inertial_targets`` (`fsw.config.SkyZoneConfig.armed`).

The flight software keeps such a zone out only while its POINTING target is a fixed direction: a nadir or
ground target disarms it, and it is armed once the boresight has left it. So the check leaves it out for
nadir and ground targets (an Earth zone on an Earth-observation camera: its cities and nadir lie inside
the Earth's disc), holds an inertial target to it exactly as to an ``armed: always`` zone, and an initial
boresight inside it is no error.

The oracles are the mission without the zone (what the flight software flies for a target on the Earth),
the same zone with ``armed: always`` (for an inertial target), and the Earth's angular radius in closed form.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import Mission
from hil_sim.mission.physics_checks import ZONES_LOC, check_mission

EO = Path(__file__).resolve().parents[2] / "config" / "missions" / "earth-observation.yaml"
EARTH_RADIUS_KM, ORBIT_RADIUS_KM = 6378.137, 6978.0  # the example's circular orbit
EARTH_CONE_DEG = 1.0  # the zone's own cone, added to the Earth's disc
# the Earth's disc seen from the orbit, in closed form: every ground target and nadir lie inside it
EARTH_DISC_DEG = math.degrees(math.asin(EARTH_RADIUS_KM / ORBIT_RADIUS_KM))
STEP_S = 50.0  # a coarse sweep keeps the full assumption check to seconds; the zones move < 3 deg per step
TARGET_LOCS = [("flight_software", "pointing", "target_ground"), ("timeline", 0, "ground"), ("timeline", 1, "nadir")]


def _earth_zone(armed: str) -> dict:
    return {"name": "earth", "body": "earth", "armed": armed,
            "geometry": {"shape": "cone", "half_angle_deg": EARTH_CONE_DEG}}


def _data(armed: str | None) -> dict:
    """The Earth-observation example (Bengaluru, Karachi, nadir) with an Earth zone between its Sun and
    Moon zones (None: without it), so that the zones after it are numbered one on."""
    data = yaml.safe_load(EO.read_text())
    if armed is not None:
        data["flight_software"]["pointing"]["zones"].insert(1, _earth_zone(armed))
    return data


def _check(data: dict, **kwargs):
    return check_mission(Mission.model_validate(data), **kwargs)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _directions(data: dict, t_s: float) -> dict[str, np.ndarray]:
    """Earth, Sun and Moon directions at ``t_s`` with the onboard ephemeris the check uses."""
    from gnc.sky_ephemeris import SkyEphemeris

    dirs = SkyEphemeris(Mission.model_validate(data).flight_software).directions(t_s)
    return {body: _unit(dirs[body]) for body in ("earth", "sun", "moon")}


def _away(centre: np.ndarray, avoid: np.ndarray, angle_deg: float) -> list[float]:
    """The direction ``angle_deg`` from ``centre`` on the great circle through ``avoid``, on the far side."""
    tangent = _unit((avoid @ centre) * centre - avoid)
    a = math.radians(angle_deg)
    return list(math.cos(a) * centre + math.sin(a) * tangent)


def _shift_zone_loc(loc, inserted_at: int = 1):
    """A key path of the mission without the Earth zone, as it reads with the zone inserted."""
    if loc is not None and tuple(loc[:3]) == ZONES_LOC and loc[3] >= inserted_at:
        return (*ZONES_LOC, loc[3] + 1, *loc[4:])
    return loc


def _findings(report) -> list[tuple]:
    return [(f.level, f.check, f.message, f.loc, f.numbers) for f in report.findings]


def test_the_earth_zone_is_inside_the_ground_targets_reach():
    """The premise: the zone (the Earth's disc and 1 deg) covers the example's cities and nadir."""
    report = _check(_data("always"), quick=True)
    inside = [f for f in report.errors if f.check == "target"]
    assert sorted(f.loc for f in inside) == sorted(TARGET_LOCS)
    assert all("inside zone 'earth'" in f.message and f.numbers["margin_deg"] < 0 for f in inside)
    assert EARTH_DISC_DEG + EARTH_CONE_DEG > 66.0


@pytest.mark.parametrize("gap_deg, eps", [(2.0, "auto"), (6.0, 0.005)])
def test_ground_and_nadir_targets_are_checked_as_without_the_zone(gap_deg, eps):
    """With the zone armed for inertial targets only, the check of a mission of cities and nadir is the check
    of the mission without it, assumption sweep included: the same findings word for word (zone numbers,
    names, eps bound), at the same keys (zones after it one on). A small zone by the Sun's, numbered after
    the Earth zone, is named right: merged with the Sun's (a 2 deg gap), or with a fixed eps too thick for
    a 6 deg gap (the paper's assumptions fail, naming both zones)."""
    glint = {"name": "glint", "body": "inertial", "geometry": {"shape": "cone", "half_angle_deg": 5.0}}
    with_zone, without = _data("inertial_targets"), _data(None)
    dirs = _directions(with_zone, 0.0)
    # beyond the Sun zone (40 deg + 3 deg margin) on the side away from the Earth
    glint["direction_N"] = _away(dirs["sun"], dirs["earth"], 40.0 + 3.0 + gap_deg + 5.0 + 3.0)
    for data in (with_zone, without):
        data["flight_software"]["pointing"]["zones"].append(copy.deepcopy(glint))
        data["flight_software"]["law"]["eps"] = eps
    report, expected = _check(with_zone, step_s=STEP_S), _check(without, step_s=STEP_S)
    assert report.samples == expected.samples
    assert _findings(report) == [(lv, ck, msg, _shift_zone_loc(loc), nums) for lv, ck, msg, loc, nums
                                 in _findings(expected)]
    assert not any(f.check == "initial-state" or "earth" in f.message for f in report.findings)
    if eps == "auto":
        assert report.ok, report.format()
        assert any(f.check == "merge" and "'sun' and 'glint'" in f.message for f in report.findings)
    else:
        thick = [f for f in report.errors if "too thick for the gap between zones 'sun' and 'glint'" in f.message]
        assert len(thick) == 3  # once per target: the city, the other city, nadir
        assert not report.ok


def test_the_same_zone_armed_always_refuses_the_ground_targets_and_the_start():
    report = _check(_data("always"), quick=True)
    assert not report.ok
    assert sorted(f.loc for f in report.errors if f.check == "target") == sorted(TARGET_LOCS)
    (start,) = [f for f in report.findings if f.check == "initial-state"]
    assert start.level == "error" and "inside zone 'earth'" in start.message
    ok = _check(_data("inertial_targets"), quick=True)
    assert ok.ok, ok.format()
    assert not any("earth" in f.message for f in ok.findings)


@pytest.mark.parametrize("key", ["target_N", "ra_dec_deg", "initial"])
def test_an_inertial_target_inside_the_zone_is_an_error_as_for_always(key):
    """A fixed direction near nadir (as commanded, or the initial target) lies inside the Earth zone: the
    flight software keeps the zone out for it, so the check refuses it, the same finding as armed always."""
    reports = {}
    for armed in ("inertial_targets", "always"):
        data = _data(armed)
        t_s = 0.0 if key == "initial" else 350.0
        near_nadir = _away(_directions(data, t_s)["earth"], _directions(data, t_s)["moon"], 10.0)
        if key == "initial":
            pointing = data["flight_software"]["pointing"]
            pointing.update(target_kind="inertial", target_N=near_nadir)
            del pointing["target_ground"]
            data["timeline"] = []
            loc = ("flight_software", "pointing", "target_N")
        elif key == "target_N":
            data["timeline"][1] = {"t_s": t_s, "command": "SET_TARGET", "target_N": near_nadir}
            loc = ("timeline", 1, "target_N")
        else:
            x, y, z = near_nadir
            radec = [math.degrees(math.atan2(y, x)) % 360.0, math.degrees(math.asin(z))]
            data["timeline"][1] = {"t_s": t_s, "command": "SET_TARGET", "ra_dec_deg": radec}
            loc = ("timeline", 1, "ra_dec_deg")
        reports[armed] = report = _check(data, quick=True)
        (error,) = [f for f in report.errors if f.check == "target" and f.loc == loc]
        assert "inside zone 'earth'" in error.message
        assert error.numbers["margin_deg"] == pytest.approx(-(EARTH_DISC_DEG + EARTH_CONE_DEG - 10.0), abs=0.05)
    target_errors = {armed: [f for f in _findings(r) if f[1] == "target" and f[3] == loc]
                     for armed, r in reports.items()}
    assert target_errors["inertial_targets"] == target_errors["always"]


def test_an_inertial_target_in_the_zones_eps_layer_is_an_error_as_for_always():
    """Just outside the zone as the law flies it (the Earth's disc, the cone, law.margin_deg and the rebuild
    tolerance) lies the eps-layer the law does not come to rest in: refused for the inertial-only zone too."""
    from fsw.guidance import ZONE_REBUILD_TOL_DEG

    findings = {}
    for armed in ("inertial_targets", "always"):
        data = _data(armed)
        margin = data["flight_software"]["law"]["margin_deg"]
        inflated = EARTH_DISC_DEG + EARTH_CONE_DEG + margin + ZONE_REBUILD_TOL_DEG
        dirs = _directions(data, 350.0)
        target = _away(dirs["earth"], dirs["moon"], inflated + 0.05)
        data["timeline"][1] = {"t_s": 350.0, "command": "SET_TARGET", "target_N": target}
        report = _check(data, quick=True)
        findings[armed] = [f for f in _findings(report) if f[3] == ("timeline", 1, "target_N")]
        (error,) = [f for f in report.errors if f.loc == ("timeline", 1, "target_N")]
        assert "eps-layer" in error.message and "earth" in error.message
    assert findings["inertial_targets"] == findings["always"]


def _inertial_start(armed: str) -> dict:
    """The example with a fixed initial target 90 deg from the Earth on the Moon's far side, the boresight
    still starting on Bengaluru, inside the Earth zone. Without the Moon zone: at this epoch it overlaps the
    Earth zone, and the merge of the two round this target is another check's business."""
    data = _data(armed)
    data["flight_software"]["pointing"]["zones"] = [
        z for z in data["flight_software"]["pointing"]["zones"] if z["name"] != "moon"]
    dirs = _directions(data, 0.0)
    target = _away(dirs["earth"], dirs["moon"], 90.0)
    assert math.degrees(math.acos(np.dot(target, dirs["sun"]))) > 40.0 + 3.0 + 10.0
    pointing = data["flight_software"]["pointing"]
    pointing.update(target_kind="inertial", target_N=target)
    del pointing["target_ground"]
    return data


def test_an_initial_boresight_inside_the_zone_is_an_info_with_an_inertial_target():
    report = _check(_inertial_start("inertial_targets"), quick=True)
    assert report.ok, report.format()
    (start,) = [f for f in report.findings if f.check == "initial-state"]
    assert start.level == "info" and start.loc == ("initial_state",)
    assert "inside zone 'earth'" in start.message and "arms it once the boresight has left it" in start.message
    # Bengaluru seen from the spacecraft at 24.9 deg elevation: inside the disc
    assert -(EARTH_DISC_DEG + EARTH_CONE_DEG) < start.numbers["margin_deg"] < 0
    always = _check(_inertial_start("always"), quick=True)
    (error,) = [f for f in always.errors if f.check == "initial-state"]
    assert error.message.startswith(start.message.split("), which is kept out")[0] + "): start outside it")
    assert error.numbers == start.numbers
