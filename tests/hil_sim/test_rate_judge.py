"""The rate judge uses the rate limit the flight software acknowledged, not the timeline's word: a SET_GAINS the
flight software refused used to change the limit `peak_body_rate_fraction` divided by."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from hil_sim.mission.model import load_mission
from hil_sim.sil.judge import acknowledged_rate_limits, peak_body_rate_fraction, rate_limit_series

DEMO = Path(__file__).resolve().parents[2] / "config" / "missions" / "demo-pointing.yaml"


def test_the_acknowledged_limit_and_not_the_timeline_is_judged(tmp_path: Path) -> None:
    data = yaml.safe_load(DEMO.read_text())
    data["timeline"].insert(0, {"t_s": 5.0, "command": "SET_GAINS", "rate_limit_deg_s": 0.5})
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data))
    mission = load_mission(path)
    configured = mission.flight_software.spacecraft.max_rate_deg_s
    t = np.arange(0.0, 10.0, 0.1)
    # refused onboard (no GAINS_SET): the configured limit all along
    assert np.allclose(rate_limit_series(mission, t, gains_set=[]), math.radians(configured))
    # acknowledged at 5.2 s (the event's onboard time), from then on
    acked = acknowledged_rate_limits([(5.2, "GAINS_SET", {"rate_limit_deg_s": 0.5}), (6.0, "CMD_REJECTED", {})])
    series = rate_limit_series(mission, t, acked)
    assert np.allclose(series[t < 5.2 - 1e-9], math.radians(configured)) and np.allclose(series[t >= 5.2], math.radians(0.5))
    # the judge: 0.8 deg/s flown is 80 % of the configured limit when the SET_GAINS was refused
    truth = {"t_s": t, "omega_BN_B": np.tile(np.radians([0.0, 0.0, 0.8 * configured]), (len(t), 1))}
    assert abs(peak_body_rate_fraction(mission, truth, gains_set=[])[0] - 0.8) < 1e-12
    assert abs(peak_body_rate_fraction(mission, truth, gains_set=acked)[0] - 0.8 * configured / 0.5) < 1e-9
