"""Which settling requirements a mission is judged on (hil_sim.sil.judge.settling)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from hil_sim.mission.model import load_mission
from hil_sim.mission.physics_checks import schedule
from hil_sim.sil.judge import settling

MISSIONS = Path(__file__).resolve().parents[2] / "config" / "missions"


def _error_profile(t: np.ndarray, segments, initial_end_deg: float) -> np.ndarray:
    """0.26 deg still off when the initial hold ends (a dispersed start); every slew settles mid-span."""
    err = np.full_like(t, 0.001)
    first = segments[0]
    err[(t >= first.t_start_s) & (t < first.t_end_s)] = initial_end_deg
    for s in segments[1:]:
        err[(t >= s.t_start_s) & (t < 0.5 * (s.t_start_s + s.t_end_s))] = 90.0
    return err


def test_initial_hold_before_a_timeline_slew_is_reported_but_not_judged():
    mission = load_mission(MISSIONS / "demo-pointing.yaml")
    segments = schedule(mission)
    t = np.arange(0.0, mission.duration_s, 0.1)
    spans = settling(mission, t, _error_profile(t, segments, 0.26), segments)
    initial, *slews = spans
    assert not initial["target_from"].startswith("timeline")
    assert initial["settled_at_s"] is None and initial["judged"] is False
    assert slews and all(s["judged"] and s["settled_at_s"] is not None for s in slews)


def test_a_mission_whose_only_manoeuvre_is_the_initial_target_is_judged_on_it():
    mission = load_mission(MISSIONS / "paper-s3-cones.yaml")
    segments = schedule(mission)
    t = np.arange(0.0, mission.duration_s, 0.1)
    err = np.full_like(t, 5.0)  # never settles
    spans = settling(mission, t, err, segments)
    assert spans[-1]["judged"] is True and spans[-1]["settled_at_s"] is None


def test_torque_variation_is_summed_over_each_commanded_span():
    from hil_sim.sil.judge import add_torque_variation

    t = np.arange(0.0, 10.0, 0.1)
    tau = np.zeros((len(t), 2))
    tau[(t > 2.05) & (t < 3.05), 0] = 0.05     # one 50 mN m pulse on wheel 1 in the first span
    tau[t > 6.05, 1] = np.where(np.arange((t > 6.05).sum()) % 2, 0.01, -0.01)  # chatter in the second
    spans = [{"commanded_at_s": 0.0, "until_s": 5.0}, {"commanded_at_s": 5.0, "until_s": 10.0}]
    add_torque_variation(spans, t, tau)
    assert spans[0]["torque_variation_Nm"] == 0.1  # up and down
    n = int((t > 6.05).sum())
    assert abs(spans[1]["torque_variation_Nm"] - (0.01 + 0.02 * (n - 1))) < 1e-12
