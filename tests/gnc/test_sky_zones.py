"""gnc.sky_zones: sky frame, angular shapes, margin inflation, merging, checked by brute force."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gnc import sky_zones as sz


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _angle_deg(a, b) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(np.dot(a, b))))))


def _offset(c, basis_rows, x_deg, y_deg):
    """Point at angular offset (x, y) deg from c along the local axes (exact great-circle offset)."""
    r = math.radians(math.hypot(x_deg, y_deg))
    d = (x_deg * basis_rows[0] + y_deg * basis_rows[1]) / max(math.hypot(x_deg, y_deg), 1e-12)
    return math.cos(r) * c + math.sin(r) * d


def test_sky_frame_points_north_and_east() -> None:
    c = _unit([1.0, 1.0, 0.3])
    x, y = sz.sky_frame(c)
    assert abs(x @ c) < 1e-12 and abs(y @ c) < 1e-12 and abs(x @ y) < 1e-12
    assert x[2] > 0  # north has a +z component
    np.testing.assert_allclose(np.cross(x, y), -c, atol=1e-12)  # north x east = -c: the sky seen from inside
    # east is the direction of increasing right ascension
    ra = math.atan2(c[1], c[0])
    east = np.array([-math.sin(ra), math.cos(ra), 0.0])
    np.testing.assert_allclose(y, east, atol=1e-12)
    x30, _ = sz.sky_frame(c, 30.0)
    assert _angle_deg(x30, x) == pytest.approx(30.0)
    assert x30 @ y > 0  # rotated from north towards east
    # at the pole the frame is still orthonormal
    xp, yp = sz.sky_frame(np.array([0.0, 0.0, 1.0]))
    assert abs(xp @ yp) < 1e-12 and abs(np.linalg.norm(xp) - 1) < 1e-12


def test_cone_is_exact_and_inflates_by_the_margin() -> None:
    c = _unit([0.2, -0.5, 0.8])
    zone = sz.cone_zone(c, 20.0, margin_deg=3.0)
    frame = sz.sky_frame(c)
    p = _offset(c, frame, 30.0, 0.0)
    assert zone.separation(p) == pytest.approx(1 - math.cos(math.radians(7.0)), rel=1e-9)
    assert zone.contains(_offset(c, frame, 0.0, 22.9)) and not zone.contains(_offset(c, frame, 0.0, 23.1))


@pytest.mark.parametrize("fast", [False, True])
def test_superellipse_extent_along_its_axes_matches_the_angles(fast: bool) -> None:
    c = _unit([0.3, 0.9, -0.2])
    shape = {"shape": "superellipse", "semi_axes_deg": [25.0, 12.0], "exponent": 0.7, "orientation_deg": 40.0}
    zone = sz.build_sky_zone(shape, c, fast=fast)
    frame = sz.sky_frame(c, 40.0)
    tol = 0.05 if fast else 1e-3
    for x_deg, y_deg, inside in ((25 - tol, 0, True), (25 + tol, 0, False), (0, 12 - tol, True), (0, 12 + tol, False),
                                 (-25 + tol, 0, True), (0, -12 - tol, False)):
        assert zone.contains(_offset(c, frame, x_deg, y_deg)) == inside, (x_deg, y_deg)
    # the star shape (p < 1) is concave: the diagonal point at 60 % of both semi-axes is outside
    assert not zone.contains(_offset(c, frame, 0.6 * 25 / math.sqrt(2) * math.sqrt(2), 0.6 * 12))


def test_polygon_vertices_lie_on_the_boundary() -> None:
    c = _unit([-0.4, 0.1, 0.9])
    verts = [[20, 0], [4, 4], [0, 15], [-4, 4], [-20, 0], [-4, -4], [0, -15], [4, -4]]
    zone = sz.polygon_zone(c, verts, orientation_deg=-15.0)
    frame = sz.sky_frame(c, -15.0)
    for vx, vy in verts:
        r = math.hypot(vx, vy)
        assert zone.contains(_offset(c, frame, vx * (r - 0.01) / r, vy * (r - 0.01) / r))
        assert not zone.contains(_offset(c, frame, vx * (r + 0.01) / r, vy * (r + 0.01) / r))


@pytest.mark.parametrize(
    "shape",
    [
        {"shape": "superellipse", "semi_axes_deg": [25.0, 12.0], "exponent": 0.7, "orientation_deg": 20.0},
        {"shape": "polygon", "vertices_deg": [[20, 0], [4, 4], [0, 15], [-4, 4], [-20, 0], [-4, -4], [0, -15], [4, -4]]},
    ],
)
def test_inflated_zone_contains_the_margin_neighbourhood_and_no_more_than_needed(shape) -> None:
    c = _unit([0.6, -0.3, 0.5])
    margin = 3.0
    phys = sz.build_sky_zone(shape, c)
    infl = sz.build_sky_zone(shape, c, margin_deg=margin)
    # Brute force distance to the physical zone from a dense boundary sample (independent of gnc.zones).
    B = phys.boundary(4000)
    rng = np.random.default_rng(3)
    X = rng.normal(size=(6000, 3))
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    X = X[(X @ c) > math.cos(math.radians(40.0))]
    dist = np.degrees(np.arccos(np.clip(X @ B.T, -1, 1))).min(axis=1)
    inside_phys = np.array([phys.contains(x) for x in X])
    d_signed = np.where(inside_phys, 0.0, dist)
    contained = np.array([infl.contains(x) for x in X])
    near = d_signed < margin - 0.02
    assert np.all(contained[near]), "a point closer than the margin is outside the inflated zone"
    # Not grossly larger: points farther than margin + 1.5 deg are outside (radial hull slack is small).
    far = d_signed > margin + 1.5
    assert not np.any(contained[far])


def test_enclosing_cone_contains_both_zones_and_has_the_closed_form_radius() -> None:
    a = sz.cone_zone(_unit([1, 0, 0]), 10.0)
    b = sz.cone_zone(_unit([math.cos(0.5), math.sin(0.5), 0]), 5.0)
    merged = sz.enclosing_cone([sz.cap_of(a), sz.cap_of(b)])
    _, r = sz.cap_of(merged)
    assert math.degrees(r) == pytest.approx((math.degrees(0.5) + 10 + 5) / 2)
    for z in (a, b):
        assert all(merged.contains(p) or merged.separation(p) < 1e-12 for p in z.boundary(200))
    # one cap inside the other: the larger is returned unchanged
    inner = sz.enclosing_cone([sz.cap_of(a), (np.array([1.0, 0, 0]), math.radians(2))])
    assert math.degrees(sz.cap_of(inner)[1]) == pytest.approx(10.0)


def test_bad_shapes_are_rejected_with_a_clear_message() -> None:
    with pytest.raises(ValueError, match="unknown sky-zone shape"):
        sz.build_sky_zone({"shape": "blob"}, np.array([1.0, 0, 0]))
    with pytest.raises(ValueError, match="at least 3"):
        sz.polygon_zone(np.array([1.0, 0, 0]), [[1, 0], [0, 1]])
    with pytest.raises(ValueError, match="non-zero"):
        sz.cone_zone(np.zeros(3), 10.0)


def test_bridge_zone_contains_both_caps_and_is_star_shaped_about_their_overlap() -> None:
    import math

    from gnc.sky_zones import bridge_zone
    from gnc.zones import ConicZone

    rng = np.random.default_rng(3)
    built = 0
    for _ in range(25):
        a = rng.standard_normal(3)
        a /= np.linalg.norm(a)
        ra, rb = np.radians(rng.uniform(5.0, 25.0, 2))
        d = ra + rb + math.radians(rng.uniform(-10.0, 4.0))  # overlapping, touching or a few deg apart
        p = np.cross(a, rng.standard_normal(3))
        p /= np.linalg.norm(p)
        b = math.cos(d) * a + math.sin(d) * p
        zone = bridge_zone((a, ra), (b, rb))
        assert zone is not None
        built += 1
        for cap in (ConicZone(a, ra), ConicZone(b, rb)):
            assert cap.contains(zone.kernel) or cap.separation(zone.kernel) < math.radians(4.0)
            assert all(zone.separation(x) < 1e-9 for x in cap.boundary(600)[::3])
        # not a blanket: far from both caps stays free
        far = -(a + b) / np.linalg.norm(a + b)
        assert zone.separation(far) > 0.5
    assert built == 25


def test_bridge_zone_refuses_caps_it_cannot_cover_from_one_kernel() -> None:
    from gnc.sky_zones import bridge_zone

    a, b = np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    assert bridge_zone((a, np.radians(60.0)), (b, np.radians(60.0))) is None
