"""Campaigns in ``sil`` mode: runs side by side on their own buses run to their end; a run that could not
run is an error, never a requirement failure."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil_sim.sil import orchestrator as sil
from hil_sim.campaign import sil_mode

ROOT = Path(__file__).resolve().parents[2]
DURATION_S = 30.0


@pytest.mark.slow
def test_two_workers_run_every_sil_run_to_its_end(tmp_path):
    """Two workers start their runs in the same second: each on its own bus, each simulates the whole
    duration (they used to share a run id and a bus and stop after 1-3 s, recorded as "fail")."""
    out = tmp_path / "campaign"
    result = subprocess.run(
        [sys.executable, "-m", "cli", "campaign", "run", str(ROOT / "config" / "campaigns" / "regression.yaml"),
         "--mode", "sil", "--workers", "2", "--runs", "2", "--duration", str(DURATION_S), "--out", str(out),
         "--no-report"], cwd=tmp_path, capture_output=True, text=True, timeout=1200)
    with open(out / "results.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2, result.stdout + result.stderr
    for row in rows:
        assert row["status"] in ("pass", "fail"), row["error"]
        assert float(row["sim_time_s"]) == pytest.approx(DURATION_S, abs=0.2), row


def test_a_sil_run_that_crashed_is_an_error_not_a_fail(monkeypatch, tmp_path):
    from hil_sim.mission.model import load_mission

    mission = load_mission(ROOT / "config" / "missions" / "demo-pointing.yaml")

    def crashed_run(options):
        run_dir = tmp_path / "run"
        run_dir.mkdir()
        summary = {"status": "crashed: fsw at t = 1.2 s (exit code -9)", "pass": False, "requirements": []}
        (run_dir / "summary.json").write_text(json.dumps(summary))
        return sil.RunResult(run_dir, sil.EXIT_CRASHED, summary)

    monkeypatch.setattr(sil, "run_sil", crashed_run)
    with pytest.raises(sil_mode.SilRunError, match="crashed: fsw at t = 1.2 s"):
        sil_mode.run_sil(mission, seed=1)
