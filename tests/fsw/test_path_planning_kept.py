"""`plan_path` with the caller's kept polygons (``kept``): the same paths as planning afresh, the polygons
reused only for the same zone object, standoff and rays."""
from __future__ import annotations

import math

import numpy as np

from fsw.guidance.path_planning import plan_path, planning_polygon
from gnc.zones import ConicZone, StarZone


def _dir(lon_deg: float, lat_deg: float) -> np.ndarray:
    lon, lat = math.radians(lon_deg), math.radians(lat_deg)
    return np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])


def _zones() -> list:
    ang = np.linspace(0.0, 2.0 * math.pi, 7, endpoint=False)
    verts = 0.2 * np.stack([np.cos(ang), np.sin(ang)], axis=1) * (1.0 + 0.3 * np.cos(3 * ang))[:, None]
    return [ConicZone(_dir(0, 11.5), math.radians(10.0)), ConicZone(_dir(0, -11.5), math.radians(10.0)),
            StarZone.polygon(_dir(20, 30), vertices=verts)]


def _same(a, b) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))


def test_kept_polygons_give_the_same_paths_as_planning_afresh() -> None:
    rng = np.random.default_rng(5)
    zones = _zones()
    kept: dict = {}
    for _ in range(30):
        start, end = rng.normal(size=3), rng.normal(size=3)
        start, end = start / np.linalg.norm(start), end / np.linalg.norm(end)
        for standoff in (2.0, 0.0):
            assert _same(plan_path(start, end, zones, standoff, 48, kept), plan_path(start, end, zones, standoff, 48))
    # a start inside a zone's standoff: that zone planned round at zero standoff, kept apart
    start = _dir(0, 22.5)
    assert _same(plan_path(start, _dir(60, 0), zones, 2.0, 48, kept), plan_path(start, _dir(60, 0), zones, 2.0, 48))


def test_kept_polygon_only_for_the_same_zone_object_and_parameters() -> None:
    zone = _zones()[0]
    kept: dict = {}
    plan_path(_dir(-60, 0), _dir(60, 0), [zone], 2.0, 48, kept)
    (key, (z, poly)), = kept.items()
    assert z is zone and key == (id(zone), 2.0, 48)
    ref = planning_polygon(zone, 2.0, 48)
    assert np.array_equal(poly[0], ref[0]) and np.array_equal(poly[1], ref[1])
    assert not poly[0].flags.writeable  # shared between plans: read-only
    plan_path(_dir(-60, 0), _dir(60, 0), [zone], 2.0, 24, kept)
    assert len(kept) == 2  # other rays: another polygon
    other = ConicZone(_dir(0, 11.5), math.radians(10.0))  # equal, but another object
    plan_path(_dir(-60, 0), _dir(60, 0), [other], 2.0, 48, kept)
    assert len(kept) == 3 or kept[(id(other), 2.0, 48)][0] is other
