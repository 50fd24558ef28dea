"""gnc.checks: every assumption violation is detected and named; the kappa trap; forward invariance.

Independent references: the paper's own numbers (delta = pi/6 for the seven cones, the literal S^3 zone
reaching d_s = 0.066 of x_d), brute force over boundary samples, a kappa_bar recomputed here from the
paper's formula, and closed-loop simulations.
"""
from __future__ import annotations

import numpy as np
import pytest

from gnc.checks import check_assumptions
from gnc.laws import GradientLaw, StarShapedLaw
from gnc.zones import ConicZone, StarZone

E4 = np.eye(4)


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def sph(polar_deg, az_deg):
    p, a = np.radians(polar_deg), np.radians(az_deg)
    return np.array([np.sin(p) * np.cos(a), np.sin(p) * np.sin(a), np.cos(p)])


def seven_cones():
    return [ConicZone(a, np.pi / 12) for a in (E4[1], E4[2], E4[3], -E4[1], -E4[2], -E4[3], -E4[0])]


def rk4(velocity_batch, X, dt, steps, record=False):
    hist = [X.copy()] if record else None
    for _ in range(steps):
        def f(Y):
            return velocity_batch(Y / np.linalg.norm(Y, axis=1, keepdims=True))

        k1 = f(X)
        k2 = f(X + 0.5 * dt * k1)
        k3 = f(X + 0.5 * dt * k2)
        k4 = f(X + dt * k3)
        X = X + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        X /= np.linalg.norm(X, axis=1, keepdims=True)
        if record:
            hist.append(X.copy())
    return (X, np.array(hist)) if record else X


# ------------------------------------------------------------------------------------------------
# the paper's S^3 configurations
# ------------------------------------------------------------------------------------------------


def test_seven_cones_delta_is_pi_over_6():
    rep = check_assumptions(E4[0], seven_cones(), 0.125)
    assert rep.law == "gradient" and rep.ok, rep.summary()
    assert rep.delta == pytest.approx(np.pi / 6, abs=1e-12)  # the paper: "delta = pi/6 rad"
    assert rep.eps_max == pytest.approx(1 - np.cos(np.pi / 6), abs=1e-12)
    assert rep.kappa_bar is None


def test_literal_paper_zone_rejected_with_numbers():
    from gnc.zones import paper_s3_star_zone

    rep = check_assumptions(E4[0], [paper_s3_star_zone(literal=True)], 0.1, kappa=1.0)
    assert not rep.ok
    # the spike tip psi(g1 + a e1), a = 1.5^2.5, is the closest point to x_d
    tip = unit(np.array([-0.5, -0.5, -0.5, -0.5]) + 1.5**2.5 * E4[0])
    assert rep.target_separation == pytest.approx(1 - tip[0], abs=1e-9)
    text = " ".join(rep.errors)
    assert "eps = 0.1" in text and "0.066" in text and "zone 0" in text
    # the spurious equilibrium is about 3.8 deg from x_d
    stable = [e for e in rep.undesired_equilibria if e["stable"]]
    assert stable and np.degrees(np.arccos(stable[0]["x"][0])) == pytest.approx(3.84, abs=0.02)
    good = check_assumptions(E4[0], [paper_s3_star_zone()], 0.1, kappa=1.0)
    assert good.ok, good.summary()


# ------------------------------------------------------------------------------------------------
# each violation detected, with zones and numbers in the message
# ------------------------------------------------------------------------------------------------


def test_overlapping_zones():
    zones = [ConicZone(sph(90, 0), 0.3), ConicZone(sph(90, 30), 0.3)]
    rep = check_assumptions(np.array([0, 0, 1.0]), zones, 0.01)
    assert not rep.ok
    assert any("Assumption 1" in e and "zones 0 and 1" in e for e in rep.errors)


def test_eps_too_large_for_delta():
    zones = [ConicZone(sph(90, 0), 0.3), ConicZone(sph(90, 50), 0.3)]
    gap = np.radians(50) - 0.6
    limit = 1 - np.cos(gap / 2)
    ok = check_assumptions(np.array([0, 0, 1.0]), zones, 0.9 * limit)
    assert ok.ok, ok.summary()
    assert ok.eps_max == pytest.approx(limit, rel=1e-9)
    bad = check_assumptions(np.array([0, 0, 1.0]), zones, 1.1 * limit)
    assert not bad.ok
    assert any("1 - cos(delta)" in e and "zones 0 and 1" in e and f"{limit:.6g}" in e for e in bad.errors)


def test_target_inside_zone():
    rep = check_assumptions(sph(85, 2), [ConicZone(sph(90, 0), 0.3)], 0.01, kappa=1.0)
    assert not rep.ok
    assert any("inside zone 0" in e for e in rep.errors)


def test_kernel_antipodal_to_target_only_matters_for_star_law():
    zones = seven_cones()
    assert check_assumptions(E4[0], zones, 0.125, law="gradient").ok
    rep = check_assumptions(E4[0], zones, 0.125, kappa=1.0, check_r_sets=False)
    assert not rep.ok and any("zone 6" in e and "g_i != -x_d" in e for e in rep.errors)


class MovedKernel:
    """A zone whose declared kernel is not an interior point (everything else delegated)."""

    def __init__(self, zone, kernel):
        self._z, self.kernel = zone, np.asarray(kernel, float)

    def __getattr__(self, name):
        return getattr(self._z, name)


def test_kernel_outside_the_zone():
    zone = ConicZone(sph(90, 0), 0.3)
    rep = check_assumptions(np.array([0, 0, 1.0]), [MovedKernel(zone, sph(90, 40))], 0.01, kappa=1.0)
    assert not rep.ok and any("kernel g_0" in e and "not strictly inside" in e for e in rep.errors)


def test_assumption_2_shadowing_zones():
    # R_i = points on geodesics from x_d to D_eps(U_i) no nearer to x_d than D_eps(U_i) itself. A wide
    # zone B whose near edge (69 deg from x_d) is nearer than the far edge of zone A (76 deg) and whose
    # shadow covers A's direction: R_A and R_B overlap although Assumption 1 holds.
    x_d = np.array([0.0, 0.0, 1.0])
    eps = 0.005
    a = ConicZone(sph(60, 0), np.radians(10))
    shadowing = [a, ConicZone(sph(105, 35), np.radians(30))]
    rep = check_assumptions(x_d, shadowing, eps, kappa=1.0)
    assert not rep.ok
    assert not any("Assumption 1" in e or "1 - cos(delta)" in e for e in rep.errors)
    hits = [e for e in rep.errors if "Assumption 2" in e]
    assert hits and "R_0 and R_1" in hits[0]
    # the witness point is in both R sets: on a geodesic from x_d into D_eps of both zones
    w = np.array([float(v) for v in hits[0].split("x = [")[1].split("]")[0].split(",")])
    t_w = np.degrees(np.arccos(w @ x_d))
    assert 69.0 < t_w < 76.0
    # check the witness against the definition directly (printed to 4 decimals, so allow 1e-3 slack):
    # some point of D_eps(U_i) lies beyond w on the half great circle from x_d through w, and w is no
    # nearer to x_d than D_eps(U_i) is
    v = w - x_d * (w @ x_d)
    v /= np.linalg.norm(v)
    t = np.radians(np.linspace(t_w, 179.0, 4000))
    ray = np.cos(t)[:, None] * x_d + np.sin(t)[:, None] * v
    theta_eps = np.arccos(1 - eps)
    for zone in shadowing:
        assert zone.separation_batch(ray).min() <= eps + 1e-3
        near_edge = np.arccos(1 - zone.separation(x_d)) - theta_eps
        assert np.radians(t_w) >= near_edge - 1e-3
    # turned away by 90 deg of azimuth the shadows are disjoint
    rep2 = check_assumptions(x_d, [a, ConicZone(sph(105, 90), np.radians(30))], eps, kappa=1.0)
    assert rep2.ok, rep2.summary()
    # a zone straight behind another at a larger distance is allowed: their R sets are at different
    # distances from x_d (the paper's definition), so Assumption 2 holds
    behind = [ConicZone(sph(60, 0), np.radians(10)), ConicZone(sph(120, 0), np.radians(10))]
    assert check_assumptions(x_d, behind, 0.01, kappa=1.0).ok


def test_star_pair_delta_against_brute_force():
    k = np.arange(10)
    ang = np.pi / 2 + np.pi * k / 5
    r = np.where(k % 2 == 0, 0.55, 0.2)
    star = StarZone.polygon(sph(75, 0), None, np.column_stack([r * np.cos(ang), r * np.sin(ang)]))
    spiky = StarZone.superellipsoid(sph(95, 60), None, [0.6, 0.42], 0.6)
    rep = check_assumptions(np.array([0, 0, 1.0]), [star, spiky], 0.01, kappa=1.0)
    A, B = star.boundary(6000), spiky.boundary(6000)
    brute = 1.0 - max(float(np.max(A[i:i + 1000] @ B.T)) for i in range(0, 6000, 1000))
    d = rep.pair_separations[(0, 1)]
    assert d <= brute + 1e-12  # refinement never worse than the samples
    assert d >= brute - 2e-5  # and the samples are dense
    assert rep.delta == pytest.approx(0.5 * np.arccos(1 - d), rel=1e-12)


# ------------------------------------------------------------------------------------------------
# the kappa trap: a zone larger than a hemisphere (a spike reaching 150 deg from its kernel)
# ------------------------------------------------------------------------------------------------


class SpikeZone:
    """Cap of radius `cap` about g = +z plus a thin wedge (azimuths az0 +- half_width) reaching polar
    angle `reach` > 90 deg. A union of meridian arcs from g, so star-shaped about g; -g outside.
    Exact separation in closed form (angle to the cap, or to the wedge's two meridian arcs / its end)."""

    dim = 3

    def __init__(self, cap, reach, az0, half_width):
        self.cap, self.reach, self.az0, self.hw = cap, reach, az0, half_width
        self.kernel = np.array([0.0, 0.0, 1.0])
        self.bounding_cap = (self.kernel.copy(), reach)

    @staticmethod
    def _polar_az(X):
        return np.arctan2(np.hypot(X[:, 0], X[:, 1]), X[:, 2]), np.arctan2(X[:, 1], X[:, 0])

    def _in_wedge(self, az):
        return np.abs(np.angle(np.exp(1j * (az - self.az0)))) <= self.hw

    def _angle_to_arc(self, X, psi):
        n = np.array([-np.sin(psi), np.cos(psi), 0.0])
        h = np.array([np.cos(psi), np.sin(psi), 0.0])
        xn = X @ n
        f = X - xn[:, None] * n
        t_foot = np.arctan2(f @ h, f[:, 2])
        perp = np.arcsin(np.clip(np.abs(xn), 0, 1))
        end = np.array([np.sin(self.reach) * h[0], np.sin(self.reach) * h[1], np.cos(self.reach)])
        ends = np.minimum(np.arccos(np.clip(X[:, 2], -1, 1)), np.arccos(np.clip(X @ end, -1, 1)))
        return np.where((t_foot >= 0) & (t_foot <= self.reach), perp, ends)

    def contains_batch(self, X):
        polar, az = self._polar_az(X)
        return (polar <= self.cap) | (self._in_wedge(az) & (polar <= self.reach))

    def separation_batch(self, X):
        X = np.atleast_2d(np.asarray(X, float))
        polar, az = self._polar_az(X)
        a_wedge = np.where(self._in_wedge(az), np.maximum(polar - self.reach, 0.0),
                           np.minimum(self._angle_to_arc(X, self.az0 - self.hw), self._angle_to_arc(X, self.az0 + self.hw)))
        return 1.0 - np.cos(np.minimum(np.maximum(polar - self.cap, 0.0), a_wedge))

    def signed_separation_batch(self, X):
        X = np.atleast_2d(np.asarray(X, float))
        polar, az = self._polar_az(X)
        depth = np.maximum(self.cap - polar, np.where(self._in_wedge(az), self.reach - polar, 0.0))
        return np.where(self.contains_batch(X), -(1.0 - np.cos(depth)), self.separation_batch(X))

    def separation(self, x):
        return float(self.separation_batch(x)[0])

    def signed_separation(self, x):
        return float(self.signed_separation_batch(x)[0])

    def contains(self, x):
        return bool(self.contains_batch(np.atleast_2d(np.asarray(x, float)))[0])


SPIKE = dict(cap=np.radians(30), reach=np.radians(150), az0=np.radians(202), half_width=np.radians(2))
X_D_TRAP = np.array([-1.0, 0.0, 0.0])
EPS_TRAP = 0.05


def kappa_bar_brute(zone, x_d, eps, n=200001):
    """max over the layer on G(x_d, -g) of q^-(eps - d)/d, from the paper's formulas, by dense sampling."""
    g = zone.kernel
    theta = np.arccos(x_d @ -g)
    lam = np.linspace(0, 1, n)[1:]
    X = (np.sin((1 - lam) * theta)[:, None] * x_d + np.sin(lam * theta)[:, None] * -g) / np.sin(theta)
    d = zone.separation_batch(X)
    Pxd = x_d - X * (X @ x_d)[:, None]
    q = (Pxd @ g) / np.einsum("ij,ij->i", Pxd, Pxd)
    layer = (d <= eps) & (d > 0)
    return float(np.max(q[layer] * (eps - d[layer]) / d[layer]))


def test_spike_zone_separation_against_brute_force():
    zone = SpikeZone(**SPIKE)
    rng = np.random.default_rng(0)
    # dense samples of the zone's boundary: cap rim (outside the wedge), wedge sides and end
    t = np.linspace(0, 1, 4000)
    az = np.linspace(-np.pi, np.pi, 20000)
    rim = np.column_stack([np.sin(SPIKE["cap"]) * np.cos(az), np.sin(SPIKE["cap"]) * np.sin(az), np.full_like(az, np.cos(SPIKE["cap"]))])
    pts = [rim]
    for psi in (SPIKE["az0"] - SPIKE["half_width"], SPIKE["az0"] + SPIKE["half_width"]):
        pol = t * SPIKE["reach"]
        pts.append(np.column_stack([np.sin(pol) * np.cos(psi), np.sin(pol) * np.sin(psi), np.cos(pol)]))
    a_end = np.linspace(SPIKE["az0"] - SPIKE["half_width"], SPIKE["az0"] + SPIKE["half_width"], 400)
    pts.append(np.column_stack([np.sin(SPIKE["reach"]) * np.cos(a_end), np.sin(SPIKE["reach"]) * np.sin(a_end), np.full_like(a_end, np.cos(SPIKE["reach"]))]))
    bnd = np.vstack(pts)
    X = unit(rng.normal(size=(400, 3)))
    X = X[~zone.contains_batch(X)]
    brute = 1.0 - np.max(X @ bnd.T, axis=1)
    np.testing.assert_allclose(zone.separation_batch(X), brute, atol=2e-6)


def test_kappa_trap_reported_and_real():
    zone = SpikeZone(**SPIKE)
    rep = check_assumptions(X_D_TRAP, [zone], EPS_TRAP, kappa=1.0)
    assert not rep.ok
    assert rep.kappa_bar == pytest.approx(kappa_bar_brute(zone, X_D_TRAP, EPS_TRAP), rel=1e-6)
    assert 1.0 < rep.kappa_bar < 2.0
    msg = [e for e in rep.errors if "kappa_bar" in e]
    assert msg and "STABLE" in msg[0] and "zone 0" in msg[0]
    stable = [e["x"] for e in rep.undesired_equilibria if e["stable"]]
    assert len(stable) == 1
    x_star = stable[0]

    starts = np.array([sph(165, 180), sph(170, 176), sph(160, 185), sph(175, 190), sph(158, 178), sph(168, 195)])
    # kappa = 1 <= kappa_bar: every trajectory stops at the reported equilibrium, far from x_d
    trapped = StarShapedLaw(X_D_TRAP, [zone], k1=1.0, kappa=1.0, eps=EPS_TRAP)
    Xf = rk4(trapped.velocity_batch, starts.copy(), 0.02, 1500)
    assert np.all(np.degrees(np.arccos(np.clip(Xf @ x_star, -1, 1))) < 0.01)
    assert np.all(np.linalg.norm(trapped.velocity_batch(Xf), axis=1) < 1e-8)
    assert np.all(np.degrees(np.arccos(Xf @ X_D_TRAP)) > 60.0)
    # kappa > kappa_bar: the check passes and the same starts reach x_d
    kappa = 1.2 * rep.kappa_bar
    assert check_assumptions(X_D_TRAP, [zone], EPS_TRAP, kappa=kappa).ok
    free = StarShapedLaw(X_D_TRAP, [zone], k1=1.0, kappa=kappa, eps=EPS_TRAP)
    Xf, hist = rk4(free.velocity_batch, starts.copy(), 0.02, 1500, record=True)
    assert np.all(0.5 * np.sum((Xf - X_D_TRAP) ** 2, axis=1) < 1e-8)
    assert zone.signed_separation_batch(hist.reshape(-1, 3)).min() > 0.0


# ------------------------------------------------------------------------------------------------
# forward invariance of M_0: 1,000 random initial conditions never enter U
# ------------------------------------------------------------------------------------------------


def random_free_states(zones, dim, count, rng, margin=1e-3):
    out = []
    while sum(len(o) for o in out) < count:
        X = unit(rng.normal(size=(2 * count, dim)))
        s = np.min([z.separation_batch(X) for z in zones], axis=0)
        out.append(X[s > margin])
    return np.vstack(out)[:count]


def test_invariance_seven_cones_gradient_law():
    from gnc.paper import signed_separation_history

    zones = seven_cones()
    law = GradientLaw(E4[0], zones, k1=1.0, eps=0.125)
    X0 = random_free_states(zones, 4, 1000, np.random.default_rng(1))
    _, hist = rk4(law.velocity_batch, X0, 0.02, 600, record=True)
    sep = signed_separation_history(zones, hist)
    assert sep.min() > 0.0
    # and the behind-the-cone region was actually visited: some states came within 0.01 of a cone
    assert (sep.min(axis=0) < 0.01).sum() > 20


def test_invariance_s2_star_zones():
    from gnc.paper import s2_star_setup, signed_separation_history

    x_d, zones, p = s2_star_setup()
    zones = [zones[0], zones[1], zones[3]]  # the two polygons and the concave superellipse
    law = StarShapedLaw(x_d, zones, k1=p["k1"], kappa=p["kappa"], eps=p["eps"])
    assert check_assumptions(x_d, zones, p["eps"], p["kappa"]).ok
    X0 = random_free_states(zones, 3, 1000, np.random.default_rng(2))
    _, hist = rk4(law.velocity_batch, X0, 0.02, 500, record=True)
    sep = signed_separation_history(zones, hist)
    assert sep.min() > 0.0
    assert (sep.min(axis=0) < p["eps"]).sum() > 50  # many runs went through a layer
