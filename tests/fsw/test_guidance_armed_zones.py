"""A keep-out zone kept for inertial targets only (`SkyZoneConfig.armed: inertial_targets`): an Earth zone on
an Earth-observing camera. Nadir and ground targets lie inside it and are followed as if it were not there;
a fixed target (a dark field) arms it once the boresight has left it, and from then on the law keeps the
boresight out of it as the Earth sweeps towards the field; a target on the Earth disarms it at once."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fsw.config import FswConfig
from fsw.guidance import Guidance
from test_guidance_earth_targets import _cfg, _q_with_boresight, _step, _unit

EARTH = {"name": "earth", "body": "earth", "geometry": {"shape": "cone", "half_angle_deg": 5.0},
         "atmosphere_height_km": 100.0}


def _guidance(armed: str, **pointing) -> tuple[Guidance, list]:
    events: list = []
    cfg = _cfg({"zones": [{**EARTH, "armed": armed}], **pointing})
    return Guidance(cfg, events=lambda name, **args: events.append((name, args))), events


def _fly(g: Guidance, q: np.ndarray, t0: float, seconds: float, dt: float = 0.1):
    rows = []
    for k in range(int(round(seconds / dt))):
        out = g.step(t0 + k * dt, dt, q, np.zeros(3))
        rows.append((out.margins_deg[0], out.margin_min_deg, out.pointing_error_deg, out.boresight_N.copy()))
        q = _step(q, out.omega_cmd_BN_B, dt)
    return q, rows


def _names(events: list) -> list[str]:
    return [name for name, _ in events if name.startswith("ZONE_")]


def test_nadir_is_followed_inside_a_disarmed_earth_zone() -> None:
    g, events = _guidance("inertial_targets", target_kind="nadir")
    q = _q_with_boresight(_unit(-g.ephem.position_N_km(0.0)))
    q, rows = _fly(g, q, 0.0, 60.0)
    # the compiled steady cycle and the Python one both leave the disarmed zone's margin out
    assert all(math.isnan(m) and math.isnan(mm) for m, mm, _, _ in rows)
    assert max(err for _, _, err, _ in rows[100:]) < 0.4  # on nadir, the law's lag only
    assert _names(events) == []
    nadir = _unit(-g.ephem.position_N_km(60.0))
    assert g.target_violation("DIRECTION", nadir, on_earth=True) is None
    assert g.target_violation("DIRECTION", nadir) is not None  # as a fixed direction it would be refused


def test_an_always_armed_earth_zone_refuses_nadir() -> None:
    g, _ = _guidance("always")
    nadir = _unit(-g.ephem.position_N_km(0.0))
    zone, margin = g.target_violation("DIRECTION", nadir, on_earth=True)
    assert zone == 0 and margin < -60.0


def test_a_dark_field_arms_the_zone_once_clear_and_the_law_keeps_the_earth_out() -> None:
    """From nadir to a field 80 deg ahead of nadir in the orbit plane: the boresight leaves the Earth zone
    (the zone is armed then, not before), settles on the field, and as nadir turns towards the field at the
    orbit rate (0.064 deg/s) and the zone (68.2 deg limb + atmosphere + 5 deg, 3 deg more for the law) reaches
    it, the boresight is pushed off the field and never enters the zone."""
    g, events = _guidance("inertial_targets", target_kind="nadir")
    eph = g.ephem
    q = _q_with_boresight(_unit(-eph.position_N_km(0.0)))
    q, _ = _fly(g, q, 0.0, 10.0)
    nadir, v = _unit(-eph.position_N_km(10.0)), eph.velocity_direction_N(10.0)
    field = _unit(math.cos(math.radians(80.0)) * nadir - math.sin(math.radians(80.0)) * v)
    g.set_target_direction(field)
    q, rows = _fly(g, q, 10.0, 400.0)
    armed_at = next(k for k, (m, _, _, _) in enumerate(rows) if not math.isnan(m))
    assert _names(events) == ["ZONE_ARMED"]
    assert armed_at > 10  # not before the boresight had left the zone
    margins = np.array([m for m, _, _, _ in rows[armed_at:]])
    assert np.all(np.isfinite(margins)) and margins.min() > 0.0
    errors = np.array([err for _, _, err, _ in rows])
    settled = int(np.argmax(errors < 0.1))
    assert 0 < settled < 1500  # it reached the field
    assert errors[settled:].max() > 1.0  # and was pushed off it when the zone came


def test_a_target_on_the_earth_disarms_the_zone_at_once() -> None:
    g, events = _guidance("inertial_targets")
    eph = g.ephem
    field = _unit(np.cross(eph.position_N_km(0.0), eph.velocity_direction_N(0.0)))  # the orbit normal
    g.set_target_direction(field)
    q, rows = _fly(g, _q_with_boresight(field), 0.0, 2.0)
    assert _names(events) == ["ZONE_ARMED"] and rows[-1][0] > 10.0
    g.set_target_on_earth("nadir")
    assert _names(events) == ["ZONE_ARMED", "ZONE_DISARMED"]
    q, rows = _fly(g, q, 2.0, 200.0)
    assert all(math.isnan(m) for m, _, _, _ in rows)
    assert rows[-1][2] < 0.5  # through the zone's edge and onto nadir


def test_armed_takes_only_its_two_values() -> None:
    with pytest.raises(ValueError, match="armed"):
        FswConfig.model_validate({"pointing": {"zones": [{**EARTH, "armed": "sometimes"}]}})


def test_a_zone_is_armed_only_where_the_boresight_can_stop_short_of_it() -> None:
    """A fixed target commanded while the boresight still heads into the zone (2 deg/s): the zone is not
    armed, though outside it, until the boresight has turned away; a zone sweeping at the orbit rate is
    armed as soon as the boresight is outside it."""
    from fsw.guidance.slew_limits import braking_distance_deg

    g, events = _guidance("inertial_targets", target_kind="nadir")
    need = braking_distance_deg(2.0, g.accel_deg_s2, g.bandwidth_rad_s)
    assert need > 2.7 + g.cfg.law.margin_deg  # more than the room at the start of the approach below
    assert g.armable(0.1, 0.064) and not g.armable(-0.1, 0.0) and not g.armable(2.7, 2.0)
    eph = g.ephem
    nadir = _unit(-eph.position_N_km(0.0))
    normal = _unit(np.cross(eph.position_N_km(0.0), eph.velocity_direction_N(0.0)))
    g.step(0.0, 0.1, _q_with_boresight(nadir), np.zeros(3))
    g.set_target_direction(normal)
    law_edge = eph.earth_angular_radius_deg + 5.0 + g.cfg.law.margin_deg  # the zone as the law sees it
    # from 2.7 deg outside the law's zone in at 2 deg/s for 2.5 s (2.3 deg inside), then out at 2 deg/s
    angles = [law_edge + 2.7 - 0.2 * k for k in range(26)] + [law_edge - 2.3 + 0.2 * k for k in range(1, 60)]
    armed_at = None
    for k, angle in enumerate(angles):
        a = math.radians(angle)
        g.step(0.1 * (k + 1), 0.1, _q_with_boresight(math.cos(a) * nadir + math.sin(a) * normal), np.zeros(3))
        if armed_at is None and _names(events) == ["ZONE_ARMED"]:
            armed_at = k
    assert armed_at is not None and armed_at > 25  # after the turn
    assert angles[armed_at] > law_edge  # and outside the zone


def test_a_target_on_the_earth_is_still_followed_after_safe_and_the_zone_stays_disarmed() -> None:
    """SAFE flies its own aim through the POINTING law (the Sun acquisition): the nadir target is held for
    POINTING, not taken for a fixed direction, so the zone stays disarmed and nadir is followed again."""
    g, events = _guidance("inertial_targets", target_kind="nadir")
    q = _q_with_boresight(_unit(-g.ephem.position_N_km(0.0)))
    q, _ = _fly(g, q, 0.0, 5.0)
    g.set_mode("SAFE")
    q, _ = _fly(g, q, 5.0, 30.0)
    assert g.safe_phase != "RATE_DAMPING"  # the Sun acquisition ran the POINTING law
    g.set_mode("POINTING")
    q, rows = _fly(g, q, 35.0, 1.0)
    out = g.step(36.0, 0.1, q, np.zeros(3))
    assert np.allclose(out.target_N, _unit(-g.ephem.position_N_km(36.0)), atol=1e-12)
    assert math.isnan(out.margins_deg[0]) and _names(events) == []
