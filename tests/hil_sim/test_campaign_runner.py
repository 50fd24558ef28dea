"""Runner: seeds independent of workers/order/backend, resumable folders, Ctrl-C keeps finished runs."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from hil_sim.campaign import results as res
from hil_sim.campaign.execute import execute_run
from hil_sim.campaign.runner import finished_runs, load_records, prepare_out_dir, run_campaign, run_path
from hil_sim.campaign.seeds import RunSeeds, run_sequence

from campaign_kit import toy_plan, write_toy

RUNS = 6


def _run(tmp_path, name, **kw):
    path = write_toy(tmp_path, runs=RUNS)
    plan, base = toy_plan(path)
    out = tmp_path / name
    prepare_out_dir(out, plan, path, base)
    outcome = run_campaign(plan, out, **kw)
    return plan, out, outcome


def _comparable(plan, records):
    df = res.table(plan.campaign, records).drop(columns=["wall_s"])
    return df.sort_values("run").reset_index(drop=True)


def test_run_sequence_is_the_spawned_child():
    for master in (0, 7, 2**40 + 3):
        children = np.random.SeedSequence(master).spawn(20)
        for i in (0, 5, 19):
            assert run_sequence(master, i).generate_state(4).tolist() == children[i].generate_state(4).tolist()
    # run i's seeds do not depend on how many runs there are
    assert RunSeeds(5, 3).simulation_seed == RunSeeds(5, 3).simulation_seed
    assert len({RunSeeds(5, i).simulation_seed for i in range(200)}) == 200


def test_same_results_with_1_and_2_workers_and_any_order(tmp_path):
    plan, out1, o1 = _run(tmp_path, "w1", workers=1)
    _, out2, o2 = _run(tmp_path, "w2", workers=2)
    assert o1.executed == o2.executed == RUNS
    pd.testing.assert_frame_equal(_comparable(plan, o1.records), _comparable(plan, o2.records))
    # reversed order, in this process, one by one
    backwards = [execute_run(plan, i) for i in reversed(range(RUNS))]
    pd.testing.assert_frame_equal(_comparable(plan, o1.records), _comparable(plan, backwards))
    # trajectories stored per run are identical too
    for i in range(RUNS):
        with np.load(run_path(out1, i, ".npz")) as a, np.load(run_path(out2, i, ".npz")) as b:
            assert np.array_equal(a["x"], b["x"])


def test_same_results_on_a_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    plan, _, local = _run(tmp_path, "local", workers=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        _, _, dask = _run(tmp_path, "dask", scheduler=client)
    assert dask.executed == RUNS
    pd.testing.assert_frame_equal(_comparable(plan, local.records), _comparable(plan, dask.records))


def test_rerun_skips_finished_runs_and_fills_the_gaps(tmp_path):
    plan, out, first = _run(tmp_path, "resume", workers=2)
    before = _comparable(plan, first.records)
    for i in (2, 5):
        run_path(out, i).unlink()
    second = run_campaign(plan, out, workers=2)
    assert second.executed == 2
    pd.testing.assert_frame_equal(before, _comparable(plan, second.records))
    third = run_campaign(plan, out, workers=2)
    assert third.executed == 0


def test_ctrl_c_keeps_finished_runs(tmp_path):
    path = write_toy(tmp_path, runs=RUNS)
    plan, base = toy_plan(path)
    out = tmp_path / "interrupted"
    prepare_out_dir(out, plan, path, base)

    def interrupt(progress, record):
        if progress.done >= 3:
            raise KeyboardInterrupt

    outcome = run_campaign(plan, out, workers=1, on_progress=interrupt)
    assert outcome.interrupted
    kept = finished_runs(out)
    assert 3 <= len(kept) < RUNS
    assert all(json.loads(run_path(out, i).read_text())["run"] == i for i in kept)
    resumed = run_campaign(plan, out, workers=2)
    assert not resumed.interrupted and resumed.executed == RUNS - len(kept)
    assert sorted(r.run for r in load_records(out)) == list(range(RUNS))


def test_resuming_into_a_folder_of_another_campaign_is_refused(tmp_path):
    from hil_sim.campaign.runner import CampaignMismatch
    path = write_toy(tmp_path, runs=RUNS)
    plan, base = toy_plan(path)
    out = tmp_path / "mixed"
    prepare_out_dir(out, plan, path, base)
    other = plan.campaign.model_copy(update={"master_seed": 999})
    plan.campaign = other
    with pytest.raises(CampaignMismatch, match="fingerprint"):
        prepare_out_dir(out, plan, path, base)


def test_forkserver_preload_names_modules_that_exist_and_start_no_thread() -> None:
    """The forkserver silently skips a preload module it cannot import (the workers would then import it
    each on their own again), and must not inherit threads (the reason for the forkserver)."""
    import importlib
    import threading

    from hil_sim.campaign.runner import _FORKSERVER_PRELOAD

    before = threading.active_count()
    for name in _FORKSERVER_PRELOAD:
        importlib.import_module(name)
    assert threading.active_count() == before
