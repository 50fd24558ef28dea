"""Statistical verdict (Clopper-Pearson), results tables, JUnit XML against the CI schema, report files."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest
import xmlschema
from scipy import stats

from hil_sim.campaign import results as res
from hil_sim.campaign.execute import RunRecord
from hil_sim.campaign.runner import finalize, prepare_out_dir, run_campaign

from campaign_kit import toy_plan, write_toy

JUNIT_XSD = Path(__file__).parent / "data" / "junit.xsd"


def test_59_runs_without_failure_show_95_percent_at_95_percent_confidence():
    lower = res.clopper_pearson_lower(59, 59, 0.95)
    assert lower == pytest.approx(0.05 ** (1 / 59), rel=1e-9)  # closed form for zero failures
    assert lower >= 0.95
    assert res.clopper_pearson_lower(58, 58, 0.95) < 0.95  # 58 is not enough
    assert res.runs_needed(0.95, 0.95) == 59
    assert res.runs_needed(0.99, 0.95) == 299


@pytest.mark.parametrize("successes,trials", [(190, 200), (45, 50), (3, 10)])
def test_clopper_pearson_bound_is_exact(successes, trials):
    # The one-sided exact bound p_L solves P(X >= successes | p_L) = 1 - confidence.
    p = res.clopper_pearson_lower(successes, trials, 0.95)
    assert stats.binom.sf(successes - 1, trials, p) == pytest.approx(0.05, rel=1e-6)


def _records(n_pass, n_fail, n_error):
    out = []
    for i in range(n_pass + n_fail + n_error):
        status = "pass" if i < n_pass else ("fail" if i < n_pass + n_fail else "error")
        out.append(RunRecord(run=i, status=status, params={}, values={"law.k1": 0.2},
                             metrics={"min_margin_deg": 1.0 if status == "pass" else -1.0,
                                      "settling_time_s": 20.0, "final_error_deg": 0.1},
                             verdicts={"keep_out": status == "pass", "settling": True, "final_error": True},
                             error="RuntimeError: boom <&>" if status == "error" else "", wall_s=0.25))
    return out


def test_junit_xml_validates_against_the_ci_schema_and_counts(tmp_path):
    plan, _ = toy_plan(write_toy(tmp_path))
    schema = xmlschema.XMLSchema(JUNIT_XSD)
    for n_pass, n_fail, n_error in ((59, 0, 0), (10, 3, 2)):
        path = res.junit_xml(plan.campaign, _records(n_pass, n_fail, n_error), tmp_path / "junit.xml")
        schema.validate(path)
        root = ET.parse(path).getroot()
        cases = root.findall(".//testcase")
        n = n_pass + n_fail + n_error
        assert len(cases) == n * len(plan.campaign.criteria) + 1  # one per run and requirement, + verdict
        assert len(root.findall(".//testcase/failure")) == n_fail + (0 if n_fail + n_error == 0 else 1)
        assert len(root.findall(".//testcase/error")) == n_error * len(plan.campaign.criteria)
        assert int(root.get("tests")) == len(cases)
        verdict = root.find("testsuite[@name='toy-campaign.verdict']/testcase")
        assert (verdict.find("failure") is None) == (n_fail + n_error == 0)


def test_junit_schema_rejects_a_malformed_report(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text("<testsuites><testsuite name='x' tests='1'><testcase/></testsuite></testsuites>")
    assert not xmlschema.XMLSchema(JUNIT_XSD).is_valid(bad)


def test_finalize_writes_tables_junit_and_report(tmp_path):
    path = write_toy(tmp_path, runs=10)
    plan, base = toy_plan(path)
    out = tmp_path / "out"
    prepare_out_dir(out, plan, path, base)
    outcome = run_campaign(plan, out, workers=2)
    files = finalize(plan, out, outcome.records)
    df_parquet = pd.read_parquet(files["parquet"])
    df_csv = pd.read_csv(files["csv"])
    assert list(df_parquet["run"]) == list(range(10)) == list(df_csv["run"])
    for col in ("p.attitude.angle_deg", "p.inertia.scale", "p.gain.value", "m.min_margin_deg", "v.keep_out"):
        assert col in df_parquet
    # a verdict column agrees with its metric and limit, recomputed here
    assert (df_parquet["v.keep_out"] == (df_parquet["m.min_margin_deg"] > 0)).all()
    xmlschema.XMLSchema(JUNIT_XSD).validate(files["junit"])
    report = files["report"]
    for key in ("markdown", "html", "distribution_keep_out", "worst_trajectories", "scatter_min_margin_deg",
                "basin"):
        assert report[key].exists() and report[key].stat().st_size > 0
    md = report["markdown"].read_text()
    assert "Verdict:" in md and "report/worst_trajectories.png" in md
    failures = int((df_parquet["status"] != "pass").sum())
    assert f"{failures} failed of 10 runs" in md
