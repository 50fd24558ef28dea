"""Shrink: an injected failure (disturbance > 0.03) is reduced to its smallest failing case."""
from __future__ import annotations

import pytest

from hil_sim.campaign.execute import execute_run
from hil_sim.campaign.shrink import shrink_run, shrunk_mission

from campaign_kit import TOY_CAMPAIGN_YAML, toy_plan, toy_run_threshold, write_toy

THRESHOLD = 0.03


def _plan(tmp_path):
    text = TOY_CAMPAIGN_YAML.format(runs=40, settle_limit=1000).replace(
        "{dist: normal, mean: 0.0, sigma: 0.002}", "{dist: uniform, low: 0.0, high: 0.1}")
    plan, _ = toy_plan(write_toy(tmp_path, campaign_text=text), run_function=toy_run_threshold)
    return plan


def test_shrink_finds_the_smallest_failing_case(tmp_path):
    plan = _plan(tmp_path)
    # a run that fails only through the injected cause (its disturbance is well above the threshold)
    index = next(i for i in range(40) if plan.draw(i)["disturbance"]["value"] > 0.07
                 and [k for k, ok in execute_run(plan, i).verdicts.items() if not ok] == ["keep_out"])
    drawn = plan.draw(index)["disturbance"]["value"]
    result = shrink_run(plan, index, bisect_steps=8)
    assert result.shrunk.status == "fail" and not result.shrunk.verdicts["keep_out"]
    # every dispersion that is not the cause went back to nominal
    assert result.remaining == ["disturbance"]
    for name in ("attitude", "inertia", "gain", "epoch", "target"):
        assert result.fractions[name] == 0.0
    # and the cause was bisected down to the threshold (8 halvings of the drawn deviation)
    shrunk = result.shrunk.params["disturbance"]["value"]
    assert THRESHOLD < shrunk <= THRESHOLD + drawn / 2 ** 8 + 1e-12
    assert shrunk < drawn
    # the smallest failing mission is a valid mission with that value
    assert shrunk_mission(plan, result)["disturbance"] == pytest.approx(shrunk)
    assert "disturbance" in result.text(plan)


def test_shrinking_a_passing_run_is_refused(tmp_path):
    plan = _plan(tmp_path)
    index = next(i for i in range(40) if plan.draw(i)["disturbance"]["value"] < 0.02
                 and execute_run(plan, i).status == "pass")
    with pytest.raises(ValueError, match="passes"):
        shrink_run(plan, index)
