"""gnc.zones against brute force.

The references here are independent of gnc's search code: dense samples of a smooth boundary
parameterisation (numpy, millions of points; for superellipsoids p_k = a_k sign(w_k)|w_k|^(2/q) with
w on a sphere, which resolves the cusped spikes) followed by local polishing with scipy
(Nelder-Mead / bounded Brent) around several distinct best samples. Agreement is required to 1e-9
absolute in d_s, everywhere including just outside cusp tips and across the fins (creases).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize, minimize_scalar

from gnc.sphere import geodesic, sample_uniform
from gnc.zones import ConicZone, StarZone, default_tangent_basis, paper_s3_star_zone

TOL = 1e-9


# ------------------------------------------------------------------------------------------------
# independent brute force
def _fib_sphere(count):
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


class BruteSuperellipsoid:
    """max of x.b over b = psi(c + B (a * sign(w)|w|^(2/q))), w dense on S^(n-1), then polished."""

    def __init__(self, c, B, a, q, count):
        self.c, self.B, self.a, self.q = np.asarray(c, float), np.asarray(B, float), np.asarray(a, float), q
        self.n = self.B.shape[1]
        if self.n == 2:
            t = 2 * np.pi * np.arange(count) / count
            self.W = np.stack([np.cos(t), np.sin(t)], axis=1)
            self.t = t
        else:
            self.W = _fib_sphere(count)
        self.P = self.map(self.W)

    def map(self, W):
        W = np.atleast_2d(W)
        W = W / np.linalg.norm(W, axis=1, keepdims=True)
        p = self.a * np.sign(W) * np.abs(W) ** (2.0 / self.q)
        Y = self.c + p @ self.B.T
        return Y / np.linalg.norm(Y, axis=1, keepdims=True)

    def inside(self, x):
        foot = self.c - self.B @ (self.B.T @ self.c)
        nu = foot / np.linalg.norm(foot)
        if x @ nu <= 0:
            return False
        p = self.B.T @ (x * np.linalg.norm(foot) / (x @ nu) - self.c)
        return float(np.sum(np.abs(p / self.a) ** self.q)) <= 1.0

    def distance(self, x, starts=8):
        f = self.P @ x
        top = np.flatnonzero(f >= f.max() - 0.02)  # cheaper than a full argpartition of 1e6 values
        if len(top) > 3000:
            top = top[np.argpartition(-f[top], 3000)[:3000]]
        top = top[np.argsort(-f[top])]
        # greedy choice of up to `starts` well separated (in w) best samples
        free = np.ones(len(top), dtype=bool)
        chosen = []
        while len(chosen) < starts and free.any():
            j = top[np.argmax(free)]
            chosen.append(j)
            free &= np.linalg.norm(self.W[top] - self.W[j], axis=1) > 0.03
        best_f, best_b = -2.0, None
        for j in chosen:
            b = self._polish(x, j)
            fb = float(b @ x)
            if fb > best_f:
                best_f, best_b = fb, b
        return 0.5 * float(np.sum((x - best_b) ** 2)), best_b

    def _polish(self, x, j):
        if self.n == 2:
            dt = 4 * 2 * np.pi / len(self.t)
            t0 = self.t[j]
            fun = lambda t: -float(self.map(np.array([math.cos(t), math.sin(t)]))[0] @ x)
            res = minimize_scalar(fun, bounds=(t0 - dt, t0 + dt), method="bounded", options={"xatol": 1e-14})
            t = res.x if res.fun <= fun(t0) else t0
            return self.map(np.array([math.cos(t), math.sin(t)]))[0]
        # n = 3: successive refinement of a 21 x 21 grid in tangent coordinates around the sample
        # (vectorised, no assumption beyond local unimodality at the grid scale)
        w0 = self.W[j]
        e = np.zeros(3)
        e[np.argmin(np.abs(w0))] = 1
        t1 = np.cross(w0, e)
        t1 /= np.linalg.norm(t1)
        T = np.stack([t1, np.cross(w0, t1)], axis=1)
        offsets = np.stack(np.meshgrid(np.arange(-10, 11), np.arange(-10, 11), indexing="ij"), -1).reshape(-1, 2)
        z = np.zeros(2)
        h = 0.004
        for _ in range(300):
            Z = z + h * offsets
            vals = self.map(w0 + Z @ T.T) @ x
            k = int(np.argmax(vals))
            z = Z[k]
            # best on the grid's rim: the maximum lies further along (a flat fin ridge), recentre
            # at the same scale; inside: zoom in
            if np.max(np.abs(offsets[k])) < 10:
                h /= 4.0
                if h < 1e-9:
                    break
            else:
                h *= 1.5
        return self.map(w0 + T @ z)[0]


@pytest.fixture(scope="module")
def paper_zone():
    return paper_s3_star_zone()


@pytest.fixture(scope="module")
def paper_brute(paper_zone):
    z = paper_zone
    return BruteSuperellipsoid(z.center_point, z.basis, z.semi_axes, z.exponent, 1_000_000)


def _tip_points(c, B, a):
    tips = []
    for k in range(B.shape[1]):
        for s in (1.0, -1.0):
            y = c + s * a[k] * B[:, k]
            tips.append(y / np.linalg.norm(y))
    return tips


def _near_boundary_points(brute, g, rng, count):
    """x placed around the boundary: beyond/behind cusp tips, sideways off tips, across fins, random."""
    pts = []
    for tip in _tip_points(brute.c, brute.B, brute.a):
        out = tip - (tip @ g) * g
        out /= np.linalg.norm(out)
        side = rng.standard_normal(len(g))
        side -= (side @ tip) * tip + (side @ out) * out
        side /= np.linalg.norm(side)
        for delta in (1e-7, 1e-4, 3e-3, 5e-2):
            pts.append(np.cos(delta) * tip + np.sin(delta) * out)       # just beyond the tip
            pts.append(np.cos(delta) * tip - np.sin(delta) * out)       # just inside the spike
            pts.append(np.cos(delta) * tip + np.sin(delta) * side)      # sideways off the tip
    # across the fins / creases (w_k = 0) and elsewhere on the boundary
    n = brute.B.shape[1]
    for _ in range(count):
        w = rng.standard_normal(n)
        if n == 3 and rng.random() < 0.6:
            w[rng.integers(3)] = 0.0
        b = brute.map(w)[0]
        v = rng.standard_normal(len(g))
        v -= (v @ b) * b
        v /= np.linalg.norm(v)
        delta = 10 ** rng.uniform(-6, -0.7)
        pts.append(np.cos(delta) * b + np.sin(delta) * v)
    return pts


def _check_against_brute(zone, brute, points):
    worst = 0.0
    for x in points:
        x = x / np.linalg.norm(x)
        d_ref, b_ref = brute.distance(x)
        s = zone.signed_separation(x)
        err = abs(abs(s) - d_ref)
        worst = max(worst, err)
        assert err < TOL, f"|signed_separation| {abs(s)!r} vs brute force {d_ref!r} at x={x.tolist()}"
        if d_ref > 1e-12:
            inside = brute.inside(x)
            assert zone.contains(x) == inside
            assert (s < 0) == inside
            assert zone.separation(x) == (0.0 if inside else pytest.approx(d_ref, abs=TOL))
    return worst


# ------------------------------------------------------------------------------------------------
def test_paper_s3_zone_random_points_match_brute_force(paper_zone, paper_brute):
    X = sample_uniform(4, 30, np.random.default_rng(11))
    _check_against_brute(paper_zone, paper_brute, list(X))


def test_paper_s3_zone_cusps_and_creases_match_brute_force(paper_zone, paper_brute):
    pts = _near_boundary_points(paper_brute, paper_zone.kernel, np.random.default_rng(12), 40)
    _check_against_brute(paper_zone, paper_brute, pts)


def test_paper_s3_zone_eps_layer_points_match_brute_force(paper_zone, paper_brute):
    rng = np.random.default_rng(13)
    pts = []
    while len(pts) < 25:
        x = sample_uniform(4, 1, rng)[0]
        if 0.0 < paper_zone.separation(x) < 0.1:
            pts.append(x)
    _check_against_brute(paper_zone, paper_brute, pts)


def test_s3_literal_plane_not_tangent_matches_brute_force():
    zone = paper_s3_star_zone(literal=True)
    brute = BruteSuperellipsoid(zone.center_point, zone.basis, zone.semi_axes, 0.4, 1_000_000)
    rng = np.random.default_rng(14)
    pts = list(sample_uniform(4, 10, rng)) + _near_boundary_points(brute, zone.kernel, rng, 8)[::3]
    _check_against_brute(zone, brute, pts)
    # the note: read literally, the spike reaches within d_s ~ 0.066 of x_d = e1
    assert zone.separation(np.array([1.0, 0, 0, 0])) == pytest.approx(0.066, abs=0.001)


@pytest.mark.parametrize("q, axes", [(0.4, (0.6, 0.25)), (0.7, (0.3, 0.5)), (1.0, (0.4, 0.4)),
                                     (1.5, (0.5, 0.2)), (2.0, (0.3, 0.6)), (4.0, (0.4, 0.25))])
def test_s2_superellipse_matches_brute_force(q, axes):
    center = np.array([0.3, -0.5, 0.8])
    zone = StarZone.superellipsoid(center, None, axes, q)
    brute = BruteSuperellipsoid(zone.center_point, zone.basis, np.array(axes), q, 500_000)
    rng = np.random.default_rng(int(q * 100))
    pts = list(sample_uniform(3, 10, rng)) + _near_boundary_points(brute, zone.kernel, rng, 15)
    _check_against_brute(zone, brute, pts)


def test_s3_convex_superellipsoid_matches_brute_force():
    center = np.array([0.1, 0.7, -0.2, 0.5])
    zone = StarZone.superellipsoid(center, None, (0.3, 0.5, 0.2), 3.0)
    brute = BruteSuperellipsoid(zone.center_point, zone.basis, np.array([0.3, 0.5, 0.2]), 3.0, 1_000_000)
    rng = np.random.default_rng(15)
    pts = list(sample_uniform(4, 8, rng)) + _near_boundary_points(brute, zone.kernel, rng, 10)[::2]
    _check_against_brute(zone, brute, pts)


def test_superellipsoid_nearest_kernel_cap_and_batch(paper_zone, paper_brute):
    z = paper_zone
    g = z.kernel
    assert np.allclose(g, [-0.5, -0.5, -0.5, -0.5])
    # nearest boundary point to the kernel: the diagonal p = t (1, 1, 1), 3 t^0.4 = 1.5
    t = 0.5 ** 2.5
    assert z.contains(g)
    assert z.signed_separation(g) == pytest.approx(-(1 - math.cos(math.atan(math.sqrt(3) * t))), abs=TOL)
    rng = np.random.default_rng(16)
    X = sample_uniform(4, 40, rng)
    for x in X[:10]:
        b = z.nearest(x)
        assert abs(np.linalg.norm(b) - 1) < 1e-12
        assert abs(z.signed_separation(b)) < 1e-12                       # on the boundary
        assert 0.5 * np.sum((x - b) ** 2) == pytest.approx(abs(z.signed_separation(x)), abs=1e-15)
    batch = z.separation_batch(X)
    assert np.array_equal(batch, np.array([z.separation(x) for x in X]))
    axis, half = z.bounding_cap
    ang = np.arccos(np.clip(paper_brute.P @ axis, -1, 1))
    assert np.all(ang <= half) and half < np.max(ang) + 0.05
    B = z.boundary(500)
    assert B.shape == (500, 4) and np.all(np.abs([z.signed_separation(b) for b in B[:50]]) < 1e-12)


def test_paper_zone_expressed_exactly():
    z = paper_s3_star_zone()
    # points of O in the paper's form: |p1|^0.4 + |p2|^0.4 + |p3|^0.4 <= 1.5 about g1 in the tangent plane
    cols = np.array([[.5, -.5, -.5, .5], [-.5, .5, -.5, .5], [-.5, -.5, .5, .5]]).T
    g1 = np.full(4, -0.5)
    rng = np.random.default_rng(17)
    for _ in range(200):
        p = rng.uniform(-3, 3, 3) * rng.random() ** 3
        y = g1 + cols @ p
        expected = np.sum(np.abs(p) ** 0.4) <= 1.5
        if abs(np.sum(np.abs(p) ** 0.4) - 1.5) > 1e-9:
            assert z.contains(y / np.linalg.norm(y)) == expected


# ------------------------------------------------------------------------------------------------
def _cone_brute(x, g, xi):
    """min over the cap boundary of 1 - x.b by dense sampling + polishing (independent of closed form)."""
    dim = len(g)
    T = default_tangent_basis(g)
    if dim == 3:
        def bpt(z):
            t = T @ np.array([math.cos(z[0]), math.sin(z[0])])
            return math.cos(xi) * g + math.sin(xi) * t
        grid = [np.array([s]) for s in np.linspace(0, 2 * np.pi, 2000, endpoint=False)]
    else:
        def bpt(z):
            u = np.array([math.sin(z[0]) * math.cos(z[1]), math.sin(z[0]) * math.sin(z[1]), math.cos(z[0])])
            return math.cos(xi) * g + math.sin(xi) * (T @ u)
        grid = [np.array([a, b]) for a in np.linspace(0, np.pi, 60) for b in np.linspace(0, 2 * np.pi, 120)]
    vals = [bpt(z) @ x for z in grid]
    z0 = grid[int(np.argmax(vals))]
    res = minimize(lambda z: -bpt(z) @ x, z0, method="Nelder-Mead", options={"xatol": 1e-13, "fatol": 1e-18})
    b = bpt(res.x)
    return 0.5 * float(np.sum((x - b) ** 2))


def test_conic_zone_closed_forms_against_brute_force():
    rng = np.random.default_rng(21)
    for dim in (3, 4):
        g = sample_uniform(dim, 1, rng)[0]
        xi = 0.4
        zone = ConicZone(g, xi)
        for x in sample_uniform(dim, 15, rng):
            d = _cone_brute(x, g, xi)
            s = zone.signed_separation(x)
            assert abs(abs(s) - d) < TOL
            inside = x @ g >= math.cos(xi)
            assert zone.contains(x) == inside and (s < 0) == inside
            assert zone.separation(x) == (0.0 if inside else pytest.approx(d, abs=TOL))
            b = zone.nearest(x)
            assert b @ g == pytest.approx(math.cos(xi), abs=1e-14)
            assert 0.5 * np.sum((x - b) ** 2) == pytest.approx(abs(s), abs=1e-14)
        X = sample_uniform(dim, 50, rng)
        assert np.allclose(zone.signed_separation_batch(X), [zone.signed_separation(x) for x in X], atol=1e-15)
        assert zone.kernel @ g == pytest.approx(1.0)
        assert zone.bounding_cap[1] == xi
        assert np.allclose(zone.boundary(64) @ g, math.cos(xi))
    # accurate next to the boundary: 1e-7 rad outside gives 5e-15
    zone = ConicZone([0, 0, 1], 0.3)
    x = np.array([math.sin(0.3 + 1e-7), 0, math.cos(0.3 + 1e-7)])
    assert zone.separation(x) == pytest.approx(0.5e-14, rel=1e-6)
    with pytest.raises(ValueError):
        ConicZone([0, 0, 1], 0.0)


# ------------------------------------------------------------------------------------------------
def _star_outline(points, r_out, r_in, phase=0.0):
    ang = phase + np.pi * np.arange(2 * points) / points
    r = np.where(np.arange(2 * points) % 2 == 0, r_out, r_in)
    return np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)


def _polygon_brute(x, P):
    """dense samples on each arc + bounded Brent on the best few arcs."""
    Pn = np.roll(P, -1, axis=0)
    lam = np.linspace(0, 1, 4001)
    best = []
    for a, b in zip(P, Pn):
        pts = geodesic(a, b, lam)
        best.append(np.max(pts @ x))
    best_d = 3.0
    for k in np.argsort(best)[::-1][:3]:
        a, b = P[k], Pn[k]
        fun = lambda l: -float(geodesic(a, b, l) @ x)
        res = minimize_scalar(fun, bounds=(0, 1), method="bounded", options={"xatol": 1e-14})
        for l in (res.x, 0.0, 1.0):
            pt = geodesic(a, b, l)
            best_d = min(best_d, 0.5 * float(np.sum((x - pt) ** 2)))
    return best_d


def test_star_polygon_closed_form_against_dense_edges():
    center = np.array([0.2, 0.4, -0.9])
    V = _star_outline(5, 0.5, 0.18, 0.3)
    zone = StarZone.polygon(center, None, V)
    rng = np.random.default_rng(31)
    pts = list(sample_uniform(3, 30, rng))
    for v in zone.vertices_sphere:
        for delta in (1e-6, 1e-3, 0.05):
            pts.append(v + delta * rng.standard_normal(3))
    from matplotlib.path import Path  # independent point-in-polygon

    path = Path(V)
    for x in pts:
        x = x / np.linalg.norm(x)
        d = _polygon_brute(x, zone.vertices_sphere)
        s = zone.signed_separation(x)
        assert abs(abs(s) - d) < TOL
        p = zone.plane_coordinates(x)
        inside = p is not None and path.contains_point(p)
        if d > 1e-12:
            assert zone.contains(x) == inside and (s < 0) == inside
        b = zone.nearest(x)
        assert abs(zone.signed_separation(b)) < 1e-12
    assert zone.contains(zone.kernel)
    B = zone.boundary(300)
    assert B.shape == (300, 3) and np.max(np.abs(zone.signed_separation_batch(B))) < 1e-12
    axis, half = zone.bounding_cap
    assert np.all(np.arccos(np.clip(B @ axis, -1, 1)) <= half)


def test_polygon_edge_culling_gives_the_full_pass_minimum_and_nearest_point_exactly():
    """`nearest_on_boundary` skips edges by a midpoint bound; it must return the very numbers of the pass
    over every edge (same minimum, same nearest point), for fine sky polygons, coarse stars with long
    edges, and points on and next to the vertices (ties between the two edges of a vertex)."""
    from gnc import _zone_polygon as poly
    from gnc.sky_zones import SkyZoneBuilder

    se = {"shape": "superellipse", "semi_axes_deg": [40.0, 30.0], "exponent": 1.5, "orientation_deg": 20.0}
    zones = [SkyZoneBuilder(se, 3.1).build(np.array([0.3, 0.5, 0.8])),
             StarZone.polygon([0.2, 0.4, -0.9], None, _star_outline(5, 0.5, 0.18, 0.3)),
             StarZone.polygon([0.0, 1.0, 0.0], None, [[0.2, -0.05], [0.0, 0.15], [-0.2, -0.05]])]
    rng = np.random.default_rng(7)
    skipped = 0
    for zone in zones:
        V = zone.vertices_sphere
        near = V[rng.integers(0, len(V), 400)] + rng.normal(0.0, 1e-7, (400, 3))
        X = np.vstack([sample_uniform(3, 2000, rng), near / np.linalg.norm(near, axis=1, keepdims=True), V])
        for x in X:
            b_cull, b_full = np.empty(3), np.empty(3)
            d_cull = poly.nearest_on_boundary(x, zone._edges, zone._mids, zone._reach, b_cull)
            assert d_cull == poly.nearest_on_boundary_full(x, zone._edges, b_full)
            assert np.array_equal(b_cull, b_full)
        # the bound does skip edges (else it is only overhead): most arcs of a fine polygon are far
        x = X[0]
        c = zone._mids @ x
        d0 = poly.nearest_on_boundary(x, zone._edges, zone._mids, zone._reach, np.empty(3))
        skipped += int(np.sum(c < math.cos(math.acos(1.0 - d0) + zone._reach)))
    assert skipped > 300


def test_polygon_rejects_self_intersecting_star():
    ang = 4 * np.pi * np.arange(5) / 5  # pentagram {5/2}: winds twice
    V = 0.4 * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    with pytest.raises(ValueError, match="wind once"):
        StarZone.polygon([0, 0, 1], None, V)


# ------------------------------------------------------------------------------------------------
def test_radial_lobed_zone_against_brute_force():
    radius = lambda u: 0.3 + 0.12 * np.cos(5 * np.arctan2(u[:, 1], u[:, 0]))
    center = np.array([-0.6, 0.2, 0.4])
    zone = StarZone.radial(center, None, radius)
    c, B = zone.center_point, zone.basis
    t = np.linspace(0, 2 * np.pi, 2_000_000, endpoint=False)
    U = np.stack([np.cos(t), np.sin(t)], axis=1)
    Y = c + (radius(U)[:, None] * U) @ B.T
    P = Y / np.linalg.norm(Y, axis=1, keepdims=True)

    def bpt(s):
        u = np.array([[math.cos(s), math.sin(s)]])
        y = c + (radius(u)[:, None] * u) @ B.T
        return (y / np.linalg.norm(y))[0]

    rng = np.random.default_rng(41)
    pts = list(sample_uniform(3, 8, rng)) + [P[j] + 1e-3 * rng.standard_normal(3) for j in rng.integers(0, len(P), 6)]
    for x in pts:
        x = x / np.linalg.norm(x)
        f = P @ x
        d = 3.0
        for j in np.argsort(-f)[:2000:400]:
            res = minimize_scalar(lambda s: -bpt(s) @ x, bounds=(t[j] - 1e-5, t[j] + 1e-5), method="bounded",
                                  options={"xatol": 1e-14})
            d = min(d, 0.5 * float(np.sum((x - bpt(res.x)) ** 2)))
        s = zone.signed_separation(x)
        assert abs(abs(s) - d) < TOL
        pp = zone.plane_coordinates(x)
        if d > 1e-12 and pp is not None:
            r_here = radius((pp / np.linalg.norm(pp))[None, :])[0]
            assert zone.contains(x) == (np.linalg.norm(pp) <= r_here)
    # periodic samples define the same zone as the spline callable through them
    samples = radius(np.stack([np.cos(np.arange(64) * 2 * np.pi / 64), np.sin(np.arange(64) * 2 * np.pi / 64)], 1))
    zs = StarZone.radial(center, None, samples)
    for x in pts[:5]:
        x = x / np.linalg.norm(x)
        assert zs.signed_separation(x) == pytest.approx(zone.signed_separation(x), abs=2e-4)
    assert zone.contains(zone.kernel)
    axis, half = zone.bounding_cap
    assert np.all(np.arccos(np.clip(P[::50] @ axis, -1, 1)) <= half)


# ------------------------------------------------------------------------------------------------
def test_default_basis_is_documented_tangent_basis():
    B = default_tangent_basis([0, 0, 2.0])
    assert np.allclose(B, [[1, 0], [0, 1], [0, 0]])
    c = np.array([0.3, -0.2, 0.9, 0.1])
    c /= np.linalg.norm(c)
    B = default_tangent_basis(c)
    assert np.allclose(B.T @ B, np.eye(3)) and np.allclose(B.T @ c, 0)


def test_bad_inputs_are_rejected_with_clear_errors():
    with pytest.raises(ValueError, match="orthonormal"):
        StarZone.superellipsoid([0, 0, 1], [[1, 0], [0, 2], [0, 0]], (0.2, 0.2), 0.5)
    with pytest.raises(ValueError, match="contains the origin"):
        StarZone.superellipsoid([1, 0, 0], [[1, 0], [0, 1], [0, 0]], (0.2, 0.2), 0.5)
    with pytest.raises(ValueError, match="semi_axes"):
        StarZone.superellipsoid([0, 0, 1], None, (0.2, -1), 0.5)
    with pytest.raises(ValueError, match="exponent"):
        StarZone.superellipsoid([0, 0, 1], None, (0.2, 0.2), 0.0)
    z = StarZone.superellipsoid([0, 0, 1], None, (0.2, 0.3), 0.5)
    with pytest.raises(ValueError, match="shape"):
        z.separation(np.ones(4) / 2)
    with pytest.raises(ValueError, match="positive"):
        StarZone.radial([0, 0, 1], None, lambda u: -np.ones(len(u)))
