"""SAFE in low orbit: the Sun-safe aim is chosen again when a zone moves over it. The Earth's zone sweeps
round the sky once an orbit; before 2026-11-29 an aim it covered stayed the aim until the Sun itself had
moved 1 deg, and the boresight was left pressed against the moving zone's edge (the detumble mission touched
the physical Earth zone by 0.013 deg in SAFE)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fsw.guidance import Guidance, signed_margin_deg
from hil_sim.mission.model import load_mission

MISSION = Path(__file__).resolve().parents[2] / "config" / "missions" / "smallsat-example.yaml"


def _in_sun_acquisition() -> tuple[Guidance, np.ndarray]:
    g = Guidance(load_mission(MISSION).flight_software)
    g.set_mode("SAFE")
    q = np.array([1.0, 0.0, 0.0, 0.0])
    for k in range(12):  # 1 s of rate damping at rest, then Sun acquisition
        g.step(0.1 * k, 0.1, q, np.zeros(3))
    assert g.safe_phase == "SUN_ACQUISITION"
    return g, q


def test_a_clear_aim_is_kept() -> None:
    g, q = _in_sun_acquisition()
    aim = g.target_N.copy()
    assert all(signed_margin_deg(s.law, aim) > 0.0 for s in g.slots)
    g.step(1.3, 0.1, q, np.zeros(3))
    assert np.array_equal(g.target_N, aim)


def test_an_aim_a_zone_has_moved_over_is_chosen_again_clear_of_it() -> None:
    g, q = _in_sun_acquisition()
    earth = next(s for s in g.slots if s.body == "earth")
    g.target_N = np.array(earth.center_N, dtype=float)  # the Earth's zone over the aim
    assert signed_margin_deg(earth.law, g.target_N) < 0.0
    g.step(1.3, 0.1, q, np.zeros(3))
    assert all(signed_margin_deg(s.law, g.target_N) > 0.0 for s in g.slots)
