"""gnc.sphere against the paper's definitions and independent computations."""
from __future__ import annotations

import numpy as np
import pytest

from gnc.sphere import angle_between, geodesic, normalize, projector, sample_uniform, separation


def test_projector_is_orthogonal_projection_onto_tangent_space():
    rng = np.random.default_rng(3)
    for dim in (3, 4, 6):
        x = sample_uniform(dim, 1, rng)[0]
        P = projector(x)
        assert np.allclose(P @ P, P, atol=1e-14)
        assert np.allclose(P, P.T)
        assert np.allclose(P @ x, 0.0, atol=1e-15)
        v = rng.standard_normal(dim)
        assert abs(x @ (P @ v)) < 1e-14
        # component orthogonal to x is untouched
        t = v - (v @ x) * x
        assert np.allclose(P @ t, t, atol=1e-14)
    stack = sample_uniform(4, 5, rng)
    assert projector(stack).shape == (5, 4, 4)


def test_separation_equals_one_minus_dot_and_keeps_precision_near_a():
    rng = np.random.default_rng(4)
    X = sample_uniform(4, 100, rng)
    A = sample_uniform(4, 100, rng)
    assert np.allclose(separation(X, A), 1.0 - np.sum(X * A, axis=1), atol=1e-15)
    # two unit vectors at angle 1e-9 rad: exact d_s = 1 - cos(1e-9) = 5e-19; 1 - x.a gives 0
    a = np.array([1.0, 0.0, 0.0])
    x = np.array([np.cos(1e-9), np.sin(1e-9), 0.0])
    assert separation(x, a) == pytest.approx(2.0 * np.sin(0.5e-9) ** 2, rel=1e-6)
    assert separation(a, -a) == pytest.approx(2.0)
    with pytest.raises(ValueError):
        separation(np.ones(3), np.ones(4))


def test_geodesic_matches_slerp_definition_and_is_a_great_circle_arc():
    rng = np.random.default_rng(5)
    for dim in (3, 4):
        a, b = sample_uniform(dim, 2, rng)
        lam = np.linspace(0.0, 1.0, 11)
        pts = geodesic(a, b, lam)
        theta = np.arccos(np.clip(a @ b, -1, 1))
        expected = (np.sin((1 - lam)[:, None] * theta) * a + np.sin(lam[:, None] * theta) * b) / np.sin(theta)
        assert np.allclose(pts, expected, atol=1e-14)
        assert np.allclose(np.linalg.norm(pts, axis=1), 1.0, atol=1e-14)
        assert np.allclose(pts[0], a) and np.allclose(pts[-1], b)
        # constant speed: equal angles between consecutive points
        steps = angle_between(pts[:-1], pts[1:])
        assert np.allclose(steps, theta / 10, atol=1e-12)
        # P(g) g'' = 0: second difference is parallel to g (geodesic equation)
        h = 1e-4
        mid = 0.37
        g0, gm, gp = geodesic(a, b, mid), geodesic(a, b, mid - h), geodesic(a, b, mid + h)
        acc = (gp - 2 * g0 + gm) / h ** 2
        assert np.linalg.norm(projector(g0) @ acc) < 1e-5 * (1 + np.linalg.norm(acc))
    a = np.array([0.0, 0.0, 1.0])
    assert np.allclose(geodesic(a, a, 0.3), a)
    with pytest.raises(ValueError):
        geodesic(a, -a, 0.5)


def test_sample_uniform_is_unit_and_uniform():
    X = sample_uniform(3, 200_000, 7)
    assert X.shape == (200_000, 3)
    assert np.allclose(np.linalg.norm(X, axis=1), 1.0)
    # Archimedes: z is uniform on [-1, 1] for the uniform measure on S^2
    hist, _ = np.histogram(X[:, 2], bins=10, range=(-1, 1))
    assert np.all(np.abs(hist / len(X) - 0.1) < 0.005)
    assert np.allclose(X.mean(axis=0), 0.0, atol=0.01)
    Y = sample_uniform(4, 100_000, np.random.default_rng(1))
    # on S^3 every coordinate has mean 0 and variance 1/4
    assert np.allclose(Y.var(axis=0), 0.25, atol=0.01)
    with pytest.raises(ValueError):
        sample_uniform(1, 5)


def test_normalize_and_angle():
    assert np.allclose(normalize([3.0, 4.0, 0.0]), [0.6, 0.8, 0.0])
    with pytest.raises(ValueError):
        normalize([0.0, 0.0, 0.0])
    a = np.array([1.0, 0.0, 0.0])
    assert angle_between(a, np.array([0.0, 1.0, 0.0])) == pytest.approx(np.pi / 2)
    assert angle_between(a, -a) == pytest.approx(np.pi)
    assert angle_between(a, np.array([np.cos(1e-12), np.sin(1e-12), 0])) == pytest.approx(1e-12, rel=1e-6)
