"""`gnc._zone_polygon.contains_point_boxed` (the vertex loop skipped outside the plane box) against the
full crossing-number loop `contains_point` it replaces in the guidance kernels: the same answer and the
same signed separations, on random directions, directions near the zone and its vertices, and edge
inputs (the antipode, NaN)."""
from __future__ import annotations

import math

import numpy as np

from gnc import _zone_polygon as P
from gnc.zones import StarZone


def _zones() -> list:
    rng = np.random.default_rng(17)
    zones = []
    for n in (3, 7, 60, 360):
        ang = np.sort(rng.uniform(0.0, 2.0 * math.pi, n))
        r = rng.uniform(0.3, 1.0, n)
        verts = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1) * rng.uniform(0.05, 0.8)
        axis = rng.normal(size=3)
        zones.append(StarZone.polygon(axis / np.linalg.norm(axis), vertices=verts))
    return zones


def _points(zone, rng) -> np.ndarray:
    e = zone._poly_args[0]
    near = e[:, 0:3][None, :, :] + rng.normal(scale=1e-3, size=(4,) + e[:, 0:3].shape)
    exact = e[:, 0:3]  # the vertices themselves: the crossing test's ties
    axis = zone.bounding_cap[0]
    X = np.concatenate([rng.normal(size=(400, 3)), near.reshape(-1, 3), exact, axis[None], -axis[None],
                        axis[None] + rng.normal(scale=0.05, size=(200, 3))])
    return X / np.linalg.norm(X, axis=1)[:, None]


def test_boxed_containment_and_separation_equal_the_full_loop():
    rng = np.random.default_rng(3)
    for zone in _zones():
        e, m, reach, v, c, B, normal, offset = zone._poly_args
        box = P.polygon_box(v)
        X = _points(zone, rng)
        skipped = 0
        for x in X:
            full = P.contains_point(x, v, c, B, normal, offset)
            assert P.contains_point_boxed(x, v, box, c, B, normal, offset) == full
            for clamp in (False, True):
                a = P.signed_separation_one_boxed(x, e, m, reach, v, box, c, B, normal, offset, clamp)
                assert a == P.signed_separation_one(x, e, m, reach, v, c, B, normal, offset, clamp)
            xn = float(x @ normal)
            if xn > 0.0:
                p = B.T @ (x * (offset / xn) - c)
                skipped += not (box[0] <= p[0] <= box[1] and box[2] <= p[1] < box[3])
        assert skipped > 0  # the precheck does skip


def test_boxed_containment_edge_inputs():
    zone = _zones()[2]
    e, m, reach, v, c, B, normal, offset = zone._poly_args
    box = P.polygon_box(v)
    for x in (np.array([np.nan, 0.0, 1.0]), np.array([0.0, 0.0, 0.0]), np.array([np.inf, 1.0, 0.0]),
              -np.asarray(normal), np.asarray(normal), np.asarray(normal) * 1e-300):
        assert P.contains_point_boxed(x, v, box, c, B, normal, offset) == P.contains_point(x, v, c, B, normal, offset)
    # a point projecting exactly onto the box's top edge and onto a vertex's line
    top = v[int(np.argmax(v[:, 1]))]
    for p in (top, top + np.array([0.0, 1e-17]), np.array([box[1], top[1] * 0.5]), np.array([box[0], 0.0])):
        x = c + B @ p
        x = x / np.linalg.norm(x)
        assert P.contains_point_boxed(x, v, box, c, B, normal, offset) == P.contains_point(x, v, c, B, normal, offset)
