"""A dispersion that adds faults composes with the base mission's own: drawing a wheel failure on
fault-imu-dropout (which has its IMU dropout in `faults`) used to make every run `error` (DispersionNotLanded:
the drawn faults carried delay_s, bit and probability that the read-back lacked), so a run that flew and
failed was counted as one that could not be flown. Now every flown run is pass or fail."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]

CAMPAIGN = """\
schema_version: 1
name: compose
base_mission: {base}
runs: 3
master_seed: 11
mode: fast
dispersions:
  - name: wheel_failure
    path: faults
    kind: wheel_failure
    n_wheels: 4
    probability: 1.0
    max_failed: 1
    fault_kind: {kind}
    start_s: {{dist: uniform, low: 20.0, high: 150.0}}
criteria:
  - {{name: keep_out, metric: min_margin_deg, op: ">", limit: 0.0}}
verdict:
  confidence: 0.95
  required_success: 0.5
"""


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["drop", "wheel_no_torque"])  # frames lost, or the wheel's motor dead
def test_a_wheel_failure_drawn_on_a_mission_with_faults_flies_and_is_judged(tmp_path: Path, kind: str) -> None:
    spec = tmp_path / "compose.yaml"
    spec.write_text(CAMPAIGN.format(base=ROOT / "config" / "missions" / "fault-imu-dropout.yaml", kind=kind))
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, "-m", "cli", "campaign", "run", str(spec), "--workers", "1",
                             "--duration", "200", "--no-report", "--out", str(out)], cwd=ROOT,
                            capture_output=True, text=True, timeout=600)
    results = pd.read_csv(out / "results.csv")
    assert len(results) == 3, result.stdout[-2000:] + result.stderr[-2000:]
    assert set(results["status"]) <= {"pass", "fail"}, results[["status"]].to_string()
    # the base mission's own IMU dropout was injected in every run, beside the drawn wheel failure
    for record in sorted((out / "runs").glob("run-*.json")):
        used = json.loads(record.read_text())["used"]["faults"]
        assert [f["message"] for f in used][0] == "IMU_RATE" and used[1]["message"].endswith("_CMD"), used
        assert used[1]["kind"] == kind
