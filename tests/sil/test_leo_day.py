"""config/missions/leo-day.yaml is what its header says: a day of Earth observation from a Sun-synchronous
orbit that enters the Earth's shadow on every orbit (not dawn-dusk), at least 40 targets of every kind
placed where the spacecraft sees them, every environment torque on and the wheels unloaded by the rods;
and its first day-side pass flies clean in fast mode."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hil_sim.mission.model import Mission, SetTargetCommand, load_mission

ROOT = Path(__file__).resolve().parents[2]
LEO_DAY = ROOT / "config" / "missions" / "leo-day.yaml"
MU_KM3_S2 = 398600.4418


@pytest.fixture(scope="module")
def mission() -> Mission:
    return load_mission(LEO_DAY)


def _targets(mission: Mission) -> dict[str, int]:
    kinds = {"ground": 0, "nadir": 0, "inertial": 0}
    for entry in mission.timeline:
        if isinstance(entry, SetTargetCommand):
            kinds["ground" if entry.ground is not None else "nadir" if entry.nadir else "inertial"] += 1
    return kinds


def test_a_day_of_at_least_forty_targets_of_every_kind(mission):
    kinds = _targets(mission)
    assert mission.duration_s == 86400.0
    assert sum(kinds.values()) >= 40
    assert kinds["ground"] >= 20 and kinds["nadir"] >= 1 and kinds["inertial"] >= 1, kinds
    assert mission.timeline[-1].t_s < mission.duration_s - 600.0  # the last target has time to settle


def test_sun_synchronous_at_550_km_with_a_shadow_on_every_orbit(mission):
    """The truth orbit and the truth eclipse model (conical umbra and penumbra) over the whole day."""
    from gnc.ephemeris import EARTH_RADIUS_KM, julian_date_tdb
    from hil_sim.mission.model import world_params
    from hil_sim.world.eclipse import eclipse_spans
    from hil_sim.world.ephemeris import TruthEphemeris
    from hil_sim.world.orbit import KeplerOrbit

    orbit = KeplerOrbit(world_params(mission).orbit)
    a = mission.orbit.semi_major_axis_km
    assert abs(a - EARTH_RADIUS_KM - 550.0) < 1.0
    # Sun-synchronous: J2 turns the node 360 deg a year (0.9856 deg/day)
    j2, n = 1.08263e-3, math.sqrt(MU_KM3_S2 / a**3)
    node_rate_deg_day = math.degrees(-1.5 * n * j2 * (EARTH_RADIUS_KM / a) ** 2
                                     * math.cos(math.radians(mission.orbit.inclination_deg))) * 86400.0
    assert node_rate_deg_day == pytest.approx(0.9856, abs=0.005)
    t = np.arange(0.0, mission.duration_s, 10.0)
    sun_km, _ = TruthEphemeris(julian_date_tdb(mission.epoch_utc)).positions_N_km(t)
    spans = eclipse_spans(t, orbit.position_N_km(t), sun_km / np.linalg.norm(sun_km, axis=1)[:, None])
    full_orbits = int(mission.duration_s // orbit.period_s)
    assert full_orbits >= 15
    for k in range(full_orbits):  # a shadow begins or lasts in every whole orbit of the day
        t0, t1 = k * orbit.period_s, (k + 1) * orbit.period_s
        assert any(s < t1 and e > t0 for s, e, _ in spans), f"no shadow in orbit {k}"
    umbra = [e - s for s, e, least in spans if least == 0.0 and s > 0.0 and e < t[-1]]
    assert min(umbra) > 1500.0  # ~35 min behind the Earth: far from a dawn-dusk orbit's grazing


def test_every_environment_torque_on_and_the_rods_unload_the_wheels(mission):
    d = mission.spacecraft.disturbance
    assert d.gravity_gradient and d.solar_radiation_pressure and d.aerodynamic_drag
    assert np.linalg.norm(d.residual_dipole_B_Am2) > 0.0
    assert len(mission.spacecraft.facets) >= 6
    assert mission.spacecraft.magnetometer is not None and mission.spacecraft.magnetorquers is not None
    fsw = mission.flight_software
    assert fsw.momentum_management.enabled
    assert fsw.magnetic_devices.magnetometer and fsw.magnetic_devices.magnetorquers
    assert mission.requirements.max_wheel_speed_fraction <= 0.9
    # Sun, Moon and Earth zones; the Earth's kept on the dark fields only (its ground targets lie inside it)
    assert {z.body: z.armed for z in fsw.pointing.zones} == {"sun": "always", "moon": "always",
                                                             "earth": "inertial_targets"}
    assert next(z for z in fsw.pointing.zones if z.body == "earth").atmosphere_height_km > 0.0


def test_the_mission_check_sees_every_ground_target_in_its_dwell(mission):
    from hil_sim.mission.physics_checks import check_mission

    report = check_mission(mission, quick=True)
    assert not [f for f in report.findings if f.level == "error"], report
    windows = [f for f in report.findings if f.check == "visibility" and f.level == "info"]
    assert len(windows) == _targets(mission)["ground"]


@pytest.mark.slow
def test_the_first_day_side_pass_flies_clean_in_fast_mode(mission):
    """Nadir strip, four ground targets, nadir through sunset and the first dark field (about 0.9 orbit),
    judged on truth: the Earth zone armed on the field and kept out."""
    from hil_sim.campaign.fast import run_fast

    night = next(e.t_s for e in mission.timeline if isinstance(e, SetTargetCommand) and e.ra_dec_deg is not None)
    duration = night + 300.0
    short = mission.model_copy(update={"duration_s": duration,
                                       "timeline": [e for e in mission.timeline if e.t_s <= night]})
    kinds = _targets(short)
    assert kinds["ground"] >= 4 and kinds["nadir"] >= 2 and kinds["inertial"] == 1
    m = run_fast(short, 1).metrics
    assert m["min_margin_deg"] > 0.0
    assert m["margin_earth_deg"] > 0.0  # finite: armed and judged on the field
    assert m["settling_time_s"] <= 330.0  # every target reached within its dwell
    assert m["final_error_deg"] < short.requirements.max_final_pointing_error_deg
    assert m["peak_wheel_speed_fraction"] < short.requirements.max_wheel_speed_fraction
    assert m["peak_body_rate_fraction"] <= short.requirements.max_body_rate_fraction
    assert m["unexpected_fdir_events"] == 0 and m["cycle_slips"] == 0 and m["rejected_commands"] == 0


def test_its_campaign_disperses_the_surfaces_the_dipole_and_the_day_flown(mission):
    """config/campaigns/leo-day.yaml: each dispersed truth value reaches the mission the run flies; the flight
    software keeps the nominal inertia, but flies the dispersed epoch (the day itself moved)."""
    from datetime import timedelta

    from hil_sim.campaign.runner import build_plan

    plan, _ = build_plan(ROOT / "config" / "campaigns" / "leo-day.yaml")
    runs = [plan.mission(plan.draw(i), 0)[1] for i in range(plan.campaign.runs)]
    nominal = mission.spacecraft
    for m in runs:
        panel = m.spacecraft.facets[6].area_m2
        assert panel == m.spacecraft.facets[7].area_m2 != nominal.facets[6].area_m2  # both sides of one panel
        assert 0.9 * nominal.facets[6].area_m2 <= panel <= 1.1 * nominal.facets[6].area_m2
        assert m.spacecraft.disturbance.residual_dipole_B_Am2 != nominal.disturbance.residual_dipole_B_Am2
        assert m.spacecraft.disturbance.atmosphere_density_kg_m3 != nominal.disturbance.atmosphere_density_kg_m3
        assert m.flight_software.epoch_utc == m.epoch_utc != mission.epoch_utc
        assert abs(m.epoch_utc - mission.epoch_utc) <= timedelta(minutes=5)
        assert m.spacecraft.inertia_B_kgm2 != nominal.inertia_B_kgm2
        assert m.flight_software.spacecraft.inertia_B_kgm2 == mission.flight_software.spacecraft.inertia_B_kgm2
    failed = sum(1 for m in runs if m.faults)
    assert 0 < failed < len(runs)  # some days lose a wheel, some do not
