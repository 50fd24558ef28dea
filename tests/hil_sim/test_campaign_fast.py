"""The real thing, shortened: the regression campaign in fast mode through the CLI, then an exact rerun."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest
import xmlschema

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.spec import load_campaign
from cli.main import main

ROOT = Path(__file__).resolve().parents[2]
REGRESSION = ROOT / "config" / "campaigns" / "regression.yaml"
JUNIT_XSD = Path(__file__).parent / "data" / "junit.xsd"
RUNS = 2


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory) -> tuple[Path, int]:
    out = tmp_path_factory.mktemp("regression") / "out"
    code = main(["campaign", "run", str(REGRESSION), "--runs", str(RUNS), "--workers", "2", "--duration", "25",
                 "--out", str(out), "--no-report"])
    return out, code


def test_shortened_regression_campaign_runs_end_to_end(campaign_dir):
    out, code = campaign_dir
    df = pd.read_parquet(out / "results.parquet")
    assert list(df["run"]) == list(range(RUNS))
    assert (df["status"] != "error").all(), df["error"].tolist()
    assert df["sim_time_s"].tolist() == pytest.approx([25.0] * RUNS)
    # 25 s of a 600 s mission: the slew that starts at t = 10 s cannot have settled, so the campaign
    # fails (exit 1) while the keep-out requirement holds on truth.
    assert code == 1
    assert (~df["v.settling"]).all() and df["v.keep_out"].all()
    assert (df["m.min_margin_deg"] > 0).all()
    xmlschema.XMLSchema(JUNIT_XSD).validate(out / "junit.xml")
    cases = ET.parse(out / "junit.xml").getroot().findall(".//testcase")
    criteria = len(load_campaign(REGRESSION).criteria)
    assert len(cases) == RUNS * criteria + 1  # one per criterion and run, and the verdict


def test_every_dispersion_was_read_back_from_the_run(campaign_dir):
    out, _ = campaign_dir
    for i in range(RUNS):
        record = json.loads((out / "runs" / f"run-{i:06d}.json").read_text())
        assert set(record["used"]) == set(record["values"])
        assert "flight_software.epoch_utc" in record["used"]
        for path, value in record["values"].items():
            assert dsp.same_value(value, record["used"][path]), path
        # the inertia the world integrated is the dispersed one, not the mission's nominal
        nominal = [[42.0, 0.6, -0.3], [0.6, 48.0, 0.4], [-0.3, 0.4, 31.0]]
        assert not dsp.same_value(nominal, record["used"]["spacecraft.inertia_B_kgm2"])


def test_rerun_reproduces_a_run_exactly(campaign_dir, capsys):
    out, _ = campaign_dir
    assert main(["campaign", "rerun", str(out), "--run", "1"]) == 0
    assert "reproduced exactly" in capsys.readouterr().err


@pytest.mark.slow
def test_ctrl_c_stops_the_campaign_and_keeps_finished_runs(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "interrupted"
    # 1800 s runs (a few seconds each here): Ctrl-C must land while runs remain (600 s runs all finished
    # before the signal once the loop got fast)
    proc = subprocess.Popen([sys.executable, "-m", "cli", "campaign", "run", str(REGRESSION), "--runs", "8",
                             "--workers", "1", "--duration", "1800", "--out", str(out), "--no-report"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 240
        while not list((out / "runs").glob("run-*.json")) and time.monotonic() < deadline:
            assert proc.poll() is None, proc.stdout.read()
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, output
    kept = sorted(out.glob("runs/run-*.json"))
    assert 1 <= len(kept) < 8 and "interrupted" in output
    # the finished runs were tabulated, and the folder resumes
    assert len(pd.read_parquet(out / "results.parquet")) == len(kept)


def test_ctrl_c_while_tabulating_exits_130_and_keeps_the_runs(tmp_path, monkeypatch, capsys):
    from hil_sim.campaign import runner

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "finalize", interrupted)
    out = tmp_path / "tabulating"
    code = main(["campaign", "run", str(REGRESSION), "--runs", "2", "--workers", "1", "--duration", "5",
                 "--out", str(out), "--no-report"])
    assert code == 130
    assert len(list((out / "runs").glob("run-*.json"))) == 2
    said = capsys.readouterr()
    assert "interrupted while tabulating" in said.out + said.err and "campaign report" in said.out + said.err


@pytest.mark.slow
def test_sil_mode_runs_the_three_process_sil_per_run(tmp_path):
    """One dispersed run as a full SIL (simulator, flight software and ground processes over its own
    udp_multicast group), judged like fast mode; its dispersions read back from the SIL's config."""
    from hil_sim.campaign.execute import execute_run
    from hil_sim.campaign.runner import build_plan

    campaign = load_campaign(REGRESSION).model_copy(update={"duration_s": 15.0, "mode": "sil"})
    plan, _ = build_plan(REGRESSION, campaign=campaign, runs=1)
    record = execute_run(plan, 0)
    assert record.status in ("pass", "fail"), record.error
    assert record.sim_time_s == pytest.approx(15.0, abs=0.2)
    assert set(record.used) == set(record.values)
    assert record.metrics["min_margin_deg"] > 0


def test_baseline_save_and_compare_through_the_cli(campaign_dir, tmp_path, capsys):
    out, _ = campaign_dir
    base = tmp_path / "baseline"
    assert main(["campaign", "baseline", "save", str(out), "--to", str(base)]) == 0
    assert main(["campaign", "compare", str(out), "--baseline", str(base)]) == 0
    assert "no regression beyond tolerance" in capsys.readouterr().out
    # a moved metric in the new results is flagged (exit 1)
    df = pd.read_parquet(out / "results.parquet")
    moved = tmp_path / "moved"
    moved.mkdir()
    for name in ("plan.json", "campaign.yaml"):
        (moved / name).write_text((out / name).read_text())
    df.assign(**{"m.min_margin_deg": df["m.min_margin_deg"] - 1.0}).to_parquet(moved / "results.parquet")
    assert main(["campaign", "compare", str(moved), "--baseline", str(base)]) == 1
    text = capsys.readouterr().out
    assert "WORSE (larger is better)" in text and text.rstrip().endswith("REGRESSION")
    # a larger keep-out margin (criterion `>`) and a shorter settling (`<=`) are improvements, not regressions
    df.assign(**{"m.min_margin_deg": df["m.min_margin_deg"] + 1.0,
                 "m.settling_time_s": df["m.settling_time_s"] - 1.0}).to_parquet(moved / "results.parquet")
    assert main(["campaign", "compare", str(moved), "--baseline", str(base)]) == 0
    text = capsys.readouterr().out
    assert "IMPROVED" in text and "REGRESSION" not in text and "MOVED" not in text


def test_compare_without_a_baseline_is_one_clear_line(campaign_dir, tmp_path, capsys):
    out, _ = campaign_dir
    assert main(["campaign", "compare", str(out), "--baseline", str(tmp_path / "none")]) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and "no baseline at" in captured.err and "baseline save" in captured.err
    assert "Traceback" not in captured.err + captured.out
    assert main(["campaign", "compare", str(tmp_path), "--baseline", str(tmp_path / "none")]) == 2
    assert "not a campaign output folder" in capsys.readouterr().err


@pytest.mark.parametrize("run", [RUNS, -1, 500])
def test_rerun_or_shrink_of_a_run_outside_the_campaign_is_an_error(campaign_dir, capsys, run):
    out, _ = campaign_dir
    assert main(["campaign", "rerun", str(out), "--run", str(run)]) == 2
    err = capsys.readouterr().err
    assert f"run {run} is not a run of" in err and f"runs 0 to {RUNS - 1}" in err
    assert main(["campaign", "shrink", str(out), "--run", str(run)]) == 2
    assert f"run {run} is not a run of" in capsys.readouterr().err


def test_report_regenerates_the_tables_and_report_of_a_folder(campaign_dir, capsys):
    out, code = campaign_dir
    (out / "results.parquet").unlink()
    assert not (out / "report.html").exists()  # the campaign ran with --no-report
    assert main(["campaign", "report", str(out)]) == code == 1
    assert (out / "report.html").exists() and (out / "report.md").exists()
    assert len(pd.read_parquet(out / "results.parquet")) == RUNS
    assert "FAIL: 2 failed of 2 runs" in capsys.readouterr().err
    assert main(["campaign", "report", str(out / "nowhere")]) == 2


def test_too_few_passing_runs_exit_inconclusive(tmp_path, capsys):
    """Two passing runs cannot show 95 % at 95 % confidence: INCONCLUSIVE, exit 4, never 'FAIL: 0 failed'."""
    import yaml
    campaign = yaml.safe_load(REGRESSION.read_text())
    campaign["base_mission"] = str(REGRESSION.parent / campaign["base_mission"])
    campaign["criteria"] = [c for c in campaign["criteria"] if c["name"] == "keep_out"]
    path = tmp_path / "keep-out-only.yaml"
    path.write_text(yaml.safe_dump(campaign))
    code = main(["campaign", "run", str(path), "--runs", "2", "--workers", "1", "--duration", "12",
                 "--out", str(tmp_path / "out"), "--no-report"])
    err = capsys.readouterr().err
    assert code == 4, err
    assert "INCONCLUSIVE: 0 failed of 2 runs" in err and "--runs 59" in err and "FAIL" not in err
    assert (tmp_path / "out" / "verdict.txt").read_text().startswith("INCONCLUSIVE")


@pytest.mark.slow
def test_shrink_through_the_cli_writes_the_smallest_failing_mission(campaign_dir, capsys):
    out, _ = campaign_dir
    assert main(["campaign", "shrink", str(out), "--run", "0", "--criterion", "settling",
                 "--max-evaluations", "4"]) == 0
    text = capsys.readouterr().out
    assert "smallest failing case" in text
    from hil_sim.mission.model import load_mission
    assert load_mission(out / "shrink-run-000000.yaml").duration_s == 25.0
