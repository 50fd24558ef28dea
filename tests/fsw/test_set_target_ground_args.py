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


class _Fsw:
    """What `CommandHandlers.set_target` uses of the flight software: its guidance, events, target watch."""

    def __init__(self, guidance) -> None:
        self.guidance, self.events, self.watch_restarts = guidance, [], 0

    def event(self, name: str, **args) -> None:
        self.events.append((name, args))

    def restart_target_watch(self) -> None:
        self.watch_restarts += 1


def _guidance(zones=()):
    from fsw.config import FswConfig
    from fsw.guidance import Guidance

    return Guidance(FswConfig.model_validate({
        "epoch_utc": "2026-06-25T10:00:00Z", "initial_mode": "POINTING",
        "orbit": {"radius_km": 6978.0, "inclination_deg": 51.6, "raan_deg": 120.0, "arg_latitude_at_epoch_deg": 10.0},
        "pointing": {"zones": list(zones)}}))


def test_set_target_ground_and_nadir_telecommands_are_followed():
    from fsw.command_handlers import CommandHandlers
    from fsw.config import GroundTargetConfig

    g = _guidance()
    fsw = _Fsw(g)
    handlers = CommandHandlers(fsw)
    args = ground_target_args(12.97, 77.59, 920.0)
    handlers.set_target(**args)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    out = g.step(50.0, 0.1, q, np.zeros(3))
    want = g.target_on_earth_N("ground", GroundTargetConfig(latitude_deg=12.97, longitude_deg=77.59,
                                                            altitude_m=920.0), 50.0)
    assert np.allclose(out.target_N, want, atol=1e-9)
    assert fsw.events[-1][0] == "TARGET_SET" and fsw.events[-1][1]["kind"] == "GROUND" and fsw.watch_restarts == 1
    handlers.set_target("NADIR", 0.0, 0.0, 0.0, 0.0)
    out = g.step(60.0, 0.1, q, np.zeros(3))
    r = g.ephem.position_N_km(60.0)
    assert np.allclose(out.target_N, -r / np.linalg.norm(r), atol=1e-12)


def test_set_target_nadir_inside_a_zone_is_refused():
    from fsw.command_handlers import CommandHandlers

    g = _guidance([{"name": "earth", "body": "earth", "geometry": {"shape": "cone", "half_angle_deg": 5.0}}])
    fsw = _Fsw(g)
    with pytest.raises(CommandValidationError) as info:
        CommandHandlers(fsw).set_target("NADIR", 0.0, 0.0, 0.0, 0.0)
    assert info.value.code == "TARGET_IN_KEEP_OUT"
    assert fsw.events[-1][0] == "TARGET_REJECTED" and fsw.events[-1][1]["body"] == "EARTH"
