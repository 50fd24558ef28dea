"""Truth Sun and Moon for the simulator, from astropy's built-in ephemeris (no download, works offline).

astropy (``solar_system_ephemeris.set('builtin')``: ERFA epv00 for the Earth/Sun, the full Meeus/ELP
series for the Moon) is far too slow to call every 10 ms, so it is evaluated once on a grid of TDB epochs
(``node_spacing_s``, default 1 h) and the geocentric GCRS positions are interpolated with a cubic spline.
Interpolation error (tests/hil_sim/test_world.py bounds it by 1e-7 rad; measured over 20 days at 1 h nodes:
Moon 8e-11 rad, Sun 4e-12 rad), negligible next to astropy's own built-in accuracy (Moon ~10 arcsec,
Sun ~1 arcsec). The grid is extended lazily as the run advances. Its nodes lie on one absolute TDB grid
(multiples of the node spacing since J2000), not on each run's epoch, so worlds with different epochs
(a campaign dispersing the epoch by hours) share the same fitted blocks: a worker calls astropy once
per block, not once per run. Each block of 96 nodes is fitted on its own, so the numbers a run sees
never depend on what ran before it in the process.

IERS: GCRS positions of bodies need no Earth-orientation data, and we pass TDB times directly, so no IERS
table or leap-second download is ever attempted (``iers.conf.auto_download`` is switched off here anyway).
"""
from __future__ import annotations

import math
import os
import tempfile
import threading
import warnings
from functools import lru_cache
from importlib import metadata
from pathlib import Path

import numpy as np
from numba import njit

_ASTROPY_LOCK = threading.Lock()


def _configure_astropy_offline() -> None:
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None


GRID_ORIGIN_TDB_JD = 2451545.0  # J2000: node k of every table is at this epoch + k * node spacing


# Node blocks are also kept on disk (one small .npy per block), so a new process (each campaign worker,
# each SIL run) does not pay ~1.5 s of astropy import and evaluation for the same nodes again. A file holds
# exactly the float64 numbers astropy gave, keyed by the astropy and pyerfa versions: a run's numbers
# are the same whether they come from the file or from astropy. KEEPOUT_EPHEMERIS_CACHE: another folder,
# or "off".
CACHE_ENV = "KEEPOUT_EPHEMERIS_CACHE"


def _cache_file(node_spacing_s: float, first: int, count: int) -> Path | None:
    setting = os.environ.get(CACHE_ENV, "")
    if setting.lower() == "off":
        return None
    folder = Path(setting) if setting else Path(__file__).resolve().parent / "__pycache__" / "truth_ephemeris"
    try:
        versions = f"astropy{metadata.version('astropy')}-erfa{metadata.version('pyerfa')}"
    except metadata.PackageNotFoundError:
        return None
    return folder / f"nodes-{versions}-h{node_spacing_s!r}-k{first}-n{count}.npy"


@lru_cache(maxsize=64)
def _astropy_nodes(node_spacing_s: float, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Sun and Moon geocentric GCRS positions (km), shape (count, 3) each, at the absolute grid nodes
    GRID_ORIGIN_TDB_JD + (first..first+count-1) * h (from the disk cache when there, see CACHE_ENV)."""
    path = _cache_file(node_spacing_s, first, count)
    if path is not None:
        try:
            both = np.load(path, allow_pickle=False)
            if both.shape == (2, count, 3) and both.dtype == np.float64:
                return np.ascontiguousarray(both[0]), np.ascontiguousarray(both[1])
        except (OSError, ValueError):
            pass  # absent or unreadable: compute it
    sun, moon = _compute_nodes(node_spacing_s, first, count)
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".tmp", delete=False) as tmp:
                np.save(tmp, np.stack([sun, moon]), allow_pickle=False)
            os.replace(tmp.name, path)  # atomic: a concurrent reader sees the whole file or none
        except OSError:
            pass  # a read-only tree: no cache, same numbers
    return sun, moon


def _compute_nodes(node_spacing_s: float, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    _configure_astropy_offline()
    from astropy.coordinates import get_body, solar_system_ephemeris
    from astropy.time import Time

    offsets_day = (first + np.arange(count)) * node_spacing_s / 86400.0
    with _ASTROPY_LOCK, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ERFA "dubious year" notes concern UTC, which we never use
        with solar_system_ephemeris.set("builtin"):
            times = Time(GRID_ORIGIN_TDB_JD, offsets_day, format="jd", scale="tdb")
            sun = get_body("sun", times).cartesian.xyz.to_value("km").T
            moon = get_body("moon", times).cartesian.xyz.to_value("km").T
    return np.ascontiguousarray(sun), np.ascontiguousarray(moon)


def astropy_sun_moon_N_km(t_tdb_jd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Direct (uninterpolated) astropy geocentric GCRS Sun and Moon positions, km, shape (n, 3)."""
    _configure_astropy_offline()
    from astropy.coordinates import get_body, solar_system_ephemeris
    from astropy.time import Time

    with _ASTROPY_LOCK, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with solar_system_ephemeris.set("builtin"):
            times = Time(np.atleast_1d(np.asarray(t_tdb_jd, dtype=float)), format="jd", scale="tdb")
            sun = get_body("sun", times).cartesian.xyz.to_value("km").T
            moon = get_body("moon", times).cartesian.xyz.to_value("km").T
    return sun, moon


def _spline_coefficients(values: np.ndarray, h: float) -> np.ndarray:
    """Not-a-knot cubic spline through equally spaced nodes: coefficients (n-1, 4, 3) for s in [0, h):
    p(s) = c0 s^3 + c1 s^2 + c2 s + c3."""
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(np.arange(values.shape[0]) * h, values, axis=0)
    return np.ascontiguousarray(np.transpose(spline.c, (1, 0, 2)))


@lru_cache(maxsize=256)
def _block_coefficients(node_spacing_s: float, block: int, block_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Spline segments of one block of the absolute grid: nodes block*B .. (block+1)*B, each block fitted
    on its own (with two extra nodes each side so the not-a-knot end conditions stay outside), so a
    block's coefficients never depend on which other blocks exist: a run gives the same numbers whatever
    ran before it."""
    sun, moon = _astropy_nodes(node_spacing_s, block * block_nodes - 2, block_nodes + 5)
    return (_spline_coefficients(sun, node_spacing_s)[2:2 + block_nodes],
            _spline_coefficients(moon, node_spacing_s)[2:2 + block_nodes])


class TruthEphemeris:
    """Geocentric Sun and Moon positions (km, GCRS) as functions of t (s since ``epoch_tdb_jd``)."""

    # Nodes are fetched in blocks of this many (about 4 days at 1 h) so astropy is called rarely.
    BLOCK_NODES = 96

    def __init__(self, epoch_tdb_jd: float, node_spacing_s: float = 3600.0) -> None:
        self.epoch_tdb_jd = float(epoch_tdb_jd)
        self.node_spacing_s = float(node_spacing_s)
        # the epoch on the absolute grid's time axis (s since GRID_ORIGIN_TDB_JD); tables are kept in
        # the run's own time (s since epoch_tdb_jd), so only this one subtraction sees the large number
        self._epoch_on_grid_s = (self.epoch_tdb_jd - GRID_ORIGIN_TDB_JD) * 86400.0
        self._lock = threading.Lock()
        self._blocks = (0, 0)  # [first, last) block covered
        self.t_start_s = 0.0
        self.t_end_s = -1.0
        self.ensure(0.0, 1.0)

    def ensure(self, t_min_s: float, t_max_s: float) -> None:
        """Make the table cover [t_min_s, t_max_s] (extends by whole blocks; cheap when already covered).
        The table is swapped in one assignment, so a reader always sees a consistent (t0, sun, moon) set."""
        if self.t_start_s <= t_min_s and t_max_s < self.t_end_s:
            return
        with self._lock:
            span = self.node_spacing_s * self.BLOCK_NODES
            shift = self._epoch_on_grid_s
            first, last = self._blocks
            lo = math.floor((t_min_s + shift) / span)
            hi = math.floor((t_max_s + shift) / span) + 1
            if last > first:
                lo, hi = min(lo, first), max(hi, last)
            blocks = [_block_coefficients(self.node_spacing_s, b, self.BLOCK_NODES) for b in range(lo, hi)]
            t0 = lo * span - shift
            self.table = (t0, np.ascontiguousarray(np.concatenate([s for s, _ in blocks])),
                          np.ascontiguousarray(np.concatenate([m for _, m in blocks])))
            self._blocks = (lo, hi)
            self.t_start_s, self.t_end_s = t0, t0 + (hi - lo) * span

    @property
    def t0_s(self) -> float:
        return self.table[0]

    @property
    def sun_coeffs(self) -> np.ndarray:
        return self.table[1]

    @property
    def moon_coeffs(self) -> np.ndarray:
        return self.table[2]

    def positions_N_km(self, t_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Sun and Moon geocentric positions at t (s since epoch), shape (..., 3) each."""
        t = np.asarray(t_s, dtype=float)
        self.ensure(float(t.min()), float(t.max()))
        t0, sun_c, moon_c = self.table
        flat = t.reshape(-1)
        sun = np.empty((flat.size, 3))
        moon = np.empty((flat.size, 3))
        for k in range(flat.size):
            spline_eval(sun_c, t0, self.node_spacing_s, flat[k], sun[k])
            spline_eval(moon_c, t0, self.node_spacing_s, flat[k], moon[k])
        return sun.reshape(t.shape + (3,)), moon.reshape(t.shape + (3,))


@njit(cache=True, error_model="numpy")
def spline_eval(coeffs, t0_s, h_s, t_s, out):
    """Evaluate the (n-1, 4, 3) spline at t_s into out[0:3] (km)."""
    x = (t_s - t0_s) / h_s
    k = int(math.floor(x))
    if k < 0:
        k = 0
    elif k > coeffs.shape[0] - 1:
        k = coeffs.shape[0] - 1
    s = t_s - t0_s - k * h_s
    for j in range(3):
        out[j] = ((coeffs[k, 0, j] * s + coeffs[k, 1, j]) * s + coeffs[k, 2, j]) * s + coeffs[k, 3, j]
