"""Corrupt frames are a bus fault, not a wheel's: a wheel whose status frames arrive but fail their E2E check
is heard (its node is alive and obeys its commands), so a burst of them isolates no healthy wheel; only a
wheel from which nothing has been read for CORRUPT_STATUS_HEARD_S is silent (demo-pointing, fast mode)."""
from __future__ import annotations

from pathlib import Path

import pytest

from fsw.intake import CORRUPT_STATUS_HEARD_S
from hil_sim.campaign.fast import run_fast
from hil_sim.mission.model import BusFault, load_mission

ROOT = Path(__file__).resolve().parents[2]


def _fly(corrupt_s: float):
    mission = load_mission(ROOT / "config" / "missions" / "demo-pointing.yaml")
    fault = BusFault(kind="corrupt", message="RW2_STATUS", start_s=100.0, end_s=100.0 + corrupt_s, bit=30)
    return run_fast(mission.model_copy(update={"faults": [fault]}), 3)


def test_a_burst_of_corrupt_wheel_status_frames_isolates_no_wheel() -> None:
    result = _fly(CORRUPT_STATUS_HEARD_S - 2.0)  # every RW2_STATUS frame fails its CRC for 8 s
    assert result.metrics["unexpected_fdir_events"] == 0.0  # no WHEEL_FAULT: the wheel stays in use
    assert result.metrics["min_margin_deg"] > 0.0 and result.metrics["final_error_deg"] < 0.05


def test_a_wheel_unreadable_for_longer_is_silent_after_all() -> None:
    result = _fly(CORRUPT_STATUS_HEARD_S + 10.0)
    assert result.metrics["unexpected_fdir_events"] >= 1.0  # WHEEL_FAULT (status lost) once the streak is over
    assert result.metrics["min_margin_deg"] > 0.0
