"""peak_body_rate_fraction (hil_sim.sil.judge): true |omega| over the configured rate limit, which a SET_GAINS the
flight software acknowledged changes from its time on (the timeline's word alone changes nothing); a tumbling
start is not judged until the rate is within the limit."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import Mission
from hil_sim.sil.judge import peak_body_rate_fraction

DEMO = Path(__file__).resolve().parents[2] / "config" / "missions" / "demo-pointing.yaml"


def _mission(timeline) -> Mission:
    data = yaml.safe_load(DEMO.read_text())
    data["timeline"] = timeline
    return Mission.model_validate(data)


def _truth(rates_deg_s):
    t = np.arange(len(rates_deg_s)) * 1.0
    omega = np.zeros((len(t), 3))
    omega[:, 2] = np.radians(rates_deg_s)
    return {"t_s": t, "omega_BN_B": omega}


def test_fraction_follows_the_limit_in_force() -> None:
    # demo limit 1 deg/s; from t = 2 s a SET_GAINS raises it to 2 deg/s
    m = _mission([{"t_s": 2.0, "command": "SET_GAINS", "rate_limit_deg_s": 2.0}])
    frac, t = peak_body_rate_fraction(m, _truth([0.5, 1.02, 1.9, 1.0]), gains_set=[(2.0, 2.0)])
    assert frac == pytest.approx(1.02) and t == 1.0
    frac, t = peak_body_rate_fraction(m, _truth([0.5, 1.02, 1.9, 1.0]))  # not acknowledged: 1 deg/s holds
    assert frac == pytest.approx(1.9) and t == 2.0
    frac, t = peak_body_rate_fraction(_mission([]), _truth([0.5, 1.02, 1.9, 1.0]))
    assert frac == pytest.approx(1.9) and t == 2.0


def test_tumbling_start_is_judged_from_the_first_sample_within_the_limit() -> None:
    frac, t = peak_body_rate_fraction(_mission([]), _truth([5.0, 3.0, 0.9, 1.04, 0.2]))
    assert frac == pytest.approx(1.04) and t == 3.0
    assert math.isnan(peak_body_rate_fraction(_mission([]), _truth([]))[0])
