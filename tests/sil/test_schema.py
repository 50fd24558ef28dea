"""The committed editor schema equals the generated one, is draft-07, and accepts every YAML in config/.

Validation uses the independent `jsonschema` implementation (Draft7Validator), so a schema that only
pydantic understands would fail here.
"""
from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from hil_sim.mission.model import SCHEMA_PATH, mission_json_schema

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = sorted((ROOT / "config" / "missions").glob("*.yaml"))
MODELINE = "# yaml-language-server: $schema=../schema/mission.schema.json"
# keywords that appeared after draft-07: a yaml-language-server on draft-07 would ignore them silently
NEWER_KEYWORDS = {"$defs", "prefixItems", "unevaluatedProperties", "unevaluatedItems", "dependentRequired",
                  "dependentSchemas", "$anchor", "$dynamicRef", "$recursiveRef", "minContains", "maxContains"}


def _keywords(node, found: set[str]) -> set[str]:
    if isinstance(node, dict):
        for key, value in node.items():
            found.add(key)
            if key not in ("properties", "definitions"):
                _keywords(value, found)
            else:
                for sub in value.values():
                    _keywords(sub, found)
    elif isinstance(node, list):
        for item in node:
            _keywords(item, found)
    return found


def _as_yaml_1_2(node):
    """yaml-language-server reads YAML 1.2 (timestamps are strings); PyYAML 1.1 makes datetimes."""
    if isinstance(node, dict):
        return {k: _as_yaml_1_2(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_as_yaml_1_2(v) for v in node]
    if isinstance(node, (dt.datetime, dt.date)):
        return node.isoformat().replace("+00:00", "Z")
    return node


def test_committed_schema_equals_generated():
    committed = json.loads(SCHEMA_PATH.read_text())
    assert committed == mission_json_schema(), "run `keepout config schema` and commit the result"


def test_schema_is_draft07_only():
    schema = mission_json_schema()
    assert schema["$schema"] == "http://json-schema.org/draft-07/schema#"
    jsonschema.Draft7Validator.check_schema(schema)
    used = _keywords(schema, set())
    assert not (used & NEWER_KEYWORDS), f"post-draft-07 keywords: {used & NEWER_KEYWORDS}"
    refs = json.dumps(schema)
    assert '"#/$defs/' not in refs


def test_schema_has_descriptions_and_defaults_from_the_models():
    schema = mission_json_schema()
    imu = schema["definitions"]["ImuTruth"]["properties"]["rate_hz"]
    assert imu["default"] == 100.0 and "[Hz]" in imu["description"]
    fsw = schema["definitions"]["FswConfig"]
    assert "law" in fsw["properties"]


def test_there_are_missions():
    names = {p.name for p in MISSIONS}
    assert {"demo-pointing.yaml", "demo-quaternion.yaml", "paper-s3-cones.yaml", "paper-s3-star.yaml",
            "fault-imu-dropout.yaml"} <= names


@pytest.mark.parametrize("path", MISSIONS, ids=lambda p: p.name)
def test_every_mission_has_the_modeline_and_validates(path):
    text = path.read_text()
    assert text.splitlines()[0] == MODELINE
    data = _as_yaml_1_2(yaml.safe_load(text))
    validator = jsonschema.Draft7Validator(mission_json_schema())
    errors = sorted(validator.iter_errors(data), key=lambda e: list(e.path))
    assert not errors, "\n".join(f"{'.'.join(map(str, e.path))}: {e.message}" for e in errors)


def test_schema_rejects_what_the_models_reject():
    """The schema is not a rubber stamp: an unknown key and an out-of-range value are refused."""
    data = _as_yaml_1_2(yaml.safe_load((ROOT / "config" / "missions" / "demo-pointing.yaml").read_text()))
    validator = jsonschema.Draft7Validator(mission_json_schema())
    data["spacecraft"]["imu"]["rate_hzz"] = 3
    data["flight_software"]["law"]["k1"] = -1
    messages = [e.message for e in validator.iter_errors(data)]
    assert any("rate_hzz" in m for m in messages)
    assert any("-1" in m for m in messages)


def test_schema_cli_check_detects_drift(tmp_path, capsys):
    from cli.main import main

    stale = tmp_path / "schema.json"
    stale.write_text(json.dumps({"$schema": "http://json-schema.org/draft-07/schema#"}))
    assert main(["config", "schema", "--check", "--out", str(stale)]) == 1
    assert main(["config", "schema", "--out", str(stale)]) == 0
    assert main(["config", "schema", "--check", "--out", str(stale)]) == 0


def test_mission_reference_is_current_and_lists_every_key(tmp_path, capsys):
    """docs/missions.md is generated from the schema: it is up to date, and every key of
    every mapping in the schema appears in it with its unit, default and range."""
    from cli.main import main
    from hil_sim.mission.docs import DOCS_PATH, mission_docs

    assert DOCS_PATH.read_text() == mission_docs(), "run `keepout config docs` and commit the result"
    assert main(["config", "docs", "--check"]) == 0
    stale = tmp_path / "missions.md"
    stale.write_text(mission_docs().replace("| `duration_s` |", "| `duration` |"))
    assert main(["config", "docs", "--check", "--out", str(stale)]) == 1
    assert "out of date" in capsys.readouterr().err
    text = DOCS_PATH.read_text()
    schema = mission_json_schema()
    for name, definition in schema["definitions"].items():
        for key in definition.get("properties", {}):
            assert f"| `{key}` |" in text, f"{name}.{key} missing from docs/missions.md"
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| `")}
    assert "| s | *required* | (0, 864000] |" in rows["`duration_s`"]
    assert "| Hz | `100.0` | (0, 2000] |" in rows["`dynamics_rate_hz`"]
    assert "| from the file: spacecraft.inertia_B_kgm2 |" in text and "| from the file: epoch_utc |" in text
