"""gnc.checks' culled ray-window kernel gives bit-identical windows to the full double loop it replaced.

`_ray_windows` skips groups of ray directions that a Cauchy-Schwarz bound proves cannot come within
theta_eps of a boundary sample. The reference below is the full loop over every (direction, sample) pair,
as it was before the culling; the two must agree exactly (not approximately) on random and adversarial
inputs: samples grazing the cull threshold, eps tiny and large, x_d on the boundary set, S^2 and S^3.
"""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from gnc.checks import RAY_DIRECTION_GROUPS, _direction_clusters, _extremes_first, _ray_directions, _ray_windows
from gnc.zones import ConicZone, StarZone


@njit
def reference_ray_windows(V, Bd, x_d, cos_eps, lo, hi):
    """The full loop over every pair (the code before the culling, verbatim)."""
    nb = Bd.shape[0]
    dim = Bd.shape[1]
    two_pi = 2.0 * np.pi
    for k in range(V.shape[0]):
        best_lo = np.inf
        best_hi = -np.inf
        for l in range(nb):
            a_x = 0.0
            a_v = 0.0
            for c in range(dim):
                a_x += Bd[l, c] * x_d[c]
                a_v += Bd[l, c] * V[k, c]
            A = np.sqrt(a_x * a_x + a_v * a_v)
            if A < cos_eps or A == 0.0:
                continue
            r = cos_eps / A
            alpha = np.arccos(r if r > -1.0 else -1.0)
            phi = np.arctan2(a_v, a_x)
            for shift in (-two_pi, 0.0, two_pi):
                t_lo = phi + shift - alpha
                t_hi = phi + shift + alpha
                if t_lo < 0.0:
                    t_lo = 0.0
                if t_hi > np.pi:
                    t_hi = np.pi
                if t_lo <= t_hi:
                    if t_lo < best_lo:
                        best_lo = t_lo
                    if t_hi > best_hi:
                        best_hi = t_hi
        lo[k] = best_lo
        hi[k] = best_hi


def both(x_d, Bd, eps, directions, groups=RAY_DIRECTION_GROUPS):
    V = np.ascontiguousarray(_ray_directions(x_d, directions))
    Bd = np.ascontiguousarray(Bd, dtype=float)
    cos_eps = float(np.cos(np.arccos(1.0 - eps)))
    lo0, hi0 = np.full(len(V), np.inf), np.full(len(V), -np.inf)
    reference_ray_windows(V, Bd, x_d, cos_eps, lo0, hi0)
    # the skips must be exact whatever order the samples come in: the one used, the natural one, a random one
    orders = (_extremes_first(Bd, x_d), np.arange(len(Bd)), np.random.default_rng(len(Bd)).permutation(len(Bd)))
    fast = []
    for sample_order in orders:
        lo, hi = np.full(len(V), np.inf), np.full(len(V), -np.inf)
        _ray_windows(V, Bd, x_d, cos_eps, lo, hi, *_direction_clusters(V, groups), sample_order)
        fast.append((lo, hi))
    return (lo0, hi0), fast


def assert_identical(ref, fast):
    lo0, hi0 = ref
    for lo1, hi1 in fast:
        assert np.array_equal(lo0, lo1) and np.array_equal(hi0, hi1)
    assert np.isfinite(lo0).any()  # the case is not vacuous: some ray meets the layer


def test_extremes_first_is_a_permutation():
    Bd = ConicZone(unit(np.array([1.0, 0.2, 0.1])), 0.4).boundary(501)
    order = _extremes_first(Bd, np.array([0.0, 0.0, 1.0]))
    assert np.array_equal(np.sort(order), np.arange(501))


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_clusters_cover_every_direction_once_within_their_radius():
    for dim, count in ((3, 3600), (4, 4000)):
        V = _ray_directions(unit(np.arange(1.0, dim + 1)), count)
        centres, radii, order, starts = _direction_clusters(V, RAY_DIRECTION_GROUPS)
        assert np.array_equal(np.sort(order), np.arange(count)) and starts[-1] == count
        for j in range(len(centres)):
            members = V[order[starts[j]:starts[j + 1]]]
            assert np.all(np.linalg.norm(members - centres[j], axis=1) <= radii[j])


@pytest.mark.parametrize("seed", range(6))
def test_random_zones_on_s2(seed):
    rng = np.random.default_rng(seed)
    x_d = unit(rng.standard_normal(3))
    for zone in (ConicZone(unit(rng.standard_normal(3)), rng.uniform(0.05, 1.2)),
                 StarZone.superellipsoid(unit(rng.standard_normal(3)), None, rng.uniform(0.1, 0.8, 2), rng.uniform(0.5, 3))):
        eps = float(rng.choice([1e-9, 1e-4, 0.01, 0.1, 0.5]))
        Bd = zone.boundary(int(rng.integers(200, 1500)))
        assert_identical(*both(x_d, Bd, eps, int(rng.integers(500, 3600)), int(rng.integers(1, 200))))


@pytest.mark.parametrize("seed", range(3))
def test_random_points_on_s3(seed):
    rng = np.random.default_rng(100 + seed)
    x_d = unit(rng.standard_normal(4))
    Bd = unit(rng.standard_normal((400, 4)))
    assert_identical(*both(x_d, Bd, float(rng.choice([0.01, 0.1, 0.3])), 1500))


def test_samples_grazing_the_cull_threshold():
    """Samples placed so that A = cos_eps (to the last bits) for some ray: the margins must keep them."""
    rng = np.random.default_rng(7)
    x_d = np.array([0.0, 0.0, 1.0])
    eps = 0.02
    theta_eps = np.arccos(1.0 - eps)
    V = _ray_directions(x_d, 3600)
    pts = []
    for _ in range(600):
        v = V[rng.integers(len(V))]
        t = rng.uniform(0.0, np.pi)
        on_ray = np.cos(t) * x_d + np.sin(t) * v
        w = unit(np.cross(on_ray, v if abs(np.cos(t)) > 0.5 else x_d))  # off the ray's plane
        d = theta_eps * (1.0 + rng.choice([-1, 1]) * 10.0 ** rng.uniform(-16, -6))
        pts.append(np.cos(d) * on_ray + np.sin(d) * w)
    assert_identical(*both(x_d, np.array(pts), eps, 3600))


def test_samples_on_the_target_and_its_antipode():
    """a_x = +-1 (A from a_x alone) and b = x_d, -x_d exactly, with tiny and large eps."""
    x_d = unit(np.array([0.3, -0.2, 0.9]))
    Bd = np.vstack([x_d, -x_d, unit(x_d + 1e-8), unit(np.array([1.0, 0.0, 0.0]))])
    for eps in (1e-12, 1e-3, 0.9, 1.5):
        assert_identical(*both(x_d, Bd, eps, 720))


def two_step(x_d, zones, pick, kappa):
    """The old way: a probe for eps_max, then the full check at the eps picked from it."""
    from gnc.checks import check_assumptions

    probe = check_assumptions(x_d, zones, 1e-9, kappa=None, check_r_sets=False, law="star")
    return check_assumptions(x_d, zones, pick(float(probe.eps_max)), kappa=kappa, law="star")


@pytest.mark.parametrize("pick", [lambda e: 0.5 * e, lambda e: min(0.5 * e, 0.004), lambda e: 2.0 * e, lambda e: 0.0])
def test_eps_chosen_from_eps_max_in_one_pass_matches_the_probe_then_check(pick):
    from gnc.checks import check_assumptions

    def sph(polar_deg, az_deg):
        p, a = np.radians(polar_deg), np.radians(az_deg)
        return np.array([np.sin(p) * np.cos(a), np.sin(p) * np.sin(a), np.cos(p)])

    x_d = np.array([0.0, 0.0, 1.0])
    cases = [
        [ConicZone(sph(60, 0), np.radians(10)), ConicZone(sph(105, 35), np.radians(30))],  # shadowing
        [ConicZone(sph(60, 0), np.radians(10)), ConicZone(sph(120, 0), np.radians(10))],
        [StarZone.superellipsoid(sph(95, 60), None, [0.6, 0.42], 0.6), ConicZone(sph(40, 200), 0.3)],
        [ConicZone(sph(30, 0), 0.4), ConicZone(sph(35, 10), 0.4)],  # overlapping: delta = 0
    ]
    for zones in cases:
        old, new = two_step(x_d, zones, pick, 1.0), check_assumptions(x_d, zones, pick, kappa=1.0, law="star")
        assert new.summary() == old.summary()
        assert (new.errors, new.warnings, new.eps_max, new.kappa_bar, new.pair_separations) == \
            (old.errors, old.warnings, old.eps_max, old.kappa_bar, old.pair_separations)
        assert new.kappa_bar_per_zone == old.kappa_bar_per_zone


def test_second_largest_per_row_is_the_partition_order_statistic():
    from gnc.checks import _second_largest_per_row

    rng = np.random.default_rng(3)
    Bd = ConicZone(unit(np.array([0.2, 0.5, 0.8])), 0.7).boundary(3000)
    cases = [Bd[:400] @ Bd.T, rng.standard_normal((50, 97)), np.round(rng.standard_normal((40, 30)), 1),
             np.ones((3, 5)), np.array([[2.0, 2.0, 1.0], [1.0, 3.0, 3.0], [-0.0, 0.0, -1.0]])]
    for M in cases:
        assert np.array_equal(_second_largest_per_row(M), np.partition(M, -2, axis=1)[:, -2])
