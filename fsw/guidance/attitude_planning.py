"""Slew planning for QUATERNION mode: a path on S^3 round the forbidden-attitude zones, as POINTING plans
on S^2 (`path_planning`), flown by pursuit with the paper's law guarding every zone.

The S^3 law heads along the geodesic to its target and turns only in a zone's eps-layer, so a slew whose
geodesic crosses a zone runs into the layer and slides round it. Here each zone is replaced by its
bounding cap (a geodesic ball containing it: exact for a cone, conservative for a star-shaped zone) grown
by a standoff, and the slew by the shortest path through at most one waypoint whose two geodesic legs
clear every ball: the waypoints tried lie just outside the balls the geodesic hits, in every direction
round them (a 3-D tangent space at the ball's centre, sampled evenly). A geodesic's distance to a ball is
exact in closed form, so the legs are tested exactly. A slew that needs more than one waypoint, or starts
or ends inside a ball, is left to the law alone (it is still safe, only slower).

Then, as in POINTING, the law's target x_d is the path point a look-ahead beyond the attitude, the real
target on the last leg, and the law runs on the inflated zones with its eps chosen for that x_d, so the
paper's invariance of the inflated zones holds whatever x_d is: the plan only chooses which way round.
Angles on S^3 are quaternion angles: a rotation by phi moves the quaternion by phi / 2.
"""
from __future__ import annotations

import math

import numpy as np

from gnc.sky_zones import cap_of

TANGENT_DIRECTIONS = 240               # directions round each ball, evenly on the tangent 2-sphere
RADIUS_STEPS_DEG = (0.5, 3.0, 8.0, 15.0)  # how far outside the grown ball the waypoints are tried


def _tangent_directions(n: int) -> np.ndarray:
    """n unit vectors spread evenly on S^2 (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


_DIRECTIONS = _tangent_directions(TANGENT_DIRECTIONS)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, float(a @ b))))


def arc_distance(a: np.ndarray, b: np.ndarray, g: np.ndarray) -> float:
    """Angle [rad] from the point ``g`` to the shorter geodesic arc a -> b (unit vectors of any dimension)."""
    ang = _angle(a, b)
    if ang < 1e-12:
        return _angle(a, g)
    e = b - (a @ b) * a
    e /= np.linalg.norm(e)  # a, e: orthonormal basis of the arc's plane, the arc at angles [0, ang]
    ga, ge = float(g @ a), float(g @ e)
    theta = math.atan2(ge, ga)
    if 0.0 <= theta <= ang:
        return math.acos(max(-1.0, min(1.0, math.hypot(ga, ge))))
    return min(_angle(a, g), _angle(b, g))


def _clear(a: np.ndarray, b: np.ndarray, balls: list[tuple[np.ndarray, float]]) -> bool:
    return all(arc_distance(a, b, g) > r for g, r in balls)


def _around(g: np.ndarray, radius: float) -> np.ndarray:
    """Points at angle ``radius`` from ``g`` on S^3, in the evenly spread tangent directions."""
    Q, _ = np.linalg.qr(np.column_stack([g, np.eye(4)]))  # first column +-g, the next three span its tangent space
    T = _DIRECTIONS @ Q[:, 1:4].T
    return math.cos(radius) * g + math.sin(radius) * T


def plan_attitude_path(x: np.ndarray, x_d: np.ndarray, zones: list, standoff_deg: float) -> np.ndarray | None:
    """Vertices (x, [waypoint,] x_d) of the shortest path found from the (lifted) quaternion ``x`` to
    ``x_d`` keeping ``standoff_deg`` (quaternion angle) from every zone's bounding ball, or None (the law
    alone flies it). A ball within the standoff of x or x_d is passed at zero standoff."""
    x, x_d = np.asarray(x, dtype=float), np.asarray(x_d, dtype=float)
    s = math.radians(standoff_deg)
    balls = []
    for z in zones:
        g, r = cap_of(z)
        if min(_angle(x, g), _angle(x_d, g)) <= r:
            return None  # starting or ending inside a ball: no geodesic leg can clear it
        grown = r + s if min(_angle(x, g), _angle(x_d, g)) > r + s else r
        balls.append((g, grown))
    if _clear(x, x_d, balls):
        return np.array([x, x_d])
    best, best_len = None, math.inf
    for g, r in balls:
        if arc_distance(x, x_d, g) > r:
            continue  # this ball is not in the way
        for step in RADIUS_STEPS_DEG:
            for w in _around(g, r + math.radians(step)):
                length = _angle(x, w) + _angle(w, x_d)
                if length < best_len and all(_angle(w, h) > rh for h, rh in balls) \
                        and _clear(x, w, balls) and _clear(w, x_d, balls):
                    best, best_len = w, length
    return None if best is None else np.array([x, best, x_d])
