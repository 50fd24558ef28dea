"""A campaign suite: member campaigns flown into their folders and judged as one, and faults drawn by several
dispersions composed into one fault list."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.spec import Campaign
from cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def _campaign(dispersions: list[dict]) -> Campaign:
    return Campaign.model_validate({"schema_version": 1, "name": "t", "base_mission": "x.yaml", "runs": 1,
                                    "master_seed": 0, "dispersions": dispersions,
                                    "criteria": [{"name": "c", "metric": "m", "op": ">", "limit": 0}]})


def test_a_fault_dispersion_appends_one_drawn_fault_at_a_drawn_time() -> None:
    d = _campaign([{"name": "f", "path": "faults", "kind": "fault", "probability": 0.5,
                    "start_s": {"dist": "uniform", "low": 10, "high": 100},
                    "faults": [{"kind": "drop", "message": "IMU_RATE", "duration_s": 3.0},
                               {"kind": "corrupt", "message": "ST_QUAT_A", "duration_s": 40.0, "bit": 20},
                               {"kind": "door_slow", "message": "DOOR_CMD", "delay_s": 2.0}]}]).dispersions[0]
    rng = np.random.default_rng(5)
    lists = [dsp.realize(d, dsp.draw(d, rng, []), []) for _ in range(600)]
    hit = [f[0] for f in lists if f]
    assert 240 < len(hit) < 360  # probability 0.5
    assert {f["kind"] for f in hit} == {"drop", "corrupt", "door_slow"}
    for f in hit:
        assert 10 <= f["start_s"] <= 100
        if f["kind"] == "drop":
            assert f["end_s"] == f["start_s"] + 3.0
        if f["kind"] == "corrupt":
            assert f["bit"] == 20
        if f["kind"] == "door_slow":  # no duration: to the end of any run
            assert f["end_s"] == dsp.NEVER_ENDS_S and f["delay_s"] == 2.0


def test_dispersions_that_append_faults_share_the_path_and_compose() -> None:
    from hil_sim.campaign.execute import Plan

    campaign = _campaign([
        {"name": "wheels", "path": "faults", "kind": "wheel_failure", "n_wheels": 4, "probability": 1.0,
         "max_failed": 1, "start_s": {"dist": "uniform", "low": 10, "high": 20}},
        {"name": "fault", "path": "faults", "kind": "fault", "start_s": {"dist": "uniform", "low": 30, "high": 40},
         "faults": [{"kind": "silent", "message": "ST_QUAT_A", "duration_s": 5.0}]}])
    base = [{"kind": "drop", "message": "IMU_RATE", "start_s": 1.0, "end_s": 2.0}]

    nominal = dsp.nominal_values(campaign.dispersions, {"faults": base})
    plan = Plan.__new__(Plan)
    plan.campaign, plan.nominal = campaign, nominal
    rng = np.random.default_rng(1)
    params = {d.name: dsp.draw(d, rng, nominal[d.name]) for d in campaign.dispersions}
    faults = plan.values(params)["faults"]
    assert faults[0] == base[0]  # the base mission's own first, then each dispersion's, in order
    assert faults[1]["message"].startswith("RW") and faults[2]["message"] == "ST_QUAT_A"
    # a dispersion that replaces the value may not share the path
    bad = _campaign([campaign.dispersions[1].model_dump(),
                     {"name": "c", "path": "faults", "kind": "choice", "values": [[]]}])
    try:
        dsp.nominal_values(bad.dispersions, {"faults": base})
    except dsp.DispersionError as exc:
        assert "several dispersions write the same path" in str(exc)
    else:
        raise AssertionError("a choice and a fault dispersion on one path were accepted")


def test_a_suite_flies_every_member_and_judges_all_runs_together(tmp_path: Path, monkeypatch) -> None:
    suite = tmp_path / "suite.yaml"
    suite.write_text(f"""schema_version: 1
name: small-release
suite:
  - {{campaign: {ROOT / 'config/campaigns/release-pointing.yaml'}, runs: 2}}
  - {{campaign: {ROOT / 'config/campaigns/release-smallsat.yaml'}, runs: 1}}
verdict: {{confidence: 0.95, required_success: 0.5}}
""")
    out = tmp_path / "out"
    monkeypatch.chdir(tmp_path)
    code = main(["campaign", "run", str(suite), "--workers", "1", "--no-report", "--duration", "60", "--out", str(out)])
    record = json.loads((out / "suite.json").read_text())
    assert [m["runs"] for m in record["members"]] == [2, 1]
    assert record["runs"] == 3 and record["failures"] == sum(m["failures"] for m in record["members"])
    assert (out / "release-pointing" / "results.csv").is_file() and (out / "release-smallsat" / "results.csv").is_file()
    # 3 runs without a failure cannot show 50 % at 95 %: inconclusive (exit 4), and the text says why
    assert record["verdict"] == ("INCONCLUSIVE" if record["failures"] == 0 else "FAIL")
    assert code == (4 if record["failures"] == 0 else 1)
    junit = ET.parse(out / "junit.xml").getroot()
    names = [ts.get("name") for ts in junit.findall("testsuite")]
    assert "release-pointing.run-000001" in names and "release-smallsat.run-000000" in names
    assert names[-1] == "small-release.verdict"
    assert int(junit.get("tests")) == 1 + sum(int(ts.get("tests")) for ts in junit.findall("testsuite")[:-1])


def test_a_suite_with_a_bad_member_flies_nothing(tmp_path: Path, monkeypatch) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROOT / "config/campaigns/release-smallsat.yaml").read_text()
                   .replace("base_mission: ../missions/smallsat-example.yaml", f"base_mission: {ROOT}/config/missions/smallsat-example.yaml")
                   .replace("dist: uniform, low: 5.0, high: 380.0", "dist: uniform, low: 5.0, high: 380.0}\n    bogus: {x: 1"))
    suite = tmp_path / "suite.yaml"
    suite.write_text(f"""schema_version: 1
name: bad-release
suite:
  - {{campaign: {ROOT / 'config/campaigns/release-pointing.yaml'}, runs: 1}}
  - {{campaign: bad.yaml}}
""")
    monkeypatch.chdir(tmp_path)
    assert main(["campaign", "run", str(suite), "--workers", "1", "--no-report", "--out", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out").exists()
