"""Graceful degradation past one fault (demo-pointing, fast mode): a wheel whose only fault is a lost
status still obeys its commands, so with another wheel lost the spacecraft keeps three usable wheels and
must stay out of every zone and reach its targets, whichever of the two faults comes first."""
from __future__ import annotations

from pathlib import Path

import pytest

from hil_sim.campaign.fast import run_fast
from hil_sim.mission.model import BusFault, load_mission

ROOT = Path(__file__).resolve().parents[2]
# the two ways a wheel is lost here: its status frames (it still obeys), or the wheel itself
AS_FAULT = {"status_lost": ("drop", "STATUS"), "cmd_lost": ("drop", "CMD"), "stuck": ("wheel_stuck", "CMD")}


@pytest.mark.parametrize("faults", [
    [(1, "status_lost", 266.0), (3, "cmd_lost", 337.0)],  # silent first: it is brought back mid-slew
    [(2, "stuck", 238.0), (3, "status_lost", 368.0)],  # silent second: it is kept, open loop
    [(3, "status_lost", 184.0), (1, "stuck", 415.0)],
])
def test_a_silent_wheel_is_used_again_when_another_is_lost(faults):
    mission = load_mission(ROOT / "config" / "missions" / "demo-pointing.yaml")
    added = [BusFault(kind=AS_FAULT[k][0], message=f"RW{w + 1}_{AS_FAULT[k][1]}", start_s=t, end_s=1e5)
             for w, k, t in faults]
    result = run_fast(mission.model_copy(update={"faults": list(mission.faults) + added}), 7)
    assert result.metrics["wheels_lost"] == 1.0  # three usable wheels remain
    assert result.metrics["min_margin_deg"] > 0.0
    assert result.metrics["final_error_deg"] < 0.1  # target C reached
