"""inflated_radial_profile_deg keeps its result per (shape, margin, rays, samples): a second call returns the
same values as a fresh computation, as copies the caller may change."""
from __future__ import annotations

import numpy as np

from gnc import sky_zones


def test_cached_profile_is_the_computed_one_and_a_copy() -> None:
    shape = {"shape": "superellipse", "semi_axes_deg": [25.0, 12.0], "exponent": 0.8, "orientation_deg": 10.0}
    sky_zones._INFLATED_CACHE.clear()
    fresh = sky_zones._inflated_radial_profile_deg(shape, 1.5, 90, 360)
    first = sky_zones.inflated_radial_profile_deg(shape, 1.5, rays=90, boundary_samples=360)
    first[1][:] = -1.0  # the caller's copy only
    second = sky_zones.inflated_radial_profile_deg(shape, 1.5, rays=90, boundary_samples=360)
    assert np.array_equal(second[0], fresh[0]) and np.array_equal(second[1], fresh[1])
    other = sky_zones.inflated_radial_profile_deg(shape, 2.0, rays=90, boundary_samples=360)
    assert not np.array_equal(other[1], fresh[1])  # another margin, another entry
    sky_zones._INFLATED_CACHE.clear()
