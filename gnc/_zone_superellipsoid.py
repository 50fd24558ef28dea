"""Compiled kernels for a superellipsoid star zone on S^n (n = 2 or 3).

The zone is U = psi(O), O = {c + B p : sum_k |p_k / a_k|^q <= 1}, psi(y) = y / |y|.
For a point x outside U the separation is 1 - max_{b in dU} x^T b and dU = psi(c + B dK); for a
point inside, the separation to the complement is the same expression. So everything reduces to

    maximise f(w) = x^T y(w) / |y(w)|,   y(w) = c + B (a * s(w)),   w on the unit sphere S^(n-1),

where s(w) parameterises the boundary of the unit superball {sum |s_k|^q <= 1}:

* mode 0 (q <= 2): s_k = sign(w_k) |w_k|^(2/q). Smooth in w for q <= 1, and it resolves the thin
  cusped spikes of q < 1 (the tips sit at w = +-e_k and occupy a large neighbourhood in w) and
  the fins (w_k = 0, where |w_k|^(2/q) is flat), unlike a radial parameterisation.
* mode 1 (q > 2): the radial map s = w / ||w||_q (smooth, since |w|^q is C^2 for q >= 2;
  2/q < 1 would make mode 0 singular at w_k = 0).

Global search (the part that makes it correct): the w-sphere is cut into cells (arcs for n = 2,
equi-angular cube-sphere patches for n = 3), each with precomputed boundary samples, a cap
(axis, radius rho) on S^n containing the image of the whole cell, and the covering radius h of the
cell's samples (every image point of the cell lies within angle h of one of its samples). For a
query x:

1. an upper bound of f over each cell from its cap: cos(max(0, angle(x, axis) - rho));
2. the samples of every cell whose cap bound beats the best sample found so far are evaluated;
3. a cell can contain a value above cos(max(0, theta_best_sample - h)) only; cells whose bound
   beats the best refined value get a safeguarded Riemannian Newton ascent on S^(n-1) from their
   best sample (analytic gradient and Hessian), in order of their best sample value.

Cells pruned in 1 or 3 provably cannot contain the global maximum (up to the stated cap and
covering radii, computed at construction from a 4x denser sub-sampling with a safety factor).
The answer is then accurate to the Newton convergence (steps below 1e-11 rad, i.e. f to ~1e-16).

Geometry vector layout (float64): [q, e, mode, c (dim), B row-major (dim * n), a (n)].
Sample rows: [w (n), b (dim)]. Cell rows: [axis (dim), cos rho, sin rho, cos h, sin h].
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# Floor on |w_k| where the second derivative of |w_k|^e is singular (1 < e < 2, i.e. 1 < q < 2).
_W_FLOOR = 1e-12


@njit(cache=True)
def _unpack(geom, dim, n):
    q = geom[0]
    e = geom[1]
    mode = int(geom[2])
    c = geom[3:3 + dim]
    B = geom[3 + dim:3 + dim + dim * n].reshape((dim, n))
    a = geom[3 + dim + dim * n:3 + dim + dim * n + n]
    return q, e, mode, c, B, a


@njit(cache=True)
def _surface(w, q, e, mode, s):
    """s(w) only."""
    n = w.shape[0]
    if mode == 0:
        for k in range(n):
            aw = abs(w[k])
            v = aw ** e
            s[k] = v if w[k] >= 0.0 else -v
    else:
        acc = 0.0
        for k in range(n):
            acc += abs(w[k]) ** q
        nq = acc ** (1.0 / q)
        for k in range(n):
            s[k] = w[k] / nq


@njit(cache=True)
def _surface_derivs(w, q, e, mode, s, Ds, D2s):
    """s(w), Jacobian Ds[k, l] = ds_k/dw_l and D2s[k, l, m] = d2 s_k / dw_l dw_m (ambient in w)."""
    n = w.shape[0]
    for k in range(n):
        for l in range(n):
            Ds[k, l] = 0.0
            for m in range(n):
                D2s[k, l, m] = 0.0
    if mode == 0:
        for k in range(n):
            aw = abs(w[k])
            sg = 1.0 if w[k] >= 0.0 else -1.0
            s[k] = sg * aw ** e
            Ds[k, k] = e * aw ** (e - 1.0)
            if e >= 2.0:
                D2s[k, k, k] = e * (e - 1.0) * sg * aw ** (e - 2.0)
            else:
                D2s[k, k, k] = e * (e - 1.0) * sg * max(aw, _W_FLOOR) ** (e - 2.0)
    else:
        acc = 0.0
        for k in range(n):
            acc += abs(w[k]) ** q
        N = acc ** (1.0 / q)
        Nl = np.empty(n)
        for k in range(n):
            sg = 1.0 if w[k] >= 0.0 else -1.0
            Nl[k] = sg * abs(w[k]) ** (q - 1.0) * N ** (1.0 - q)
        for k in range(n):
            s[k] = w[k] / N
        for k in range(n):
            for l in range(n):
                Ds[k, l] = (1.0 / N if k == l else 0.0) - w[k] * Nl[l] / (N * N)
        # N_lm = (q-1)|w_l|^(q-2) N^(1-q) delta_lm + (1-q) N_l N_m / N
        for k in range(n):
            for l in range(n):
                for m in range(n):
                    Nlm = (1.0 - q) * Nl[l] * Nl[m] / N
                    if l == m:
                        Nlm += (q - 1.0) * abs(w[l]) ** (q - 2.0) * N ** (1.0 - q)
                    v = -w[k] * Nlm / (N * N) + 2.0 * w[k] * Nl[l] * Nl[m] / (N * N * N)
                    if k == l:
                        v -= Nl[m] / (N * N)
                    if k == m:
                        v -= Nl[l] / (N * N)
                    D2s[k, l, m] = v


@njit(cache=True)
def _point(x, geom, w, dim, n, y):
    """Fill y = c + B (a * s(w)); return f = x^T y / |y|."""
    q, e, mode, c, B, a = _unpack(geom, dim, n)
    s = np.empty(n)
    _surface(w, q, e, mode, s)
    num = 0.0
    yy = 0.0
    for i in range(dim):
        v = c[i]
        for k in range(n):
            v += B[i, k] * a[k] * s[k]
        y[i] = v
        num += x[i] * v
        yy += v * v
    return num / math.sqrt(yy)


@njit(cache=True)
def _fgh(x, geom, w, dim, n, G, H):
    """f(w), ambient gradient G (n) and Hessian H (n, n) of f(w) = x^T y / |y| in w."""
    q, e, mode, c, B, a = _unpack(geom, dim, n)
    s = np.empty(n)
    Ds = np.empty((n, n))
    D2s = np.empty((n, n, n))
    _surface_derivs(w, q, e, mode, s, Ds, D2s)
    y = np.empty(dim)
    yy = 0.0
    for i in range(dim):
        v = c[i]
        for k in range(n):
            v += B[i, k] * a[k] * s[k]
        y[i] = v
        yy += v * v
    ny = math.sqrt(yy)
    F = 0.0
    for i in range(dim):
        F += x[i] * y[i]
    F /= ny
    # gradient of F in y: (x - F yhat) / |y|; its components along the plane basis: Bt_g = B^T g_y
    Bt_g = np.zeros(n)
    Bt_x = np.zeros(n)
    Bt_yh = np.zeros(n)
    for k in range(n):
        for i in range(dim):
            yh = y[i] / ny
            Bt_g[k] += B[i, k] * (x[i] - F * yh) / ny
            Bt_x[k] += B[i, k] * x[i]
            Bt_yh[k] += B[i, k] * yh
    # M = diag(a) Ds  (so J = B M); G = M^T Bt_g
    M = np.empty((n, n))
    for k in range(n):
        for l in range(n):
            M[k, l] = a[k] * Ds[k, l]
    Jx = np.zeros(n)
    Jy = np.zeros(n)
    for l in range(n):
        gl = 0.0
        for k in range(n):
            gl += M[k, l] * Bt_g[k]
            Jx[l] += M[k, l] * Bt_x[k]
            Jy[l] += M[k, l] * Bt_yh[k]
        G[l] = gl
    # H = J^T H_y J + sum_k (B^T g_y)_k a_k D2s[k]
    # J^T H_y J = [-(Jx Jy^T + Jy Jx^T) - F M^T M + 3 F Jy Jy^T] / |y|^2   (B^T B = I)
    inv = 1.0 / yy
    for l in range(n):
        for m in range(n):
            mtm = 0.0
            for k in range(n):
                mtm += M[k, l] * M[k, m]
            h = (-(Jx[l] * Jy[m] + Jy[l] * Jx[m]) - F * mtm + 3.0 * F * Jy[l] * Jy[m]) * inv
            for k in range(n):
                h += Bt_g[k] * a[k] * D2s[k, l, m]
            H[l, m] = h
    return F


@njit(cache=True)
def _tangent_basis(w, T):
    """Orthonormal basis of the tangent space of S^(n-1) at w, as columns of T (n, n-1); n = 2 or 3."""
    n = w.shape[0]
    if n == 2:
        T[0, 0] = -w[1]
        T[1, 0] = w[0]
        return
    # n == 3: cross with the least aligned coordinate axis
    j = 0
    if abs(w[1]) < abs(w[j]):
        j = 1
    if abs(w[2]) < abs(w[j]):
        j = 2
    ej = np.zeros(3)
    ej[j] = 1.0
    t1 = np.empty(3)
    t1[0] = w[1] * ej[2] - w[2] * ej[1]
    t1[1] = w[2] * ej[0] - w[0] * ej[2]
    t1[2] = w[0] * ej[1] - w[1] * ej[0]
    nt = math.sqrt(t1[0] ** 2 + t1[1] ** 2 + t1[2] ** 2)
    for i in range(3):
        t1[i] /= nt
    T[0, 0] = t1[0]
    T[1, 0] = t1[1]
    T[2, 0] = t1[2]
    T[0, 1] = w[1] * t1[2] - w[2] * t1[1]
    T[1, 1] = w[2] * t1[0] - w[0] * t1[2]
    T[2, 1] = w[0] * t1[1] - w[1] * t1[0]


@njit(cache=True)
def newton_ascent(x, geom, w0, dim, n, w_out):
    """Safeguarded Riemannian Newton ascent of f on S^(n-1) from w0. Returns f at w_out."""
    w = w0.copy()
    G = np.empty(n)
    H = np.empty((n, n))
    T = np.empty((n, n - 1))
    y = np.empty(dim)
    w_try = np.empty(n)
    f = _fgh(x, geom, w, dim, n, G, H)
    radius = 0.3
    for _ in range(100):
        _tangent_basis(w, T)
        wg = 0.0
        for k in range(n):
            wg += w[k] * G[k]
        m = n - 1
        gT = np.zeros(m)
        HT = np.zeros((m, m))
        for i in range(m):
            for k in range(n):
                gT[i] += T[k, i] * G[k]
            for j in range(m):
                acc = 0.0
                for k in range(n):
                    for l in range(n):
                        acc += T[k, i] * H[k, l] * T[l, j]
                HT[i, j] = acc - (wg if i == j else 0.0)
        d = np.zeros(m)
        newton_step = False
        if m == 1:
            if HT[0, 0] < 0.0:
                d[0] = -gT[0] / HT[0, 0]
                newton_step = True
            else:
                d[0] = radius if gT[0] >= 0.0 else -radius
        else:
            det = HT[0, 0] * HT[1, 1] - HT[0, 1] * HT[1, 0]
            if HT[0, 0] < 0.0 and det > 0.0:
                d[0] = -(HT[1, 1] * gT[0] - HT[0, 1] * gT[1]) / det
                d[1] = -(-HT[1, 0] * gT[0] + HT[0, 0] * gT[1]) / det
                newton_step = True
            else:
                ng = math.sqrt(gT[0] ** 2 + gT[1] ** 2)
                if ng > 0.0:
                    d[0] = gT[0] / ng * radius
                    d[1] = gT[1] / ng * radius
        nd = 0.0
        for i in range(m):
            nd += d[i] * d[i]
        nd = math.sqrt(nd)
        if nd == 0.0:
            break
        if nd > radius:
            for i in range(m):
                d[i] *= radius / nd
            nd = radius
            newton_step = False
        nw = 0.0
        for k in range(n):
            v = w[k]
            for i in range(m):
                v += T[k, i] * d[i]
            w_try[k] = v
            nw += v * v
        nw = math.sqrt(nw)
        for k in range(n):
            w_try[k] /= nw
        f_try = _point(x, geom, w_try, dim, n, y)
        if f_try >= f or (newton_step and nd < 1e-9):
            for k in range(n):
                w[k] = w_try[k]
            f = _fgh(x, geom, w, dim, n, G, H)
            if newton_step and nd < 1e-11:
                break
            if not newton_step:
                radius = min(2.0 * radius, 0.5)
        else:
            radius = 0.25 * nd
            if radius < 1e-14:
                break
    for k in range(n):
        w_out[k] = w[k]
    return f


@njit(cache=True)
def boundary_max(x, geom, samples, cells, cell_start, dim, n, w_best, b_best):
    """Global maximum of x^T b over the zone boundary. Fills w_best (n), b_best (dim); returns f."""
    M = cells.shape[0]
    # 1. cap bounds
    ub = np.empty(M)
    top = 0
    for P in range(M):
        ct = 0.0
        for i in range(dim):
            ct += x[i] * cells[P, i]
        cr = cells[P, dim]
        sr = cells[P, dim + 1]
        if ct >= cr:
            ub[P] = 1.0
        else:
            st = math.sqrt(max(0.0, 1.0 - ct * ct))
            ub[P] = ct * cr + st * sr
        if ub[P] > ub[top]:
            top = P
    # 2. sample values in cells whose cap bound beats the best sample so far
    best_sample = -2.0
    cell_best_val = np.full(M, -3.0)
    cell_best_idx = np.full(M, -1, dtype=np.int64)
    order = np.empty(M, dtype=np.int64)
    order[0] = top
    cnt = 1
    for P in range(M):
        if P != top:
            order[cnt] = P
            cnt += 1
    ncand = 0
    cand = np.empty(M, dtype=np.int64)
    for r in range(M):
        P = order[r]
        if ub[P] <= best_sample:
            continue
        bv = -3.0
        bi = -1
        for j in range(cell_start[P], cell_start[P + 1]):
            v = 0.0
            for i in range(dim):
                v += x[i] * samples[j, n + i]
            if v > bv:
                bv = v
                bi = j
        cell_best_val[P] = bv
        cell_best_idx[P] = bi
        if bv > best_sample:
            best_sample = bv
        cand[ncand] = P
        ncand += 1
    # 3. order candidates by best sample value (descending), refine those whose bound can still win
    cand = cand[:ncand]
    vals = np.empty(ncand)
    for r in range(ncand):
        vals[r] = -cell_best_val[cand[r]]
    idx = np.argsort(vals)
    best = -2.0
    w_try = np.empty(n)
    for r in range(ncand):
        P = cand[idx[r]]
        v = cell_best_val[P]
        if v > 1.0:
            v = 1.0
        ch = cells[P, dim + 2]
        sh = cells[P, dim + 3]
        # bound cos(max(0, theta - h)) with cos theta = v
        if v >= ch:
            bound = 1.0
        else:
            bound = v * ch + math.sqrt(max(0.0, 1.0 - v * v)) * sh
        if bound <= best:
            continue
        j = cell_best_idx[P]
        f = newton_ascent(x, geom, samples[j, :n], dim, n, w_try)
        if f < v:  # cannot happen (ascent), kept as a guard: fall back to the sample itself
            f = v
            for k in range(n):
                w_try[k] = samples[j, k]
        if f > best:
            best = f
            for k in range(n):
                w_best[k] = w_try[k]
    y = np.empty(dim)
    _point(x, geom, w_best, dim, n, y)
    ny = 0.0
    for i in range(dim):
        ny += y[i] * y[i]
    ny = math.sqrt(ny)
    for i in range(dim):
        b_best[i] = y[i] / ny
    return best


@njit(cache=True)
def separation_to_boundary(x, geom, samples, cells, cell_start, dim, n):
    """min over the boundary of |x - b|^2 / 2 (the separation to the zone from outside, to its
    complement from inside)."""
    w_best = np.empty(n)
    b_best = np.empty(dim)
    boundary_max(x, geom, samples, cells, cell_start, dim, n, w_best, b_best)
    d = 0.0
    for i in range(dim):
        t = x[i] - b_best[i]
        d += t * t
    return 0.5 * d


@njit(cache=True)
def contains_point(x, geom, plane_normal, plane_offset, dim, n):
    """True when x is in the closed zone: the ray through x meets the plane inside K."""
    q, e, mode, c, B, a = _unpack(geom, dim, n)
    xn = 0.0
    for i in range(dim):
        xn += x[i] * plane_normal[i]
    if xn <= 0.0:
        return False
    scale = plane_offset / xn
    acc = 0.0
    for k in range(n):
        p = 0.0
        for i in range(dim):
            p += B[i, k] * (x[i] * scale - c[i])
        acc += abs(p / a[k]) ** q
    return acc <= 1.0


@njit(cache=True)
def signed_separation_batch(X, geom, samples, cells, cell_start, plane_normal, plane_offset, dim, n, clamp):
    """Signed separation for each row of X; clamp=True gives the (unsigned, 0 inside) separation."""
    m = X.shape[0]
    out = np.empty(m)
    for r in range(m):
        x = X[r]
        d = separation_to_boundary(x, geom, samples, cells, cell_start, dim, n)
        if contains_point(x, geom, plane_normal, plane_offset, dim, n):
            out[r] = 0.0 if clamp else -d
        else:
            out[r] = d
    return out


@njit(cache=True)
def boundary_points(W, geom, dim, n):
    """Boundary points psi(c + B (a * s(w))) for each row w of W -> (len(W), dim)."""
    m = W.shape[0]
    out = np.empty((m, dim))
    y = np.empty(dim)
    zero = np.zeros(dim)
    for r in range(m):
        _point(zero, geom, W[r], dim, n, y)
        ny = 0.0
        for i in range(dim):
            ny += y[i] * y[i]
        ny = math.sqrt(ny)
        for i in range(dim):
            out[r, i] = y[i] / ny
    return out


# ----------------------------------------------------------------------------------------------
# Construction of the cell structure (numpy, once per zone)

def _cells_circle(cells_count: int, per_cell: int, sub: int):
    """Cells on S^1: returns (sample w (N, 2), cell_start, list of dense sub-sample w per cell)."""
    t_edges = np.linspace(0.0, 2.0 * np.pi, cells_count + 1)
    samples = []
    dense = []
    for P in range(cells_count):
        t0, t1 = t_edges[P], t_edges[P + 1]
        ts = t0 + (np.arange(per_cell) + 0.5) / per_cell * (t1 - t0)
        td = np.linspace(t0, t1, sub * per_cell + 1)
        samples.append(np.stack([np.cos(ts), np.sin(ts)], axis=1))
        dense.append(np.stack([np.cos(td), np.sin(td)], axis=1))
    return samples, dense


def _cells_cube_sphere(cells_per_edge: int, per_cell_edge: int, sub: int):
    """Equi-angular cube-sphere cells on S^2 (6 faces x m x m cells, k x k samples per cell)."""
    m, k = cells_per_edge, per_cell_edge
    edges = np.linspace(-np.pi / 4.0, np.pi / 4.0, m + 1)
    samples = []
    dense = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            for i in range(m):
                for j in range(m):
                    a0, a1 = edges[i], edges[i + 1]
                    b0, b1 = edges[j], edges[j + 1]
                    sa = a0 + (np.arange(k) + 0.5) / k * (a1 - a0)
                    sb = b0 + (np.arange(k) + 0.5) / k * (b1 - b0)
                    da = np.linspace(a0, a1, sub * k + 1)
                    db = np.linspace(b0, b1, sub * k + 1)
                    for grid_a, grid_b, store in ((sa, sb, samples), (da, db, dense)):
                        A, Bg = np.meshgrid(grid_a, grid_b, indexing="ij")
                        v = np.empty(A.shape + (3,))
                        v[..., axis] = sign
                        v[..., (axis + 1) % 3] = np.tan(A)
                        v[..., (axis + 2) % 3] = np.tan(Bg)
                        v = v.reshape(-1, 3)
                        store.append(v / np.linalg.norm(v, axis=1, keepdims=True))
    return samples, dense


def build_cells(geom: np.ndarray, dim: int, n: int, resolution: tuple[int, int] | None = None):
    """Precompute samples (N, n + dim), cells (M, dim + 4) and cell_start (M + 1,) for a zone."""
    sub = 4
    if n == 2:
        cells_count, per_cell = resolution or (128, 16)
        w_cells, w_dense = _cells_circle(cells_count, per_cell, sub)
    elif n == 3:
        cells_per_edge, per_cell_edge = resolution or (12, 4)
        w_cells, w_dense = _cells_cube_sphere(cells_per_edge, per_cell_edge, sub)
    else:
        raise ValueError(f"superellipsoid zones are implemented for S^2 and S^3 (n = 2, 3), got n = {n}")
    rows = []
    cell_rows = []
    start = [0]
    for ws, wd in zip(w_cells, w_dense):
        bs = boundary_points(ws, geom, dim, n)
        bd = boundary_points(wd, geom, dim, n)
        axis = bd.mean(axis=0)
        axis /= np.linalg.norm(axis)
        rho = np.max(2.0 * np.arctan2(np.linalg.norm(bd - axis, axis=1), np.linalg.norm(bd + axis, axis=1)))
        # covering radius: farthest dense point from its nearest sample
        diff = bd[:, None, :] - bs[None, :, :]
        chord = np.sqrt(np.min(np.einsum("ijk,ijk->ij", diff, diff), axis=1))
        h = np.max(2.0 * np.arcsin(np.minimum(1.0, chord / 2.0)))
        # Safety factors: the dense sub-sampling is 4x finer than the samples, so the missed excess
        # is second order; 10% plus a small absolute margin covers it.
        rho = min(np.pi, 1.1 * rho + 1e-9)
        h = min(np.pi, 1.1 * h + 1e-9)
        rows.append(np.hstack([ws, bs]))
        cell_rows.append(np.concatenate([axis, [np.cos(rho), np.sin(rho), np.cos(h), np.sin(h)]]))
        start.append(start[-1] + len(ws))
    return (np.ascontiguousarray(np.vstack(rows)), np.ascontiguousarray(np.array(cell_rows)),
            np.asarray(start, dtype=np.int64))
