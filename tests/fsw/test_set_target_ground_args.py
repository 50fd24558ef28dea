"""SET_TARGET GROUND's argument codec (comms.telecommand.ground_target_args / ground_target_of): a WGS-84
point as its geodetic vertical in the Earth-fixed frame and its height / 10 km, within the command's +-1
component range, and back; a vertical that is not a unit vector is refused as TARGET_NOT_UNIT."""
from __future__ import annotations

import numpy as np
import pytest

from comms.dictionary import DICTIONARY
from comms.telecommand import CommandValidationError, ground_target_args, ground_target_of
from gnc.earth import geodetic_up_earth_fixed


@pytest.mark.parametrize("lat, lon, alt", [(12.97, 77.59, 920.0), (-89.9, -179.5, -500.0), (0.0, 359.0, 9000.0),
                                           (51.48, -0.0015, 46.0)])
def test_round_trip_and_range(lat, lon, alt):
    args = ground_target_args(lat, lon, alt)
    c = [args[k] for k in ("c0", "c1", "c2", "c3")]
    assert np.allclose(c[:3], geodetic_up_earth_fixed(lat, lon), atol=1e-15)
    set_target = DICTIONARY.command("SET_TARGET")
    limits = {a.name: (a.min, a.max) for a in set_target.args if a.name.startswith("c")}
    assert all(limits[k][0] <= args[k] <= limits[k][1] for k in limits)
    lat2, lon2, alt2 = ground_target_of(*c)
    assert lat2 == pytest.approx(lat, abs=1e-9)
    assert (lon2 - lon + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
    assert alt2 == pytest.approx(alt, abs=1e-9)


def test_not_unit_is_refused():
    with pytest.raises(CommandValidationError) as info:
        ground_target_of(0.5, 0.5, 0.5, 0.0)
    assert info.value.code == "TARGET_NOT_UNIT"
