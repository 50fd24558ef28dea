"""The small things a new user trips on: help texts, units, messages, where files go, what the wheel carries."""
from __future__ import annotations

import json
import re
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cli import main as cli

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = ROOT / "config" / "missions"


def _help(capsys, *args: str) -> str:
    with pytest.raises(SystemExit):
        cli.main([*args, "--help"])
    return capsys.readouterr().out


# ---- the wheel and `keepout init` ------------------------------------------------------------------

def test_the_wheel_takes_package_data_from_the_globs_only_and_ships_the_docs():
    """`make wheel` printed a "Package would be ignored" block for every data folder (__pycache__, static,
    Open MCT's dist/...) found through the file list; the globs alone give the same files, without them."""
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert tool["include-package-data"] is False
    assert "keepout_docs" in tool["packages"] and tool["package-dir"]["keepout_docs"] == "docs"
    assert "*.md" in tool["package-data"]["keepout_docs"] and (ROOT / "docs" / "missions.md").is_file()


def test_init_copies_the_mission_reference_and_names_it(tmp_path):
    project = tmp_path / "sat"
    assert cli.main(["init", str(project)]) == 0
    reference = project / "docs" / "missions.md"
    assert reference.read_text() == (ROOT / "docs" / "missions.md").read_text()
    assert "`docs/missions.md`: the mission-file reference" in (project / "README.md").read_text()


def test_readme_installs_the_wheel_from_dist():
    text = (ROOT / "README.md").read_text()
    assert "pip install dist/keepout-0.1.0-py3-none-any.whl" in text
    assert not re.search(r"pip install keepout-0\.1\.0", text)


# ---- help texts and the bench simulator's table ----------------------------------------------------

def test_sim_help_shows_plain_text_not_rest_literals(capsys):
    out = _help(capsys, "sim")
    assert "``" not in out and "keepout fsw MISSION --bus SPEC" in out


def test_sil_run_help_lists_every_bus_form_the_docs_accept(capsys):
    out = " ".join(_help(capsys, "sil", "run").split())
    for form in ("auto", "socketcan[:IFACE]", "udp_multicast[:GROUP:PORT]", "INTERFACE:CHANNEL[,KEY=VALUE...]"):
        assert form in out, form


def test_sim_prints_each_truth_requirement_with_its_unit():
    from cli.sim import result_lines

    lines = result_lines([
        {"name": "final pointing error", "value": 29.9, "unit": "deg", "limit": "< 0.05", "pass": False},
        {"name": "settling (timeline[0])", "value": 153.5, "unit": "s", "limit": "<= 290", "pass": True},
        {"name": "run completed", "value": "yes", "unit": "", "limit": "yes", "pass": True}])
    assert lines == ["  FAIL  final pointing error: 29.9 deg (limit < 0.05 deg)",
                     "  PASS  settling (timeline[0]): 153.5 s (limit <= 290 s)",
                     "  PASS  run completed: yes (limit yes)"]


# ---- mission validation: units ---------------------------------------------------------------------

def _problems(path: Path) -> list:
    from hil_sim.mission.model import load_mission
    from hil_sim.mission.loader import ConfigError

    with pytest.raises(ConfigError) as info:
        load_mission(path)
    return info.value.problems


@pytest.mark.parametrize("mission", ["smallsat-example", "demo-pointing"])
def test_rpm_typed_into_a_rad_s_key_is_one_message_with_the_unit_and_the_conversion(tmp_path, mission):
    """smallsat-example leaves the flight software's wheels to the truth (its copy refused 6000 too, under a
    key the file does not have); demo-pointing gives them separately."""
    text = (MISSIONS / f"{mission}.yaml").read_text().replace("max_speed_rad_s: 628.0", "max_speed_rad_s: 6000", 1)
    path = tmp_path / "m.yaml"
    path.write_text(text)
    problems = _problems(path)
    assert [p.path for p in problems] == ["spacecraft.wheels[0].max_speed_rad_s"], [str(p) for p in problems]
    msg = problems[0].message
    assert "less than or equal to 1000 rad/s (got 6000)" in msg and "6000 rpm = 628.3 rad/s" in msg


def test_a_copy_refused_where_the_truth_passes_is_reported_at_the_truth_key():
    """An error in a flight-software key filled from the truth is placed at the truth key the user wrote."""
    from hil_sim.mission.model import _ErrorsAsWritten

    data = {"spacecraft": {"wheels": [{"max_torque_Nm": 5.0}]}, "flight_software": {"initial_mode": "SAFE"}}
    # the one error pydantic would give: the copied key refused, the truth key (as written) accepted
    errors = [{"type": "less_than_equal", "loc": ("flight_software", "spacecraft", "wheels", 0, "max_torque_Nm"),
               "msg": "Input should be less than or equal to 1", "input": 5.0, "ctx": {"le": 1.0}}]
    shim = _ErrorsAsWritten(data, type("E", (), {"errors": lambda self, include_url=False: errors})())
    (err,) = shim.errors()
    assert err["loc"] == ("spacecraft", "wheels", 0, "max_torque_Nm")
    assert "flight_software.spacecraft.wheels[0].max_torque_Nm, the flight software's copy" in err["msg"]
    assert "1 N m (got 5.0)" in err["msg"]


def test_range_errors_name_the_unit(tmp_path):
    text = (MISSIONS / "demo-pointing.yaml").read_text().replace("max_torque_Nm: 0.1,", "max_torque_Nm: 20,", 1)
    path = tmp_path / "m.yaml"
    path.write_text(text)
    (problem,) = _problems(path)
    assert problem.message.startswith("Input should be less than or equal to 10 N m (got 20)")


def test_values_whose_size_suggests_another_unit_are_warned_about(tmp_path, capsys):
    text = (MISSIONS / "demo-pointing.yaml").read_text().replace(
        "omega_BN_B_rad_s: [0.0, 0.0, 0.0]", "omega_BN_B_rad_s: [0.11, 0.0, 0.0]")  # within the wheels' momentum
    path = tmp_path / "m.yaml"
    path.write_text(text)
    assert cli.main(["config", "validate", str(path)]) == 0  # a warning, not an error
    err = capsys.readouterr().err
    line = next(x for x in err.splitlines() if "omega_BN_B_rad_s[0]: warning:" in x)
    assert line.startswith(f"{path}:") and "6.3 deg/s" in line and "write 0.00192" in line


def test_the_packaged_missions_raise_no_unit_warning():
    from hil_sim.mission.model import unit_warnings
    from hil_sim.mission.loader import load_marked

    for path in sorted(MISSIONS.glob("*.yaml")):
        assert unit_warnings(load_marked(path)) == [], path


# ---- campaigns -------------------------------------------------------------------------------------

def test_baseline_defaults_beside_the_campaign_file_wherever_the_command_runs(tmp_path, monkeypatch):
    from cli.campaign import _baseline_dir

    campaigns = tmp_path / "project" / "campaigns"
    campaigns.mkdir(parents=True)
    results = tmp_path / "out" / "mine-20260425"
    results.mkdir(parents=True)
    (results / "plan.json").write_text(json.dumps({"campaign": "mine"}))
    (results / "campaign.yaml").write_text(f"# campaign as run, from {campaigns / 'mine.yaml'}\nname: mine\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert _baseline_dir(results, None) == campaigns / "baselines" / "mine"
    assert _baseline_dir(results, tmp_path / "given") == tmp_path / "given"
    (results / "campaign.yaml").write_text("# campaign as run, from /nowhere/mine.yaml\nname: mine\n")
    with pytest.raises(FileNotFoundError, match="give the baseline folder with --to"):
        _baseline_dir(results, None)


def test_a_dask_campaign_without_distributed_leaves_no_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ModuleNotFoundError
    out = tmp_path / "campaign-out"
    code = cli.main(["campaign", "run", str(ROOT / "config" / "campaigns" / "regression.yaml"), "--runs", "1",
                     "--scheduler", "tcp://127.0.0.1:1", "--out", str(out)])
    assert code == cli.EXIT_CANNOT_START
    assert "pip install 'keepout[dask]'" in capsys.readouterr().err
    assert not out.exists()


def test_histograms_span_the_runs_not_a_far_limit():
    from hil_sim.campaign.report import histogram_range

    lo, hi = histogram_range(np.array([8.1, 8.4, 8.9]), 0.0)  # margins of 8 to 9 deg, limit > 0
    assert 7.9 < lo < 8.1 and 8.9 < hi < 9.0
    lo, hi = histogram_range(np.array([0.5, 1.2, 2.0]), 0.0)  # a limit near the runs stays in view
    assert lo < 0.0 < 0.5 and hi > 2.0
    assert histogram_range(np.array([]), 0.0) is None


def test_the_regression_campaign_does_not_state_a_run_count_its_report_may_contradict():
    from hil_sim.campaign.spec import load_campaign

    description = load_campaign(ROOT / "config" / "campaigns" / "regression.yaml").description
    assert not re.search(r"\d+\s+dispersed runs", description), description


def test_the_campaign_copy_records_the_file_baseline_save_looks_beside(tmp_path):
    """`campaign run` records the campaign file's absolute path where `baseline save` reads it."""
    from hil_sim.campaign.runner import build_plan, prepare_out_dir
    from cli.campaign import campaign_source

    campaign = ROOT / "config" / "campaigns" / "regression.yaml"
    plan, base = build_plan(campaign, runs=1)
    prepare_out_dir(tmp_path / "out", plan, campaign.resolve(), base)
    assert campaign_source(tmp_path / "out") == campaign.resolve()
