"""The Earth's magnetic field for the truth models: a centred dipole whose Gauss coefficients (g10, g11, h11)
are IGRF-14's at the mission epoch, from ppigrf (a maintained, pure-Python IGRF: numpy and pandas only, the
IAGA coefficient file shipped with it, MIT licence; chosen over pyIGRF for its reader of the coefficients,
which is what the dipole needs, and its degree-limited field, which the test compares with).

The dipole is the default: a handful of flops in the numba kernel (hil_sim.world.environment.dipole_field_N),
and what every mission flew before the full field existed. In the Earth-fixed frame, with m = (g11, h11, g10)
and a = 6371.2 km (IGRF's reference radius):

    B(r) = (a / |r|)^3 [3 (m . r_hat) r_hat - m]

(the degree-1 part of IGRF exactly, and Basilisk's magneticFieldCenteredDipole). The Earth-fixed frame is N
turned about its z axis by the Earth rotation angle (precession, nutation and polar motion neglected: a
fraction of a degree, far below the dipole's own error). How far the dipole is from the full IGRF at 550 km is
measured in tests/hil_sim/test_geomagnetic.py.

The full field, on request (``spacecraft.disturbance.magnetic_field: {model: igrf, degree: N}``): IGRF-14's
Gauss coefficients to degree N at the mission epoch (`gauss_coefficients_T`), synthesised in the numba kernel
gnc._geomagnetic_nb.field_E at every stage (~0.7 us at degree 13), because ppigrf's own evaluation
costs ~10 ms a call. The coefficients are taken once, at the epoch: their secular variation is not applied
during a run (at most 0.4 nT a day at 550 km, 4 nT over a ten-day mission; IGRF-14 and WMM2025 differ by up to
17.5 nT from 400 km up: tests/hil_sim/test_igrf.py).
"""
from __future__ import annotations

from datetime import datetime, timezone
from typing import Any


from gnc import earth as gnc_earth
from gnc._geomagnetic_nb import IGRF_REFERENCE_RADIUS_KM  # noqa: F401  (one definition, the kernel's)
from gnc.field_model import IGRF_MAX_DEGREE, degree_of, unnormalised_rows  # noqa: F401  (shared with the flight software)



def _igrf_at(epoch_utc: datetime) -> tuple[Any, Any]:
    """IGRF-14's Gauss coefficients g, h [nT] at ``epoch_utc`` (pandas Series keyed by (n, m)), interpolated in
    time as ppigrf does for the full field (linearly between the 5-yearly models, the secular variation after
    the last). ValueError outside the model's years."""
    import pandas as pd
    from ppigrf.ppigrf import read_shc  # the coefficient reader ppigrf's own igrf_gc uses

    g, h = read_shc()
    date = pd.Timestamp(epoch_utc.astimezone(timezone.utc).replace(tzinfo=None))
    if not g.index[0] <= date <= g.index[-1]:
        raise ValueError(f"the epoch {epoch_utc.isoformat()} is outside IGRF-14's years "
                         f"({g.index[0].year}-{g.index[-1].year})")
    index = g.index.union([date])
    at = [c.reindex(index).groupby(index).first().interpolate(method="time").loc[date] for c in (g, h)]
    return at[0], at[1]


def dipole_coefficients_T(epoch_utc: datetime) -> tuple[float, float, float]:
    """IGRF-14's (g10, g11, h11) at ``epoch_utc`` [T] (`_igrf_at`)."""
    g, h = _igrf_at(epoch_utc)
    return (1e-9 * float(g[(1, 0)]), 1e-9 * float(g[(1, 1)]), 1e-9 * float(h[(1, 1)]))


def gauss_coefficients_T(epoch_utc: datetime, degree: int = IGRF_MAX_DEGREE) -> tuple[tuple[float, float], ...]:
    """IGRF-14's Schmidt semi-normalised (g_n^m, h_n^m) [T] at ``epoch_utc`` (`_igrf_at`) for n = 1..degree,
    m = 0..n, in that order (degree (degree + 3) / 2 pairs; h_n^0 = 0)."""
    if not 1 <= degree <= IGRF_MAX_DEGREE:
        raise ValueError(f"degree: IGRF-14 goes from 1 to {IGRF_MAX_DEGREE}, got {degree}")
    g, h = _igrf_at(epoch_utc)
    return tuple((1e-9 * float(g[(n, m)]), 1e-9 * float(h[(n, m)]))
                 for n in range(1, degree + 1) for m in range(n + 1))


def earth_rotation_angle_rad(epoch_utc: datetime) -> float:
    """The Earth rotation angle at ``epoch_utc`` (gnc.earth's IERS 2010 formula, UT1 taken as UTC)."""
    return gnc_earth.earth_rotation_angle_rad(epoch_utc.astimezone(timezone.utc).timestamp() / 86400.0 + 2440587.5)
