"""Sky maps with one convention for every plot (SIL run and campaign report).

Right ascension in [0, 360) deg, increasing to the LEFT (as the sky is seen from inside, the astronomers'
map convention), declination in [-90, 90] deg. Two views:

* full sky: Mollweide (equal area, so zones keep their size at any declination), centred on RA 180 deg;
* local: azimuthal equidistant about a centre direction (north up, east to the left). Distances from the
  centre are true angles, so a zone round a celestial pole is drawn as the cap it is, not smeared over
  360 deg of RA as on an RA/Dec rectangle.
"""
from __future__ import annotations

import math

import numpy as np

RA_LABEL = "right ascension [deg]"
DEC_LABEL = "declination [deg]"
_CENTER_RA_DEG = 180.0


def ra_dec_deg(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RA in [0, 360) and Dec [deg] of unit vectors (rows)."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    ra = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360.0
    dec = np.degrees(np.arcsin(np.clip(v[:, 2], -1.0, 1.0)))
    return ra, dec


def mollweide_lon_lat(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Longitude/latitude [rad] for matplotlib's Mollweide axes: RA 180 in the middle, RA increasing left."""
    ra, dec = ra_dec_deg(v)
    lon = np.radians(((_CENTER_RA_DEG - ra + 180.0) % 360.0) - 180.0)
    return lon, np.radians(dec)


def format_full_sky(ax) -> None:
    """RA tick labels (0..360, increasing to the left), axis labels with units, grid."""
    import matplotlib.ticker

    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(
        lambda lon, _: f"{(_CENTER_RA_DEG - math.degrees(lon)) % 360.0:.0f}\N{DEGREE SIGN}"))
    ax.set_xlabel(RA_LABEL)
    ax.set_ylabel(DEC_LABEL)
    ax.grid(alpha=0.4)


def sky_line(ax, v: np.ndarray, **kw) -> None:
    """A path on the full-sky axes, split where it crosses the map's edge."""
    lon, lat = mollweide_lon_lat(v)
    breaks = np.nonzero(np.abs(np.diff(lon)) > math.pi)[0] + 1
    label = kw.pop("label", None)
    for k, (a, b) in enumerate(zip(np.split(lon, breaks), np.split(lat, breaks))):
        ax.plot(a, b, label=label if k == 0 else None, **kw)


def sky_points(ax, v: np.ndarray, **kw):
    lon, lat = mollweide_lon_lat(v)
    return ax.scatter(lon, lat, **kw)


def local_frame(center_N: np.ndarray) -> np.ndarray:
    """Rows: east, north, centre (unit vectors); at a pole, "north" is the direction of RA 180 deg."""
    c = np.asarray(center_N, dtype=float)
    c = c / np.linalg.norm(c)
    z = np.array([0.0, 0.0, 1.0])
    east = np.cross(z, c)
    if np.linalg.norm(east) < 1e-9:
        east = np.array([0.0, 1.0, 0.0])
    east /= np.linalg.norm(east)
    return np.vstack([east, np.cross(c, east), c])


def local_xy_deg(v: np.ndarray, center_N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuthal equidistant coordinates [deg] about ``center_N``: x toward the east (plotted to the
    left), y toward the north; the distance from the origin is the true angle to the centre."""
    frame = local_frame(center_N)
    p = np.atleast_2d(np.asarray(v, dtype=float)) @ frame.T
    theta = np.degrees(np.arccos(np.clip(p[:, 2], -1.0, 1.0)))
    az = np.arctan2(p[:, 1], p[:, 0])
    return theta * np.cos(az), theta * np.sin(az)


def format_local(ax, center_N: np.ndarray, radius_deg: float) -> None:
    ra, dec = ra_dec_deg(center_N)
    ax.set_xlim(radius_deg, -radius_deg)  # east to the left, as on the full-sky map
    ax.set_ylim(-radius_deg, radius_deg)
    ax.set_aspect("equal")
    ax.set_xlabel(f"angle east of RA {ra[0]:.0f}, Dec {dec[0]:+.0f} [deg]")
    ax.set_ylabel("angle north [deg]")
    ax.grid(alpha=0.3)


def local_view(points_N: np.ndarray, margin_deg: float = 5.0) -> tuple[np.ndarray, float]:
    """Centre (mean direction) and radius [deg] of a local view that holds ``points_N``."""
    p = np.atleast_2d(np.asarray(points_N, dtype=float))
    c = p.sum(axis=0)
    c = c / np.linalg.norm(c) if np.linalg.norm(c) > 1e-9 else p[0] / np.linalg.norm(p[0])
    radius = float(np.degrees(np.arccos(np.clip(p @ c, -1.0, 1.0))).max()) + margin_deg
    return c, min(radius, 180.0)
