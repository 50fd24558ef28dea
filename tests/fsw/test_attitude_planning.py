"""QUATERNION-mode slew planning on S^3: the geometry of the planner (exact geodesic-to-ball
distances, checked by dense sampling) and a blocked slew flown by the flight guidance, planned round the
forbidden-attitude zone with every margin kept and faster than the paper's law alone.

Kinematic loop: perfect rate tracking at 10 Hz (scipy's Rotation integrates the commanded body rate)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig
from fsw.guidance import Guidance
from fsw.guidance.attitude_planning import arc_distance, plan_attitude_path


def _q(rot: Rotation) -> np.ndarray:
    return np.roll(rot.as_quat(), 1)  # scalar first


def test_arc_distance_matches_dense_sampling_on_s3() -> None:
    rng = np.random.default_rng(5)
    for _ in range(200):
        a, b, g = (v / np.linalg.norm(v) for v in rng.normal(size=(3, 4)))
        ang = math.acos(np.clip(a @ b, -1, 1))
        e = (b - (a @ b) * a) / np.linalg.norm(b - (a @ b) * a)
        s = np.linspace(0.0, ang, 20001)
        arc = np.cos(s)[:, None] * a + np.sin(s)[:, None] * e
        brute = float(np.arccos(np.clip(arc @ g, -1, 1)).min())
        assert arc_distance(a, b, g) == pytest.approx(brute, abs=1e-6)


def _cfg(path: bool, zones: list, target: np.ndarray) -> FswConfig:
    return FswConfig.model_validate({
        "initial_mode": "QUATERNION", "spacecraft": {"max_rate_deg_s": 1.0},
        "law": {"k1": 0.3, "margin_deg": 2.0, "eps_max_used": 0.035, "assumption_check": "off"},
        "quaternion": {"target_q_NB": list(target), "law": "star", "zones": zones, "path": {"enabled": path}}})


START = _q(Rotation.identity())
TARGET = _q(Rotation.from_rotvec(np.radians([0.0, 0.0, 150.0])))
MIDDLE = _q(Rotation.from_rotvec(np.radians([0.0, 4.0, 75.0])))  # near the geodesic's middle
ZONES = [{"shape": "cone", "name": "radiator-sun", "center_q": list(MIDDLE), "half_angle_deg": 10.0}]


def test_planned_path_clears_every_zone_ball_by_the_standoff() -> None:
    from fsw.guidance import Guidance

    g = Guidance(_cfg(True, ZONES, TARGET))
    path = plan_attitude_path(START, TARGET, g.s3_law_zones, 2.0)
    assert path is not None and len(path) == 3
    axis, radius = g.s3_law_zones[0].bounding_cap
    for a, b in zip(path[:-1], path[1:]):
        assert arc_distance(a, b, np.asarray(axis)) > radius + math.radians(2.0) - 1e-9
    assert arc_distance(START, TARGET, np.asarray(axis)) < radius  # the geodesic itself was blocked


def _slew(path: bool, events: list) -> tuple[float, float]:
    """(time to within 0.1 deg [s], smallest physical margin [deg])."""
    g = Guidance(_cfg(path, ZONES, TARGET), lambda name, **args: events.append((name, args)))
    q, worst = START.copy(), math.inf
    for k in range(6000):
        out = g.step(0.1 * k, 0.1, q, np.zeros(3))
        worst = min(worst, out.margin_min_deg)
        if out.att_error_deg < 0.1:
            return 0.1 * k, worst
        r = Rotation.from_quat(np.roll(q, -1)) * Rotation.from_rotvec(out.omega_cmd_BN_B * 0.1)
        q = _q(r)
    return math.inf, worst


def test_a_blocked_quaternion_slew_is_planned_flown_with_margins_and_faster_than_the_law_alone() -> None:
    events: list = []
    t_path, m_path = _slew(True, events)
    t_law, m_law = _slew(False, [])
    print(f"\nS^3 planned: {t_path:.1f} s, margin {m_path:.2f} deg; law alone: {t_law:.1f} s, margin {m_law:.2f} deg")
    assert any(n == "PATH_PLANNED" for n, _ in events)
    assert m_path > 2.0 - 0.05 and m_law > 2.0 - 0.05  # outside the inflated zone both ways: the law guards it
    assert t_path < 0.9 * t_law, (t_path, t_law)
