"""FswConfig: defaults, units/ranges, clear errors naming the key, mission-file and bare loading, schema."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from fsw.config import ConfigError, FswConfig, load_fsw_config, parse_fsw_config


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
    with pytest.raises(ConfigError) as err:
        parse_fsw_config(data, source="mission.yaml", prefix="flight_software.")
    text = str(err.value)
    assert "mission.yaml" in text and f"flight_software.{key}" in text and fragment in text


def test_vectors_and_quaternions_are_normalised() -> None:
    cfg = parse_fsw_config({"pointing": {"boresight_B": [0, 0, 2], "target_N": [3, 4, 0]},
                            "quaternion": {"target_q_NB": [2, 0, 0, 0]}})
    assert cfg.pointing.target_N == pytest.approx([0.6, 0.8, 0.0])
    assert cfg.quaternion.target_q_NB == pytest.approx([1, 0, 0, 0])


def test_loads_mission_file_key_and_bare_file(tmp_path) -> None:
    body = {"initial_mode": "POINTING", "law": {"margin_deg": 4.5}}
    mission = tmp_path / "mission.yaml"
    mission.write_text(yaml.safe_dump({"name": "demo", "flight_software": body}))
    bare = tmp_path / "fsw.yaml"
    bare.write_text(yaml.safe_dump(body))
    for path in (mission, bare):
        cfg = load_fsw_config(path)
        assert cfg.initial_mode == "POINTING" and cfg.law.margin_deg == 4.5


def test_load_errors_name_the_file(tmp_path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_fsw_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("flight_software: [1, 2")
    with pytest.raises(ConfigError, match="bad.yaml: not valid YAML"):
        load_fsw_config(bad)
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(yaml.safe_dump({"flight_software": {"rates": {"gnc_rate_hz": 0}}}))
    with pytest.raises(ConfigError, match=r"flight_software\.rates\.gnc_rate_hz"):
        load_fsw_config(wrong)


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


def test_every_knowledge_source_is_what_knowledge_from_truth_copies() -> None:
    """KNOWLEDGE_SOURCES (the validator's and the docs' table) and knowledge_from_truth (what fills the
    knowledge in) name the same keys: each plain copy in the table is filled from its truth key, and nothing
    the function fills is missing from the table."""
    import copy

    import yaml

    from fsw.config import KNOWLEDGE_SOURCES, knowledge_from_truth

    data = yaml.safe_load((Path(__file__).resolve().parents[2] / "config" / "missions" / "demo-pointing-door.yaml").read_text())
    data["flight_software"] = {}
    data["initial_state"] = {"ra_dec_deg": [10.0, 20.0]}
    data["spacecraft"].setdefault("imu", {})["saturation_rad_s"] = 0.3
    data["spacecraft"].setdefault("star_tracker", {})["max_rate_deg_s"] = 1.7
    filled = knowledge_from_truth(copy.deepcopy(data))

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
        if known[-1] not in ("wheels", "target_N", "arg_latitude_at_epoch_deg"):  # the three derived ones
            assert value == get(data, truth), known
    for path in leaves(filled["flight_software"], ("flight_software",)):
        assert any(path[:len(k)] == k for k in KNOWLEDGE_SOURCES), f"{path} is filled but not in KNOWLEDGE_SOURCES"
