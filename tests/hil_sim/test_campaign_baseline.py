"""Baseline compare: an unchanged rerun passes, an injected regression (kappa changed) is flagged."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hil_sim.campaign import baseline as bl
from hil_sim.campaign.runner import finalize, prepare_out_dir, run_campaign
from hil_sim.campaign.spec import BaselinePolicy, Tolerance

from campaign_kit import TOY_MISSION_YAML, toy_plan, write_toy

RUNS = 10


def _campaign(tmp_path, name, mission_text=TOY_MISSION_YAML):
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = write_toy(tmp_path, runs=RUNS)
    (tmp_path / "toy-mission.yaml").write_text(mission_text)
    plan, base = toy_plan(path)
    out = tmp_path / name
    prepare_out_dir(out, plan, path, base)
    outcome = run_campaign(plan, out, workers=2)
    finalize(plan, out, outcome.records, report=False)
    return plan, out


def _compare(base_dir, out, plan):
    base_df, _ = bl.load_baseline(base_dir)
    return bl.compare(base_df, pd.read_parquet(out / "results.parquet"), plan.campaign.baseline)


def test_unchanged_rerun_passes_and_changed_kappa_is_flagged(tmp_path):
    plan, first = _campaign(tmp_path / "a", "first")
    base_dir = bl.save_baseline(first, tmp_path / "baseline")
    _, again = _campaign(tmp_path / "b", "again")
    same = _compare(base_dir, again, plan)
    assert not same.regressed, same.text()
    assert all(m.runs_beyond_tolerance == 0 and m.max_abs_diff == 0.0 for m in same.metrics)

    # Injected regression: the repulsion gain kappa of the keep-out law is weakened.
    weaker = TOY_MISSION_YAML.replace("kappa: 2.0", "kappa: 0.3")
    _, changed = _campaign(tmp_path / "c", "changed", weaker)
    moved = _compare(base_dir, changed, plan)
    assert moved.regressed, moved.text()
    # same seeds and dispersed values, so the runs are compared pair by pair
    assert moved.same_inputs
    margin = next(m for m in moved.metrics if m.metric == "min_margin_deg")
    assert margin.flagged and margin.runs_beyond_tolerance > 0
    assert "MOVED" in moved.text()

    # A campaign with other seeds is not paired: only the distribution tests apply, and noise passes them.
    other = TOY_MISSION_YAML.replace("name: toy", "name: toy")
    _, reseeded = _campaign(tmp_path / "d", "reseeded", other)
    df = pd.read_parquet(reseeded / "results.parquet")
    df["sim_seed"] = df["sim_seed"] + 1
    assert not bl.compare(pd.read_parquet(base_dir / "results.parquet"), df, plan.campaign.baseline).same_inputs


def test_distribution_tests_flag_a_shift_and_accept_noise():
    rng = np.random.default_rng(4)
    policy = BaselinePolicy(alpha=0.01, tolerances={"x": Tolerance(abs=10.0)})
    a = pd.DataFrame({"run": range(200), "status": "pass", "m.x": rng.normal(0, 1, 200)})
    b = pd.DataFrame({"run": range(200), "status": "pass", "m.x": rng.normal(0, 1, 200)})
    c = pd.DataFrame({"run": range(200), "status": "pass", "m.x": rng.normal(0.6, 1, 200)})
    assert not bl.compare(a, b, policy, same_inputs=False).regressed
    shifted = bl.compare(a, c, policy, same_inputs=False)
    assert shifted.regressed and shifted.metrics[0].ks_pvalue < 0.01 and shifted.metrics[0].mw_pvalue < 0.01


def test_a_newly_failing_run_is_a_regression():
    policy = BaselinePolicy(tolerances={"x": Tolerance(abs=1.0)})
    a = pd.DataFrame({"run": [0, 1, 2], "status": ["pass", "pass", "fail"], "m.x": [1.0, 2.0, 3.0]})
    b = pd.DataFrame({"run": [0, 1, 2], "status": ["pass", "fail", "pass"], "m.x": [1.0, 2.0, 3.0]})
    cmp = bl.compare(a, b, policy, same_inputs=True)
    assert cmp.regressed and cmp.new_failures == [1] and cmp.fixed_runs == [2]


def test_tolerance_and_infinities():
    tol = Tolerance(abs=0.5, rel=0.1)
    old = np.array([10.0, 10.0, np.inf, np.nan, 1.0])
    new = np.array([11.4, 11.6, np.inf, np.nan, np.inf])
    assert bl._beyond(old, new, tol).tolist() == [False, True, False, False, True]


def test_missing_baseline_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="baseline save"):
        bl.load_baseline(tmp_path / "nope")
