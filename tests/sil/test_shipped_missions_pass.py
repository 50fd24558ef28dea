"""Every shipped mission of up to two hours passes `keepout sil run` with its own requirements, at its full
duration (it once did not: demo-quaternion arrived at its second target at 0.91 deg/s, overshot 2.6 deg and
ended 0.15 deg off against 0.1). TARGET_REACHED means held: the true body rate stayed near zero for the dwell before it."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "config" / "missions").glob("*.yaml"))
# A day in orbit flies ~20 min in lockstep on this host: too long for the suite. Its first pass flies in fast
# mode in tests/sil/test_leo_day.py, the whole day in its campaign (config/campaigns/leo-day.yaml).
LONGEST_IN_SUITE_S = 7200.0
FLOWN_ELSEWHERE = {"leo-day": "tests/sil/test_leo_day.py", "star-tracker-lost": "tests/sil/test_star_tracker_lost.py"}


def _duration_s(path: Path) -> float:
    return float(yaml.safe_load(path.read_text())["duration_s"])


MISSIONS = [m for m in SHIPPED if _duration_s(m) <= LONGEST_IN_SUITE_S]


def test_every_mission_too_long_for_the_suite_is_flown_by_a_test_of_its_own() -> None:
    long = {m.stem for m in SHIPPED if _duration_s(m) > LONGEST_IN_SUITE_S}
    assert long == set(FLOWN_ELSEWHERE), f"missions over {LONGEST_IN_SUITE_S:.0f} s: {sorted(long)}"
    assert all((ROOT / test).exists() for test in FLOWN_ELSEWHERE.values())


@pytest.fixture(scope="module")
def flown(tmp_path_factory) -> dict[str, tuple[int, str, Path]]:
    out = tmp_path_factory.mktemp("shipped")
    results: dict[str, tuple[int, str, Path]] = {}
    pending = list(MISSIONS)
    while pending:  # two at a time: the host has two cores
        batch, pending = pending[:2], pending[2:]
        procs = {m.stem: subprocess.Popen([sys.executable, "-m", "cli", "sil", "run", str(m), "--bus",
                                           "udp_multicast", "--out", str(out / m.stem), "--no-progress"],
                                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
                 for m in batch}
        for name, proc in procs.items():
            output, _ = proc.communicate(timeout=900)
            results[name] = (proc.returncode, output, next((out / name).glob(f"{name}-*")))
    return results


@pytest.mark.slow
@pytest.mark.parametrize("mission", [m.stem for m in MISSIONS])
def test_every_shipped_mission_passes_its_own_requirements(flown, mission: str) -> None:
    code, output, run_dir = flown[mission]
    assert code == 0, output[-3000:]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["pass"] and summary["status"] == "completed"


@pytest.mark.slow
@pytest.mark.parametrize("mission", ["demo-quaternion", "demo-pointing"])
def test_target_reached_means_held(flown, mission: str) -> None:
    _, _, run_dir = flown[mission]
    events = [json.loads(line) for line in (run_dir / "ground" / "events.jsonl").read_text().splitlines()]
    reached = [e["time_s"] for e in events if e.get("event") == "TARGET_REACHED"]
    assert reached, "no TARGET_REACHED"
    truth = np.load(run_dir / "truth.npz")
    t, w = truth["t_s"], np.degrees(np.linalg.norm(truth["omega_BN_B"], axis=1))
    for t_ev in reached:
        window = (t >= t_ev - 5.0) & (t <= t_ev)
        assert window.any() and float(w[window].max()) < 0.02, (t_ev, float(w[window].max()))
