"""gnc.laws against the paper's formulas, written out independently here.

* GradientLaw: the closed form must equal -grad W, W = k1 d/(d + beta) evaluated from the paper's
  definitions (d_s(x, a) = 1 - x^T a, footnote cubic h_i), by central finite differences in R^(n+1).
* StarShapedLaw: u = k1 u_i(x) in the layer of the nearest zone, k1 x_d outside; checked against the
  formula with an independent closed-form cone separation and with an all-zones (unpruned) evaluation.
"""
from __future__ import annotations

import numpy as np
import pytest

from gnc.laws import GradientLaw, StarShapedLaw, cubic_h
from gnc.zones import ConicZone, StarZone

E4 = np.eye(4)
SEVEN_AXES = [E4[1], E4[2], E4[3], -E4[1], -E4[2], -E4[3], -E4[0]]
XI = np.pi / 12
EPS_S3 = 0.125


def seven_cones():
    return [ConicZone(a, XI) for a in SEVEN_AXES]


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def w_paper(x, x_d, axes, xis, eps, k1):
    """W from the paper, with the linear d_s(x, a) = 1 - x^T a (the function whose gradient is the law)."""
    d = 1.0 - x @ x_d
    theta_eps = np.arccos(1.0 - eps)
    beta = 1.0
    for g, xi in zip(axes, xis):
        p = 1.0 - x @ g
        lo, hi = 1.0 - np.cos(xi), 1.0 - np.cos(xi + theta_eps)
        if lo <= p <= hi:  # x in N_eps(U_i): d_s(x, U_i) <= eps
            beta = 1.0 + (p - hi) ** 3 / (hi - lo) ** 3
    return k1 * d / (d + beta)


def grad_fd(f, x, h=1e-6):
    g = np.zeros_like(x)
    for k in range(x.shape[0]):
        e = np.zeros_like(x)
        e[k] = h
        g[k] = (f(x + e) - f(x - e)) / (2 * h)
    return g


def layer_states(rng, axes, xi, eps, count):
    """Random unit vectors in the eps-layers of the cones (angle from an axis in (xi, xi + theta_eps))."""
    theta_eps = np.arccos(1.0 - eps)
    out = []
    for _ in range(count):
        g = axes[rng.integers(len(axes))]
        ang = xi + rng.uniform(0.02, 0.98) * theta_eps
        t = rng.normal(size=g.shape[0])
        t -= g * (t @ g)
        t /= np.linalg.norm(t)
        out.append(np.cos(ang) * g + np.sin(ang) * t)
    return np.array(out)


def test_cubic_h_matches_footnote_properties():
    lo, hi = 0.1, 0.3
    h, hp = cubic_h(np.array([lo, hi]), lo, hi)
    assert h[0] == pytest.approx(0.0, abs=1e-15) and h[1] == pytest.approx(1.0)
    assert hp[1] == 0.0 and hp[0] > 0
    p = np.linspace(lo, hi, 50)
    h, hp = cubic_h(p, lo, hi)
    assert np.all(np.diff(h) > 0)
    step = 1e-7
    fd = (cubic_h(p + step, lo, hi)[0] - cubic_h(p - step, lo, hi)[0]) / (2 * step)
    np.testing.assert_allclose(hp, fd, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("k1", [1.0, 2.5])
def test_gradient_law_is_minus_grad_w(k1):
    rng = np.random.default_rng(7)
    x_d = E4[0]
    law = GradientLaw(x_d, seven_cones(), k1=k1, eps=EPS_S3)
    states = np.vstack([layer_states(rng, SEVEN_AXES, XI, EPS_S3, 150), rng.normal(size=(50, 4))])
    states /= np.linalg.norm(states, axis=1, keepdims=True)
    checked_layer = 0
    for x in states:
        if min(1 - x @ g for g in SEVEN_AXES) < 1 - np.cos(XI) + 1e-4:
            continue  # inside a cone (the law is defined on M_0 only)
        u = law.control(x)
        g_fd = grad_fd(lambda y: w_paper(y, x_d, SEVEN_AXES, [XI] * 7, EPS_S3, k1), x)
        np.testing.assert_allclose(u, -g_fd, rtol=1e-6, atol=1e-6 * max(1.0, np.linalg.norm(u)))
        checked_layer += law.diagnose(x).active_zone is not None
    assert checked_layer > 100


def test_gradient_law_potential_matches_paper():
    rng = np.random.default_rng(3)
    law = GradientLaw(E4[0], seven_cones(), k1=1.3, eps=EPS_S3)
    for x in layer_states(rng, SEVEN_AXES, XI, EPS_S3, 30):
        assert law.potential(x) == pytest.approx(w_paper(x, E4[0], SEVEN_AXES, [XI] * 7, EPS_S3, 1.3), rel=1e-9)


def test_gradient_law_boundary_limit_and_outside():
    # On the cone boundary u = -k1 h'(Dlo)/d_s(x, x_d) g_i (paper, after eq. conic_individual_control_expression)
    k1 = 1.0
    law = GradientLaw(E4[0], seven_cones(), k1=k1, eps=EPS_S3)
    g = E4[2]
    t = unit([0.6, 0.0, 0.0, 0.8])  # tangent at g, also mixes in x_d
    x = np.cos(XI) * g + np.sin(XI) * t
    lo, hi = 1 - np.cos(XI), 1 - np.cos(XI + np.arccos(1 - EPS_S3))
    _, hp = cubic_h(lo, lo, hi)
    d = 1 - x @ E4[0]
    np.testing.assert_allclose(law.control(x), -k1 * hp / d * g, rtol=1e-9)
    # velocity on the boundary points out of the cone
    assert law.velocity(x) @ g < 0
    # outside every layer: k1/(1 + d)^2 x_d
    y = unit([0.9, 0.1, -0.1, 0.05])
    assert law.diagnose(y).active_zone is None
    np.testing.assert_allclose(law.control(y), k1 / (1 + (1 - y @ E4[0])) ** 2 * E4[0], rtol=1e-12)


def test_gradient_law_inside_a_cone_pushes_out():
    law = GradientLaw(E4[0], seven_cones(), k1=1.0, eps=EPS_S3)
    x = unit([0.1, 0.99, 0.05, 0.0])  # inside the +e2 cone
    assert law.velocity(x) @ E4[1] < 0
    assert np.all(np.isfinite(law.control(x)))


def test_gradient_law_jacobian_at_target():
    # J(x_d) = -k1 (I + x_d x_d^T): on the tangent space the flow is -k1 eta (paper, proof of Theorem 1)
    k1 = 1.7
    law = GradientLaw(E4[0], seven_cones(), k1=k1, eps=EPS_S3)
    for eta in (E4[1], unit([0, 1, 1, 0]), E4[3]):
        h = 1e-6
        xp = unit(E4[0] + h * eta)
        xm = unit(E4[0] - h * eta)
        jac = (law.velocity(xp) - law.velocity(xm)) / (2 * h)
        np.testing.assert_allclose(jac, -k1 * eta, atol=1e-6)


def test_gradient_batch_equals_single():
    rng = np.random.default_rng(11)
    law = GradientLaw(E4[0], seven_cones(), k1=1.0, eps=EPS_S3)
    X = np.vstack([layer_states(rng, SEVEN_AXES, XI, EPS_S3, 200), rng.normal(size=(300, 4))])
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    U = law.control_batch(X)
    for x, u in zip(X, U):
        np.testing.assert_array_equal(u, law.control(x))
    np.testing.assert_allclose(law.velocity_batch(X)[:5], [law.velocity(x) for x in X[:5]], atol=1e-15)


# ------------------------------------------------------------------------------------------------
# StarShapedLaw
# ------------------------------------------------------------------------------------------------


def star_u_paper(x, x_d, kernels, d_list, eps, k1, kappa):
    i = int(np.argmin(d_list))
    if d_list[i] > eps:
        return k1 * x_d
    a = d_list[i] / eps
    return k1 * (a * x_d - (1.0 - a) / kappa * kernels[i])


def cone_separation(x, g, xi):
    ang = np.arccos(np.clip(x @ g, -1, 1))
    return 1 - np.cos(max(ang - xi, 0.0))


def test_star_law_with_cones_matches_paper_formula():
    rng = np.random.default_rng(5)
    x_d = E4[0]
    cones = seven_cones()[:6]  # the star law needs g_i != -x_d
    k1, kappa, eps = 1.3, 2.0, 0.1
    law = StarShapedLaw(x_d, cones, k1=k1, kappa=kappa, eps=eps)
    X = np.vstack([layer_states(rng, SEVEN_AXES[:6], XI, eps, 200), rng.normal(size=(100, 4))])
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    n_layer = 0
    for x in X:
        d_list = [cone_separation(x, g, XI) for g in SEVEN_AXES[:6]]
        expected = star_u_paper(x, x_d, SEVEN_AXES[:6], d_list, eps, k1, kappa)
        np.testing.assert_allclose(law.control(x), expected, atol=1e-12)
        n_layer += min(d_list) <= eps
    assert n_layer > 150
    np.testing.assert_allclose(law.control_batch(X), [law.control(x) for x in X], atol=1e-15)


def test_star_law_boundary_edge_and_outside():
    k1, kappa, eps = 1.0, 1.5, 0.05
    zone = ConicZone(E4[1], XI)
    law = StarShapedLaw(E4[0], [zone], k1=k1, kappa=kappa, eps=eps)
    t = unit([1.0, 0.0, 0.3, 0.0])
    on_boundary = np.cos(XI) * E4[1] + np.sin(XI) * t
    np.testing.assert_allclose(law.control(on_boundary), -k1 / kappa * E4[1], atol=1e-12)
    edge = np.cos(XI + np.arccos(1 - eps) - 1e-9) * E4[1] + np.sin(XI + np.arccos(1 - eps) - 1e-9) * t
    np.testing.assert_allclose(law.control(edge), k1 * E4[0], atol=1e-6)  # continuous at the layer edge
    far = unit([0.8, -0.5, 0.2, 0.1])
    np.testing.assert_array_equal(law.control(far), k1 * E4[0])
    diag = law.diagnose(on_boundary)
    assert diag.active_zone == 0 and diag.separation_to_unsafe == pytest.approx(0.0, abs=1e-12)
    assert diag.separation_to_target == pytest.approx(1 - on_boundary[0])
    assert law.diagnose(far).active_zone is None


def s2_star_zones():
    def sph(polar, az):
        p, a = np.radians(polar), np.radians(az)
        return np.array([np.sin(p) * np.cos(a), np.sin(p) * np.sin(a), np.cos(p)])

    ang = np.pi / 2 + np.pi * np.arange(10) / 5
    r = np.where(np.arange(10) % 2 == 0, 0.55, 0.2)
    star = StarZone.polygon(sph(75, 0), None, np.column_stack([r * np.cos(ang), r * np.sin(ang)]))
    spiky = StarZone.superellipsoid(sph(95, 90), None, [0.6, 0.42], 0.6)
    return [star, spiky]


def test_star_law_cap_pruning_changes_nothing():
    # Unpruned reference: every zone's separation, then the paper's formula.
    rng = np.random.default_rng(2)
    zones = s2_star_zones()
    x_d = np.array([0.0, 0.0, 1.0])
    eps = 0.01
    law = StarShapedLaw(x_d, zones, k1=1.0, kappa=1.0, eps=eps)
    kernels = [z.kernel for z in zones]
    pts = []
    for z in zones:  # states concentrated around the zones, many inside the thin layer
        b = z.boundary(400)
        jitter = rng.normal(scale=0.05, size=b.shape)
        pts.append(b + jitter)
    X = np.vstack(pts + [rng.normal(size=(200, 3))])
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    n_layer = 0
    for x in X:
        d_list = [z.separation(x) for z in zones]
        np.testing.assert_allclose(law.control(x), star_u_paper(x, x_d, kernels, d_list, eps, 1.0, 1.0), atol=1e-12)
        n_layer += 0 < min(d_list) <= eps
    assert n_layer > 30
    np.testing.assert_allclose(law.control_batch(X), [law.control(x) for x in X], atol=1e-12)


def test_star_law_picks_nearest_layer_when_layers_overlap():
    # Outside the paper's assumptions (eps too large) the law still uses the nearest zone.
    a, b = ConicZone(unit([0, 1, 0.2]), 0.2), ConicZone(unit([0, 1, -0.2]), 0.2)
    law = StarShapedLaw(np.array([1.0, 0, 0]), [a, b], k1=1.0, kappa=1.0, eps=0.5)
    x = unit([0.3, 1.0, 0.05])
    d = [a.separation(x), b.separation(x)]
    assert law.diagnose(x).active_zone == int(np.argmin(d))


def test_paper_s3_star_zone_batch_equals_single():
    from gnc.zones import paper_s3_star_zone

    zone = paper_s3_star_zone()
    law = StarShapedLaw(E4[0], [zone], k1=1.0, kappa=1.0, eps=0.1)
    rng = np.random.default_rng(9)
    b = zone.boundary(40)
    X = b + rng.normal(scale=0.05, size=b.shape)
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    np.testing.assert_allclose(law.control_batch(X), [law.control(x) for x in X], atol=1e-12)
    assert sum(law.diagnose(x).active_zone is not None for x in X) > 10


def test_bad_inputs_are_rejected():
    cones = seven_cones()
    law = GradientLaw(E4[0], cones, k1=1.0, eps=EPS_S3)
    with pytest.raises(ValueError, match="unit vector"):
        law.control([1.0, 1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="shape"):
        law.control([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="unit vectors; row 1"):
        law.control_batch([[1.0, 0, 0, 0], [2.0, 0, 0, 0]])
    star = StarShapedLaw(E4[0], cones[:6], k1=1.0, kappa=1.0, eps=0.1)
    with pytest.raises(ValueError, match="unit vector"):
        star.control([0.5, 0.5, 0.0, 0.0])
    with pytest.raises(ValueError, match="shape"):
        star.control([1.0, 0.0, 0.0])
    with pytest.raises(TypeError, match="StarShapedLaw"):
        GradientLaw(np.array([0, 0, 1.0]), s2_star_zones(), k1=1.0, eps=0.01)
    with pytest.raises(ValueError, match="eps"):
        StarShapedLaw(E4[0], cones, k1=1.0, kappa=1.0, eps=0.0)
    with pytest.raises(ValueError, match="kappa"):
        StarShapedLaw(E4[0], cones, k1=1.0, kappa=-1.0, eps=0.1)
    with pytest.raises(ValueError, match="R\\^3"):
        StarShapedLaw(E4[0], s2_star_zones(), k1=1.0, kappa=1.0, eps=0.1)
    with pytest.raises(ValueError, match="antipode"):
        GradientLaw(E4[0], [ConicZone(E4[1], 3.0)], k1=1.0, eps=0.5)
