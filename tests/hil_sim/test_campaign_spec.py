"""Campaign files: schema round trip, every shipped campaign loads and builds, errors name file:line:col."""
from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from hil_sim.campaign.runner import build_plan
from hil_sim.campaign.spec import SCHEMA_PATH, campaign_json_schema, load_campaign
from hil_sim.mission.loader import ConfigError

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGNS = sorted((ROOT / "config" / "campaigns").glob("*.yaml"))


def test_committed_schema_is_the_generated_one():
    assert json.loads(SCHEMA_PATH.read_text()) == campaign_json_schema(), \
        "regenerate: python -c 'from hil_sim.campaign.spec import write_json_schema; write_json_schema()'"


def test_committed_suite_schema_is_the_generated_one():
    from hil_sim.campaign.suite import SUITE_SCHEMA_PATH, suite_json_schema
    assert json.loads(SUITE_SCHEMA_PATH.read_text()) == suite_json_schema(), \
        "regenerate: python -c 'from hil_sim.campaign.suite import write_suite_schema; write_suite_schema()'"


@pytest.mark.parametrize("path", CAMPAIGNS, ids=lambda p: p.name)
def test_shipped_campaign_validates_and_builds(path):
    from hil_sim.campaign.suite import SUITE_SCHEMA_PATH, is_suite, load_suite
    first = path.read_text().splitlines()[0]
    if is_suite(path):  # a suite: its schema, and every member is a shipped campaign (tested here too)
        assert first == "# yaml-language-server: $schema=../schema/suite.schema.json"
        jsonschema.Draft7Validator(json.loads(SUITE_SCHEMA_PATH.read_text())).validate(yaml.safe_load(path.read_text()))
        assert all((path.parent / m.campaign).resolve() in CAMPAIGNS for m in load_suite(path).suite)
        return
    assert first == "# yaml-language-server: $schema=../schema/campaign.schema.json"
    jsonschema.Draft7Validator(json.loads(SCHEMA_PATH.read_text())).validate(yaml.safe_load(path.read_text()))
    plan, base = build_plan(path)  # every dispersion path exists and a dispersed mission validates
    assert base.is_file()
    for i in range(3):
        _, mission = plan.mission(plan.draw(i), 0)
        assert mission.name


@pytest.mark.parametrize("path", sorted((ROOT / "config" / "campaigns" / "missions").glob("*.yaml")),
                         ids=lambda p: p.name)
def test_campaign_base_missions_validate(path):
    from hil_sim.mission.model import load_mission
    assert path.read_text().startswith("# yaml-language-server: $schema=../../schema/mission.schema.json")
    load_mission(path)


def test_errors_are_reported_with_file_line_and_column(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema_version: 1\nname: x\nbase_mission: m.yaml\nruns: 0\nmaster_seed: 1\n"
                   "dispersions:\n  - {name: a, path: x, kind: scalar, distribution: {dist: uniform, low: 2, high: 1}}\n"
                   "criteria:\n  - {name: c, metric: m, op: '>', limit: 0}\nsurprise: 1\n")
    with pytest.raises(ConfigError) as info:
        load_campaign(bad)
    text = str(info.value)
    assert f"{bad}:4:7 runs:" in text
    assert "surprise" in text and f"{bad}:10:1" in text
    assert "dispersions[0]" in text and "high (1.0) must be greater than low (2.0)" in text


def test_missing_base_mission_is_a_clear_error(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("schema_version: 1\nname: x\nbase_mission: nowhere.yaml\nruns: 1\nmaster_seed: 1\n"
                    "criteria:\n  - {name: c, metric: m, op: '>', limit: 0}\n")
    with pytest.raises(FileNotFoundError, match="base_mission 'nowhere.yaml' not found"):
        build_plan(path)
