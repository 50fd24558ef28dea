"""gnc._zone_superellipsoid.build_cells (all cells at once, two small kernels) against the per-cell numpy
construction it replaced, kept here verbatim as the reference: every array must be bit for bit the same
(the search structure decides which samples are scored, so a last-bit change could move a judged margin).
"""
from __future__ import annotations

import numpy as np
import pytest

from gnc import _zone_superellipsoid as se
from gnc._zone_superellipsoid import boundary_points, grid_sizes
from gnc.zones import default_tangent_basis, paper_s3_star_zone


# ------------------------------------------------------------------------------------------------
# reference: the per-cell construction as it was

def _ref_cap_of(points: np.ndarray) -> tuple[np.ndarray, float]:
    axis = points.mean(axis=0)
    axis /= np.linalg.norm(axis)
    rho = float(np.max(2.0 * np.arctan2(np.linalg.norm(points - axis, axis=1), np.linalg.norm(points + axis, axis=1))))
    return axis, rho


def _ref_face_points(axis: int, sign: float, alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    A, Bg = np.meshgrid(alpha, beta, indexing="ij")
    v = np.empty(A.shape + (3,))
    v[..., axis] = sign
    v[..., (axis + 1) % 3] = np.tan(A)
    v[..., (axis + 2) % 3] = np.tan(Bg)
    v = v.reshape(-1, 3)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _ref_cell_grids(n: int, m: int, k: int, sc: int, sub: int):
    """Per cell (in kernel numbering): its sample w (grid order inside the cell) and a dense
    sub-sampling including the cell's edges. n = 2: m arcs of k samples on S^1. n = 3: equi-angular
    cube-sphere, 6 faces x m x m cells of k x k samples, sample index face G^2 + i G + j (G = m k)."""
    G = m * k
    if n == 2:
        dt = 2.0 * np.pi / G
        for P in range(m):
            ts = (P * k + np.arange(k) + 0.5) * dt
            td = np.linspace(P * k * dt, (P + 1) * k * dt, sub * k + 1)
            yield P, np.stack([np.cos(ts), np.sin(ts)], axis=1), np.stack([np.cos(td), np.sin(td)], axis=1)
        return
    da = 0.5 * np.pi / G
    for face in range(6):
        axis, sign = face // 2, (1.0 if face % 2 == 0 else -1.0)
        for bi in range(m):
            for bj in range(m):
                a_s = -0.25 * np.pi + (bi * k + np.arange(k) + 0.5) * da
                b_s = -0.25 * np.pi + (bj * k + np.arange(k) + 0.5) * da
                a_d = np.linspace(-0.25 * np.pi + bi * k * da, -0.25 * np.pi + (bi + 1) * k * da, sub * k + 1)
                b_d = np.linspace(-0.25 * np.pi + bj * k * da, -0.25 * np.pi + (bj + 1) * k * da, sub * k + 1)
                P = face * m * m + ((bi // sc) * (m // sc) + bj // sc) * sc * sc + (bi % sc) * sc + bj % sc
                yield (P, _ref_face_points(axis, sign, a_s, b_s), _ref_face_points(axis, sign, a_d, b_d))


def _ref_build_cells(geom: np.ndarray, dim: int, n: int, resolution: tuple[int, int] | None = None):
    """Precompute samples (2N, dim) in grid order (rows [0, N): boundary points b; rows [N, 2N): their
    w in the first n columns; scoring reads only the compact b block), cells (M, dim + 4), super-cells (Ms, dim + 2),
    grid = [G, k, m, sc, first sample of each cell (M), 8 neighbour cells of each cell (8M)] (samples per circle / cube-face edge, samples
    per cell edge, cells per circle / face edge, cells per super-cell edge) and cell_of (N,), the cell
    of every sample."""
    sub = 4
    m, k, sc, M, N = grid_sizes(n, resolution)
    G = m * k
    samples = np.zeros((2 * N, dim))
    cell_of = np.empty(N, dtype=np.int32)
    cells = np.empty((M, dim + 4))
    dense_of = [None] * M
    for P, ws, wd in _ref_cell_grids(n, m, k, sc, sub):
        bs = boundary_points(np.ascontiguousarray(ws), geom, dim, n)
        bd = boundary_points(np.ascontiguousarray(wd), geom, dim, n)
        axis, rho = _ref_cap_of(bd)
        # covering radius: farthest dense point from its nearest sample of the same cell
        diff = bd[:, None, :] - bs[None, :, :]
        chord = np.sqrt(np.min(np.einsum("ijk,ijk->ij", diff, diff), axis=1))
        h = float(np.max(2.0 * np.arcsin(np.minimum(1.0, chord / 2.0))))
        # Safety factors: the dense sub-sampling is 4x finer than the samples, so the missed excess
        # is second order; 10% plus a small absolute margin covers it.
        rho = min(np.pi, 1.1 * rho + 1e-9)
        h = min(np.pi, 1.1 * h + 1e-9)
        cells[P] = np.concatenate([axis, [np.cos(rho), np.sin(rho), np.cos(h), np.sin(h)]])
        dense_of[P] = bd
        rows = np.hstack([bs, ws, np.zeros((len(ws), dim - n))])  # [b (dim), w (n), pad]
        if n == 2:
            samples[P * k:(P + 1) * k] = rows[:, :dim]
            samples[N + P * k:N + (P + 1) * k] = rows[:, dim:]
            cell_of[P * k:(P + 1) * k] = P
        else:
            face, rem = divmod(P, m * m)
            S, t = divmod(rem, sc * sc)
            SI, SJ = divmod(S, m // sc)
            ti, tj = divmod(t, sc)
            bi, bj = SI * sc + ti, SJ * sc + tj
            blk = rows.reshape(k, k, 2 * dim)
            for a in range(k):
                base = face * G * G + (bi * k + a) * G + bj * k
                samples[base:base + k] = blk[a, :, :dim]
                samples[N + base:N + base + k] = blk[a, :, dim:]
                cell_of[base:base + k] = P
    per_super = sc if n == 2 else sc * sc
    supers = np.empty((M // per_super, dim + 2))
    for S in range(M // per_super):
        axis, rho = _ref_cap_of(np.vstack(dense_of[S * per_super:(S + 1) * per_super]))
        rho = min(np.pi, 1.1 * rho + 1e-9)
        supers[S] = np.concatenate([axis, [np.cos(rho), np.sin(rho)]])
    if n == 2:
        first = np.arange(M, dtype=np.int64) * k
    else:
        first = np.empty(M, dtype=np.int64)
        for P in range(M):
            face, rem = divmod(P, m * m)
            S, t = divmod(rem, sc * sc)
            SI, SJ = divmod(S, m // sc)
            ti, tj = divmod(t, sc)
            first[P] = face * G * G + (SI * sc + ti) * k * G + (SJ * sc + tj) * k
    # the 8 neighbour cells of every cell on the same cube face (-1 across a face edge; unused on S^1)
    adj = -np.ones((M, 8), dtype=np.int64)
    if n == 3:
        for P in range(M):
            face, rem = divmod(P, m * m)
            S, t = divmod(rem, sc * sc)
            SI, SJ = divmod(S, m // sc)
            ti, tj = divmod(t, sc)
            bi, bj = SI * sc + ti, SJ * sc + tj
            q = 0
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    if di == 0 and dj == 0:
                        continue
                    ni, nj = bi + di, bj + dj
                    if 0 <= ni < m and 0 <= nj < m:
                        adj[P, q] = (face * m * m + ((ni // sc) * (m // sc) + nj // sc) * sc * sc
                                     + (ni % sc) * sc + nj % sc)
                    q += 1
    grid = np.concatenate([np.array([G, k, m, sc], dtype=np.int64), first, adj.ravel()])
    return (np.ascontiguousarray(samples), np.ascontiguousarray(cells), np.ascontiguousarray(supers),
            grid, cell_of)


# ------------------------------------------------------------------------------------------------
def _bitwise_equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _assert_same_cells(geom, dim, n, resolution=None):
    names = ("samples", "cells", "supers", "grid", "cell_of")
    for name, ref, new in zip(names, _ref_build_cells(geom, dim, n, resolution), se.build_cells(geom, dim, n, resolution)):
        assert _bitwise_equal(ref, new), name


def _plane_rotated(B, angle):
    return B @ np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def test_demo_sun_zone_cells_identical():
    # shaped as demo-pointing's Sun zone (semi-axes 40 x 30 deg, exponent 1.5, axes turned 20 deg), centred on
    # the Sun's direction at its epoch; the axes orthonormal, as StarZone.superellipsoid requires
    c = np.array([0.8198773706005024, 0.5252811349002053, 0.22777362993805708])
    B = _plane_rotated(default_tangent_basis(c), np.radians(20.0))
    a = np.tan(np.radians([40.0, 30.0]))
    _assert_same_cells(se.make_geom(1.5, c, B, a), 3, 2)


@pytest.mark.parametrize("seed", range(6))
def test_random_s2_zones_identical(seed):
    rng = np.random.default_rng(seed)
    c = rng.standard_normal(3)
    c /= np.linalg.norm(c)
    B = _plane_rotated(default_tangent_basis(c), rng.uniform(0.0, 2.0 * np.pi))
    q = [0.4, 1.0, 1.5, 2.0, 3.0, rng.uniform(0.3, 4.0)][seed]  # spiky, integer-power, pow and radial modes
    resolution = [None, None, (32, 4), None, (100, 16), (8, 8)][seed]
    _assert_same_cells(se.make_geom(q, c, B, rng.uniform(0.05, 1.5, 2)), 3, 2, resolution)


def test_s3_zones_identical():
    zone = paper_s3_star_zone()
    _assert_same_cells(zone._geom, 4, 3)
    rng = np.random.default_rng(7)
    c = rng.standard_normal(4)
    c /= np.linalg.norm(c)
    _assert_same_cells(se.make_geom(3.0, c, default_tangent_basis(c), rng.uniform(0.1, 0.8, 3)), 4, 3, (3, 2))


@pytest.mark.parametrize("dim", [3, 4])
def test_nearest_sq_dist_matches_einsum(dim):
    rng = np.random.default_rng(dim)
    bd = rng.standard_normal((7, 50, dim)) * rng.uniform(1e-6, 1.0, (7, 50, 1))
    bs = rng.standard_normal((7, 16, dim))
    bs[0, 3] = bd[0, 5]  # a zero distance
    bd[1, 2, 0] = np.nan  # a NaN wins the minimum as in np.min
    diff = bd[:, :, None, :] - bs[:, None, :, :]
    ref = np.min(np.einsum("ijk,ijk->ij", diff.reshape(-1, 16, dim), diff.reshape(-1, 16, dim)), axis=1).reshape(7, 50)
    new = se._nearest_sq_dist(bd, bs)
    assert np.isnan(new[1, 2]) and new[0, 5] == 0.0
    assert _bitwise_equal(ref, new)


def test_caps_match_per_group_cap_of():
    rng = np.random.default_rng(3)
    pts = rng.standard_normal((9, 65, 3)) + np.array([0.0, 0.0, 4.0])
    pts /= np.linalg.norm(pts, axis=2, keepdims=True)
    axis, rho = se._caps(pts)
    for g in range(9):
        ref_axis, ref_rho = _ref_cap_of(pts[g])
        assert _bitwise_equal(ref_axis, axis[g]) and ref_rho == rho[g]


def test_cells_cached_by_exact_geometry():
    from gnc import zones

    zones._CELLS_CACHE.clear()
    c = np.array([0.3, -0.5, 0.8])
    first = zones.StarZone.superellipsoid(c, None, (0.4, 0.25), 0.7)
    again = zones.StarZone.superellipsoid(c, None, (0.4, 0.25), 0.7)
    other = zones.StarZone.superellipsoid(c, None, (0.4, 0.2500000001), 0.7)
    assert again._samples is first._samples and other._samples is not first._samples
    fresh = _ref_build_cells(first._geom, 3, 2)
    assert all(_bitwise_equal(a, b) for a, b in zip(fresh, (again._samples, again._cells, again._supers, again._grid,
                                                           again._cell_of)))
    X = np.random.default_rng(1).standard_normal((50, 3))
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    assert np.array_equal(first.signed_separation_batch(X), again.signed_separation_batch(X))
    zones._CELLS_CACHE.clear()
