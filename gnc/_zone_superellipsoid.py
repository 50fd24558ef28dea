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
equi-angular cube-sphere patches of k x k samples for n = 3), grouped into super-cells. Every cell
and super-cell has a cap (axis, radius rho) on S^n containing the image of the whole (continuous)
cell, and every cell the covering radius h of its samples (each image point of the cell lies within
angle h of one of its samples). Both are computed at construction from a 4x denser sub-sampling,
with a 10 % safety factor. For a query x:

1. upper bounds of f over the super-cells, then over their cells, from the caps:
   cos(max(0, angle(x, axis) - rho)); the samples of every cell whose bound beats the best sample
   found so far are scored (the most promising cell first). Skipped cells provably cannot hold a
   value above the best sample.
2. a safeguarded Riemannian Newton ascent on S^(n-1) from the best sample (analytic gradient and
   Hessian; Newton along negative-curvature eigen-directions and trust-length steps along flat or
   positive ones, which matters on the flat ridges that run along the fins into the cusps). A run
   stops when a Newton step predicts a gain below 1e-14 (the local maximum is then within 2e-14,
   even for the degenerate maxima next to fins).
3. the global maximum lies within angle h of a sample whose value is then at least
   cos(arccos(best) + h); among the scored samples above that threshold, the discrete local maxima
   of the sample grid (8-neighbourhood; branch-free when the cell's 8 neighbour cells were scored)
   are the further candidates. Best first, each gets a Newton ascent while its covering bound
   cos(max(0, arccos(v) - h)) can still beat the best value; a run stops early once a short Newton
   step shows that its local maximum cannot beat the best (f + 2 * gain < best).

The separation is |x - b|^2 / 2 at the best boundary point b (no cancellation near the boundary).
Residual risk, stated honestly: a local maximum whose basin of attraction is narrower than the sample
spacing (about 2 degrees on the paper's zone) could be missed; the tests compare against brute force
over a million-point parameterisation with polishing, including cusp tips and fins, to 1e-9.

Geometry vector layout (float64, see make_geom): [q, e, mode, c (dim), B diag(a) row-major, B row-major, a].
Samples: a (2N, dim) array, boundary points b in rows [0, N), their w in rows [N, 2N). Cell rows: [axis (dim), cos rho, sin rho, cos h, sin h].
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# Floor on |w_k| where the second derivative of |w_k|^e is singular (1 < e < 2, i.e. 1 < q < 2).
_W_FLOOR = 1e-12
_WORK = 192  # size of the scratch vector the kernels share (n <= 3, dim <= 4)


def make_geom(q: float, c: np.ndarray, B: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Pack [q, e, mode, c (dim), B diag(a) row-major, B row-major, a] for the kernels."""
    mode = 0 if q <= 2.0 else 1
    e = 2.0 / q if mode == 0 else 1.0
    if mode == 0 and abs(e - round(e)) < 1e-12 and round(e) <= 16:
        e = float(round(e))
        mode = 2  # integer power: repeated multiplication instead of pow()
    return np.ascontiguousarray(np.concatenate([[q, e, float(mode)], c, (B * a).ravel(), B.ravel(), a]))


@njit(cache=True, inline="always")
def _best_first(r, best):
    """Visit order that takes index ``best`` first, then the others in order (r = 0, 1, ...)."""
    if r == 0:
        return best
    if r <= best:
        return r - 1
    return r


@njit(cache=True, inline="always")
def _pow(aw, e, mode):
    """aw ** e, by repeated squaring when e is a small integer (mode 2): pow() dominates otherwise."""
    if mode != 2:
        return aw ** e
    ie = int(e)
    r = 1.0
    b = aw
    while ie > 0:
        if ie & 1:
            r *= b
        b *= b
        ie >>= 1
    return r


@njit(cache=True)
def _point(x, geom, w, dim, n, y):
    """Fill y = c + B (a * s(w)); return f = x^T y / |y|."""
    e = geom[1]
    q = geom[0]
    mode = int(geom[2])
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    if mode != 1:
        s0 = _pow(abs(w[0]), e, mode)
        if w[0] < 0.0:
            s0 = -s0
        s1 = _pow(abs(w[1]), e, mode)
        if w[1] < 0.0:
            s1 = -s1
        if n == 3:
            s2 = _pow(abs(w[2]), e, mode)
            if w[2] < 0.0:
                s2 = -s2
    else:
        acc = abs(w[0]) ** q + abs(w[1]) ** q
        if n == 3:
            acc += abs(w[2]) ** q
        inv = acc ** (-1.0 / q)
        s0 = w[0] * inv
        s1 = w[1] * inv
        if n == 3:
            s2 = w[2] * inv
    ob = 3 + dim
    num = 0.0
    yy = 0.0
    for i in range(dim):
        r = ob + i * n
        v = geom[3 + i] + geom[r] * s0 + geom[r + 1] * s1
        if n == 3:
            v += geom[r + 2] * s2
        y[i] = v
        num += x[i] * v
        yy += v * v
    return num / math.sqrt(yy)


@njit(cache=True)
def _fgh(x, geom, w, dim, n, G, H, wk):
    """f(w), ambient gradient G (n) and Hessian H (n*n, row-major) of f = x^T y / |y| in w.

    With y = c + B diag(a) s(w), J = B diag(a) Ds:  G = J^T g_y, g_y = (x - f yhat) / |y|, and
    H = J^T H_y J + sum_k (B^T g_y)_k a_k D2 s_k,  H_y = [-(x yhat^T + yhat x^T) - f I + 3 f yhat yhat^T] / |y|^2,
    where J^T J = (diag(a) Ds)^T (diag(a) Ds) because B has orthonormal columns.
    """
    q = geom[0]
    e = geom[1]
    mode = int(geom[2])
    # scratch layout
    s = wk[0:3]
    Ds = wk[3:12]      # [k*n + l]
    D2 = wk[12:39]     # [k*nn + l*n + m] (mode 1) or D2[k] diagonal (mode 0)
    y = wk[40:44]
    Btg = wk[44:47]
    Jx = wk[47:50]
    Jy = wk[50:53]
    Btx = wk[53:56]
    Bty = wk[56:59]
    Mm = wk[60:69]     # diag(a) Ds, [k*n + l]
    if mode != 1:
        _s_power(w, e, mode, n, s, Ds, D2)
    else:
        _s_radial(w, q, n, s, Ds, D2, wk[69:72])
    yy = 0.0
    F = 0.0
    for i in range(dim):
        r = 3 + dim + i * n
        v = geom[3 + i]
        for k in range(n):
            v += geom[r + k] * s[k]
        y[i] = v
        yy += v * v
        F += x[i] * v
    ny = math.sqrt(yy)
    F /= ny
    _b_projections(x, geom, y, F, ny, dim, n, Btx, Bty, Btg)
    inv = 1.0 / yy
    if mode != 1:
        _gh_power(geom, Ds, D2, Btx, Bty, Btg, F, inv, dim, n, G, H, Jx, Jy)
    else:
        _gh_radial(geom, Ds, D2, Btx, Bty, Btg, F, inv, dim, n, G, H, Jx, Jy, Mm)
    return F


@njit(cache=True, inline="always")
def _s_power(w, e, mode, n, s, Ds, D2):
    """s_k = sign(w_k) |w_k|^e (modes 0 and 2) and its derivatives, both diagonal: Ds[k], D2[k]."""
    floor = 1e-300 if e >= 2.0 else _W_FLOOR
    for k in range(n):
        aw = max(abs(w[k]), floor)
        sg = 1.0 if w[k] >= 0.0 else -1.0
        v = _pow(aw, e, mode)
        s[k] = sg * v
        d1 = e * v / aw
        Ds[k] = d1                       # diagonal only
        D2[k] = sg * (e - 1.0) * d1 / aw


@njit(cache=True, inline="always")
def _s_radial(w, q, n, s, Ds, D2, Nl):
    """s = w / ||w||_q (mode 1), its Jacobian Ds[k*n + l] and second derivatives D2[k*nn + l*n + m];
    Nl: scratch for the gradient of ||w||_q."""
    nn = n * n
    acc = 0.0
    for k in range(n):
        acc += abs(w[k]) ** q
    N = acc ** (1.0 / q)
    for k in range(n):
        sg = 1.0 if w[k] >= 0.0 else -1.0
        Nl[k] = sg * abs(w[k]) ** (q - 1.0) * N ** (1.0 - q)
        s[k] = w[k] / N
    N2 = N * N
    N3 = N2 * N
    for k in range(n):
        for l in range(n):
            Ds[k * n + l] = (1.0 / N if k == l else 0.0) - w[k] * Nl[l] / N2
    for k in range(n):
        for l in range(n):
            for m in range(n):
                Nlm = (1.0 - q) * Nl[l] * Nl[m] / N
                if l == m:
                    Nlm += (q - 1.0) * max(abs(w[l]), _W_FLOOR) ** (q - 2.0) * N ** (1.0 - q)
                v = -w[k] * Nlm / N2 + 2.0 * w[k] * Nl[l] * Nl[m] / N3
                if k == l:
                    v -= Nl[m] / N2
                if k == m:
                    v -= Nl[l] / N2
                D2[k * nn + l * n + m] = v


@njit(cache=True, inline="always")
def _b_projections(x, geom, y, F, ny, dim, n, Btx, Bty, Btg):
    """B^T x, B^T yhat and B^T g_y, g_y = (x - f yhat) / |y| (plain B: the columns of the geometry's B)."""
    obb = 3 + dim + dim * n  # plain B
    for k in range(n):
        gx = 0.0
        gy = 0.0
        for i in range(dim):
            bik = geom[obb + i * n + k]
            gx += bik * x[i]
            gy += bik * y[i]
        gy /= ny
        Btx[k] = gx
        Bty[k] = gy
        Btg[k] = (gx - F * gy) / ny


@njit(cache=True, inline="always")
def _gh_power(geom, Ds, D2, Btx, Bty, Btg, F, inv, dim, n, G, H, Jx, Jy):
    """G and H for the diagonal Ds and D2 of modes 0 and 2 (J = B diag(a Ds))."""
    oa = 3 + dim + 2 * dim * n
    for l in range(n):
        ml = geom[oa + l] * Ds[l]
        G[l] = ml * Btg[l]
        Jx[l] = ml * Btx[l]
        Jy[l] = ml * Bty[l]
    for l in range(n):
        ml = geom[oa + l] * Ds[l]
        for m in range(n):
            h = (-(Jx[l] * Jy[m] + Jy[l] * Jx[m]) + 3.0 * F * Jy[l] * Jy[m]) * inv
            if l == m:
                h += -F * ml * ml * inv + Btg[l] * geom[oa + l] * D2[l]
            H[l * n + m] = h


@njit(cache=True, inline="always")
def _gh_radial(geom, Ds, D2, Btx, Bty, Btg, F, inv, dim, n, G, H, Jx, Jy, Mm):
    """G and H for the full Ds and D2 of mode 1 (Mm = diag(a) Ds, J = B Mm)."""
    oa = 3 + dim + 2 * dim * n
    nn = n * n
    for k in range(n):
        for l in range(n):
            Mm[k * n + l] = geom[oa + k] * Ds[k * n + l]
    for l in range(n):
        g = 0.0
        jx = 0.0
        jy = 0.0
        for k in range(n):
            g += Mm[k * n + l] * Btg[k]
            jx += Mm[k * n + l] * Btx[k]
            jy += Mm[k * n + l] * Bty[k]
        G[l] = g
        Jx[l] = jx
        Jy[l] = jy
    for l in range(n):
        for m in range(n):
            mtm = 0.0
            for k in range(n):
                mtm += Mm[k * n + l] * Mm[k * n + m]
            h = (-(Jx[l] * Jy[m] + Jy[l] * Jx[m]) - F * mtm + 3.0 * F * Jy[l] * Jy[m]) * inv
            for k in range(n):
                h += Btg[k] * geom[oa + k] * D2[k * nn + l * n + m]
            H[l * n + m] = h


@njit(cache=True)
def _tangent_basis(w, n, T):
    """Orthonormal basis of T_w S^(n-1) (n = 2 or 3) as T[k*(n-1) + i] = component k of vector i."""
    if n == 2:
        T[0] = -w[1]
        T[1] = w[0]
        return
    # n == 3: cross with the least aligned coordinate axis
    j = 0
    if abs(w[1]) < abs(w[j]):
        j = 1
    if abs(w[2]) < abs(w[j]):
        j = 2
    if j == 0:      # w x e0
        t0, t1, t2 = 0.0, w[2], -w[1]
    elif j == 1:    # w x e1
        t0, t1, t2 = -w[2], 0.0, w[0]
    else:           # w x e2
        t0, t1, t2 = w[1], -w[0], 0.0
    nt = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0 /= nt
    t1 /= nt
    t2 /= nt
    T[0] = t0
    T[2] = t1
    T[4] = t2
    T[1] = w[1] * t2 - w[2] * t1
    T[3] = w[2] * t0 - w[0] * t2
    T[5] = w[0] * t1 - w[1] * t0


@njit(cache=True)
def newton_ascent(x, geom, w0, dim, n, w_out, wk, target):
    """Safeguarded Riemannian Newton ascent of f on S^(n-1) from w0.

    Newton step in the tangent plane when the Riemannian Hessian T^T H T - (w^T G) I is negative
    definite; along eigen-directions of non-negative curvature a step of the trust length; every step is accepted only if f does not
    decrease (the trust length shrinks otherwise). Converged when a Newton step is below 1e-11 rad or
    its predicted gain in f is below 1e-14 (f then within 2e-14 of the local maximum).
    Stops early, returning the current point, once a Newton step shows that this local maximum
    cannot exceed ``target`` (f + 2 gain < target). Returns (f at w_out, iterations).
    """
    m = n - 1
    w = wk[80:83]
    w_try = wk[83:86]
    G = wk[86:89]
    H = wk[89:98]
    T = wk[98:104]
    Gt = wk[104:107]
    Ht = wk[160:169]
    gT = wk[108:110]
    HT = wk[110:114]
    d = wk[114:116]
    work = wk[0:80]
    for k in range(n):
        w[k] = w0[k]
    f = _fgh(x, geom, w, dim, n, G, H, work)
    radius = 0.3
    its = 0
    for _ in range(100):
        its += 1
        _tangent_basis(w, n, T)
        _tangent_model(w, G, H, T, n, gT, HT)
        if m == 1:
            newton_step = _step_on_circle(gT, HT, radius, d)
        else:
            newton_step = _step_on_sphere(gT, HT, radius, d)
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
        _retract(w, T, d, n, w_try)
        gain = _predicted_gain(gT, d, m)
        converged = newton_step and (nd < 1e-11 or gain < 1e-14)
        # by the same bound this local maximum stays below f + 2 gain: if that cannot beat the best
        # value found so far (target), the run is pointless. Only trusted for short Newton steps
        # (well inside the sample spacing of ~0.03 rad), where the local model describes f.
        if newton_step and nd < 0.05 and f + 2.0 * gain + 1e-15 < target:
            break
        # evaluate the trial with derivatives: most trials are accepted
        f_try = _fgh(x, geom, w_try, dim, n, Gt, Ht, work)
        if f_try >= f or converged:
            if f_try >= f:
                for k in range(n):
                    w[k] = w_try[k]
                    G[k] = Gt[k]
                for k in range(n * n):
                    H[k] = Ht[k]
                f = f_try
            if converged:
                break
            if not newton_step:
                radius = min(2.0 * radius, 0.5)
        else:
            radius = 0.25 * nd
            if radius < 1e-12:
                break
    for k in range(n):
        w_out[k] = w[k]
    return f, its


@njit(cache=True, inline="always")
def _tangent_model(w, G, H, T, n, gT, HT):
    """The Riemannian gradient gT = T^T G and Hessian HT = T^T H T - (w^T G) I in the tangent basis T."""
    m = n - 1
    wg = 0.0
    for k in range(n):
        wg += w[k] * G[k]
    for i in range(m):
        acc = 0.0
        for k in range(n):
            acc += T[k * m + i] * G[k]
        gT[i] = acc
        for j in range(m):
            acc = 0.0
            for k in range(n):
                tki = T[k * m + i]
                for l in range(n):
                    acc += tki * H[k * n + l] * T[l * m + j]
            HT[i * m + j] = acc - (wg if i == j else 0.0)


@njit(cache=True, inline="always")
def _step_on_circle(gT, HT, radius, d):
    """The step d on S^1: Newton where the curvature is negative, else the trust length uphill. Returns
    whether it is a Newton step."""
    if HT[0] < 0.0:
        d[0] = -gT[0] / HT[0]
        return True
    d[0] = radius if gT[0] >= 0.0 else -radius
    return False


@njit(cache=True, inline="always")
def _step_on_sphere(gT, HT, radius, d):
    """The step d on S^2, from the eigen-decomposition of the symmetric 2x2 Hessian: Newton along directions
    of negative curvature, a trust-length ascent step along a direction of non-negative curvature (a flat
    ridge into a cusp has one tiny positive eigenvalue; plain gradient steps zigzag). Returns whether it is
    a Newton step (negative curvature both ways)."""
    ha = HT[0]
    hb = 0.5 * (HT[1] + HT[2])
    hc = HT[3]
    mid = 0.5 * (ha + hc)
    disc = math.sqrt(0.25 * (ha - hc) * (ha - hc) + hb * hb)
    lam1 = mid - disc
    lam2 = mid + disc
    if abs(hb) > 1e-300:
        if abs(lam1 - ha) >= abs(lam1 - hc):
            v0, v1 = hb, lam1 - ha
        else:
            v0, v1 = lam1 - hc, hb
        nv = math.sqrt(v0 * v0 + v1 * v1)
        v0 /= nv
        v1 /= nv
    elif ha <= hc:
        v0, v1 = 1.0, 0.0
    else:
        v0, v1 = 0.0, 1.0
    g1 = v0 * gT[0] + v1 * gT[1]
    g2 = -v1 * gT[0] + v0 * gT[1]
    newton_step = True
    if lam1 < 0.0:
        c1 = -g1 / lam1
    else:
        c1 = radius if g1 > 0.0 else (-radius if g1 < 0.0 else 0.0)
        newton_step = False
    if lam2 < 0.0:
        c2 = -g2 / lam2
    else:
        c2 = radius if g2 > 0.0 else (-radius if g2 < 0.0 else 0.0)
        newton_step = False
    d[0] = c1 * v0 - c2 * v1
    d[1] = c1 * v1 + c2 * v0
    return newton_step


@njit(cache=True, inline="always")
def _predicted_gain(gT, d, m):
    """Predicted gain of the Newton step, -g^T H^-1 g / 2 = g^T d / 2. For a maximum of any order p >= 2
    (f = f* - c |w - w*|^p, e.g. the nearly degenerate maxima next to a fin, where Newton is only linear)
    the remaining error f* - f is at most 2 (p-1)/p <= 2 times the predicted gain, so a gain below 1e-14
    means f is within 2e-14 of the local maximum."""
    gain = 0.0
    for i in range(m):
        gain += 0.5 * gT[i] * d[i]
    return gain


@njit(cache=True, inline="always")
def _retract(w, T, d, n, w_try):
    """w_try = (w + T d) / |w + T d|: the tangent step taken back onto the sphere."""
    m = n - 1
    nw = 0.0
    for k in range(n):
        v = w[k]
        for i in range(m):
            v += T[k * m + i] * d[i]
        w_try[k] = v
        nw += v * v
    nw = math.sqrt(nw)
    for k in range(n):
        w_try[k] /= nw


@njit(cache=True, inline="always")
def _beaten(idx, v, vals, evaluated, cell_of):
    # vals of unevaluated cells are stale: only trust a neighbour whose cell was scored
    return vals[idx] > v and evaluated[cell_of[idx]]


@njit(cache=True, inline="always")
def _no_face_neighbour_beats(j, i, jj, v, vals, evaluated, cell_of, G):
    """True when no scored neighbour of sample j (row i, column jj on its cube face) in the
    8-neighbourhood beats v; off-face neighbours are unknown and count as lower."""
    for di in range(-1, 2):
        ii = i + di
        if ii < 0 or ii >= G:
            continue
        for dj in range(-1, 2):
            jn = jj + dj
            if jn < 0 or jn >= G or (di == 0 and dj == 0):
                continue
            if _beaten(j + di * G + dj, v, vals, evaluated, cell_of):
                return False
    return True


@njit(cache=True, inline="always")
def _is_local_max_face(j, i, jj, v, vals, evaluated, cell_of, G, i0, j0, k):
    """_is_local_max for n = 3, with the sample's row i and column jj on its face and its cell's first
    row i0 and column j0 (cell size k) known."""
    if i > 0 and i < G - 1 and jj > 0 and jj < G - 1:
        # Interior of the face (the common case). Most samples tested are beaten by a neighbour, so
        # find the largest of the 8 neighbour values first (straight-line code); when it lies in the
        # sample's own cell (scored, so its value is valid) no table look-up is needed.
        a = j - G
        c = j + G
        di, dj = -1, -1
        mv = vals[a - 1]
        if vals[a] > mv:
            di, dj, mv = -1, 0, vals[a]
        if vals[a + 1] > mv:
            di, dj, mv = -1, 1, vals[a + 1]
        if vals[j - 1] > mv:
            di, dj, mv = 0, -1, vals[j - 1]
        if vals[j + 1] > mv:
            di, dj, mv = 0, 1, vals[j + 1]
        if vals[c - 1] > mv:
            di, dj, mv = 1, -1, vals[c - 1]
        if vals[c] > mv:
            di, dj, mv = 1, 0, vals[c]
        if vals[c + 1] > mv:
            di, dj, mv = 1, 1, vals[c + 1]
        if mv <= v:
            return True
        ii = i + di
        jn = jj + dj
        if ii >= i0 and ii < i0 + k and jn >= j0 and jn < j0 + k:
            return False
        if evaluated[cell_of[j + di * G + dj]]:
            return False
    return _no_face_neighbour_beats(j, i, jj, v, vals, evaluated, cell_of, G)


@njit(cache=True)
def _is_local_max(j, v, vals, evaluated, cell_of, n, G):
    """True when no evaluated grid neighbour of sample j beats v (8-neighbourhood on a cube face,
    2-neighbourhood on the circle). Neighbours in unevaluated cells are below the best sample and
    off-face neighbours are unknown: both count as lower, which can only add candidates."""
    if n == 2:
        jn = j - 1 if j > 0 else G - 1
        if evaluated[cell_of[jn]] and vals[jn] > v:
            return False
        jn = j + 1 if j < G - 1 else 0
        if evaluated[cell_of[jn]] and vals[jn] > v:
            return False
        return True
    G2 = G * G
    face = j // G2
    r = j - face * G2
    i = r // G
    jj = r - i * G
    return _no_face_neighbour_beats(j, i, jj, v, vals, evaluated, cell_of, G)


@njit(cache=True, inline="always")
def _cap_bound(v, c, s):
    """cos(max(0, arccos(v) - r)) for cos r = c, sin r = s: best value within angle r of a value v."""
    if v >= c:
        return 1.0
    return v * c + math.sqrt(max(0.0, 1.0 - v * v)) * s


@njit(cache=True)
def _eval_cell(x, samples, P, n, dim, G, k, grid, vals):
    """Score the samples of cell P into vals; return the cell's best value."""
    best = -3.0
    if n == 2:
        for j in range(P * k, P * k + k):
            v = 0.0
            for i in range(dim):
                v += x[i] * samples[j, i]
            vals[j] = v
            if v > best:
                best = v
        return best
    first = grid[4 + P]
    for ii in range(k):
        base = first + ii * G
        for j in range(base, base + k):
            v = x[0] * samples[j, 0] + x[1] * samples[j, 1] + x[2] * samples[j, 2] + x[3] * samples[j, 3]
            vals[j] = v
            if v > best:
                best = v
    return best


@njit(cache=True)
def boundary_max(x, geom, samples, cells, supers, grid, cell_of, w_best, b_best, stats):
    """Global maximum of x^T b over the zone boundary. Fills w_best (n), b_best (dim); returns f.

    stats (int64[4]) receives: cells evaluated, samples evaluated, Newton runs, Newton iterations.
    """
    dim = x.shape[0]
    n = dim - 1
    G = grid[0]
    k = grid[1]
    M = cells.shape[0]
    N = samples.shape[0] // 2
    kk = k if n == 2 else k * k
    # 1.-2. the samples of every cell whose cap bound beats the best sample so far, scored
    evaluated = np.zeros(M, dtype=np.bool_)
    cell_best = np.empty(M)
    vals = np.empty(N)
    best_sample, best_cell, n_cells = _score_cells(x, samples, cells, supers, grid, evaluated, cell_best, vals)
    # 3. Newton ascent from the best sample (necessarily a discrete local maximum): its value f1 >=
    #    best sample tightens the candidate threshold below
    best_j = _best_sample_of_cell(vals, best_cell, n, G, k, grid)
    w_try = np.empty(n)
    wk = np.empty(_WORK)
    best, its = newton_ascent(x, geom, samples[N + best_j, :n], dim, n, w_try, wk, -2.0)
    if best < best_sample:  # an ascent cannot end lower; guard against a failed step sequence
        best = best_sample
        for t in range(n):
            w_try[t] = samples[N + best_j, t]
    for t in range(n):
        w_best[t] = w_try[t]
    # 4. other discrete local maxima that could still beat it
    cand = np.empty(N, dtype=np.int64)
    cand_val = np.empty(N)
    ncand = _candidates(best, vals, evaluated, cell_best, cells, grid, cell_of, n, dim, G, k, cand, cand_val)
    # 5. Newton ascent from those candidates, best first, while their covering bound can still win
    best, n_newton, n_iter = _ascend_from_candidates(x, geom, samples, cells, cell_of, vals, cand, cand_val, ncand,
                                                     best_j, best, w_best, w_try, wk, dim, n, N)
    stats[0] = n_cells
    stats[1] = n_cells * kk
    stats[2] = 1 + n_newton
    stats[3] = its + n_iter
    y = wk[0:dim]
    _point(x, geom, w_best, dim, n, y)
    ny = 0.0
    for i in range(dim):
        ny += y[i] * y[i]
    ny = math.sqrt(ny)
    for i in range(dim):
        b_best[i] = y[i] / ny
    return best


@njit(cache=True)
def _score_cells(x, samples, cells, supers, grid, evaluated, cell_best, vals):
    """Steps 1 and 2: the cap bounds of the super-cells; in every super-cell whose bound beats the best sample
    so far, the samples of every cell whose own cap bound beats it scored into vals (the best super-cell
    first, the best cell of a super-cell first), the cells marked evaluated with their best value.
    Returns (best sample value, its cell, cells scored)."""
    dim = x.shape[0]
    n = dim - 1
    G = grid[0]
    k = grid[1]
    sc = grid[3]
    per_super = sc if n == 2 else sc * sc
    Ms = supers.shape[0]
    ubs = np.empty(Ms)
    top = 0
    for S in range(Ms):
        ct = 0.0
        for i in range(dim):
            ct += x[i] * supers[S, i]
        ubs[S] = _cap_bound(ct, supers[S, dim], supers[S, dim + 1])
        if ubs[S] > ubs[top]:
            top = S
    ubc = np.empty(per_super)
    best_sample = -2.0
    best_cell = 0
    n_cells = 0
    for r in range(Ms):
        S = _best_first(r, top)
        if ubs[S] <= best_sample:
            continue
        P0 = S * per_super
        tbest = 0
        for t in range(per_super):
            P = P0 + t
            ct = 0.0
            for i in range(dim):
                ct += x[i] * cells[P, i]
            ubc[t] = _cap_bound(ct, cells[P, dim], cells[P, dim + 1])
            if ubc[t] > ubc[tbest]:
                tbest = t
        for rr in range(per_super):
            t = _best_first(rr, tbest)
            if ubc[t] <= best_sample:
                continue
            P = P0 + t
            evaluated[P] = True
            n_cells += 1
            cell_best[P] = _eval_cell(x, samples, P, n, dim, G, k, grid, vals)
            if cell_best[P] > best_sample:
                best_sample = cell_best[P]
                best_cell = P
    return best_sample, best_cell, n_cells


@njit(cache=True)
def _best_sample_of_cell(vals, P, n, G, k, grid):
    """The index of the best scored sample of cell P (the first of equal ones)."""
    best_j = 0
    bv = -3.0
    if n == 2:
        for j in range(P * k, P * k + k):
            if vals[j] > bv:
                bv = vals[j]
                best_j = j
    else:
        first = grid[4 + P]
        for ii in range(k):
            for j in range(first + ii * G, first + ii * G + k):
                if vals[j] > bv:
                    bv = vals[j]
                    best_j = j
    return best_j


@njit(cache=True)
def _candidates(best, vals, evaluated, cell_best, cells, grid, cell_of, n, dim, G, k, cand, cand_val):
    """Step 4: the discrete local maxima that could still beat ``best``, into cand (samples) and cand_val
    (their negated values), room for every sample; returns their count. The global maximum lies within
    angle h of a sample v, so cos(arccos(v) - h) > best, i.e. v > cos(arccos(best) + h)."""
    M = cells.shape[0]
    ncand = 0
    bs = min(best, 1.0)
    sbs = math.sqrt(max(0.0, 1.0 - bs * bs))
    for P in range(M):
        if not evaluated[P]:
            continue
        thr = bs * cells[P, dim + 2] - sbs * cells[P, dim + 3]
        if cell_best[P] < thr:
            continue
        if n == 2:
            for j in range(P * k, P * k + k):
                v = vals[j]
                if v >= thr and _is_local_max(j, v, vals, evaluated, cell_of, n, G):
                    cand[ncand] = j
                    cand_val[ncand] = -v
                    ncand += 1
            continue
        first = grid[4 + P]
        r0 = first % (G * G)
        i0 = r0 // G
        j0 = r0 - i0 * G
        # all 8 neighbour cells on the face and scored: every neighbour value of every sample of
        # this cell is valid, and the local-maximum test is a branch-free max of 8 values
        ring = True
        for q in range(8):
            cq = grid[4 + M + 8 * P + q]
            if cq < 0 or not evaluated[cq]:
                ring = False
        for ii in range(k):
            base = first + ii * G
            for t in range(k):
                j = base + t
                v = vals[j]
                if v < thr:
                    continue
                if ring:
                    mv = max(max(max(vals[j - G - 1], vals[j - G]), max(vals[j - G + 1], vals[j - 1])),
                             max(max(vals[j + 1], vals[j + G - 1]), max(vals[j + G], vals[j + G + 1])))
                    is_max = mv <= v
                else:
                    is_max = _is_local_max_face(j, i0 + ii, j0 + t, v, vals, evaluated, cell_of, G, i0, j0, k)
                if is_max:
                    cand[ncand] = j
                    cand_val[ncand] = -v
                    ncand += 1
    return ncand


@njit(cache=True)
def _ascend_from_candidates(x, geom, samples, cells, cell_of, vals, cand, cand_val, ncand, best_j, best, w_best,
                            w_try, wk, dim, n, N):
    """Step 5: a Newton ascent from each candidate but ``best_j``, best first, while its covering bound can
    still beat ``best``; w_best follows the best. Returns (best, Newton runs, their iterations)."""
    order = np.argsort(cand_val[:ncand])
    n_newton = 0
    n_iter = 0
    for r in range(ncand):
        j = cand[order[r]]
        if j == best_j:
            continue
        v = min(vals[j], 1.0)
        P = cell_of[j]
        if _cap_bound(v, cells[P, dim + 2], cells[P, dim + 3]) <= best:
            continue
        f, its = newton_ascent(x, geom, samples[N + j, :n], dim, n, w_try, wk, best)
        n_newton += 1
        n_iter += its
        if f < v:  # an ascent cannot end lower; guard against a failed step sequence
            f = v
            for t in range(n):
                w_try[t] = samples[N + j, t]
        if f > best:
            best = f
            for t in range(n):
                w_best[t] = w_try[t]
    return best, n_newton, n_iter


@njit(cache=True)
def contains_point(x, geom, plane):
    """True when x is in the closed zone: the ray through x meets the plane inside K.
    plane = [unit normal nu (dim), offset h0]: the plane is {y : nu^T y = h0}."""
    dim = x.shape[0]
    n = dim - 1
    q = geom[0]
    obb = 3 + dim + dim * n
    oa = 3 + dim + 2 * dim * n
    xn = 0.0
    for i in range(dim):
        xn += x[i] * plane[i]
    if xn <= 0.0:
        return False
    scale = plane[dim] / xn
    acc = 0.0
    for k in range(n):
        p = 0.0
        for i in range(dim):
            p += geom[obb + i * n + k] * (x[i] * scale - geom[3 + i])
        acc += abs(p / geom[oa + k]) ** q
    return acc <= 1.0


def pack(geom, samples, cells, supers, grid, cell_of, plane):
    """Pack a zone's search data into the 4 arrays the entry points take (numba's per-argument
    dispatch cost is ~0.1 us): fdata = [geom, plane], samples, caps = [super-cells padded to the cell
    width; cells], idata = [grid, cell_of]."""
    pad = np.zeros((supers.shape[0], cells.shape[1]))
    pad[:, :supers.shape[1]] = supers
    return (np.ascontiguousarray(np.concatenate([geom, plane])), samples,
            np.ascontiguousarray(np.vstack([pad, cells])),
            np.ascontiguousarray(np.concatenate([grid, cell_of.astype(np.int64)])))


@njit(cache=True)
def _unpack(x, fdata, samples, caps, idata):
    dim = x.shape[0]
    n = dim - 1
    N = samples.shape[0] // 2
    M = (idata.shape[0] - 4 - N) // 9
    Ms = caps.shape[0] - M
    plane = fdata[3 + dim + 2 * dim * n + n:]
    return fdata, caps[Ms:], caps[:Ms], idata[:4 + 9 * M], idata[4 + 9 * M:], plane


@njit(cache=True)
def nearest_packed(x, fdata, samples, caps, idata, w_best, b_best, stats):
    """boundary_max on packed data."""
    geom, cells, supers, grid, cell_of, plane = _unpack(x, fdata, samples, caps, idata)
    return boundary_max(x, geom, samples, cells, supers, grid, cell_of, w_best, b_best, stats)


@njit(cache=True)
def contains_packed(x, fdata, samples, caps, idata):
    geom, cells, supers, grid, cell_of, plane = _unpack(x, fdata, samples, caps, idata)
    return contains_point(x, geom, plane)


@njit(cache=True)
def signed_separation_one(x, fdata, samples, caps, idata, clamp):
    """Signed separation of one x (negative inside); clamp=True gives 0 inside without searching."""
    geom, cells, supers, grid, cell_of, plane = _unpack(x, fdata, samples, caps, idata)
    dim = x.shape[0]
    inside = contains_point(x, geom, plane)
    if inside and clamp:
        return 0.0
    w_best = np.empty(dim - 1)
    b_best = np.empty(dim)
    stats = np.empty(4, dtype=np.int64)
    boundary_max(x, geom, samples, cells, supers, grid, cell_of, w_best, b_best, stats)
    d = 0.0
    for i in range(dim):
        t = x[i] - b_best[i]
        d += t * t
    d *= 0.5
    return -d if inside else d


@njit(cache=True)
def signed_separation_batch(X, fdata, samples, caps, idata, clamp):
    """signed_separation_one for each row of X."""
    m = X.shape[0]
    out = np.empty(m)
    for r in range(m):
        out[r] = signed_separation_one(X[r], fdata, samples, caps, idata, clamp)
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
# Construction of the search structure (once per zone: array expressions and small kernels)

@njit(cache=True)
def _row_sums(points):
    """Per group the sum of its rows, in row order: (G, R, dim) -> (G, dim). np.add.reduce over axis 0
    of a C-ordered (R, dim) block (``mean(axis=0)``) adds the rows one after the other like this."""
    G, R, dim = points.shape
    out = np.empty((G, dim))
    for g in range(G):
        for i in range(dim):
            s = points[g, 0, i]
            for r in range(1, R):
                s += points[g, r, i]
            out[g, i] = s
    return out


@njit(cache=True)
def _nearest_sq_dist(bd, bs):
    """Per cell and dense point, the squared distance to the nearest sample of the same cell:
    bd (C, D, dim), bs (C, S, dim) -> (C, D), dim 3 or 4. Each squared distance is summed in the order of
    np.einsum("ijk,ijk->ij", diff, diff) over a row of dim <= 4, which reduces one SIMD register of the
    products: (d0^2 + d2^2) + (d1^2 + d3^2) (tested against it)."""
    C, D, dim = bd.shape
    S = bs.shape[1]
    out = np.empty((C, D))
    for c in range(C):
        for j in range(D):
            best = np.inf
            for s in range(S):
                d0 = bd[c, j, 0] - bs[c, s, 0]
                d1 = bd[c, j, 1] - bs[c, s, 1]
                d2 = bd[c, j, 2] - bs[c, s, 2]
                p3 = 0.0
                if dim == 4:
                    d3 = bd[c, j, 3] - bs[c, s, 3]
                    p3 = d3 * d3
                v = (d0 * d0 + d2 * d2) + (d1 * d1 + p3)
                if np.isnan(v):  # as np.min: a NaN wins
                    best = v
                    break
                if v < best:
                    best = v
            out[c, j] = best
    return out


@njit(cache=True)
def _cap_norms(points, axis):
    """|p - axis| and |p + axis| for every point p of each group: points (G, R, dim), axis (G, dim) ->
    two (G, R) arrays, each norm as np.linalg.norm(., axis=1) of a (R, dim) block: the squares summed in
    order (tested against it)."""
    G, R, dim = points.shape
    minus = np.empty((G, R))
    plus = np.empty((G, R))
    for g in range(G):
        for r in range(R):
            sm = 0.0
            sp = 0.0
            for i in range(dim):
                dm = points[g, r, i] - axis[g, i]
                dp = points[g, r, i] + axis[g, i]
                if i == 0:
                    sm = dm * dm
                    sp = dp * dp
                else:
                    sm += dm * dm
                    sp += dp * dp
            minus[g, r] = math.sqrt(sm)
            plus[g, r] = math.sqrt(sp)
    return minus, plus


def _caps(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Caps of G point groups at once: points (G, R, dim) -> unit axes (G, dim), half-angles (G,).

    Each group's value is bit for bit that of the per-group numpy expressions
        axis = P.mean(axis=0); axis /= np.linalg.norm(axis)
        rho = max(2 arctan2(|P - axis|, |P + axis|))  (row norms: np.linalg.norm(., axis=1))
    (tested against them): the mean is the same sequential row sum divided by R, the axis norm the
    same dot product, the row norms the same sums of squares in order."""
    G, R, dim = points.shape
    axis = _row_sums(points) / R
    for g in range(G):  # np.linalg.norm of a vector is sqrt(x.dot(x)) (BLAS); keep that exact product
        axis[g] /= math.sqrt(axis[g].dot(axis[g]))
    minus, plus = _cap_norms(points, axis)
    return axis, np.max(2.0 * np.arctan2(minus, plus), axis=1)


def _inflate(angle: np.ndarray) -> np.ndarray:
    """min(pi, 1.1 angle + 1e-9) elementwise, Python's min (pi unless strictly smaller)."""
    v = 1.1 * angle + 1e-9
    return np.where(v < np.pi, v, np.pi)


def _covering_radius(bd: np.ndarray, bs: np.ndarray) -> np.ndarray:
    """Per cell: the farthest dense point from its nearest sample of the same cell [rad].
    bd (C, D, dim), bs (C, S, dim) -> (C,)."""
    C, D, _ = bd.shape
    chord = np.sqrt(_nearest_sq_dist(bd, bs).reshape(C * D))
    return np.max((2.0 * np.arcsin(np.minimum(1.0, chord / 2.0))).reshape(C, D), axis=1)


def _cell_index(m: int, sc: int, bi: np.ndarray, bj: np.ndarray) -> np.ndarray:
    """Kernel number of cell (bi, bj) within its cube face (cells grouped by sc x sc super-cell)."""
    return ((bi // sc) * (m // sc) + bj // sc) * sc * sc + (bi % sc) * sc + bj % sc


def _cell_coordinates(m: int, sc: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face, row bi and column bj of every cell in kernel numbering (6 m^2 cells), int64 arrays."""
    P = np.arange(6 * m * m, dtype=np.int64)
    face, rem = np.divmod(P, m * m)
    S, t = np.divmod(rem, sc * sc)
    SI, SJ = np.divmod(S, m // sc)
    ti, tj = np.divmod(t, sc)
    return face, SI * sc + ti, SJ * sc + tj


def _face_points(axis: int, sign: float, tan_angles: np.ndarray, bi: np.ndarray, bj: np.ndarray) -> np.ndarray:
    """Unit directions of the equi-angular grid of cells (bi, bj) of one cube face: point (i, j) of a cell
    is (sign, tan alpha_i, tan beta_j) in the face's axis order, alpha from row bi and beta from row bj of
    the per-row angles' tangents (m, K) -> (cells, K K, 3), normalised as np.linalg.norm rows."""
    K = tan_angles.shape[1]
    v = np.empty((len(bi), K, K, 3))
    v[..., axis] = sign
    v[..., (axis + 1) % 3] = tan_angles[bi][:, :, None]
    v[..., (axis + 2) % 3] = tan_angles[bj][:, None, :]
    v = v.reshape(-1, 3)
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).reshape(len(bi), K * K, 3)


def _cell_grids(n: int, m: int, k: int, sc: int, sub: int) -> tuple[np.ndarray, np.ndarray]:
    """Every cell's samples w (M, k^(n-1), n) (grid order inside the cell) and a dense sub-sampling
    including the cell's edges (M, (sub k + 1)^(n-1), n), indexed by kernel cell number.
    n = 2: m arcs of k samples on S^1. n = 3: equi-angular cube-sphere, 6 faces x m x m cells of
    k x k samples, sample index face G^2 + i G + j (G = m k)."""
    G = m * k
    if n == 2:
        dt = 2.0 * np.pi / G
        P = np.arange(m)
        ts = (P[:, None] * k + np.arange(k) + 0.5) * dt
        # one linspace per arc, as np.linspace(P k dt, (P + 1) k dt, sub k + 1) (the same expressions)
        td = np.linspace(P * k * dt, (P + 1) * k * dt, sub * k + 1, axis=1)
        return np.stack([np.cos(ts), np.sin(ts)], axis=-1), np.stack([np.cos(td), np.sin(td)], axis=-1)
    da = 0.5 * np.pi / G
    M = 6 * m * m
    row = np.arange(m)
    # per row of cells: its sample angles and its dense angles (one linspace per row, as per cell)
    tan_s = np.tan(-0.25 * np.pi + (row[:, None] * k + np.arange(k) + 0.5) * da)
    tan_d = np.tan(np.linspace(-0.25 * np.pi + row * k * da, -0.25 * np.pi + (row + 1) * k * da, sub * k + 1, axis=1))
    bi, bj = np.divmod(np.arange(m * m), m)
    in_face = _cell_index(m, sc, bi, bj)
    ws = np.empty((M, k * k, 3))
    wd = np.empty((M, (sub * k + 1) ** 2, 3))
    for face in range(6):
        axis, sign = face // 2, (1.0 if face % 2 == 0 else -1.0)
        ws[face * m * m + in_face] = _face_points(axis, sign, tan_s, bi, bj)
        wd[face * m * m + in_face] = _face_points(axis, sign, tan_d, bi, bj)
    return ws, wd


def grid_sizes(n: int, resolution: tuple[int, int] | None = None) -> tuple[int, int, int, int, int]:
    """(m, k, sc, M, N) of the grid on S^(n-1): cells per circle / cube-face edge, samples per cell edge,
    cells per super-cell edge, cells, samples."""
    if n == 2:
        m, k = resolution or (128, 16)
        sc = next(s for s in (8, 4, 2, 1) if m % s == 0)
        return m, k, sc, m, m * k
    if n == 3:
        m, k = resolution or (12, 4)
        sc = next(s for s in (3, 4, 2, 1) if m % s == 0)
        return m, k, sc, 6 * m * m, 6 * (m * k) ** 2
    raise ValueError(f"superellipsoid zones are implemented for S^2 and S^3 (n = 2, 3), got n = {n}")


def build_cells(geom: np.ndarray, dim: int, n: int, resolution: tuple[int, int] | None = None):
    """Precompute samples (2N, dim) in grid order (rows [0, N): boundary points b; rows [N, 2N): their
    w in the first n columns; scoring reads only the compact b block), cells (M, dim + 4), super-cells (Ms, dim + 2),
    grid = [G, k, m, sc, first sample of each cell (M), 8 neighbour cells of each cell (8M)] (samples per circle / cube-face edge, samples
    per cell edge, cells per circle / face edge, cells per super-cell edge) and cell_of (N,), the cell
    of every sample. All cells at once (array expressions per element as the per-cell ones)."""
    sub = 4
    m, k, sc, M, N = grid_sizes(n, resolution)
    G = m * k
    ws, wd = _cell_grids(n, m, k, sc, sub)
    S, D = ws.shape[1], wd.shape[1]
    bs = boundary_points(np.ascontiguousarray(ws.reshape(M * S, n)), geom, dim, n).reshape(M, S, dim)
    bd = boundary_points(np.ascontiguousarray(wd.reshape(M * D, n)), geom, dim, n).reshape(M, D, dim)
    axis, rho = _caps(bd)
    # Safety factors: the dense sub-sampling is 4x finer than the samples, so the missed excess
    # is second order; 10% plus a small absolute margin covers it.
    rho = _inflate(rho)
    h = _inflate(_covering_radius(bd, bs))
    cells = np.empty((M, dim + 4))
    cells[:, :dim] = axis
    cells[:, dim:] = np.stack([np.cos(rho), np.sin(rho), np.cos(h), np.sin(h)], axis=1)
    samples = np.zeros((2 * N, dim))
    cell_of = np.empty(N, dtype=np.int32)
    if n == 2:
        samples[:N] = bs.reshape(N, dim)
        samples[N:, :n] = ws.reshape(N, n)
        cell_of[:] = np.repeat(np.arange(M, dtype=np.int32), k)
    else:
        # each cell's face and (row, column) on it, then its samples' grid indices (P, a, b)
        face, bi, bj = _cell_coordinates(m, sc)
        a = np.arange(k)
        idx = (face[:, None, None] * G * G + (bi[:, None, None] * k + a[None, :, None]) * G
               + bj[:, None, None] * k + a[None, None, :]).reshape(M * k * k)
        samples[idx] = bs.reshape(M * k * k, dim)
        samples[N + idx, :n] = ws.reshape(M * k * k, n)
        cell_of[idx] = np.repeat(np.arange(M, dtype=np.int32), k * k)
    per_super = sc if n == 2 else sc * sc
    s_axis, s_rho = _caps(bd.reshape(M // per_super, per_super * D, dim))
    s_rho = _inflate(s_rho)
    supers = np.empty((M // per_super, dim + 2))
    supers[:, :dim] = s_axis
    supers[:, dim:] = np.stack([np.cos(s_rho), np.sin(s_rho)], axis=1)
    # the 8 neighbour cells of every cell on the same cube face (-1 across a face edge; unused on S^1)
    adj = -np.ones((M, 8), dtype=np.int64)
    if n == 2:
        first = np.arange(M, dtype=np.int64) * k
    else:
        first = face * G * G + bi * k * G + bj * k
        q = 0
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                if di == 0 and dj == 0:
                    continue
                ni, nj = bi + di, bj + dj
                ok = (0 <= ni) & (ni < m) & (0 <= nj) & (nj < m)
                adj[ok, q] = face[ok] * m * m + _cell_index(m, sc, ni[ok], nj[ok])
                q += 1
    grid = np.concatenate([np.array([G, k, m, sc], dtype=np.int64), first, adj.ravel()])
    return (np.ascontiguousarray(samples), np.ascontiguousarray(cells), np.ascontiguousarray(supers),
            grid, cell_of)
