"""Keep-out zones on the celestial sphere S^2 from an angular description around a sky direction.

Pure functions (numpy in, gnc zones out); used by the flight software (onboard ephemeris, zones inflated
by a margin) and by the simulator (truth ephemeris, physical zones, to judge the keep-out requirement).

Local sky frame at a centre direction ``c_N`` (the body direction, e.g. the Sun from the spacecraft):
``x`` points to celestial north projected on the tangent plane (the N-frame +z), ``y`` to the east
(``z_N x c``, increasing right ascension). ``orientation_deg`` is a position angle: it rotates the shape
about ``c`` from north through east, as in astronomy (so (x, y, c) is left-handed: the sky seen from inside). At the celestial poles, where north is undefined, N-frame +x replaces +z.

Shapes (angles in degrees, measured from ``c``):

* cone: ``half_angle_deg``; an exact `gnc.zones.ConicZone`.
* superellipse: ``|X/A|^p + |Y/B|^p <= 1`` in the gnomonic tangent plane at ``c`` with
  ``A = tan(a)``, ``B = tan(b)`` for ``semi_axes_deg = [a, b]``: the angular extent along the two
  principal directions is exactly a and b; central projection of this planar star-shaped set is the
  paper's construction of a star-shaped set on the sphere.
* polygon: vertices ``[x, y]`` as angular offsets (deg) in the local frame; vertex k maps to the
  tangent point ``tan(r_k) (cos phi_k, sin phi_k)``; edges become great-circle arcs (paper, Lemma on
  Q(a, b)). Must be star-shaped about ``c``.

Margin inflation. A cone is inflated exactly (half-angle + margin). For a star shape the inflated zone is
the radial hull of the margin-neighbourhood: along every ray from ``c`` its angular radius is the farthest
point of that ray lying within ``margin`` of the physical zone. The result contains every point whose
distance to the physical zone is below the margin (conservative), and it is star-shaped about ``c`` by
construction (it is defined by a radial function), so the paper's laws apply to it.

Merging: `enclosing_cone` returns the smallest cone containing the bounding caps of several zones; the
flight software uses it when two zones are too close for the paper's Assumption 1.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gnc import zones as _zones

__all__ = [
    "sky_frame",
    "cone_zone",
    "superellipse_zone",
    "polygon_zone",
    "build_sky_zone",
    "radial_profile_deg",
    "inflated_radial_profile_deg",
    "enclosing_cone",
    "cap_of",
]

_RAYS = 360  # angular resolution of radial profiles (1 deg of azimuth)


def sky_frame(center_N: np.ndarray, orientation_deg: float = 0.0) -> np.ndarray:
    """Local tangent basis at ``center_N``: rows (x, y) of shape (2, 3), x = north rotated by orientation."""
    cx, cy, cz = (float(v) for v in center_N)
    n = math.sqrt(cx * cx + cy * cy + cz * cz)
    cx, cy, cz = cx / n, cy / n, cz / n
    if abs(cz) < 0.999999:  # east = z_N x c
        ex, ey, ez = -cy, cx, 0.0
    else:  # at a pole: east = x_N x c
        ex, ey, ez = 0.0, -cz, cy
    en = math.sqrt(ex * ex + ey * ey + ez * ez)
    ex, ey, ez = ex / en, ey / en, ez / en
    nx, ny, nz = cy * ez - cz * ey, cz * ex - cx * ez, cx * ey - cy * ex  # north = c x east
    th = math.radians(orientation_deg)
    ct, st = math.cos(th), math.sin(th)
    return np.array([[ct * nx + st * ex, ct * ny + st * ey, ct * nz + st * ez],
                     [-st * nx + ct * ex, -st * ny + ct * ey, -st * nz + ct * ez]])


def _center(center_N: np.ndarray) -> np.ndarray:
    c = np.asarray(center_N, dtype=float)
    n = np.linalg.norm(c)
    if c.shape != (3,) or not np.isfinite(n) or n == 0.0:
        raise ValueError(f"center_N must be a non-zero 3-vector, got {center_N!r}")
    return c / n


def cone_zone(center_N: np.ndarray, half_angle_deg: float, margin_deg: float = 0.0):
    """Conic zone of half-angle ``half_angle_deg + margin_deg`` about ``center_N``."""
    ang = half_angle_deg + margin_deg
    if not 0.0 < ang < 180.0:
        raise ValueError(f"cone half-angle + margin must be in (0, 180) deg, got {ang}")
    return _zones.ConicZone(_center(center_N), math.radians(ang))


def superellipse_radius_tan(semi_axes_deg: Sequence[float], exponent: float, phi: np.ndarray) -> np.ndarray:
    """Tangent-plane radius of the superellipse boundary along azimuth ``phi`` [rad]."""
    A, B = (math.tan(math.radians(a)) for a in semi_axes_deg)
    c, s = np.abs(np.cos(phi)), np.abs(np.sin(phi))
    return (((c / A) ** exponent) + ((s / B) ** exponent)) ** (-1.0 / exponent)


def _polygon_tangent_vertices(vertices_deg: Sequence[Sequence[float]]) -> np.ndarray:
    v = np.asarray(vertices_deg, dtype=float)
    if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3:
        raise ValueError("polygon vertices_deg must be a list of at least 3 [x, y] pairs (deg)")
    r = np.radians(np.hypot(v[:, 0], v[:, 1]))
    if np.any(r <= 0) or np.any(r >= math.radians(89.0)):
        raise ValueError("polygon vertices must be between 0 and 89 deg from the centre")
    phi = np.arctan2(v[:, 1], v[:, 0])
    return np.tan(r)[:, None] * np.stack((np.cos(phi), np.sin(phi)), axis=1)


def polygon_radius_tan(vertices_deg: Sequence[Sequence[float]], phi: np.ndarray) -> np.ndarray:
    """Tangent-plane radius of the polygon boundary along azimuth ``phi`` (ray/edge intersection)."""
    P = _polygon_tangent_vertices(vertices_deg)
    Q = np.roll(P, -1, axis=0)
    d = np.stack((np.cos(phi), np.sin(phi)), axis=-1)  # (m, 2)
    e = Q - P  # (k, 2)
    # Solve t d = P + s e for t (ray length) and s in [0, 1].
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (P[None, :, 0] * e[None, :, 1] - P[None, :, 1] * e[None, :, 0]) / den
        s = (P[None, :, 0] * d[:, None, 1] - P[None, :, 1] * d[:, None, 0]) / den
    ok = (np.abs(den) > 1e-15) & (s >= -1e-12) & (s <= 1 + 1e-12) & (t > 0)
    t = np.where(ok, t, np.inf)
    r = t.min(axis=1)
    if not np.all(np.isfinite(r)):
        raise ValueError("polygon is not star-shaped about its centre (some ray misses every edge)")
    return r


def _shape_get(shape: Any, key: str, default: Any = None) -> Any:
    if isinstance(shape, Mapping):
        return shape.get(key, default)
    return getattr(shape, key, default)


def radial_profile_deg(shape: Any, phi: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Angular radius [deg] of a shape's boundary along azimuths ``phi`` [rad] in the *unrotated* frame."""
    if phi is None:
        phi = np.linspace(0.0, 2 * math.pi, _RAYS, endpoint=False)
    kind = _shape_get(shape, "shape")
    if kind == "cone":
        r = np.full(phi.shape, math.radians(float(_shape_get(shape, "half_angle_deg"))))
        return phi, np.degrees(r)
    if kind == "superellipse":
        rt = superellipse_radius_tan(_shape_get(shape, "semi_axes_deg"), float(_shape_get(shape, "exponent", 2.0)), phi)
    elif kind == "polygon":
        rt = polygon_radius_tan(_shape_get(shape, "vertices_deg"), phi)
    else:
        raise ValueError(f"unknown sky-zone shape {kind!r}; allowed: cone, superellipse, polygon")
    return phi, np.degrees(np.arctan(rt))


def _profile_points(phi: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
    """Points on S^2 in local (x, y, c) coordinates for angular radii theta along azimuths phi."""
    st = np.sin(theta_rad)
    return np.stack((st * np.cos(phi), st * np.sin(phi), np.cos(theta_rad)), axis=-1)


# inflated_radial_profile_deg by (shape, margin, rays, samples): ~12 ms for a star shape, and every run of a
# campaign worker builds the same flight-software zones. Values are copied out, so reuse changes nothing.
_INFLATED_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
_INFLATED_CACHE_SIZE = 32


def inflated_radial_profile_deg(shape: Any, margin_deg: float, rays: int = _RAYS, boundary_samples: int = 1440) -> tuple[np.ndarray, np.ndarray]:
    """Radial hull of the ``margin_deg`` neighbourhood of a shape (see module docstring) [deg].

    For every boundary sample B within ``margin`` of the great circle carrying ray phi, the ray enters
    the cap of radius ``margin`` about B up to the along-ray angle ``s_B + acos(cos m / cos d_perp)``;
    the inflated radius is the largest such angle (and never less than the physical radius + 0).
    """
    if not (isinstance(shape, Mapping) or hasattr(shape, "model_dump")):  # keyed by value: config shapes only
        return _inflated_radial_profile_deg(shape, margin_deg, rays, boundary_samples)
    key = (repr(shape), float(margin_deg), int(rays), int(boundary_samples))
    hit = _INFLATED_CACHE.get(key)
    if hit is None:
        hit = _inflated_radial_profile_deg(shape, margin_deg, rays, boundary_samples)
        if len(_INFLATED_CACHE) >= _INFLATED_CACHE_SIZE:
            _INFLATED_CACHE.pop(next(iter(_INFLATED_CACHE)))
        _INFLATED_CACHE[key] = hit
    return hit[0].copy(), hit[1].copy()


def _inflated_radial_profile_deg(shape: Any, margin_deg: float, rays: int, boundary_samples: int) -> tuple[np.ndarray, np.ndarray]:
    phi = np.linspace(0.0, 2 * math.pi, rays, endpoint=False)
    _, base = radial_profile_deg(shape, phi)
    if margin_deg <= 0.0:
        return phi, base
    m = math.radians(margin_deg)
    phib = np.linspace(0.0, 2 * math.pi, boundary_samples, endpoint=False)
    _, thb = radial_profile_deg(shape, phib)
    B = _profile_points(phib, np.radians(thb))  # (nb, 3) local coordinates, centre = +z
    out = np.empty(rays)
    for j, p in enumerate(phi):
        # Ray great circle through c=(0,0,1) and t=(cos p, sin p, 0); its pole n = c x t.
        t = np.array([math.cos(p), math.sin(p), 0.0])
        n = np.array([-math.sin(p), math.cos(p), 0.0])
        sin_dperp = B @ n
        cos_dperp = np.sqrt(np.clip(1.0 - sin_dperp**2, 0.0, 1.0))
        near = np.abs(sin_dperp) < math.sin(m)
        if not np.any(near):
            out[j] = base[j] + margin_deg
            continue
        # along-ray angle of the foot point (measured from c towards t)
        s = np.arctan2(B[near] @ t, B[near, 2])
        delta = np.arccos(np.clip(math.cos(m) / cos_dperp[near], -1.0, 1.0))
        out[j] = float(np.degrees(np.max(s + delta)))
    return phi, np.maximum(out, base)


def superellipse_zone(center_N: np.ndarray, semi_axes_deg: Sequence[float], exponent: float = 2.0, orientation_deg: float = 0.0, margin_deg: float = 0.0):
    shape = {"shape": "superellipse", "semi_axes_deg": list(semi_axes_deg), "exponent": exponent, "orientation_deg": orientation_deg}
    return build_sky_zone(shape, center_N, margin_deg)


def polygon_zone(center_N: np.ndarray, vertices_deg: Sequence[Sequence[float]], orientation_deg: float = 0.0, margin_deg: float = 0.0):
    shape = {"shape": "polygon", "vertices_deg": [list(v) for v in vertices_deg], "orientation_deg": orientation_deg}
    return build_sky_zone(shape, center_N, margin_deg)


class SkyZoneBuilder:
    """Builds one shape's zone for moving centres; the (inflated) radial profile is computed once.

    Exact zones (``fast=False`` and no margin) use `StarZone.superellipsoid` / `StarZone.polygon`; this is
    what the simulator uses to judge the requirement. Inflated zones, and all star shapes when
    ``fast=True`` (the flight software, where separation is evaluated every cycle), are polygons whose
    vertices sit on the radial profile at ``rays`` equally spaced azimuths, pushed out so the polygon
    contains the profile curve (the chord between two vertices never cuts inside the neighbouring
    samples): the error is conservative and below 0.01 % of the radius at the default 360 rays.
    """

    def __init__(self, shape: Any, margin_deg: float = 0.0, extra_radius_deg: float = 0.0, *, fast: bool = False, rays: int = 360):
        self.shape = shape
        self.kind = _shape_get(shape, "shape")
        self.margin_deg = float(margin_deg)
        self.orientation_deg = float(_shape_get(shape, "orientation_deg", 0.0) or 0.0)
        self.extra_radius_deg = float(extra_radius_deg)
        self.exact = not fast and self.margin_deg == 0.0 and self.extra_radius_deg == 0.0
        if self.kind == "cone":
            self.half_angle_deg = float(_shape_get(shape, "half_angle_deg"))
            self.profile_deg = None
            return
        total = self.margin_deg + self.extra_radius_deg
        if total > 0:
            self.phi, prof = inflated_radial_profile_deg(shape, total, rays=rays, boundary_samples=4 * rays)
        else:
            self.phi, prof = radial_profile_deg(shape, np.linspace(0.0, 2 * math.pi, rays, endpoint=False))
        if np.any(prof >= 89.0):
            raise ValueError("zone reaches 89 deg from its centre; reduce the margin or the shape")
        self.profile_deg = prof
        r = np.tan(np.radians(prof))
        # vertex radius: enclose the neighbours' samples as well (conservative chord)
        r_v = np.maximum(np.maximum(r, np.roll(r, 1)), np.roll(r, -1)) / math.cos(math.pi / rays)
        self.vertices_tan = np.stack((r_v * np.cos(self.phi), r_v * np.sin(self.phi)), axis=1)
        self.max_radius_deg = float(np.degrees(np.arctan(r_v.max())))

    def build(self, center_N: np.ndarray, extra_radius_deg: float | None = None):
        """The zone about ``center_N`` (N frame). ``extra_radius_deg`` re-inflates (cones only, cheap)."""
        c = _center(center_N)
        if self.kind == "cone":
            extra = self.extra_radius_deg if extra_radius_deg is None else extra_radius_deg
            return cone_zone(c, self.half_angle_deg + extra, self.margin_deg)
        basis = sky_frame(c, self.orientation_deg).T  # gnc.zones wants the plane basis as columns (3, 2)
        if self.exact:
            if self.kind == "superellipse":
                A = [math.tan(math.radians(a)) for a in _shape_get(self.shape, "semi_axes_deg")]
                return _zones.StarZone.superellipsoid(c, basis, np.asarray(A), float(_shape_get(self.shape, "exponent", 2.0)))
            return _zones.StarZone.polygon(c, basis, _polygon_tangent_vertices(_shape_get(self.shape, "vertices_deg")))
        return _zones.StarZone.polygon(c, basis, self.vertices_tan)


def build_sky_zone(shape: Any, center_N: np.ndarray, margin_deg: float = 0.0, extra_radius_deg: float = 0.0, *, fast: bool = False):
    """One zone from a shape description (mapping or object with the config keys) about ``center_N``."""
    return SkyZoneBuilder(shape, margin_deg, extra_radius_deg, fast=fast).build(center_N)


def cap_of(zone: Any) -> tuple[np.ndarray, float]:
    """Bounding cap (unit axis, half-angle rad) of a gnc zone."""
    axis, half = zone.bounding_cap
    return np.asarray(axis, dtype=float), float(half)


def enclosing_cone(caps: Sequence[tuple[np.ndarray, float]]):
    """Smallest cone containing the given caps (axis, half-angle rad): a conservative merged zone.

    Two caps at centre distance d with radii r1, r2 (neither inside the other) are enclosed by the cap of
    radius (d + r1 + r2)/2 centred on their great circle; more caps are merged one by one (still
    conservative, not necessarily minimal).
    """
    if not caps:
        raise ValueError("enclosing_cone needs at least one cap")
    a, r = np.asarray(caps[0][0], float), float(caps[0][1])
    for a2, r2 in caps[1:]:
        a2 = np.asarray(a2, float)
        d = math.acos(max(-1.0, min(1.0, float(a @ a2))))
        if d + r2 <= r:
            continue
        if d + r <= r2:
            a, r = a2, float(r2)
            continue
        R = 0.5 * (d + r + r2)
        if R >= math.pi:
            raise ValueError("merged zone would cover the whole sphere")
        # rotate a towards a2 by (R - r)
        perp = a2 - (a @ a2) * a
        pn = np.linalg.norm(perp)
        if pn < 1e-12:
            perp = np.cross(a, [1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.cross(a, [0.0, 1.0, 0.0])
            pn = np.linalg.norm(perp)
        perp /= pn
        ang = R - r
        a = math.cos(ang) * a + math.sin(ang) * perp
        a /= np.linalg.norm(a)
        r = R
    return _zones.ConicZone(a, r)


def bridge_zone(cap_a: tuple[np.ndarray, float], cap_b: tuple[np.ndarray, float], *,
                overlap_rad: float = math.radians(1.0), vertices: int = 180,
                max_reach_rad: float = math.radians(80.0)):
    """A star polygon containing two nearby caps (axis, half-angle rad), or None when none fits.

    The conservative replacement for two zones too close for Assumption 1 when their enclosing cone
    would swallow the boresight or the target (the spacecraft pointing into the notch between them): the
    caps are grown until they overlap by ``overlap_rad``; a cap smaller than a hemisphere is geodesically
    convex, so their union is star-shaped about any point g of the overlap (each geodesic from g leaves
    each cap once, within pi). g is the middle of the overlap on the arc between the axes. Seen from g in
    the tangent plane, the union's radius along direction phi is tan of the farther exit angle, which is
    closed-form per cap; the polygon puts vertex k at the largest radius within one vertex spacing w of
    phi_k, divided by cos(w/2): any point of an edge is then at least as far out as the union along its
    ray, so the polygon contains the union. Returns None if the union reaches ``max_reach_rad`` from g
    (the central projection needs < 90 deg; beyond 80 the polygon degenerates).
    """
    a, ra = np.asarray(cap_a[0], dtype=float), float(cap_a[1])
    b, rb = np.asarray(cap_b[0], dtype=float), float(cap_b[1])
    d = math.acos(max(-1.0, min(1.0, float(a @ b))))
    if d < 1e-9 or ra + rb >= math.pi:
        return None
    grow = max(0.0, 0.5 * (d - ra - rb + overlap_rad))
    ra, rb = ra + grow, rb + grow
    if max(ra, rb) >= 0.5 * math.pi:
        return None
    # middle of the overlap [d - rb, ra] on the arc from a towards b (clamped for a cap inside the other)
    s = 0.5 * (max(d - rb, 0.0) + min(ra, d))
    e_ab = b - (a @ b) * a
    e_ab /= np.linalg.norm(e_ab)
    g = math.cos(s) * a + math.sin(s) * e_ab
    e1 = b - (g @ b) * g
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(g, e1)
    fine = 8
    phi = np.linspace(0.0, 2.0 * math.pi, vertices * fine, endpoint=False)
    u = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    exit_angle = np.zeros_like(phi)
    for axis, radius in ((a, ra), (b, rb)):
        A, B = float(g @ axis), u @ axis
        R = np.hypot(A, B)
        exit_angle = np.maximum(exit_angle, np.arctan2(B, A) + np.arccos(np.clip(math.cos(radius) / R, -1.0, 1.0)))
    if float(exit_angle.max()) >= max_reach_rad:
        return None
    rho = np.tan(exit_angle)
    # largest radius within +-w of each vertex direction (the fine samples are w / fine apart; the small
    # factor covers the curvature between fine samples)
    window = np.max([np.roll(rho, k) for k in range(-fine, fine + 1)], axis=0)[::fine]
    w = 2.0 * math.pi / vertices
    radius_k = window * (1.0 + 1e-3) / math.cos(0.5 * w)
    plane = np.column_stack([radius_k * np.cos(phi[::fine]), radius_k * np.sin(phi[::fine])])
    return _zones.StarZone.polygon(g, np.column_stack([e1, e2]), plane)
