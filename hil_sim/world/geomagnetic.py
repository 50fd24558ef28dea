"""The Earth's magnetic field for the truth models: a centred dipole whose Gauss coefficients (g10, g11, h11)
are IGRF-14's at the mission epoch, from ppigrf (a maintained, pure-Python IGRF: numpy and pandas only, the
IAGA coefficient file shipped with it, MIT licence; chosen over pyIGRF for its reader of the coefficients,
which is what the dipole needs, and its degree-limited field, which the test compares with).

Why a dipole: ppigrf evaluates the full degree-13 expansion in ~20 ms a call, and even compiled it is ~200
Legendre terms at every RK4 stage of a 100 Hz dynamics step; the dipole is a handful of flops in the numba
kernel
(hil_sim.world.environment.dipole_field_N). In the Earth-fixed frame, with m = (g11, h11, g10) and a = 6371.2 km
(IGRF's reference radius):

    B(r) = (a / |r|)^3 [3 (m . r_hat) r_hat - m]

(the degree-1 part of IGRF exactly, and Basilisk's magneticFieldCenteredDipole). The Earth-fixed frame is N
turned about its z axis by the Earth rotation angle (precession, nutation and polar motion neglected: a
fraction of a degree, far below the dipole's own error). How far the dipole is from the full IGRF at 550 km is
measured in tests/hil_sim/test_geomagnetic.py.
"""
from __future__ import annotations

from datetime import datetime, timezone

from gnc import earth as gnc_earth

IGRF_REFERENCE_RADIUS_KM = 6371.2


def dipole_coefficients_T(epoch_utc: datetime) -> tuple[float, float, float]:
    """IGRF-14's (g10, g11, h11) at ``epoch_utc`` [T], interpolated in time as ppigrf does for the full
    field (linearly between the 5-yearly models, the secular variation after the last). ValueError outside
    the model's years."""
    import pandas as pd
    from ppigrf.ppigrf import read_shc  # the coefficient reader ppigrf's own igrf_gc uses

    g, h = read_shc()
    date = pd.Timestamp(epoch_utc.astimezone(timezone.utc).replace(tzinfo=None))
    if not g.index[0] <= date <= g.index[-1]:
        raise ValueError(f"the epoch {epoch_utc.isoformat()} is outside IGRF-14's years "
                         f"({g.index[0].year}-{g.index[-1].year})")
    index = g.index.union([date])
    at = [c.reindex(index).groupby(index).first().interpolate(method="time").loc[date] for c in (g, h)]
    return (1e-9 * float(at[0][(1, 0)]), 1e-9 * float(at[0][(1, 1)]), 1e-9 * float(at[1][(1, 1)]))


def earth_rotation_angle_rad(epoch_utc: datetime) -> float:
    """The Earth rotation angle at ``epoch_utc`` (gnc.earth's IERS 2010 formula, UT1 taken as UTC)."""
    return gnc_earth.earth_rotation_angle_rad(epoch_utc.astimezone(timezone.utc).timestamp() / 86400.0 + 2440587.5)
