"""Campaign answers a user can act on: an INCONCLUSIVE verdict when the run count cannot show the required
success probability, a compare that knows which way is better, clear one-line errors."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from hil_sim.campaign import baseline as bl
from hil_sim.campaign import results as res
from hil_sim.campaign.spec import BaselinePolicy, Criterion, Tolerance

from campaign_kit import toy_plan, write_toy
from test_campaign_results import _records


@pytest.mark.parametrize("runs", [1, 4, 16, 58])
def test_too_few_runs_without_a_failure_is_inconclusive_not_fail(tmp_path, runs):
    plan, _ = toy_plan(write_toy(tmp_path))
    v = res.verdict(plan.campaign, _records(runs, 0, 0))
    assert not v.passed and v.inconclusive and v.word == "INCONCLUSIVE"
    assert v.exit_code == res.EXIT_INCONCLUSIVE == 4
    text = v.text()
    assert text.startswith("INCONCLUSIVE") and "FAIL" not in text
    assert "59 runs" in text and "--runs 59" in text  # what would make it conclusive
    # JUnit: the verdict case is skipped (not shown either way), not a failure
    root = ET.parse(res.junit_xml(plan.campaign, _records(runs, 0, 0), tmp_path / "junit.xml")).getroot()
    case = root.find("testsuite[@name='toy-campaign.verdict']/testcase")
    assert case.find("failure") is None and case.find("skipped") is not None
    assert root.get("failures") == "0"


def test_enough_runs_pass_and_a_failure_still_fails(tmp_path):
    plan, _ = toy_plan(write_toy(tmp_path))
    ok = res.verdict(plan.campaign, _records(59, 0, 0))
    assert ok.passed and ok.exit_code == 0 and ok.text().startswith("PASS")
    bad = res.verdict(plan.campaign, _records(3, 1, 0))
    assert not bad.passed and not bad.inconclusive and bad.exit_code == 1 and bad.text().startswith("FAIL: 1 failed")


# --- compare: which way is better ------------------------------------------------------------------

def _tables(old_values, new_values, metric="x"):
    a = pd.DataFrame({"run": range(len(old_values)), "status": "pass", "sim_seed": 1, f"m.{metric}": old_values})
    b = pd.DataFrame({"run": range(len(new_values)), "status": "pass", "sim_seed": 1, f"m.{metric}": new_values})
    return a, b


@pytest.mark.parametrize("op,shift,improved", [(">", +1.0, True), (">", -1.0, False), (">=", +1.0, True),
                                               ("<", -1.0, True), ("<=", +1.0, False), ("<", +1.0, False)])
def test_a_move_to_the_better_side_of_the_criterion_is_an_improvement(op, shift, improved):
    rng = np.random.default_rng(3)
    old = rng.normal(5.0, 0.2, 60)
    a, b = _tables(old, old + shift)
    better = bl.better_sides([Criterion(name="c", metric="x", op=op, limit=0.0)])
    cmp = bl.compare(a, b, BaselinePolicy(tolerances={"x": Tolerance(abs=0.01)}), same_inputs=True, better=better)
    m = cmp.metrics[0]
    assert m.flagged and m.runs_beyond_tolerance == 60
    assert m.improved is improved and cmp.regressed is (not improved)
    text = cmp.text()
    if improved:
        assert "IMPROVED" in text and "REGRESSION" not in text and "MOVED" not in text
        assert "improved: x" in text
    else:
        assert "WORSE" in text and text.splitlines()[-1] == "REGRESSION"


def test_equality_criterion_prefers_the_limit_and_mixed_moves_are_a_regression():
    better = bl.better_sides([Criterion(name="c", metric="x", op="==", limit=0.0)])
    a, b = _tables([3.0, 2.0, 1.0, 4.0], [0.0, 0.0, 0.0, 0.0])
    assert not bl.compare(a, b, BaselinePolicy(), same_inputs=True, better=better).regressed
    # some runs better, one worse: not an improvement
    a, b = _tables([3.0, 2.0, 1.0, 4.0], [0.0, 0.0, 0.0, 6.0])
    assert bl.compare(a, b, BaselinePolicy(), same_inputs=True, better=better).regressed
    # unknown side: a move is still flagged (nobody can say it is better)
    a, b = _tables([3.0, 2.0], [4.0, 5.0])
    cmp = bl.compare(a, b, BaselinePolicy(), same_inputs=True)
    assert cmp.regressed and "no criterion says which way is better" in cmp.text()


def test_criteria_come_before_the_known_sense_of_a_metric():
    from hil_sim.campaign.fast import metric_better
    known = {m: metric_better(m) for m in ("min_margin_deg", "margin_sun_deg", "settling_time_s")}
    assert known == {"min_margin_deg": "higher", "margin_sun_deg": "higher", "settling_time_s": "lower"}
    sides = bl.better_sides([Criterion(name="c", metric="settling_time_s", op=">", limit=1.0)], known)
    assert sides["settling_time_s"] == "higher" and sides["margin_sun_deg"] == "higher"


# --- expected FDIR events follow the drawn faults ---------------------------------------------------

def _wheel_failure_plan(start_s: float, duration_s: float, probability: float = 1.0, event: str = "WHEEL_FAULT"):
    from pathlib import Path

    from hil_sim.campaign.runner import build_plan
    from hil_sim.campaign.spec import WheelFailureDispersion, load_campaign
    regression = Path(__file__).resolve().parents[2] / "config" / "campaigns" / "regression.yaml"
    campaign = load_campaign(regression)
    wheel = WheelFailureDispersion(name="wheel_failure", path="faults", kind="wheel_failure", n_wheels=4,
                                   probability=probability, max_failed=1, expected_fdir_event=event,
                                   start_s={"dist": "uniform", "low": start_s, "high": start_s + 1e-6})
    campaign = campaign.model_copy(update={"dispersions": [wheel], "duration_s": duration_s})
    plan, _ = build_plan(regression, campaign=campaign, runs=1)
    return plan


def test_a_drawn_wheel_failure_expects_its_fdir_event_and_only_then():
    plan = _wheel_failure_plan(start_s=50.0, duration_s=600.0)
    params = plan.draw(0)
    assert sum(v for k, v in params["wheel_failure"].items() if k.startswith("wheel")) == 1.0
    _, mission = plan.mission(params, 1)
    assert mission.requirements.expected_fdir_events == ["WHEEL_FAULT"]
    # the same run without the failure (as shrinking makes it) expects nothing
    healthy = {"wheel_failure": {**{k: 0.0 for k in params["wheel_failure"] if k.startswith("wheel")},
                                 "start_s": 50.0}}
    assert plan.mission(healthy, 1)[1].requirements.expected_fdir_events == []
    # a failure too close to the end to be detected, or after it, expects nothing either
    late = _wheel_failure_plan(start_s=598.0, duration_s=600.0)
    assert late.mission(late.draw(0), 1)[1].requirements.expected_fdir_events == []


def test_a_run_with_a_drawn_wheel_failure_counts_the_isolation_as_expected():
    """Fast mode, the real flight software: RW1..4 commands stop at t = 3 s; FDIR trips WHEEL_FAULT. On the
    old judging that trip was 'unexpected' and the run failed."""
    from hil_sim.campaign.execute import execute_run
    plan = _wheel_failure_plan(start_s=3.0, duration_s=12.0)
    record = execute_run(plan, 0)
    assert record.status != "error", record.error
    assert any("WHEEL_FAULT" in e for e in record.events), record.events
    assert record.metrics["unexpected_fdir_events"] == 0.0
    assert record.metrics["missing_expected_fdir_events"] == 0.0
    assert record.verdicts["no_unexpected_fdir"] and record.verdicts["expected_fdir"]


def test_an_expected_fdir_event_that_does_not_come_is_counted_missing():
    from hil_sim.campaign.execute import execute_run
    plan = _wheel_failure_plan(start_s=3.0, duration_s=12.0, event="ESTIMATOR_DIVERGENCE")
    record = execute_run(plan, 0)
    assert record.metrics["missing_expected_fdir_events"] == 1.0
    assert record.metrics["unexpected_fdir_events"] >= 1.0  # the WHEEL_FAULT trip was not the expected one
    assert not record.verdicts["expected_fdir"] and record.status == "fail"
