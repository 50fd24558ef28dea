"""Eclipses in a recorded run: the stretches the spacecraft spent in the Earth's shadow, for the plots.

The shadow's geometry (the conical umbra and penumbra, the sunlit fraction of the Sun's disc) is
`gnc.eclipse`, the one the flight software evaluates on its own ephemeris too; the truth models (solar
radiation pressure, the sun sensors) call it directly.
"""
from __future__ import annotations

import numpy as np

from gnc.eclipse import sunlit_fraction
from gnc.ephemeris import AU_KM, EARTH_RADIUS_KM


def eclipse_spans(t_s: np.ndarray, r_sc_N_km: np.ndarray, sun_N: np.ndarray) -> list[tuple[float, float, float]]:
    """Each stretch of a recorded run in the Earth's shadow: (start [s], end [s], least sunlit fraction).

    From what a run records (spacecraft position, unit Sun direction): the Sun is placed 1 AU along that
    direction, which moves the shadow's edge by far less than a recording interval. A run without an
    orbit (positions at the Earth's centre) has no eclipses."""
    t = np.asarray(t_s, dtype=float)
    r = np.asarray(r_sc_N_km, dtype=float)
    if len(t) == 0 or r.ndim != 2 or float(np.min(np.linalg.norm(r, axis=1))) <= EARTH_RADIUS_KM:
        return []
    lit = sunlit_fraction(r, r + AU_KM * np.asarray(sun_N, dtype=float))
    shaded = np.concatenate([[False], lit < 1.0, [False]])
    starts = np.flatnonzero(~shaded[:-1] & shaded[1:])
    ends = np.flatnonzero(shaded[:-1] & ~shaded[1:]) - 1
    return [(float(t[a]), float(t[b]), float(np.min(lit[a:b + 1]))) for a, b in zip(starts, ends)]
