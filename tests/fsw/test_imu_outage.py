"""A gyro silent for 30 s mid-slew (one fault, the release campaign found it): FDIR enters SAFE, and the rate
the rate loop acts on must follow the body, from the star tracker's fixes, not stay frozen at its last
value. Frozen, SAFE kept damping a rate that was gone and spun the body up to eight times its limit, straight
through the Sun zone (demo-pointing, fast mode)."""
from __future__ import annotations

from pathlib import Path

import pytest

from hil_sim.campaign.fast import run_fast
from hil_sim.mission.model import BusFault, load_mission

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("start_s", [388.5, 397.8, 444.0])  # on the slew to target C: -28.4, -28.3, -14.7 deg before
def test_a_silent_gyro_mid_slew_keeps_the_boresight_out_and_the_rate_in_its_limit(start_s: float) -> None:
    mission = load_mission(ROOT / "config" / "missions" / "demo-pointing.yaml")
    fault = BusFault(kind="silent", message="IMU_RATE", start_s=start_s, end_s=start_s + 30.0)
    metrics = run_fast(mission.model_copy(update={"faults": [fault]}), 1).metrics
    assert metrics["min_margin_deg"] > 0.0
    assert metrics["peak_body_rate_fraction"] <= 1.05
