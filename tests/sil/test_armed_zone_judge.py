"""The truth judge of a sky zone with ``armed: inertial_targets``: judged only on its armed samples, derived
from the mission's commanded POINTING targets and the truth (never from the flight software's arming):
not while a nadir or ground target is commanded; after an inertial target is commanded, from the first
sample whose true margin exceeds law.margin_deg (3 deg here), and on until a target on the Earth. The fast judge's metrics agree."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.campaign import fast
from hil_sim.mission.model import Mission
from hil_sim.sil.judge import boresight_N, evaluate, sky_zone_series, zone_minimum

EO = Path(__file__).resolve().parents[2] / "config" / "missions" / "earth-observation.yaml"
DT = 0.5
DURATION = 40.0
T = np.arange(0.0, DURATION + 0.5 * DT, DT)
INSIDE, OUTSIDE = 10.0, 60.0  # boresight angle from the Earth's centre [deg]; the zone's radius is 30 deg

EARTH_ZONES = {
    "cone": {"shape": "cone", "half_angle_deg": 30.0},
    # the same 30 deg disc, star-shaped: built per stretch, lazily in the fast judge
    "superellipse": {"shape": "superellipse", "semi_axes_deg": [30.0, 30.0], "exponent": 2.0},
}
# elongated: the fast judge's lower bound (angle to the centre - 30 deg) is below the margin on the short axis
ELONGATED = {
    "ellipse-a": {"shape": "superellipse", "semi_axes_deg": [30.0, 12.0], "exponent": 2.0},
    "ellipse-b": {"shape": "superellipse", "semi_axes_deg": [12.0, 30.0], "exponent": 2.0},
}


def _mission(armed: str, shape: str = "cone", second: dict | None = None) -> Mission:
    """The Earth-observation smallsat with an Earth zone of 30 deg (no Earth radius added) beside its Sun
    cone, and targets: a city (initial), a star field at 10 s, nadir at 20 s (or ``second``), a star field
    at 30 s, to 40 s."""
    data = yaml.safe_load(EO.read_text())
    data["duration_s"] = DURATION
    data["timeline"] = [
        {"t_s": 10.0, "command": "SET_TARGET", "ra_dec_deg": [0.0, 60.0]},
        {"t_s": 20.0, "command": "SET_TARGET", **(second or {"nadir": True})},
        {"t_s": 30.0, "command": "SET_TARGET", "target_N": [0.0, 0.0, 1.0]},
    ]
    data["flight_software"]["pointing"]["zones"] = [
        {"name": "sun", "body": "sun", "geometry": {"shape": "cone", "half_angle_deg": 40.0}},
        {"name": "earth", "body": "earth", "add_body_angular_radius": False, "armed": armed,
         "geometry": {**EARTH_ZONES, **ELONGATED}[shape]},
    ]
    return Mission.model_validate(data)


def _truth(angle_deg: np.ndarray, across_deg: np.ndarray | float = 0.0) -> dict[str, np.ndarray]:
    """The boresight (body +z) at ``angle_deg`` from the Earth's centre, which turns about N +z at 0.6 deg/s
    (a star zone is rebuilt every sample), towards N +z turned by ``across_deg`` about the Earth's direction;
    the Sun 90 deg from the Earth and N +z, at least 90 deg from the boresight."""
    n = len(T)
    phi = np.radians(0.6) * T
    earth = np.stack([np.cos(phi), np.sin(phi), np.zeros(n)], axis=1)
    a = np.radians(angle_deg)
    z = np.array([0.0, 0.0, 1.0])
    b = np.radians(np.broadcast_to(across_deg, (n,)))[:, None]
    side = np.cos(b) * z + np.sin(b) * np.cross(z, earth)
    y = np.cos(a)[:, None] * earth + np.sin(a)[:, None] * side
    axis = np.cross(z, y)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    half = 0.5 * np.arccos(np.clip(y @ z, -1.0, 1.0))
    q = np.hstack([np.cos(half)[:, None], axis * np.sin(half)[:, None]])
    assert np.allclose(boresight_N(q, z), y)
    sun = np.cross(earth, z)
    return {"t_s": T.copy(), "q_NB": q, "omega_BN_B": np.zeros((n, 3)), "wheel_speed_rad_s": np.zeros((n, 4)),
            "wheel_torque_Nm": np.zeros((n, 4)), "sun_N": sun, "moon_N": np.tile([0.0, 0.0, -1.0], (n, 1)),
            "earth_N": 6978.0 * earth, "r_sc_N_km": -6978.0 * earth, "cycle_done": np.ones(n)}


def _angles(*pieces: tuple[float, float, float]) -> np.ndarray:
    """OUTSIDE by default; (from, to, angle) pieces over [from, to)."""
    out = np.full(len(T), OUTSIDE)
    for start, stop, angle in pieces:
        out[(T >= start - 1e-9) & (T < stop - 1e-9)] = angle
    return out


def _summary(tmp_path: Path, mission: Mission, truth: dict[str, np.ndarray]) -> dict:
    run_dir = tmp_path / f"run{len(list(tmp_path.iterdir()))}"
    run_dir.mkdir()
    np.savez(run_dir / "truth.npz", **truth)
    (run_dir / "simulator.json").write_text(json.dumps({"wall_s": 1.0, "sim_s": DURATION, "clock": "lockstep"}))
    summary, _ = evaluate(run_dir, mission)
    return summary


def _row(summary: dict, name: str) -> dict:
    return next(r for r in summary["requirements"] if r["name"] == name)


def _earth(mission: Mission, truth: dict[str, np.ndarray], minimum_only: bool = False):
    y_N = boresight_N(truth["q_NB"], np.array([0.0, 0.0, 1.0]))
    return next(z for z in sky_zone_series(mission, truth, y_N, minimum_only=minimum_only) if z.name == "earth")


# after arming on the first star field, 3 deg, 5 deg, 3 deg into the zone at 15, 15.5, 16 s
DIP = ((15.0, 15.5, 27.0), (15.5, 16.0, 25.0), (16.0, 16.5, 27.0))
# inside the Earth's disc on the city (0-10 s) and at nadir (20-30 s), clear of it on the star fields
EO_DAY = _angles((0.0, 10.0, INSIDE), (20.0, 30.0, INSIDE))


@pytest.mark.parametrize("shape", sorted(EARTH_ZONES))
def test_inside_on_earth_targets_passes_and_fails_when_always_armed(tmp_path: Path, shape: str) -> None:
    truth = _truth(EO_DAY)
    armed = _summary(tmp_path, _mission("inertial_targets", shape), truth)
    row = _row(armed, "keep-out margin earth")
    assert row["pass"] and row["value"] == pytest.approx(OUTSIDE - 30.0, abs=1e-6)
    assert armed["zones"]["earth"]["min_margin_deg"] == pytest.approx(30.0, abs=1e-6)
    assert armed["exposure"]["inside_s"] == 0.0 and armed["exposure"]["exposure_s"] == 0.0
    zone = _earth(_mission("inertial_targets", shape), truth)
    on_stars = ((T >= 10.0) & (T < 20.0)) | (T >= 30.0)
    assert np.array_equal(zone.judged, on_stars)
    assert np.isnan(zone.margin_deg[~on_stars]).all() and np.isfinite(zone.margin_deg[on_stars]).all()

    always = _summary(tmp_path, _mission("always", shape), truth)
    row = _row(always, "keep-out margin earth")
    assert not row["pass"] and row["value"] == pytest.approx(INSIDE - 30.0, abs=1e-6)
    assert always["exposure"]["inside_s"] == pytest.approx(10.0 + 10.0)
    # the Sun zone is judged the same either way
    assert armed["zones"]["sun"] == always["zones"]["sun"]


@pytest.mark.parametrize("shape", sorted(EARTH_ZONES))
def test_an_inertial_target_is_judged_once_clear_of_the_laws_zone(tmp_path: Path, shape: str) -> None:
    # on each star field the boresight starts inside and slews out at 9 deg/s: margin -2 at 2 s, +2.5 at 2.5 s
    # (clear of the zone, not of law.margin_deg = 3 deg), +7 at 3 s
    angles = EO_DAY.copy()
    for start in (10.0, 30.0):
        ramp = (T >= start - 1e-9) & (T < start + 10.0 - 1e-9)
        angles[ramp] = np.minimum(INSIDE + 9.0 * (T[ramp] - start), OUTSIDE)
    truth = _truth(angles)
    mission = _mission("inertial_targets", shape)
    zone = _earth(mission, truth)
    armed_from = ((T >= 13.0) & (T < 20.0)) | (T >= 33.0)
    assert np.array_equal(zone.judged, armed_from)
    i, low = zone_minimum(zone)
    assert T[i] in (13.0, 33.0) and low == pytest.approx(7.0, abs=1e-6)
    assert np.isnan(zone.margin_deg[(T >= 10.0) & (T < 13.0)]).all()  # -20 .. +2.5 deg: not judged
    summary = _summary(tmp_path, mission, truth)
    assert _row(summary, "keep-out margin earth")["pass"]
    assert summary["exposure"]["inside_s"] == 0.0
    # the same ramps judged from the target's command: inside
    assert not _row(_summary(tmp_path, _mission("always", shape), truth), "keep-out margin earth")["pass"]


@pytest.mark.parametrize("shape", sorted(EARTH_ZONES))
def test_a_dip_back_into_the_zone_after_arming_fails(tmp_path: Path, shape: str) -> None:
    truth = _truth(_angles((0.0, 10.0, INSIDE), *DIP, (20.0, 30.0, INSIDE)))
    mission = _mission("inertial_targets", shape)
    summary = _summary(tmp_path, mission, truth)
    row = _row(summary, "keep-out margin earth")
    assert not row["pass"] and row["value"] == pytest.approx(-5.0, abs=1e-6) and "t = 15.5 s" in row["detail"]
    assert summary["exposure"]["exposure_s"] == pytest.approx(1.5)  # 15, 15.5, 16 s; no door: always open
    assert summary["exposure"]["depth_deg"] == pytest.approx(5.0, abs=1e-6)
    assert summary["exposure"]["first_t_s"] == 15.0


def test_a_further_inertial_target_keeps_the_zone_armed(tmp_path: Path) -> None:
    # armed on the first star field; the second one (20 s) is commanded with the boresight inside the zone
    truth = _truth(_angles((0.0, 10.0, INSIDE), (20.0, 22.0, INSIDE)))
    mission = _mission("inertial_targets", second={"ra_dec_deg": [90.0, 45.0]})
    zone = _earth(mission, truth)
    assert zone.judged[T >= 10.0].all() and not zone.judged[T < 10.0].any()
    assert not _row(_summary(tmp_path, mission, truth), "keep-out margin earth")["pass"]


@pytest.mark.parametrize("shape", sorted(EARTH_ZONES))
def test_a_zone_never_armed_is_not_judged(tmp_path: Path, shape: str) -> None:
    truth = _truth(np.full(len(T), INSIDE))  # inside throughout: never armed, even on the star fields
    mission = _mission("inertial_targets", shape)
    summary = _summary(tmp_path, mission, truth)
    row = _row(summary, "keep-out margin earth")
    assert row.get("judged") is False and row["value"] == "never armed"
    assert summary["zones"]["earth"]["min_margin_deg"] is None
    assert summary["exposure"]["inside_s"] == 0.0
    assert _row(summary, "keep-out margin sun")["pass"]
    metrics, _ = fast.judge(mission, truth, [], 0.0)
    assert math.isnan(metrics["margin_earth_deg"])
    assert metrics["min_margin_deg"] == metrics["margin_sun_deg"] == pytest.approx(50.0, abs=1e-6)
    assert metrics["instrument_exposure_s"] == 0.0


def test_the_margins_plot_draws_a_zone_never_armed(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    from hil_sim.sil.plots import write_plots

    truth = _truth(np.full(len(T), INSIDE))
    mission = _mission("inertial_targets")
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    np.savez(run_dir / "truth.npz", **truth)
    (run_dir / "simulator.json").write_text(json.dumps({"wall_s": 1.0, "sim_s": DURATION, "clock": "lockstep"}))
    assert (run_dir / "margins.png") in write_plots(run_dir, mission)


CASES = {
    "earth targets": EO_DAY,
    "dip": _angles((0.0, 10.0, INSIDE), *DIP, (20.0, 30.0, INSIDE)),
    # clear of the zone on the city and at nadir too, closer there than on the star fields (along one axis
    # of an ellipse there, the other on the star fields): those samples must not stop the fast judge's search
    "near at nadir": (_angles((0.0, 10.0, 34.0), (20.0, 30.0, 34.0)),
                      np.where((T < 10.0) | ((T >= 20.0) & (T < 30.0)), 0.0, 90.0)),
    "late exit": _angles((0.0, 13.0, INSIDE), (20.0, 36.0, INSIDE), (36.0, 37.0, 29.0)),
    # out of the zone at 3 deg/s from each star field's command: 20 deg at 13.5 s, 30 deg at 16.5 s
    "slow exit": np.where((T >= 10.0) & (T < 20.0), np.minimum(INSIDE + 3.0 * (T - 10.0), OUTSIDE),
                          np.where(T >= 30.0, np.minimum(INSIDE + 3.0 * (T - 30.0), OUTSIDE), INSIDE)),
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("shape", sorted(EARTH_ZONES) + sorted(ELONGATED))
@pytest.mark.parametrize("armed", ["inertial_targets", "always"])
def test_fast_judge_agrees_with_the_sil_judge(tmp_path: Path, case: str, shape: str, armed: str) -> None:
    truth = _truth(*CASES[case]) if isinstance(CASES[case], tuple) else _truth(CASES[case])
    mission = _mission(armed, shape)
    full, lazy = _earth(mission, truth), _earth(mission, truth, minimum_only=True)
    assert np.array_equal(full.judged, lazy.judged) if armed != "always" else lazy.judged is None
    assert zone_minimum(full) == zone_minimum(lazy)  # bit-identical, sample included
    summary = _summary(tmp_path, mission, truth)
    metrics, _ = fast.judge(mission, truth, [], 0.0)
    for name in ("sun", "earth"):
        assert metrics[f"margin_{name}_deg"] == summary["zones"][name]["min_margin_deg"]
    assert metrics["min_margin_deg"] == min(z["min_margin_deg"] for z in summary["zones"].values())
    assert metrics["instrument_exposure_s"] == summary["exposure"]["exposure_s"]
    assert metrics["instrument_exposure_depth_deg"] == summary["exposure"]["depth_deg"]


@pytest.mark.parametrize("shape", sorted(EARTH_ZONES))
def test_a_boresight_heading_into_the_zone_is_not_armed_until_it_can_stop(tmp_path: Path, shape: str) -> None:
    """On the first star field the boresight is still heading into the zone at 4 deg/s: 4 deg out at 10 s,
    2 deg inside at 11.5 s, out again and receding from 12 s. The flight software arms the zone only where
    it can stop short of it (`PointingGuidance.armable`): the judge with it, from 13.5 s (5 deg out)."""
    approach = [(9.0 + 0.5 * k, 9.5 + 0.5 * k, angle)
                for k, angle in enumerate([38.0, 36.0, 34.0, 32.0, 30.0, 28.0, 29.0, 31.0, 32.5, 35.0])]
    truth = _truth(_angles((0.0, 9.0, INSIDE), *approach, (20.0, 30.0, INSIDE)))
    armed_from = ((T >= 13.5) & (T < 20.0)) | (T >= 30.0)
    for minimum_only in (False, True):  # the fast judge's lazy series arms at the same sample
        assert np.array_equal(_earth(_mission("inertial_targets", shape), truth, minimum_only).judged, armed_from)
    assert _row(_summary(tmp_path, _mission("inertial_targets", shape), truth), "keep-out margin earth")["pass"]
    # the same path with the zone armed from the start of the field: inside at 11.5 s
    row = _row(_summary(tmp_path, _mission("always", shape), truth), "keep-out margin earth")
    assert not row["pass"] and row["value"] == pytest.approx(-20.0, abs=1e-6)  # the city, inside its disc
