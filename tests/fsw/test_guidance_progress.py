"""No stall: a planned slew resumed after a mode change reaches its target, and the guidance
watchdog reports and replans a slew that stands still (here: a target at the boresight's antipode).

Kinematic loop of the flight guidance: perfect rate tracking at 10 Hz (scipy's Rotation integrates the
commanded body rate), a 25 deg inertial cone across the great circle, k1 0.3, 1 deg/s, 3 deg inflation.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig
from fsw.guidance import Guidance
from fsw.guidance.watchdog import ProgressWatchdog

DT = 0.1


def _dir(lon_deg: float, lat_deg: float) -> np.ndarray:
    lon, lat = math.radians(lon_deg), math.radians(lat_deg)
    return np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])


def _guidance(start: np.ndarray, zones: list, events: list, path: bool = True, **law) -> tuple[Guidance, np.ndarray]:
    cfg = FswConfig.model_validate({
        "initial_mode": "POINTING", "spacecraft": {"max_rate_deg_s": 1.0},
        "law": {"k1": 0.3, "margin_deg": 3.0, "eps_max_used": 0.035, "assumption_check": "off", **law},
        "pointing": {"target_N": list(start), "roll_gain_1_s": 0.0, "zones": zones, "path": {"enabled": path}}})
    g = Guidance(cfg, lambda name, **args: events.append((name, args)))
    q = Rotation.align_vectors([start], [cfg.pointing.boresight_B])[0].as_quat()
    return g, np.array([q[3], q[0], q[1], q[2]])


SUN = [{"name": "sun", "body": "inertial", "direction_N": list(_dir(0, 2)),
        "geometry": {"shape": "cone", "half_angle_deg": 25.0}}]


def _fly(g: Guidance, q: np.ndarray, t0: float, seconds: float, on_tick=None) -> tuple[np.ndarray, float, float, float]:
    """(q, t, error [deg], smallest physical margin [deg]) after ``seconds`` or once within 0.05 deg."""
    worst, t, err = math.inf, t0, math.nan
    for k in range(int(round(seconds / DT))):
        t = t0 + k * DT
        if on_tick is not None:
            on_tick(t)
        out = g.step(t, DT, q, np.zeros(3))
        worst = min(worst, out.margin_min_deg) if g.slots else worst
        err = out.pointing_error_deg
        if err < 0.05:
            break
        r = Rotation.from_quat(np.roll(q, -1)) * Rotation.from_rotvec(out.omega_cmd_BN_B * DT)
        q = np.roll(r.as_quat(), 1)
    return q, t, err, worst


def test_a_planned_slew_resumed_after_a_mode_change_reaches_its_target() -> None:
    """The ground re-commands POINTING (SET_MODE, as after a SAFE trip or a quaternion manoeuvre) in the
    middle of a slew that follows its planned path. On the old guidance the law kept steering to the path
    point it had been built for and stopped there, far from the target: the path was dropped but the law
    was not rebuilt until a zone moved (an inertial zone never does)."""
    for interlude in ("POINTING", "QUATERNION"):
        events: list = []
        g, q = _guidance(_dir(-50, 5), SUN, events)
        target = _dir(50, -5)
        g.set_target_direction(target)
        q, t, err, _ = _fly(g, q, 0.0, 35.0)
        assert 40.0 < err < 80.0 and any(n == "PATH_PLANNED" for n, _ in events)
        g.set_mode(interlude)
        if interlude != "POINTING":
            g.step(t + DT, DT, q, np.zeros(3))
            g.set_mode("POINTING")
        q, t, err, worst = _fly(g, q, t + 2 * DT, 200.0)
        assert err < 0.05, (interlude, err)  # reached (uninterrupted: ~120 s for the whole slew)
        assert worst > 3.0 - 0.05
        assert not any(n == "GUIDANCE_STALLED" for n, _ in events)  # the cause is gone, not the symptom


def test_watchdog_detects_a_standstill_outside_the_layers_only() -> None:
    wd = ProgressWatchdog(10.0)
    limit = math.radians(1.0)
    fired = [wd.update(0.1 * k, 120.0, 1e-4, limit, in_layer=False, holding=False) for k in range(101)]
    assert fired.index(True) == 100 and sum(fired) == 1  # after exactly 10 s, then it starts again
    for kwargs in ({"in_layer": True, "holding": False}, {"in_layer": False, "holding": True}):
        assert not any(wd.update(0.1 * k, 120.0, 1e-4, limit, **kwargs) for k in range(300))
    # slow but real progress (0.02 deg/s, under 5 % of the limit) is not a stall
    assert not any(wd.update(0.1 * k, 120.0 - 0.002 * k, 1e-4, limit, False, False) for k in range(300))
    # a fast rate command is not a stall, whatever the error does; neither is landing (error < 1 deg)
    assert not any(wd.update(0.1 * k, 120.0, 0.5 * limit, limit, False, False) for k in range(300))
    assert not any(wd.update(0.1 * k, 0.5, 1e-4, limit, False, False) for k in range(300))


def test_a_slew_to_the_antipode_stalls_and_the_watchdog_replans_it_round_the_zones() -> None:
    """At the antipode of its target the law commands no rate at all (P(y) x_d = 0), an unstable rest
    point: without the watchdog the spacecraft stands still until rounding errors grow (e^(k1 t), some
    two minutes here); with it, GUIDANCE_STALLED after the window and a new plan round the zone (every
    great circle is a shortest path from the antipode), flown to the target with every margin kept. Slew planning is off (the law alone, as a
    mission may configure it): the watchdog's replan does not depend on it."""
    start = _dir(-60, 30)
    zones = [{"name": "sun", "body": "inertial", "direction_N": list(_dir(20, 10)),
              "geometry": {"shape": "cone", "half_angle_deg": 20.0}}]
    for window in (0.0, 20.0):
        events: list = []
        g, q = _guidance(start, zones, events, path=False, stall_watchdog_s=window)
        y = Rotation.from_quat(np.roll(q, -1)).apply(g.b_B)
        g.set_target_direction(-y)  # exactly opposite the boresight
        if window == 0.0:
            q, t, err, _ = _fly(g, q, 0.0, 60.0)
            assert err > 179.0 and not events  # one minute and nothing moved
            continue
        q, t, err, worst = _fly(g, q, 0.0, 400.0)
        stalls = [a for n, a in events if n == "GUIDANCE_STALLED"]
        assert err < 0.05, err
        assert len(stalls) == 1 and stalls[0]["error_deg"] > 179.0
        assert worst > 3.0 - 0.05
        assert t < window + 180.0 + 40.0, t  # the stall window, a 180 deg slew at 1 deg/s, the landing


def test_detour_waypoint_is_a_quarter_turn_away_clear_of_the_zones_and_towards_the_target() -> None:
    from gnc.sky_zones import SkyZoneBuilder
    from fsw.config import ConeShape
    from fsw.guidance.watchdog import detour_waypoint

    y, target = _dir(0, 0), _dir(170, 5)
    zone = SkyZoneBuilder(ConeShape(half_angle_deg=30.0), 0.0, 0.0).build(_dir(90, 0))
    w = detour_waypoint(y, target, [zone], 2.0)
    assert abs(float(w @ y)) < 1e-12  # 90 deg from the boresight
    assert float(zone.separation(w)) > 1.0 - math.cos(math.radians(2.0))
    # of the clear quarter-turn directions (every 15 deg round the boresight) it is the one nearest the target
    others = [math.cos(math.radians(a)) * _dir(90, 0) + math.sin(math.radians(a)) * _dir(0, 90) for a in range(0, 360, 15)]
    clear = [o for o in others if float(zone.separation(o)) > 1.0 - math.cos(math.radians(2.0))]
    assert float(w @ target) >= max(float(o @ target) for o in clear) - 1e-9
