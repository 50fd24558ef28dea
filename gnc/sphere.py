"""Elementary geometry of the unit n-sphere S^n embedded in R^(n+1).

Notation follows the paper (section "Notations and preliminaries"):

* ``projector(x)`` is P(x) = I - x x^T, the orthogonal projection onto the tangent space T_x S^n.
* ``separation(x, a)`` is the spherical separation d_s(x, a) = 1 - x^T a, evaluated as |x - a|^2 / 2,
  which is the same number for unit vectors but keeps full relative precision when a is close to x
  (1 - x^T a cancels catastrophically there).
* ``geodesic(a, b, lam)`` is g(lam; a, b) = (sin((1 - lam) theta) a + sin(lam theta) b) / sin(theta),
  theta = arccos(a^T b): Shoemake's slerp, the paper's parameterisation of the geodesic G(a, b).
* ``sample_uniform(dim, count, rng)`` draws points uniformly (w.r.t. surface measure) on S^(dim-1).

All functions accept a single vector or a stack of vectors (last axis = coordinates) where noted.
Vectors are dimensionless unit vectors.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["projector", "separation", "geodesic", "sample_uniform", "normalize", "angle_between"]


def _as_float_vector(x: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(x, dtype=float)
    if arr.ndim < 1 or arr.shape[-1] < 2:
        raise ValueError(f"{name} must be a vector (or stack of vectors) with >= 2 coordinates, got shape {arr.shape}")
    return arr


def normalize(x: ArrayLike) -> NDArray[np.float64]:
    """Return x / |x| along the last axis. Raises ValueError for a zero vector."""
    arr = _as_float_vector(x, "x")
    norm = np.linalg.norm(arr, axis=-1, keepdims=True)
    if np.any(norm == 0.0) or not np.all(np.isfinite(norm)):
        raise ValueError("cannot normalise a zero or non-finite vector")
    return arr / norm


def projector(x: ArrayLike) -> NDArray[np.float64]:
    """P(x) = I - x x^T for a unit vector x (shape (d,)) -> (d, d); for a stack (m, d) -> (m, d, d)."""
    arr = _as_float_vector(x, "x")
    eye = np.eye(arr.shape[-1])
    return eye - arr[..., :, None] * arr[..., None, :]


def separation(x: ArrayLike, a: ArrayLike) -> NDArray[np.float64] | float:
    """Spherical separation d_s(x, a) = 1 - x^T a of unit vectors, computed as |x - a|^2 / 2.

    Broadcasts over leading axes; returns a float for two single vectors. Range [0, 2].
    """
    xa = _as_float_vector(x, "x")
    aa = _as_float_vector(a, "a")
    if xa.shape[-1] != aa.shape[-1]:
        raise ValueError(f"x and a must have the same dimension, got {xa.shape[-1]} and {aa.shape[-1]}")
    diff = xa - aa
    value = 0.5 * np.einsum("...i,...i->...", diff, diff)
    return float(value) if np.ndim(value) == 0 else value


def angle_between(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64] | float:
    """Angle in radians between unit vectors a and b, accurate at 0 and at pi (atan2 form)."""
    aa = _as_float_vector(a, "a")
    bb = _as_float_vector(b, "b")
    s = np.linalg.norm(aa - bb, axis=-1)
    t = np.linalg.norm(aa + bb, axis=-1)
    value = 2.0 * np.arctan2(s, t)
    return float(value) if np.ndim(value) == 0 else value


def geodesic(a: ArrayLike, b: ArrayLike, lam: ArrayLike) -> NDArray[np.float64]:
    """The paper's geodesic g(lam; a, b) on S^n (eq. geodesic_parameterization).

    a, b: unit vectors of shape (d,), b != -a. lam: scalar or array of parameters in [0, 1].
    Returns shape (d,) for a scalar lam, else lam.shape + (d,). For a == b the geodesic is the point a.
    theta is computed with the atan2 form, which is accurate for nearly equal or nearly opposite
    points; for theta below 1e-8 rad the (exact) limit (1 - lam) a + lam b, renormalised, is used.
    """
    aa = _as_float_vector(a, "a")
    bb = _as_float_vector(b, "b")
    if aa.ndim != 1 or bb.shape != aa.shape:
        raise ValueError(f"a and b must be single vectors of the same dimension, got {aa.shape} and {bb.shape}")
    lam_arr = np.asarray(lam, dtype=float)
    theta = float(angle_between(aa, bb))
    if np.pi - theta < 1e-12:
        raise ValueError("geodesic(a, b) is undefined for antipodal points (b = -a)")
    lam_col = lam_arr[..., None]
    if theta < 1e-8:
        points = (1.0 - lam_col) * aa + lam_col * bb
        return points / np.linalg.norm(points, axis=-1, keepdims=True)
    return (np.sin((1.0 - lam_col) * theta) * aa + np.sin(lam_col * theta) * bb) / np.sin(theta)


def sample_uniform(dim: int, count: int, rng: np.random.Generator | int | None = None) -> NDArray[np.float64]:
    """count points uniformly distributed on S^(dim-1) (unit vectors in R^dim) -> shape (count, dim).

    Normalised standard Gaussian vectors (rotation invariant, hence uniform). rng: a numpy Generator or a seed.
    """
    if int(dim) != dim or dim < 2:
        raise ValueError(f"dim must be an integer >= 2, got {dim!r}")
    if int(count) != count or count < 0:
        raise ValueError(f"count must be a non-negative integer, got {count!r}")
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    points = gen.standard_normal((int(count), int(dim)))
    norms = np.linalg.norm(points, axis=1, keepdims=True)
    # A zero Gaussian draw has probability zero; redraw defensively rather than divide by zero.
    while np.any(norms == 0.0):
        bad = norms[:, 0] == 0.0
        points[bad] = gen.standard_normal((int(bad.sum()), int(dim)))
        norms = np.linalg.norm(points, axis=1, keepdims=True)
    return points / norms
