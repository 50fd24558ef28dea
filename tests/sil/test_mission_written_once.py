"""A mission in one place: each fact written once, the initial attitude as RA/Dec + roll.

The flight software's knowledge defaults to the truth the file gives (epoch, inertia, wheels, star-tracker
mounting, boresight, orbit), with one set of key names; knowledge is fixed from the values written in the
file, so a campaign dispersion of the truth never reaches the flight software. Expected values are read
from the YAML text with PyYAML, not from the loader.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import attitude_from_ra_dec, load_mission, ra_dec_to_unit

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "config" / "missions" / "smallsat-example.yaml"
DEMO = ROOT / "config" / "missions" / "demo-pointing.yaml"


def test_the_example_writes_no_fact_twice():
    raw = yaml.safe_load(EXAMPLE.read_text())
    fsw = raw["flight_software"]
    assert "epoch_utc" not in fsw and "orbit" not in fsw and "spacecraft" not in fsw
    assert "boresight_B" not in fsw["pointing"] and "q_NB" not in raw["initial_state"]


def test_knowledge_defaults_to_the_truth_written_in_the_file():
    raw = yaml.safe_load(EXAMPLE.read_text())
    mission = load_mission(EXAMPLE)
    fsw, sc = mission.flight_software, raw["spacecraft"]
    assert fsw.epoch_utc == mission.epoch_utc
    assert fsw.spacecraft.inertia_B_kgm2 == sc["inertia_B_kgm2"]
    assert len(fsw.spacecraft.wheels) == len(sc["wheels"]) == 4
    for known, truth in zip(fsw.spacecraft.wheels, sc["wheels"]):
        assert known.spin_inertia_kgm2 == truth["spin_inertia_kgm2"]  # one key name for both
        assert known.max_torque_Nm == truth["max_torque_Nm"] and known.max_speed_rad_s == truth["max_speed_rad_s"]
        assert np.allclose(known.axis_B, np.asarray(truth["axis_B"]) / np.linalg.norm(truth["axis_B"]))
    assert np.allclose(fsw.spacecraft.star_tracker_q_BS, np.asarray(sc["star_tracker"]["q_BS"]) /
                       np.linalg.norm(sc["star_tracker"]["q_BS"]))
    assert fsw.pointing.boresight_B == sc["instrument_boresight_B"]
    assert fsw.orbit.radius_km == raw["orbit"]["semi_major_axis_km"]
    assert fsw.orbit.inclination_deg == raw["orbit"]["inclination_deg"]
    assert fsw.orbit.raan_deg == raw["orbit"]["raan_deg"]


def test_a_value_given_for_the_flight_software_is_kept():
    data = yaml.safe_load(EXAMPLE.read_text())
    data["flight_software"]["spacecraft"] = {"inertia_B_kgm2": [[0.3, 0, 0], [0, 0.3, 0], [0, 0, 0.2]]}
    data["flight_software"]["orbit"] = {"radius_km": 6930.0}
    mission = load_mission("m.yaml", text=yaml.safe_dump(data))
    assert mission.flight_software.spacecraft.inertia_B_kgm2 == [[0.3, 0, 0], [0, 0.3, 0], [0, 0, 0.2]]
    assert mission.spacecraft.inertia_B_kgm2 == data["spacecraft"]["inertia_B_kgm2"]
    assert mission.flight_software.orbit.radius_km == 6930.0
    assert mission.flight_software.orbit.inclination_deg == 97.6  # the keys not given still come from the truth
    assert len(mission.flight_software.spacecraft.wheels) == 4


def test_campaign_dispersions_change_the_truth_alone(tmp_path):
    from hil_sim.campaign.runner import build_plan

    (tmp_path / "mission.yaml").write_text(EXAMPLE.read_text())
    (tmp_path / "campaign.yaml").write_text("""\
schema_version: 1
name: knowledge
base_mission: mission.yaml
runs: 3
master_seed: 7
dispersions:
  - {name: inertia, path: spacecraft.inertia_B_kgm2, kind: inertia,
     scale: {dist: uniform, low: 1.2, high: 1.3}, misalignment_sigma_deg: 2.0}
  - {name: bias, path: spacecraft.imu.bias_B_rad_s, kind: vector, distribution: {dist: normal, sigma: 1.0e-4}, apply: add}
  - {name: tracker, path: spacecraft.star_tracker.q_BS, kind: attitude, max_angle_deg: 1.0}
  - {name: orbit, path: orbit.semi_major_axis_km, kind: scalar, distribution: {dist: uniform, low: 6900, high: 7000}}
  - {name: wheel_torque, path: "spacecraft.wheels[0].max_torque_Nm", kind: scalar,
     distribution: {dist: uniform, low: 0.5, high: 0.8}, apply: multiply}
criteria:
  - {name: keep_out, metric: min_margin_deg, op: ">", limit: 0.0}
""")
    plan, _ = build_plan(tmp_path / "campaign.yaml")
    written = yaml.safe_load(EXAMPLE.read_text())
    for run in range(3):
        _, mission = plan.mission(plan.draw(run), run)
        truth, known = mission.spacecraft, mission.flight_software
        # the truth moved ...
        assert not np.allclose(truth.inertia_B_kgm2, written["spacecraft"]["inertia_B_kgm2"])
        assert mission.orbit.semi_major_axis_km != written["orbit"]["semi_major_axis_km"]
        assert truth.wheels[0].max_torque_Nm < written["spacecraft"]["wheels"][0]["max_torque_Nm"]
        # ... the flight software still knows the values written in the file
        assert known.spacecraft.inertia_B_kgm2 == written["spacecraft"]["inertia_B_kgm2"]
        assert known.orbit.radius_km == written["orbit"]["semi_major_axis_km"]
        assert known.spacecraft.wheels[0].max_torque_Nm == written["spacecraft"]["wheels"][0]["max_torque_Nm"]
        assert np.allclose(known.spacecraft.star_tracker_q_BS, np.asarray(written["spacecraft"]["star_tracker"]["q_BS"])
                           / np.linalg.norm(written["spacecraft"]["star_tracker"]["q_BS"]))


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).apply(v)


def test_initial_attitude_as_ra_dec_and_roll_matches_the_demo_quaternion():
    """The demo writes q_NB for 'boresight (body z) on RA 330, Dec -10, body x towards north'."""
    demo = yaml.safe_load(DEMO.read_text())
    q = attitude_from_ra_dec(330.0, -10.0, 0.0, np.array([0.0, 0.0, 1.0]))
    q_demo = np.asarray(demo["initial_state"]["q_NB"])
    assert min(np.linalg.norm(q - q_demo), np.linalg.norm(q + q_demo)) < 1e-5


@pytest.mark.parametrize("ra, dec, roll", [(10.0, 20.0, 0.0), (200.0, -45.0, 90.0), (33.0, 90.0, 30.0)])
def test_ra_dec_roll_points_the_boresight_and_rolls_about_it(ra, dec, roll):
    b_B = np.array([0.0, 0.6, 0.8])
    q = attitude_from_ra_dec(ra, dec, roll, b_B)
    y = ra_dec_to_unit(ra, dec)
    assert np.allclose(_rotate(q, b_B), y, atol=1e-9)
    x0 = _rotate(attitude_from_ra_dec(ra, dec, 0.0, b_B), np.array([1.0, 0.0, 0.0]))
    x1 = _rotate(q, np.array([1.0, 0.0, 0.0]))
    # the rolled body x is the unrolled one turned by roll about the boresight (right-handed)
    turned = math.degrees(math.atan2(float(np.cross(x0, x1) @ y), float(x0 @ x1)))
    assert turned == pytest.approx((roll + 180.0) % 360.0 - 180.0, abs=1e-6)


def test_initial_state_ra_dec_in_a_mission_and_its_errors(tmp_path):
    data = yaml.safe_load(DEMO.read_text())
    del data["initial_state"]["q_NB"]
    data["initial_state"]["ra_dec_deg"] = [330.0, -10.0]
    mission = load_mission("m.yaml", text=yaml.safe_dump(data))
    q_demo = np.asarray(yaml.safe_load(DEMO.read_text())["initial_state"]["q_NB"])
    assert min(np.linalg.norm(mission.initial_state.q_NB - q_demo), np.linalg.norm(mission.initial_state.q_NB + q_demo)) < 1e-5
    data["initial_state"]["q_NB"] = q_demo.tolist()
    from hil_sim.mission.loader import ConfigError
    with pytest.raises(ConfigError, match="initial_state: give the initial attitude once"):
        load_mission("m.yaml", text=yaml.safe_dump(data))
    del data["initial_state"]["q_NB"]
    data["initial_state"]["ra_dec_deg"] = [330.0, -100.0]
    with pytest.raises(ConfigError, match=r"initial_state\.ra_dec_deg\[1\]: Input should be greater than or equal to -90"):
        load_mission("m.yaml", text=yaml.safe_dump(data))


def test_the_example_passes_config_check():
    from hil_sim.mission.physics_checks import check_mission

    report = check_mission(load_mission(EXAMPLE), step_s=60.0)
    assert report.ok, report.format()


def test_the_flight_software_alone_is_given_the_same_knowledge(tmp_path):
    """`keepout fsw MISSION` resolves the mission with the same reader and hands the flight software its
    configuration: the same facts, and a file of it (as the SIL writes) reads back to them."""
    from fsw.config import load_fsw_run_config
    from hil_sim.mission.flight import bus_config, load_flight_config, write_flight_config

    resolved = load_flight_config(EXAMPLE)
    mission = load_mission(EXAMPLE)
    assert resolved.flight_software.model_dump() == mission.flight_software.model_dump()
    raw = yaml.safe_load(EXAMPLE.read_text())
    assert resolved.flight_software.spacecraft.inertia_B_kgm2 == raw["spacecraft"]["inertia_B_kgm2"]
    assert np.allclose(resolved.flight_software.pointing.target_N, ra_dec_to_unit(*raw["initial_state"]["ra_dec_deg"]))
    assert (resolved.bus.spec, resolved.bus.bitrate_bps, resolved.bus.authentication) == (
        raw.get("bus", "auto"), raw.get("bus_bitrate_bps", 500000), raw.get("bus_authentication", False))
    write_flight_config(tmp_path / "fsw.yaml", bus_config(mission, "virtual:k"),
                        mission.flight_software.model_dump(mode="json"))
    written = yaml.safe_load((tmp_path / "fsw.yaml").read_text())
    assert set(written) == {"bus", "flight_software"} and written["bus"]["spec"] == "virtual:k"
    again = load_fsw_run_config(tmp_path / "fsw.yaml")
    assert _to_last_bit_but_one(again.flight_software.model_dump()) == _to_last_bit_but_one(
        mission.flight_software.model_dump())


def _to_last_bit_but_one(value):
    """``value`` with every float to 15 significant digits: a unit vector read back is normalised again, and
    since numpy 2.4 its norm can move the last bit of an already normalised one (0.5773502691896258 read back
    as 0.5773502691896257)."""
    if isinstance(value, dict):
        return {k: _to_last_bit_but_one(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_last_bit_but_one(v) for v in value]
    return float(f"{value:.15g}") if isinstance(value, float) else value


def test_every_knowledge_source_is_what_knowledge_from_truth_copies() -> None:
    """KNOWLEDGE_SOURCES (the validator's and the docs' table) and knowledge_from_truth (what fills the
    knowledge in) name the same keys: each plain copy in the table is filled from its truth key, and nothing
    the function fills is missing from the table."""
    import copy

    from hil_sim.mission.knowledge import KNOWLEDGE_SOURCES, knowledge_from_truth

    data = yaml.safe_load((ROOT / "config" / "missions" / "demo-pointing-door.yaml").read_text())
    # the rods' and the coarse sensors' knowledge is filled only when their law is configured
    data["flight_software"] = {"detumble": {}, "coarse_attitude": {"field_sigma_deg": 3.0}}
    data["spacecraft"]["sun_sensors"] = {"normals_B": [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                         "full_scale_mA": 2.0, "field_of_view_half_angle_deg": 90.0}
    data["spacecraft"].setdefault("disturbance", {})["magnetic_field"] = {"model": "igrf", "degree": 4}
    data["initial_state"] = {"ra_dec_deg": [10.0, 20.0]}
    data["spacecraft"].setdefault("imu", {})["saturation_rad_s"] = 0.3
    data["spacecraft"].setdefault("star_tracker", {})["max_rate_deg_s"] = 1.7
    data["spacecraft"]["magnetometer"] = {"q_BS": [0.0, 1.0, 0.0, 0.0]}
    data["spacecraft"]["magnetorquers"] = {"axes_B": [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
                                           "max_dipole_Am2": [1.0, 2.0, 3.0]}
    filled = knowledge_from_truth(copy.deepcopy(data))
    coarse = filled["flight_software"]["coarse_attitude"]
    assert coarse["field_degree"] == 4 and len(coarse["geomagnetic_gauss_T"]) == 4 * 7 // 2  # the truth's degree

    def get(node, path):
        for part in path:
            node = node[part]
        return node

    def leaves(node, path=()):
        if isinstance(node, dict) and node:
            for key, value in node.items():
                yield from leaves(value, path + (key,))
        else:
            yield path

    for known, truth in KNOWLEDGE_SOURCES.items():
        value = get(filled, known)  # filled in (a KeyError names a table entry the function does not fill)
        if known[-1] not in ("wheels", "target_N", "arg_latitude_at_epoch_deg", "field_degree",
                             "geomagnetic_gauss_T"):  # the derived ones
            assert value == get(data, truth), known
    for path in leaves(filled["flight_software"], ("flight_software",)):
        if path[:2] == ("flight_software", "magnetic_devices"):
            continue  # flags for the devices fitted (their descriptions say so), not copies of a truth key
        if path == ("flight_software", "coarse_attitude", "field_sigma_deg"):
            continue  # written in the mission above, not filled
        assert any(path[:len(k)] == k for k in KNOWLEDGE_SOURCES), f"{path} is filled but not in KNOWLEDGE_SOURCES"
