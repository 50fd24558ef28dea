"""FswConfig: defaults, units/ranges, clear errors naming the key, the flight software's own file, schema."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from fsw.config import FswConfig, FswConfigError, load_fsw_run_config, parse_fsw_config


def test_defaults_are_complete_and_consistent() -> None:
    cfg = FswConfig()
    assert cfg.gnc_period_s == pytest.approx(0.1)
    axes = np.array([w.axis_B for w in cfg.spacecraft.wheels])
    np.testing.assert_allclose(np.linalg.norm(axes, axis=1), 1.0)
    assert np.linalg.matrix_rank(axes) == 3
    assert cfg.epoch_utc.tzinfo is not None


def test_every_schema_property_is_documented_with_a_default_where_optional() -> None:
    schema = FswConfig.model_json_schema()
    json.dumps(schema)  # serialisable for editors
    missing = []
    for name, definition in schema["$defs"].items():
        for key, prop in definition.get("properties", {}).items():
            if "description" not in prop and key not in ("shape", "enabled", "inclination_deg", "raan_deg", "telemetry_port", "name"):
                missing.append(f"{name}.{key}")
    assert not missing, f"undocumented config keys: {missing}"


@pytest.mark.parametrize(
    ("data", "key", "fragment"),
    [
        ({"rates": {"gnc_rate_hz": 100}}, "rates.gnc_rate_hz", "less than or equal to 50"),
        ({"rates": {"gnc_rate_hz": 10, "housekeeping_rate_hz": 3}}, "rates", "must divide"),
        ({"spacecraft": {"inertia_B_kgm2": [[1, 2, 0], [0, 1, 0], [0, 0, 1]]}}, "spacecraft.inertia_B_kgm2", "symmetric"),
        ({"spacecraft": {"inertia_B_kgm2": [[1, 0, 0], [0, -1, 0], [0, 0, 1]]}}, "spacecraft.inertia_B_kgm2", "positive definite"),
        ({"spacecraft": {"wheels": [{"axis_B": [1, 0, 0]}, {"axis_B": [0, 1, 0]}, {"axis_B": [1, 1, 0]}]}}, "spacecraft", "span"),
        ({"pointing": {"boresight_B": [0, 0, 1], "roll_axis_B": [0, 0, 2]}}, "pointing", "parallel"),
        ({"law": {"margin_deg": -1}}, "law.margin_deg", "greater than or equal to 0"),
        ({"unknown_key": 1}, "unknown_key", "Extra inputs are not permitted"),
        ({"pointing": {"zones": [{"name": "s", "body": "inertial", "geometry": {"shape": "cone", "half_angle_deg": 5}}]}}, "pointing.zones.0", "direction_N"),
        ({"pointing": {"zones": [{"name": "s", "body": "sun", "geometry": {"shape": "hexagon"}}]}}, "pointing.zones.0.geometry", "does not match any of the expected tags"),
        ({"quaternion": {"law": "gradient", "zones": [{"shape": "superellipsoid", "name": "a", "center_q": [1, 0, 0, 0], "semi_axes": [1, 1, 1]}]}}, "quaternion", "cone"),
    ],
)
def test_bad_values_name_the_key(data: dict, key: str, fragment: str) -> None:
    with pytest.raises(FswConfigError) as err:
        parse_fsw_config(data, source="mission.yaml", prefix="flight_software.")
    text = str(err.value)
    assert "mission.yaml" in text and f"flight_software.{key}" in text and fragment in text


def test_vectors_and_quaternions_are_normalised() -> None:
    cfg = parse_fsw_config({"pointing": {"boresight_B": [0, 0, 2], "target_N": [3, 4, 0]},
                            "quaternion": {"target_q_NB": [2, 0, 0, 0]}})
    assert cfg.pointing.target_N == pytest.approx([0.6, 0.8, 0.0])
    assert cfg.quaternion.target_q_NB == pytest.approx([1, 0, 0, 0])


def test_reads_its_own_file_as_written(tmp_path) -> None:
    """The flight software's file: its section and its bus, nothing filled in from anywhere else."""
    path = tmp_path / "fsw.yaml"
    path.write_text(yaml.safe_dump({"bus": {"spec": "virtual:x", "bitrate_bps": 250000, "authentication": True},
                                    "flight_software": {"initial_mode": "POINTING", "law": {"margin_deg": 4.5}}}))
    run = load_fsw_run_config(path)
    assert run.flight_software.initial_mode == "POINTING" and run.flight_software.law.margin_deg == 4.5
    assert run.flight_software.spacecraft == FswConfig().spacecraft  # no truth to take knowledge from
    assert (run.bus.spec, run.bus.bitrate_bps, run.bus.authentication) == ("virtual:x", 250000, True)
    path.write_text(yaml.safe_dump({"flight_software": {}}))
    assert load_fsw_run_config(path).bus.spec == "auto"


def test_a_mission_file_is_refused_with_the_command_that_resolves_it(tmp_path) -> None:
    """The truth's keys never reach the flight software: a mission given as its file is refused, by key."""
    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump({"name": "demo", "orbit": {"semi_major_axis_km": 6900.0},
                                    "flight_software": {"initial_mode": "POINTING"}}))
    with pytest.raises(FswConfigError) as err:
        load_fsw_run_config(path)
    text = str(err.value)
    assert "mission.yaml" in text and "  name: Extra inputs are not permitted" in text and "  orbit:" in text
    assert "keepout fsw MISSION" in text
    bare = tmp_path / "bare.yaml"
    bare.write_text(yaml.safe_dump({"initial_mode": "POINTING"}))
    with pytest.raises(FswConfigError, match="flight_software: Field required"):
        load_fsw_run_config(bare)


def test_load_errors_name_the_file(tmp_path) -> None:
    with pytest.raises(FswConfigError, match="cannot read"):
        load_fsw_run_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("flight_software: [1, 2")
    with pytest.raises(FswConfigError, match="bad.yaml: not valid YAML"):
        load_fsw_run_config(bad)
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(yaml.safe_dump({"flight_software": {"rates": {"gnc_rate_hz": 0}}}))
    with pytest.raises(FswConfigError, match=r"wrong.yaml: .*\n  flight_software\.rates\.gnc_rate_hz: Input should be"):
        load_fsw_run_config(wrong)
    wrong.write_text(yaml.safe_dump({"bus": {"bitrate_bps": 5}, "flight_software": {}}))
    with pytest.raises(FswConfigError, match=r"bus\.bitrate_bps: Input should be greater than or equal to 10000"):
        load_fsw_run_config(wrong)


def test_zone_shapes_round_trip() -> None:
    data = {"pointing": {"zones": [
        {"name": "sun", "body": "sun", "geometry": {"shape": "superellipse", "semi_axes_deg": [30, 15], "exponent": 0.7, "orientation_deg": 10}},
        {"name": "moon", "body": "moon", "geometry": {"shape": "cone", "half_angle_deg": 12}},
        {"name": "earth", "body": "earth", "geometry": {"shape": "polygon", "vertices_deg": [[10, 0], [0, 10], [-10, 0], [0, -10]]}},
    ]}}
    cfg = parse_fsw_config(data)
    again = FswConfig.model_validate(json.loads(cfg.model_dump_json()))
    assert again == cfg
    assert math.isclose(again.pointing.zones[0].geometry.exponent, 0.7)
