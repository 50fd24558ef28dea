"""Compiled kernels for a star-polygon zone on S^2.

The planar polygon O = {c + B p : p in K}, K a polygon star-shaped about 0, projects to a spherical
polygon whose edges are great-circle arcs (the paper's lemma Q(a, b) = G(psi(a), psi(b))). The
separation to one arc has a closed form: with m the unit normal of the arc's great circle and
x_t = x - (x^T m) m the projection of x onto that plane, the nearest point of the full circle is
x_t / |x_t|; if it lies on the arc, d_s = 1 - |x_t| = s^2 / (1 + sqrt(1 - s^2)) (s = x^T m, written
without cancellation), otherwise the nearest point is the nearer end point. The zone's separation
is the minimum over its edges.

Edge rows: [a (3), b (3), m (3)] with a, b the projected vertices and m = a x b / |a x b|.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _edge_nearest(x, edge, out):
    """Nearest point of one arc to x; returns |x - b|^2 / 2 and fills out (3)."""
    s = x[0] * edge[6] + x[1] * edge[7] + x[2] * edge[8]
    t0 = x[0] - s * edge[6]
    t1 = x[1] - s * edge[7]
    t2 = x[2] - s * edge[8]
    nt = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if nt > 0.0:
        # inside the arc's wedge: (a x t) . m >= 0 and (t x b) . m >= 0
        ax = edge[1] * t2 - edge[2] * t1
        ay = edge[2] * t0 - edge[0] * t2
        az = edge[0] * t1 - edge[1] * t0
        bx = t1 * edge[5] - t2 * edge[4]
        by = t2 * edge[3] - t0 * edge[5]
        bz = t0 * edge[4] - t1 * edge[3]
        if (ax * edge[6] + ay * edge[7] + az * edge[8] >= 0.0
                and bx * edge[6] + by * edge[7] + bz * edge[8] >= 0.0):
            out[0] = t0 / nt
            out[1] = t1 / nt
            out[2] = t2 / nt
            # 1 - |x_t| for |x| = 1, free of cancellation; the x-norm error stays at 1e-16.
            return s * s / (1.0 + math.sqrt(max(0.0, 1.0 - s * s)))
    da = 0.5 * ((x[0] - edge[0]) ** 2 + (x[1] - edge[1]) ** 2 + (x[2] - edge[2]) ** 2)
    db = 0.5 * ((x[0] - edge[3]) ** 2 + (x[1] - edge[4]) ** 2 + (x[2] - edge[5]) ** 2)
    if da <= db:
        out[0] = edge[0]
        out[1] = edge[1]
        out[2] = edge[2]
        return da
    out[0] = edge[3]
    out[1] = edge[4]
    out[2] = edge[5]
    return db


# Angle [rad] added to the culling bound of `nearest_on_boundary`: covers the rounding of the edge values,
# of x . mid and of acos (at most ~1e-8 rad), so an edge is only skipped when it is certainly farther.
_CULL_SLACK_RAD = 1e-6


def edge_midpoints(edges: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit midpoint of every arc (n, 3), largest half-arc angle + slack [rad]): the culling data of
    `nearest_on_boundary`. Every point of arc k is within its half-arc angle of the arc's midpoint."""
    a, b = edges[:, 0:3], edges[:, 3:6]
    s = a + b
    ns = np.linalg.norm(s, axis=1)
    half = np.arctan2(np.linalg.norm(a - b, axis=1), ns)
    return np.ascontiguousarray(s / ns[:, None]), float(half.max()) + _CULL_SLACK_RAD


@njit(cache=True)
def _nearest_of_edges(x, edges, cosines, cos_min, b_out):
    """min over the edges k with cosines[k] >= cos_min (all of them for cos_min = -inf), in index order;
    fills the nearest boundary point b_out."""
    best = 1e300
    tmp = np.empty(3)
    for k in range(edges.shape[0]):
        if cosines[k] < cos_min:
            continue
        d = _edge_nearest(x, edges[k], tmp)
        if d < best:
            best = d
            b_out[0] = tmp[0]
            b_out[1] = tmp[1]
            b_out[2] = tmp[2]
    return best


@njit(cache=True)
def nearest_on_boundary(x, edges, mids, reach, b_out):
    """min over edges of the arc separation; fills the nearest boundary point b_out.

    Exact, with most edges skipped: the arc whose midpoint is nearest x gives an upper bound d0 on the
    minimum (an angle theta0 = acos(1 - d0)); an arc whose midpoint is farther than theta0 + ``reach`` (its
    half-length and a rounding slack, `edge_midpoints`) from x cannot come nearer than theta0, so only the
    others are evaluated, in index order as in a full pass: same minimum, same nearest point. Needs a unit
    x (|x|^2 within 1e-12 of 1), else every edge is evaluated."""
    n = edges.shape[0]
    cosines = np.zeros(n)
    cos_min = -math.inf  # evaluate every edge
    if abs(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] - 1.0) <= 1e-12:
        k0, c0 = 0, -2.0
        for k in range(n):
            c = x[0] * mids[k, 0] + x[1] * mids[k, 1] + x[2] * mids[k, 2]
            cosines[k] = c
            if c > c0:
                k0, c0 = k, c
        limit = math.acos(max(-1.0, min(1.0, 1.0 - _edge_nearest(x, edges[k0], np.empty(3))))) + reach
        if limit < math.pi:
            cos_min = math.cos(limit)
    return _nearest_of_edges(x, edges, cosines, cos_min, b_out)


@njit(cache=True)
def nearest_on_boundary_full(x, edges, b_out):
    """`nearest_on_boundary` evaluating every edge (the reference the culled one is tested against)."""
    return _nearest_of_edges(x, edges, np.zeros(edges.shape[0]), -math.inf, b_out)


@njit(cache=True)
def _plane_point(x, c, B, plane_normal, plane_offset):
    """(in front, px, py): whether x projects onto the plane at all (x . n > 0), and its plane point."""
    xn = x[0] * plane_normal[0] + x[1] * plane_normal[1] + x[2] * plane_normal[2]
    if xn <= 0.0:
        return False, 0.0, 0.0
    scale = plane_offset / xn
    px = 0.0
    py = 0.0
    for i in range(3):
        v = x[i] * scale - c[i]
        px += B[i, 0] * v
        py += B[i, 1] * v
    return True, px, py


@njit(cache=True)
def _crossing_number_odd(vertices, px, py):
    """Whether the ray from (px, py) towards +x crosses the polygon's edges an odd number of times."""
    inside = False
    m = vertices.shape[0]
    j = m - 1
    for i in range(m):
        xi, yi = vertices[i, 0], vertices[i, 1]
        xj, yj = vertices[j, 0], vertices[j, 1]
        if (yi > py) != (yj > py):
            xcross = xi + (py - yi) * (xj - xi) / (yj - yi)
            if px < xcross:
                inside = not inside
        j = i
    return inside


@njit(cache=True)
def contains_point(x, vertices, c, B, plane_normal, plane_offset):
    """Crossing-number test of the central projection of x onto the plane against the polygon."""
    front, px, py = _plane_point(x, c, B, plane_normal, plane_offset)
    if not front:
        return False
    return _crossing_number_odd(vertices, px, py)


# Relative margin of `polygon_box`'s x range: the crossing abscissa xi + (py - yi)(xj - xi)/(yj - yi) of
# `contains_point` lies between xi and xj up to a few rounding errors of the largest coordinate (~1e-15 of
# it); 1e-9 of it covers that many times over.
_BOX_MARGIN_REL = 1e-9


def polygon_box(vertices: np.ndarray) -> np.ndarray:
    """(x_min - margin, x_max + margin, y_min, y_max) of the plane vertices (n, 2): the precheck of
    `contains_point_boxed`."""
    v = np.asarray(vertices, dtype=np.float64)
    margin = _BOX_MARGIN_REL * float(np.abs(v).max()) + 1e-300
    return np.array([float(v[:, 0].min()) - margin, float(v[:, 0].max()) + margin,
                     float(v[:, 1].min()), float(v[:, 1].max())])


@njit(cache=True)
def contains_point_boxed(x, vertices, box, c, B, plane_normal, plane_offset):
    """`contains_point` with the vertex loop skipped when the projected point lies outside ``box``
    (`polygon_box`), where the loop's answer is False anyway. py >= y_max or py < y_min: no edge has
    (yi > py) != (yj > py), so nothing toggles (exact comparisons). Otherwise the edges crossing the
    line y = py are even in number (the cyclic sequence yi > py changes value an even number of times),
    and every crossing abscissa is within the margin of [x_min, x_max]: px left of the box toggles at
    all of them, right of it at none; both give False. NaN fails every comparison and takes the loop."""
    front, px, py = _plane_point(x, c, B, plane_normal, plane_offset)
    if not front:
        return False
    if py >= box[3] or py < box[2] or px < box[0] or px > box[1]:
        return False
    return _crossing_number_odd(vertices, px, py)


@njit(cache=True, inline="always")
def _signed_from_inside(x, inside, edges, mids, reach, clamp):
    # both containment tests give the same answer; only the boundary search is shared
    if inside and clamp:
        return 0.0
    b = np.empty(3)
    d = nearest_on_boundary(x, edges, mids, reach, b)
    return -d if inside else d


@njit(cache=True)
def signed_separation_one_boxed(x, edges, mids, reach, vertices, box, c, B, plane_normal, plane_offset, clamp):
    """`signed_separation_one` with `contains_point_boxed` (the same number)."""
    inside = contains_point_boxed(x, vertices, box, c, B, plane_normal, plane_offset)
    return _signed_from_inside(x, inside, edges, mids, reach, clamp)


@njit(cache=True)
def signed_separation_one(x, edges, mids, reach, vertices, c, B, plane_normal, plane_offset, clamp):
    """Signed separation of one x (negative inside); clamp=True gives 0 inside."""
    inside = contains_point(x, vertices, c, B, plane_normal, plane_offset)
    return _signed_from_inside(x, inside, edges, mids, reach, clamp)


@njit(cache=True)
def signed_separation_batch(X, edges, mids, reach, vertices, c, B, plane_normal, plane_offset, clamp):
    m = X.shape[0]
    out = np.empty(m)
    b = np.empty(3)
    for r in range(m):
        d = nearest_on_boundary(X[r], edges, mids, reach, b)
        if contains_point(X[r], vertices, c, B, plane_normal, plane_offset):
            out[r] = 0.0 if clamp else -d
        else:
            out[r] = d
    return out
