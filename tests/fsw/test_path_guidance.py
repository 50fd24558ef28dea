"""Slew path planning round the keep-out zones (fsw.guidance.path_planning) and its use by the POINTING guidance."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig
from fsw.guidance import Guidance
from fsw.guidance.path_planning import PathFollower, densify, plan_path, planning_polygon
from gnc.zones import ConicZone, StarZone


def _dir(lon_deg: float, lat_deg: float) -> np.ndarray:
    lon, lat = math.radians(lon_deg), math.radians(lat_deg)
    return np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])


def _length_deg(vertices: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", vertices[:-1], vertices[1:]), -1, 1))).sum())


def _round_cap_path_deg(d_deg: float, radius_deg: float) -> float:
    """Shortest path between two points at d from a cap's centre, on opposite sides of it (lon -d and
    +d on the equator, cap centred at lon 0): two tangent arcs and the cap's boundary between them."""
    d, r = math.radians(d_deg), math.radians(radius_deg)
    tangent = math.acos(math.cos(d) / math.cos(r))
    at_centre = math.acos(math.tan(r) / math.tan(d))  # angle at the centre between the point and its tangent point
    return math.degrees(2.0 * tangent + math.sin(r) * (math.pi - 2.0 * at_centre))


@pytest.mark.parametrize("radius_deg", [10.0, 25.0, 40.0])
def test_path_round_a_cone_is_the_shortest_one_and_keeps_the_standoff(radius_deg: float) -> None:
    zone = ConicZone(_dir(0, 0), math.radians(radius_deg))
    start, end = _dir(-60, 0), _dir(60, 0)
    path = plan_path(start, end, [zone], standoff_deg=2.0, rays=48)
    assert path is not None and len(path) > 2
    best = _round_cap_path_deg(60.0, radius_deg + 2.0)
    assert best <= _length_deg(path) <= best + 0.3  # the polygon is circumscribed, so never shorter
    dense = densify(path, 0.1)
    margins = np.degrees(np.arccos(np.clip(dense @ zone.axis, -1, 1))) - radius_deg
    assert margins.min() > 2.0 - 1e-6


def test_a_clear_great_circle_is_the_path() -> None:
    zone = ConicZone(_dir(0, 40), math.radians(15.0))
    path = plan_path(_dir(-60, 0), _dir(60, 0), [zone], standoff_deg=2.0)
    assert path is not None and len(path) == 2


def test_two_zones_too_close_to_pass_between_are_passed_round_both() -> None:
    """Gap 3 deg < twice the standoff: the path must not thread it."""
    a, b = ConicZone(_dir(0, 11.5), math.radians(10.0)), ConicZone(_dir(0, -11.5), math.radians(10.0))
    path = plan_path(_dir(-50, 2), _dir(50, -2), [a, b], standoff_deg=2.0)
    assert path is not None
    dense = densify(path, 0.1)
    for z in (a, b):
        assert (np.degrees(np.arccos(np.clip(dense @ z.axis, -1, 1))) - 10.0).min() > 2.0 - 1e-6
    assert np.abs(np.degrees(np.arcsin(dense[:, 2]))).max() > 20.0  # went round, not through


def test_a_star_shaped_zone_is_planned_round_its_convex_hull() -> None:
    """A four-pointed star: its notches are not a way through (the law would have to undo the shortcut)."""
    star = StarZone.polygon(_dir(0, 0), None, vertices=[[math.radians(20), 0], [math.radians(4), math.radians(4)],
                                                       [0, math.radians(20)], [-math.radians(4), math.radians(4)],
                                                       [-math.radians(20), 0], [-math.radians(4), -math.radians(4)],
                                                       [0, -math.radians(20)], [math.radians(4), -math.radians(4)]])
    P, N = planning_polygon(star, 1.0, 48)
    boundary = star.boundary(400)
    assert np.all(boundary @ N.T > 0.0)  # the polygon contains the zone
    assert np.all(star.signed_separation_batch(P) >= 1.0 - math.cos(math.radians(1.0)) - 1e-9)


def test_no_path_when_the_target_is_inside_a_zone() -> None:
    zone = ConicZone(_dir(60, 0), math.radians(10.0))
    assert plan_path(_dir(-60, 0), _dir(60, 1), [zone], standoff_deg=2.0) is None


def test_a_target_within_the_standoff_is_reached_round_the_zone_at_zero_standoff() -> None:
    zone = ConicZone(_dir(0, 0), math.radians(20.0))
    end = _dir(21.0, 0)  # 1 deg outside the zone: inside its standoff polygon
    path = plan_path(_dir(-60, 0), end, [zone], standoff_deg=2.0)
    assert path is not None and np.allclose(path[-1], end)


def test_pursuit_aims_ahead_and_only_moves_forward() -> None:
    path = np.array([_dir(0, 0), _dir(30, 0), _dir(30, 30)])
    f = PathFollower(path, lookahead_deg=6.0)
    k = f.aim_index(_dir(10, 0))
    aim = f.path[k]
    assert math.degrees(math.acos(aim @ _dir(10, 0))) == pytest.approx(6.0, abs=0.5)
    assert aim[1] > _dir(10, 0)[1]  # ahead, not behind
    progress = f.index
    assert f.aim_index(_dir(1, 0)) >= progress and f.index == progress  # pushed back: progress stays
    assert f.aim_index(_dir(30, 27)) == len(f.path) - 1  # within the look-ahead of the end: the end


def _slew_guidance(path_enabled: bool, events=None) -> tuple[Guidance, np.ndarray, np.ndarray]:
    """A 100 deg slew whose great circle crosses a 25 deg Sun-like cone near its middle (inertial zone),
    3 deg inflation, k1 0.3, 1 deg/s: the kinematic loop of the flight guidance."""
    target = _dir(50, -5)
    cfg = FswConfig.model_validate({
        "initial_mode": "POINTING", "spacecraft": {"max_rate_deg_s": 1.0},
        "law": {"k1": 0.3, "margin_deg": 3.0, "eps_max_used": 0.035, "assumption_check": "off"},
        "pointing": {"target_N": list(_dir(-50, 5)), "roll_gain_1_s": 0.0, "path": {"enabled": path_enabled},
                     "zones": [{"name": "sun", "body": "inertial", "direction_N": list(_dir(0, 2)),
                                "geometry": {"shape": "cone", "half_angle_deg": 25.0}}]}})
    g = Guidance(cfg, events)
    q = Rotation.align_vectors([_dir(-50, 5)], [cfg.pointing.boresight_B])[0].as_quat()
    return g, np.array([q[3], q[0], q[1], q[2]]), target


def _slew(g: Guidance, q: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(time to within 0.05 deg [s], smallest physical margin [deg]) with perfect rate tracking at 10 Hz."""
    g.set_target_direction(target)
    dt, worst = 0.1, math.inf
    for k in range(4000):
        out = g.step(k * dt, dt, q, np.zeros(3))
        worst = min(worst, out.margin_min_deg)
        if out.pointing_error_deg < 0.05:
            return k * dt, worst
        w = out.omega_cmd_BN_B
        angle = float(np.linalg.norm(w)) * dt
        dq = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * w / max(np.linalg.norm(w), 1e-300)])
        q = np.array([q[0] * dq[0] - q[1:] @ dq[1:], *(q[0] * dq[1:] + dq[0] * q[1:] + np.cross(q[1:], dq[1:]))])
        q /= np.linalg.norm(q)
    return math.inf, worst


def test_a_slew_blocked_by_a_zone_follows_the_planned_path_and_is_faster() -> None:
    log = []
    planned, q, target = _slew_guidance(True, lambda name, **args: log.append((name, args)))
    t_path, m_path = _slew(planned, q, target)
    straight, q, target = _slew_guidance(False)
    t_law, m_law = _slew(straight, q, target)
    print(f"\nplanned path: {t_path:.1f} s, margin {m_path:.2f} deg; law alone: {t_law:.1f} s, margin {m_law:.2f} deg")
    assert m_path > 3.0 and m_law > 3.0  # outside the inflation both ways: the law still guards the zone
    assert t_path < 0.9 * t_law, (t_path, t_law)
    (name, args), = [e for e in log if e[0] == "PATH_PLANNED"]
    assert args["legs"] >= 2 and args["detour_deg"] > 0.0
