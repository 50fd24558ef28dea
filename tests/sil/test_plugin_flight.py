"""The example plug-in package (examples/keepout-example-plugin), registered as an installed distribution,
flown where users fly: a lockstep SIL run (`keepout sil run`: the flight software is its own process and
finds the plug-ins through its entry points) and a small fast-mode campaign."""
from __future__ import annotations

import json
import subprocess
import sys

import pandas as pd
import pytest
import yaml

from plugin_kit import ROOT, example_site, short_mission, use_paths

DURATION_S = 120.0
TIMEOUT_S = 900


def _sil(mission, out) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "cli", "sil", "run", str(mission), "--duration", str(DURATION_S),
                             "--out", str(out), "--no-progress"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _finish(proc: subprocess.Popen, out) -> tuple[int, dict, list[dict]]:
    try:
        text, _ = proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        text, _ = proc.communicate()
    runs = sorted(out.glob("*/summary.json"))
    assert len(runs) == 1, text
    events = [json.loads(line) for line in (runs[0].parent / "ground" / "events.jsonl").read_text().splitlines()]
    return proc.returncode, json.loads(runs[0].read_text()), events


def _settling_s(summary: dict) -> float:
    return [r for r in summary["requirements"] if r["name"].startswith("settl")][0]["value"]


@pytest.mark.slow
def test_sil_run_flies_the_example_plugins(tmp_path, monkeypatch):
    use_paths(monkeypatch, example_site(tmp_path / "site"))
    plugged = short_mission(tmp_path / "plugged.yaml", DURATION_S, guidance="geodesic", estimator="star-gyro")
    own = short_mission(tmp_path / "own.yaml", DURATION_S)
    runs = {"plugged": _sil(plugged, tmp_path / "runs-plugged"), "own": _sil(own, tmp_path / "runs-own")}
    (code, summary, events), (own_code, own_summary, own_events) = (
        _finish(runs[k], tmp_path / f"runs-{k}") for k in ("plugged", "own"))
    started = sorted(e["args"]["kind"] for e in events if e.get("event") == "PLUGIN_STARTED")
    assert started == ["ESTIMATOR", "GUIDANCE"], [e.get("event") for e in events]
    assert not [e for e in events if e.get("event") == "PLUGIN_STOPPED"]
    assert not [e for e in own_events if e.get("event", "").startswith("PLUGIN_")]
    # the verdict: every requirement of the mission passes with the user's law and estimator
    assert code == 0 and summary["status"] == "completed", summary["status"]
    assert all(r["pass"] for r in summary["requirements"]), [r for r in summary["requirements"] if not r["pass"]]
    assert own_code == 0
    # and it is their slew, not keepout's: the geodesic law's gain settles it later than keepout's law
    assert _settling_s(summary) > _settling_s(own_summary) + 2.0, (_settling_s(summary), _settling_s(own_summary))


@pytest.mark.slow
def test_sil_run_reports_a_sun_seeking_plugin_stopped_outside_the_zone(tmp_path, monkeypatch):
    use_paths(monkeypatch, example_site(tmp_path / "site"))
    mission = short_mission(tmp_path / "seeker.yaml", DURATION_S, guidance="sun-seeker")
    code, summary, events = _finish(_sil(mission, tmp_path / "runs"), tmp_path / "runs")
    stops = [e["args"] for e in events if e.get("event") == "PLUGIN_STOPPED"]
    assert len(stops) == 1 and stops[0]["kind"] == "GUIDANCE" and "guard limit" in stops[0]["reason"], stops
    to_safe = [e["args"] for e in events if e.get("event") == "MODE_CHANGED" and e["args"]["to_mode"] == "SAFE"]
    assert to_safe and to_safe[0]["cause"] == "FDIR"
    results = {r["name"]: r for r in summary["requirements"]}
    assert results["keep-out margin sun"]["pass"] and 0.0 < results["keep-out margin sun"]["value"] < 3.0
    # the run does not pass: the target was never reached (SAFE since the stop), and it says so
    assert not results["settling (timeline[0])"]["pass"] and code != 0


@pytest.mark.slow
def test_fast_campaign_flies_the_example_plugins(tmp_path, monkeypatch):
    use_paths(monkeypatch, example_site(tmp_path / "site"))
    mission = short_mission(tmp_path / "plugged.yaml", DURATION_S, guidance="geodesic", estimator="star-gyro")
    spec = tmp_path / "campaign.yaml"
    spec.write_text(yaml.safe_dump({
        "schema_version": 1, "name": "plugin", "base_mission": mission.name, "runs": 3, "master_seed": 7,
        "mode": "fast",
        "dispersions": [{"name": "initial_attitude", "path": "initial_state.q_NB", "kind": "attitude",
                         "max_angle_deg": 2.0}],
        "criteria": [
            {"name": "keep_out", "metric": "min_margin_deg", "op": ">", "limit": 0.0},
            {"name": "final_error", "metric": "final_error_deg", "op": "<", "limit": 0.05},
            {"name": "plugin_flew", "metric": "plugin_guidance_cycles", "op": ">=", "limit": 1000},
            {"name": "estimator_flew", "metric": "plugin_estimator_cycles", "op": ">=", "limit": 1000},
            {"name": "never_stopped", "metric": "plugin_stops", "op": "==", "limit": 0}],
        "verdict": {"confidence": 0.5, "required_success": 0.5}}, sort_keys=False))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "cli", "campaign", "run", str(spec), "--workers", "1",
                           "--out", str(out), "--no-report"], cwd=ROOT, capture_output=True, text=True,
                          timeout=TIMEOUT_S)
    df = pd.read_parquet(out / "results.parquet")
    assert (df["status"] != "error").all(), df["error"].tolist()
    assert (df["m.plugin_guidance_cycles"] == DURATION_S * 10 - 1).all()  # every cycle after the first fix
    assert df["v.keep_out"].all() and df["v.never_stopped"].all()
    assert proc.returncode == 0, proc.stdout + proc.stderr
