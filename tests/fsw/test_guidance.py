"""Guidance: rate maps (checked by numerical differentiation with scipy), scaling, roll, zones moving
with the ephemeris, merging near new moon, target rejection/retreat, double cover, SAFE phases."""
from __future__ import annotations

import math
import os
import pickle

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig
from fsw.guidance import Guidance, ZoneGeometry, signed_margin_deg
from gnc import sky_zones as sz
from gnc.ephemeris import julian_date_tdb, moon_direction_N


def _rot(q):
    return Rotation.from_quat(np.roll(np.asarray(q, dtype=float), -1))


def _q(rot):
    return np.roll(rot.as_quat(), 1)


def _propagate(q, omega_B, dt):
    """q_NB after rotating with body rate omega_B for dt (scipy: R(t+dt) = R(t) exp(omega dt))."""
    return _q(_rot(q) * Rotation.from_rotvec(np.asarray(omega_B) * dt))


def _events():
    log = []
    return log, (lambda name, **args: log.append((name, args)))


def _cfg(**data) -> FswConfig:
    return FswConfig.model_validate(data)


def test_pointing_map_gives_ydot_equal_to_projected_u() -> None:
    cfg = _cfg(initial_mode="POINTING", law={"k1": 0.1}, spacecraft={"max_rate_deg_s": 20.0},
               pointing={"target_N": [0.0, 1.0, 0.2], "roll_gain_1_s": 0.0})
    g = Guidance(cfg)
    q = _q(Rotation.from_euler("xyz", [20, -40, 10], degrees=True))
    out = g.step(0.0, 0.1, q, np.zeros(3))
    b = np.asarray(cfg.pointing.boresight_B)
    y = _rot(q).apply(b)
    dt = 1e-6
    y2 = _rot(_propagate(q, out.omega_cmd_BN_B, dt)).apply(b)
    ydot = (y2 - y) / dt
    u = 0.1 * np.asarray(cfg.pointing.target_N)
    np.testing.assert_allclose(ydot, u - (u @ y) * y, atol=1e-6)
    assert abs(out.omega_cmd_BN_B @ b) < 1e-12  # no roll from the law


def test_rate_command_is_saturated_without_changing_direction() -> None:
    cfg = _cfg(initial_mode="POINTING", law={"k1": 5.0}, spacecraft={"max_rate_deg_s": 0.5},
               pointing={"target_N": [0.0, 1.0, 0.0], "roll_gain_1_s": 0.0})
    q = _q(Rotation.from_euler("y", -90, degrees=True))  # boresight +z -> -x... far from the target
    out = Guidance(cfg).step(0.0, 0.1, q, np.zeros(3))
    fast = Guidance(_cfg(initial_mode="POINTING", law={"k1": 5.0}, spacecraft={"max_rate_deg_s": 20.0},
                         pointing={"target_N": [0.0, 1.0, 0.0], "roll_gain_1_s": 0.0})).step(0.0, 0.1, q, np.zeros(3))
    assert math.degrees(np.linalg.norm(out.omega_cmd_BN_B)) == pytest.approx(0.5)
    np.testing.assert_allclose(out.omega_cmd_BN_B / np.linalg.norm(out.omega_cmd_BN_B),
                               fast.omega_cmd_BN_B / np.linalg.norm(fast.omega_cmd_BN_B), atol=1e-12)


def test_roll_law_turns_about_the_boresight_only_and_converges() -> None:
    cfg = _cfg(initial_mode="POINTING", pointing={"target_N": [0.0, 0.0, 1.0], "roll_axis_B": [1, 0, 0],
                                                  "roll_reference_N": [1.0, 0.0, 0.0], "roll_gain_1_s": 0.5})
    g = Guidance(cfg)
    q = _q(Rotation.from_euler("z", 70, degrees=True))  # boresight on target, rolled 70 deg
    out = g.step(0.0, 0.1, q, np.zeros(3))
    assert out.roll_error_deg == pytest.approx(-70.0, abs=1e-6)
    for k in range(2000):  # roll rate saturates at half the rate limit (0.5 deg/s): ~140 s + decay
        out = g.step(0.1 * k, 0.1, q, np.zeros(3))
        q = _propagate(q, out.omega_cmd_BN_B, 0.1)
    assert abs(out.roll_error_deg) < 0.01
    assert out.pointing_error_deg < 1e-6  # the roll never moved the boresight


def _epoch_cfg(epoch, zones, target_N, margin=3.0, **extra):
    return _cfg(epoch_utc=epoch, initial_mode="POINTING", law={"margin_deg": margin, "k1": 0.1},
                spacecraft={"max_rate_deg_s": 2.0},
                pointing={"target_N": list(target_N), "zones": zones, "roll_gain_1_s": 0.0}, **extra)


SUN_STAR = {"name": "sun", "body": "sun", "geometry": {"shape": "superellipse", "semi_axes_deg": [25, 12], "exponent": 0.7}}
MOON_CONE = {"name": "moon", "body": "moon", "geometry": {"shape": "cone", "half_angle_deg": 12}}


def test_kinematic_closed_loop_avoids_the_inflated_zones_and_converges() -> None:
    """Perfect kinematics (scipy integration of the rate command): the boresight never enters the
    inflated zones, so the physical margin stays >= margin_deg, and it reaches the target."""
    from closed_loop_kit import attitude_with_boresight, slew_geometry

    epoch = "2030-03-29T12:00:00+00:00"
    y0, yd, _, _ = slew_geometry(epoch)
    cfg = _epoch_cfg(epoch, [SUN_STAR, MOON_CONE], yd)
    g = Guidance(cfg)
    q = attitude_with_boresight(y0)
    min_margin = 90.0
    for k in range(4000):
        out = g.step(0.1 * k, 0.1, q, np.zeros(3))
        min_margin = min(min_margin, out.margin_min_deg)
        q = _propagate(q, out.omega_cmd_BN_B, 0.1)
    assert out.pointing_error_deg < 0.01
    assert min_margin > 3.0 - 0.05  # never inside the inflated zone (up to the 10 Hz sampling)
    assert min_margin < 8.0  # and the path really went around the Sun zone


def test_zones_move_with_the_ephemeris() -> None:
    cfg = _epoch_cfg("2030-03-29T12:00:00+00:00", [MOON_CONE], [1.0, 0.0, 0.0])
    g = Guidance(cfg)
    q = np.array([1.0, 0, 0, 0])
    g.step(0.0, 0.1, q, np.zeros(3))
    c0 = g.slots[0].center_N.copy()
    g.step(3600.0, 0.1, q, np.zeros(3))
    moved = math.degrees(math.acos(c0 @ g.slots[0].center_N))
    assert 0.3 < moved < 0.8  # the Moon moves about 0.5 deg per hour
    jd = julian_date_tdb("2030-03-29T13:00:00+00:00")
    r_sc = g.ephem.position_N_km(3600.0)
    ref = moon_direction_N(jd, r_sc)
    assert math.degrees(math.acos(ref @ g.slots[0].center_N)) < 1e-3


def test_sun_and_moon_near_new_moon_are_merged_with_an_event() -> None:
    log, ev = _events()
    cfg = _epoch_cfg("2030-04-02T12:00:00+00:00", [SUN_STAR, MOON_CONE], [0.0, 0.0, 1.0])
    g = Guidance(cfg, events=ev)
    out = g.step(0.0, 0.1, np.array([1.0, 0, 0, 0]), np.zeros(3))
    assert out.zones_merged
    assert [n for n, _ in log].count("ZONES_MERGED") == 1
    merged = g._sky_law_zones
    assert len(merged) == 1
    for slot in g.slots:  # the merged cone contains both inflated zones
        pts = slot.law.boundary(300)
        assert all(merged[0].separation(p) < 1e-9 for p in pts)


def test_a_moving_aim_keeps_the_merged_zone_and_a_new_merge_around_the_boresight_is_judged_again() -> None:
    """A ground target moves the aim every cycle and the law is made again; the Sun and Moon's merged zone is
    kept (the same object) while they stay put, and equals a fresh merge. A merge that judged a new pair
    against the boresight is not kept: the next boresight may refuse it."""
    cfg = _epoch_cfg("2030-04-02T12:00:00+00:00", [SUN_STAR, MOON_CONE], [0.0, 0.0, 1.0])
    g = Guidance(cfg)
    q = np.array([1.0, 0, 0, 0])
    g.step(0.0, 0.1, q, np.zeros(3))
    first = g._sky_law_zones[0]
    for k in range(3):  # the aim moves: the law is rebuilt, twice to keep its first merge
        g.set_target_direction(np.array([0.0, math.sin(0.01 * (k + 1)), math.cos(0.01 * (k + 1))]))
        g.step(0.1 * (k + 1), 0.1, q, np.zeros(3))
    kept = g._sky_law_zones[0]
    g.set_target_direction(np.array([0.0, math.sin(0.05), math.cos(0.05)]))
    g.step(0.4, 0.1, q, np.zeros(3))
    assert g._sky_law_zones[0] is kept and len(g._sky_law_zones) == 1
    fresh, groups = ZoneGeometry(3, cfg.law.merge_gap_deg).merge([s.law for s in g.slots], keep_merged=[[0, 1]])
    assert groups == [[0, 1]] and repr(fresh[0]) == repr(kept) == repr(first)
    geometry = ZoneGeometry(3, cfg.law.merge_gap_deg)
    geometry.merge([s.law for s in g.slots], keep_outside=[np.array([0.0, 0.0, 1.0])])
    assert geometry.saw_keep_outside
    geometry.merge([s.law for s in g.slots], keep_outside=[np.array([0.0, 0.0, 1.0])], keep_merged=[[0, 1]])
    assert not geometry.saw_keep_outside


def test_target_inside_a_zone_is_refused_and_a_moving_zone_pushes_the_target_out() -> None:
    cfg = _epoch_cfg("2030-03-29T12:00:00+00:00", [MOON_CONE], [0.0, 0.0, 1.0])
    g = Guidance(cfg)
    q = np.array([1.0, 0, 0, 0])
    g.step(0.0, 0.1, q, np.zeros(3))
    moon = g.slots[0].center_N
    hit = g.target_violation("DIRECTION", moon)
    assert hit is not None and hit[0] == 0 and hit[1] < -10.0
    # 14 deg from the Moon: outside the physical 12 deg cone but inside the 3 deg margin: refused
    frame = sz.sky_frame(moon)
    near = math.cos(math.radians(14)) * moon + math.sin(math.radians(14)) * frame[0]
    assert g.target_violation("DIRECTION", near) is not None
    far = math.cos(math.radians(40)) * moon + math.sin(math.radians(40)) * frame[0]
    assert g.target_violation("DIRECTION", far) is None
    # If the zone moves onto an accepted target, guidance steers to a substitute outside the layer.
    log, ev = _events()
    g2 = Guidance(_epoch_cfg("2030-03-29T12:00:00+00:00", [MOON_CONE], list(near)), events=ev)
    out = g2.step(0.0, 0.1, q, np.zeros(3))
    sub = g2._sky_target
    assert g2.slots[0].law.separation(sub) > out.eps
    assert any(n == "ASSUMPTION_VIOLATED" for n, _ in log)


QUAT_ZONES = [{"shape": "cone", "name": f"c{i}", "center_q": c, "half_angle_deg": 15.0}
              for i, c in enumerate([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, -1, 0, 0], [0, 0, -1, 0],
                                     [0, 0, 0, -1], [-1, 0, 0, 0]])]


def test_quaternion_map_and_double_cover() -> None:
    cfg = _cfg(initial_mode="QUATERNION", law={"k1": 0.1, "margin_deg": 2.0}, spacecraft={"max_rate_deg_s": 20.0},
               quaternion={"target_q_NB": [1, 0, 0, 0], "zones": QUAT_ZONES})
    g = Guidance(cfg)
    assert g.s3_use_gradient  # all cones -> GradientLaw
    q = _q(Rotation.from_rotvec(np.radians([40, -30, 20])))
    out = g.step(0.0, 0.1, q, np.zeros(3))
    # qdot = P(q) u with u from the law: compare with a numerical derivative of the propagated q
    dt = 1e-6
    qdot = (_propagate(q, out.omega_cmd_BN_B, dt) - q) / dt
    u = 0.1 * np.asarray(g._s3_law.control(q))
    np.testing.assert_allclose(qdot, u - (u @ q) * q, atol=1e-5)
    # the estimator may hand over -q next cycle (same attitude): the lift keeps the command continuous
    out2 = g.step(0.1, 0.1, -q, np.zeros(3))
    np.testing.assert_allclose(out2.omega_cmd_BN_B, out.omega_cmd_BN_B, atol=1e-12)
    # entry from the far sheet picks the target hemisphere: same command as from +q
    g3 = Guidance(cfg)
    np.testing.assert_allclose(g3.step(0.0, 0.1, -q, np.zeros(3)).omega_cmd_BN_B, out.omega_cmd_BN_B, atol=1e-12)


def test_safe_mode_damps_then_points_the_sun_axis() -> None:
    log, ev = _events()
    cfg = _cfg(initial_mode="SAFE", safe={"sun_axis_B": [0, 0, -1], "damping_exit_rate_deg_s": 0.05})
    g = Guidance(cfg, events=ev)
    q = np.array([1.0, 0, 0, 0])
    out = g.step(0.0, 0.1, q, np.radians([0.5, 0, 0]))
    assert out.safe_phase == "RATE_DAMPING" and np.all(out.omega_cmd_BN_B == 0)
    for k in range(11):
        out = g.step(0.1 * k, 0.1, q, np.radians([0.01, 0, 0]))
    assert ("SAFE_PHASE_CHANGED", {"phase": "SUN_ACQUISITION"}) in log
    for k in range(3000):
        out = g.step(0.1 * k, 0.1, q, np.zeros(3))
        q = _propagate(q, out.omega_cmd_BN_B, 0.1)
    sun_axis_N = _rot(q).apply([0, 0, -1])
    assert math.degrees(math.acos(sun_axis_N @ out.sun_N)) < 0.1
    assert out.safe_phase == "SUN_POINTING"


def test_fast_eps_bound_is_below_the_exact_check() -> None:
    from gnc.checks import check_assumptions

    a = sz.cone_zone(np.array([1.0, 0, 0]), 20.0)
    b = sz.cone_zone(np.array([0.0, 1.0, 0]), 30.0)
    x_d = np.array([0.0, 0.0, 1.0])
    fast = ZoneGeometry.fast_eps_max(x_d, [a, b])
    exact = check_assumptions(x_d, [a, b], 0.01).eps_max
    assert 0 < fast <= exact + 1e-12
    assert fast == pytest.approx(1 - math.cos(math.radians(20.0)), rel=1e-9)  # delta = (90-20-30)/2


def test_signed_margin_is_in_degrees() -> None:
    z = sz.cone_zone(np.array([1.0, 0, 0]), 10.0)
    p = np.array([math.cos(math.radians(25)), math.sin(math.radians(25)), 0.0])
    assert signed_margin_deg(z, p) == pytest.approx(15.0)
    p = np.array([math.cos(math.radians(4)), math.sin(math.radians(4)), 0.0])
    assert signed_margin_deg(z, p) == pytest.approx(-6.0)


def test_assumption_checker_close_stops_a_busy_worker_at_once():
    """Ctrl-C of a SIL run: the flight software must not wait for, nor leave behind, a check in progress."""
    import time as _time

    import psutil

    from fsw.assumption_check import AssumptionChecker

    checker = AssumptionChecker("process")
    checker.start()
    worker = psutil.Process(checker.worker.pid)
    assert worker.pid != os.getpid()
    # a check that would outlive the flight software: the worker sleeps while unpickling the request
    checker._requests.send_bytes(pickle.dumps(_Sleep(30.0)))
    checker._in_flight = True
    _time.sleep(0.2)
    t0 = _time.monotonic()
    checker.close()
    gone, alive = psutil.wait_procs([worker], timeout=5.0)
    assert not alive
    assert _time.monotonic() - t0 < 5.0
    assert not checker.busy


def test_the_assumption_check_worker_is_a_new_interpreter_not_a_fork() -> None:
    """After a fork every page the flight process writes first is copied on a fault (~1,000 in a lockstep
    run, 110-140 ms for each of the first two cycles in the vcan-vm guest): the worker is exec'd instead,
    this interpreter with the checker's entry point, and it ends with `close`."""
    import sys
    import time

    import psutil

    from fsw.assumption_check import AssumptionChecker

    checker = AssumptionChecker("process")
    checker.start()
    try:
        worker = psutil.Process(checker.worker.pid)
        assert worker.ppid() == os.getpid()
        deadline = time.monotonic() + 30.0
        while len(cmdline := worker.cmdline()) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)  # Popen returns once the child is started; its exec may still be under way
        assert os.path.realpath(cmdline[0]) == os.path.realpath(sys.executable) and cmdline[1] == "-c"
        assert "fsw.assumption_check import serve" in cmdline[2]
    finally:
        checker.close()
    assert not psutil.pid_exists(worker.pid) or worker.status() == psutil.STATUS_ZOMBIE


class _Sleep:
    """Unpickles by sleeping: keeps the check worker busy for the close test."""

    def __init__(self, seconds: float):
        self.seconds = seconds

    def __reduce__(self):
        import time as _time

        return (_time.sleep, (self.seconds,))


def test_assumption_check_runs_in_a_worker_and_the_flight_process_starts_no_thread() -> None:
    """A helper thread in the flight process holding the GIL while the host preempts it stalls the
    real-time cycle thread (the 24 h soak saw 0.1-0.2 s slips with a process pool's feeder thread):
    the checker submits and polls from the calling thread only."""
    import threading
    import time as _time

    from fsw.assumption_check import AssumptionChecker
    from gnc.zones import ConicZone

    before = set(threading.enumerate())
    checker = AssumptionChecker("process")
    try:
        snapshot = (np.array([1.0, 0.0, 0.0]), [ConicZone(np.array([0.0, 1.0, 0.0]), math.radians(20.0))], 0.01, 1.0, "star")
        assert checker.submit(snapshot)
        assert checker.busy and not checker.submit(snapshot)  # one check in flight at most
        deadline = _time.monotonic() + 60.0
        result = None
        while result is None and _time.monotonic() < deadline:
            result = checker.poll()
            _time.sleep(0.01)
        assert result is not None and result.ok, result
        assert result.eps_max == pytest.approx(1.0 - math.cos(math.radians(70.0)), rel=1e-6)
        assert checker.completed == 1 and checker.failures == 0 and not checker.busy
        assert set(threading.enumerate()) == before
    finally:
        checker.close()


def test_without_attitude_fix_the_tracker_is_swept_out_of_its_exclusion_without_moving_the_instrument() -> None:
    """Star tracker blind from the start (it began 30.1 deg from the Sun with a 30 deg exclusion in a
    campaign run): after the delay the FSW rotates about the instrument boresight at the configured rate."""
    cfg = _cfg(initial_mode="POINTING", spacecraft={"star_tracker_q_BS": [0.7071068, 0.7071068, 0.0, 0.0]},
               estimator={"acquisition_delay_s": 2.0, "acquisition_rate_deg_s": 0.5})
    g = Guidance(cfg)
    outs = [g.step(0.1 * k, 0.1, None, np.zeros(3)).omega_cmd_BN_B for k in range(40)]
    assert all(np.all(o == 0.0) for o in outs[:19])  # rate damping only until the delay
    b = np.asarray(cfg.pointing.boresight_B)
    st_B = _rot(np.array(cfg.spacecraft.star_tracker_q_BS)).apply([0.0, 0.0, 1.0])
    late = outs[-1]
    assert np.linalg.norm(late) == pytest.approx(math.radians(0.5))
    assert np.linalg.norm(np.cross(late, b)) < 1e-12  # about the instrument boresight: it stays put
    # the tracker's boresight sweeps a great circle (it moves at the full rate), so no cone can hold it
    assert np.linalg.norm(np.cross(late, st_B)) == pytest.approx(math.radians(0.5))
    q = np.array([0.9, 0.1, -0.2, 0.3]) / np.linalg.norm([0.9, 0.1, -0.2, 0.3])
    g.step(4.0, 0.1, q, np.zeros(3))
    assert g.no_fix_s == 0.0  # a fix ends the acquisition


def _rot_toward(a: np.ndarray, b: np.ndarray, angle_rad: float) -> np.ndarray:
    e = b - (a @ b) * a
    e /= np.linalg.norm(e)
    return math.cos(angle_rad) * a + math.sin(angle_rad) * e


def test_overlapping_zones_around_the_boresight_are_bridged_and_the_law_keeps_out_of_both() -> None:
    """Earth and Moon zones overlapping with the boresight in the notch beside their overlap: the
    enclosing cone would swallow the boresight, so the pair becomes one star polygon that contains both
    zones and leaves the boresight outside; the law on it then steers past both to a target beyond."""
    from gnc.laws import StarShapedLaw
    from gnc.zones import ConicZone

    a = np.array([1.0, 0.0, 0.0])
    b = _rot_toward(a, np.array([0.0, 1.0, 0.0]), math.radians(30.0))  # caps of 18 and 15 deg overlap by 3
    za, zb = ConicZone(a, math.radians(18.0)), ConicZone(b, math.radians(15.0))
    mid = _rot_toward(a, b, math.radians(16.0))
    y0 = _rot_toward(mid, np.array([0.0, 0.0, 1.0]), math.radians(16.0))  # in the notch, outside both
    assert za.separation(y0) > 0 and zb.separation(y0) > 0
    assert sz.enclosing_cone([za.bounding_cap, zb.bounding_cap]).contains(y0)
    target = _rot_toward(mid, np.array([0.0, 0.0, -1.0]), math.radians(40.0))  # across the pair

    merged, groups = ZoneGeometry(3, merge_gap_deg=4.0).merge([za, zb], keep_outside=[y0, target])
    assert groups == [[0, 1]] and len(merged) == 1
    bridge = merged[0]
    assert not bridge.contains(y0) and not bridge.contains(target)
    for zone in (za, zb):  # the bridge holds both zones
        assert all(bridge.separation(p) < 1e-9 for p in zone.boundary(720))

    eps = 0.5 * ZoneGeometry.fast_eps_max(target, merged)
    law = StarShapedLaw(target, merged, k1=1.0, kappa=1.0, eps=eps)
    y, worst = y0.copy(), math.inf
    for _ in range(6000):
        y = y + 0.01 * np.asarray(law.control(y))
        y /= np.linalg.norm(y)
        worst = min(worst, za.signed_separation(y), zb.signed_separation(y))
    assert worst > 0.0
    assert math.degrees(math.acos(min(1.0, float(y @ target)))) < 0.5


def test_without_a_bridge_the_pair_would_stay_separate_with_no_admissible_layer() -> None:
    """The case the bridge exists for: overlapping zones left separate admit no eps (Assumption 1)."""
    from gnc.zones import ConicZone

    a = np.array([1.0, 0.0, 0.0])
    b = _rot_toward(a, np.array([0.0, 1.0, 0.0]), math.radians(30.0))
    zones = [ConicZone(a, math.radians(18.0)), ConicZone(b, math.radians(15.0))]
    target = _rot_toward(a, np.array([0.0, 0.0, -1.0]), math.radians(60.0))
    assert ZoneGeometry.fast_eps_max(target, zones) == 0.0


def test_a_merged_pair_and_a_third_zone_around_the_boresight_are_bridged() -> None:
    """Sun and Moon merged into one cone (near new moon), then the Earth zone overlapping that cone with
    the boresight in the notch: the merged cone and the Earth cap are bridged as two sides."""
    from gnc.zones import ConicZone

    a = np.array([1.0, 0.0, 0.0])
    b = _rot_toward(a, np.array([0.0, 0.0, 1.0]), math.radians(20.0))  # 8 + 10 deg caps, 2 deg apart
    mid_ab = _rot_toward(a, b, math.radians(10.0))
    cone_ab = sz.enclosing_cone([(a, math.radians(8.0)), (b, math.radians(10.0))])
    c = _rot_toward(cone_ab.axis, np.array([0.0, 1.0, 0.0]), cone_ab.half_angle + math.radians(12.0))
    zones = [ConicZone(a, math.radians(8.0)), ConicZone(b, math.radians(10.0)), ConicZone(c, math.radians(15.0))]
    # boresight beside the overlap of the merged cone and the Earth cap, outside all three
    mid = _rot_toward(cone_ab.axis, c, cone_ab.half_angle - math.radians(1.5))
    y0 = _rot_toward(mid, np.array([0.0, 0.0, -1.0]), math.radians(14.0))
    assert all(z.separation(y0) > 0 for z in zones) and not cone_ab.contains(y0)
    assert sz.enclosing_cone([cone_ab.bounding_cap, zones[2].bounding_cap]).contains(y0)
    target = -mid_ab

    merged, groups = ZoneGeometry(3, merge_gap_deg=4.0).merge(zones, keep_outside=[y0, target])
    assert groups == [[0, 1, 2]] and len(merged) == 1
    assert not merged[0].contains(y0)
    for zone in zones:
        assert all(merged[0].separation(p) < 1e-9 for p in zone.boundary(360))


def _arc_point(a: np.ndarray, b: np.ndarray, angle_deg: float) -> np.ndarray:
    return _rot_toward(a, b, math.radians(angle_deg))


def test_retreat_target_is_the_nearest_direction_clear_of_every_zone_by_the_standoff() -> None:
    from gnc.zones import ConicZone

    a = np.array([1.0, 0.0, 0.0])
    zones = [ConicZone(a, math.radians(20.0)), ConicZone(_arc_point(a, np.array([0.0, 1.0, 0.0]), 45.0), math.radians(15.0))]
    target = _arc_point(a, np.array([0.0, 0.3, 1.0]), 15.0)  # 5 deg inside the first zone
    x, occ = ZoneGeometry.retreat_target(target, zones, 1e-4, standoff_deg=3.0, near=target)
    assert occ == 0
    margins = [math.degrees(math.acos(1.0 - z.separation(x))) for z in zones]
    assert min(margins) >= 3.0 - 1e-9
    # nearest: 5 deg to the boundary plus the 3 deg standoff, within one ring step (0.5 deg)
    moved = math.degrees(math.acos(min(1.0, float(x @ target))))
    assert 8.0 - 1e-6 <= moved <= 8.0 + ZoneGeometry.RETREAT_RING_STEP_DEG
    # a usable target is kept
    free = _arc_point(a, np.array([0.0, 0.0, 1.0]), 60.0)
    x2, occ2 = ZoneGeometry.retreat_target(free, zones, 1e-4, standoff_deg=3.0)
    assert occ2 == -1 and np.array_equal(x2, free)


def test_retreat_target_leaves_a_gap_about_to_merge_around_the_spacecraft() -> None:
    """Two zones 3 deg apart with the boresight (and target) in the neck between them: the pair cannot
    merge (both its cone and its bridge would swallow the boresight), so its would-be shape is pending and
    the substitute target lies clear of it, out of the gap."""
    from gnc.zones import ConicZone

    a = np.array([1.0, 0.0, 0.0])
    b = _arc_point(a, np.array([0.0, 1.0, 0.0]), 33.0)
    zones = [ConicZone(a, math.radians(15.0)), ConicZone(b, math.radians(15.0))]
    y = _arc_point(a, b, 16.5)  # the middle of the 3 deg neck
    geometry = ZoneGeometry(3, merge_gap_deg=4.0)
    merged, groups = geometry.merge(zones, keep_outside=[y])
    assert groups == [[0], [1]] and len(geometry.pending) == 1 and geometry.pending[0].contains(y)
    x, occ = ZoneGeometry.retreat_target(y, merged, 1e-6, standoff_deg=3.0, avoid=geometry.pending, near=y)
    assert occ == len(merged)
    assert not geometry.pending[0].contains(x)
    assert min(math.degrees(math.acos(1.0 - z.separation(x))) for z in zones) >= 3.0
    # once the boresight is out, the pair merges; a merged pair stays merged when its shape later grows
    # over the boresight (keep_merged), instead of splitting into two zones too close for the law
    merged2, groups2 = geometry.merge(zones, keep_outside=[x])
    assert groups2 == [[0, 1]] and not geometry.pending
    inside = merged2[0].kernel
    assert geometry.merge(zones, keep_outside=[inside])[1] == [[0], [1]]
    assert geometry.merge(zones, keep_outside=[inside], keep_merged=groups2)[1] == [[0, 1]]


_FIXED = np.array([1.0, 0.0, 0.0])   # centre of the zone that stays put (Moon, Sun)
_TOWARD = np.array([0.0, 1.0, 0.0])  # the Earth zone comes from this side, along the equator


def _octagon(r: float) -> dict:
    return {"shape": "polygon", "vertices_deg": [[r, 0], [0.7 * r, 0.7 * r], [0, r], [-0.7 * r, 0.7 * r],
                                                 [-r, 0], [-0.7 * r, -0.7 * r], [0, -r], [0.7 * r, -0.7 * r]]}


def _closing_pair(fixed_half_angle_deg: float, earth: dict, y0: np.ndarray, earth_start_deg: float, events=None):
    """Guidance with a fixed cone at _FIXED and an Earth zone moving towards it at 0.06 deg/s (from low
    orbit), 3 deg inflation, 1 deg/s; and an attitude with the boresight on y0 (also the first target)."""
    cfg = _cfg(initial_mode="POINTING", law={"k1": 0.3, "margin_deg": 3.0, "eps_max_used": 0.035, "assumption_check": "off"},
               spacecraft={"max_rate_deg_s": 1.0},
               pointing={"target_N": list(y0), "roll_gain_1_s": 0.0, "zones": [
                   {"name": "fixed", "body": "inertial", "direction_N": list(_FIXED),
                    "geometry": {"shape": "cone", "half_angle_deg": fixed_half_angle_deg}},
                   {"name": "earth", "body": "earth", "add_body_angular_radius": False, "geometry": earth}]})
    g = Guidance(cfg, events)
    g.ephem.directions = lambda t: {"earth": _arc_point(_FIXED, _TOWARD, earth_start_deg - 0.06 * t)}
    return g, _q(Rotation.align_vectors([y0], [cfg.pointing.boresight_B])[0])


def _fly(g: Guidance, q: np.ndarray, duration_s: float, retarget: tuple[float, np.ndarray] | None = None) -> float:
    """Kinematic loop (perfect rate tracking, 10 Hz); the smallest physical margin [deg] on the way."""
    worst, dt = math.inf, 0.1
    for k in range(int(duration_s / dt)):
        if retarget is not None and k == int(retarget[0] / dt):
            g.set_target_direction(retarget[1])
        out = g.step(k * dt, dt, q, np.zeros(3))
        worst = min(worst, out.margin_min_deg)
        q = _propagate(q, out.omega_cmd_BN_B, dt)
    return worst


def test_a_zone_sweeping_towards_another_never_traps_the_boresight_between_them() -> None:
    """The case the 24 h soak found: a large Earth zone (78 deg, as from low orbit) sweeps at 0.06 deg/s
    towards a Moon cone, over the commanded target, with the spacecraft parked in the gap between them.
    The pair is too large to merge, so the gap closes to nothing; the boresight has to leave it sideways
    in time. The physical margin stays positive and the law keeps out of the 3 deg inflation (before the
    fix, the substitute target crept along the Earth's edge into the neck and the margin reached -0.36 deg)."""
    target = _rot_toward(_arc_point(_FIXED, _TOWARD, 20.0), np.array([0.0, 0.0, 1.0]), math.radians(0.3))
    log, events = _events()
    g, q = _closing_pair(12.0, {"shape": "cone", "half_angle_deg": 78.0}, target, 106.0, events)
    worst = _fly(g, q, 500.0)
    assert worst > 2.5, f"keep-out margin reached {worst:.3f} deg"
    assert ("ASSUMPTION_VIOLATED", {"reason": "target in the eps-layer of zone 1: steering to the nearest safe direction"}) in log


def test_retargeting_near_a_closing_gap_keeps_every_margin_positive() -> None:
    """Dispersed version of the soak's case: the spacecraft starts in or near the gap between a Moon cone
    and an Earth polygon (78 deg) sweeping over it at 0.06 deg/s, and is retargeted to a random direction
    (sometimes across the pair, sometimes inside a zone) during the approach; the Earth then starts to
    pass over the Moon. With the substitute target kept 3 deg clear of every zone, and the unmergeable
    pair left out of eps, no margin drops below the inflation (the earlier guidance consumed 1.2 deg of
    it here, and reached -2.8 deg when the same eight ran to 1400 s)."""
    rng = np.random.default_rng(1)
    worst_all = math.inf
    for _ in range(8):
        a = rng.normal(size=3)
        y0 = _rot_toward(_arc_point(_FIXED, _TOWARD, rng.uniform(16, 26)), a / np.linalg.norm(a), math.radians(rng.uniform(0, 8)))
        t = rng.normal(size=3)
        new_target, t_switch = t / np.linalg.norm(t), rng.uniform(50, 600)
        g, q = _closing_pair(12.0, _octagon(78.0), y0, 110.0)
        # the approach and the first 10 deg of the Earth over the Moon
        worst_all = min(worst_all, _fly(g, q, 800.0, retarget=(t_switch, new_target)))
    assert worst_all > 2.5, f"keep-out margin reached {worst_all:.3f} deg"


@pytest.mark.parametrize("side_deg", [10.0, 25.0])
def test_a_slew_across_the_neck_of_a_closing_unmergeable_pair_never_enters_it(side_deg: float) -> None:
    """The soak's second case: a 40 deg Sun cone and a 78 deg Earth polygon closing at 0.06 deg/s (too
    large to merge or bridge), and a target across their neck commanded when the neck is 7 deg wide. The
    law alone would thread the neck and be caught as it closes (the earlier guidance reached -5.8 deg).
    The boresight squeezed between the two zones steers out of the gap first, and then waits at its mouth."""
    up = np.array([0.0, 0.0, 1.0])
    mid = _arc_point(_FIXED, _TOWARD, 48.0)
    y0, target = _rot_toward(mid, up, math.radians(side_deg)), _rot_toward(mid, -up, math.radians(side_deg))
    log, events = _events()
    g, q = _closing_pair(40.0, _octagon(78.0), y0, 140.0, events)
    worst = _fly(g, q, 600.0, retarget=(250.0, target))
    assert worst > 2.5, f"keep-out margin reached {worst:.3f} deg"
    assert ("ASSUMPTION_VIOLATED", {"reason": "boresight between two close zones that cannot merge: steering out of the gap"}) in log


def test_merge_zones_public_entry_groups_close_cones_and_keeps_far_ones_apart():
    """`fsw.guidance.merge_zones` (the configuration's load-time checks use it): two 10 deg cones 22 deg
    apart (2 deg gap < 4 deg merge gap) become one zone containing both; a cone 90 deg away stays alone."""
    from fsw.guidance import merge_zones
    from gnc.zones import ConicZone

    r = math.radians(10.0)
    a = ConicZone(np.array([1.0, 0.0, 0.0]), r)
    b = ConicZone(np.array([math.cos(math.radians(22)), math.sin(math.radians(22)), 0.0]), r)
    c = ConicZone(np.array([0.0, 0.0, 1.0]), r)
    merged, groups = merge_zones([a, b, c], merge_gap_deg=4.0)
    assert groups == [[0, 1], [2]]
    for x in (a.axis, b.axis):
        assert merged[0].contains(x)
    assert not merged[1].contains(a.axis)
    assert merge_zones([a, b, c], merge_gap_deg=1.0)[1] == [[0], [1], [2]]


def _safe_slew(zones: list[dict], steps: int):
    """SAFE from rest with the boresight 60 deg from the Sun; the Sun axis is the anti-boresight, so the
    Sun-safe boresight is the anti-Sun direction, 120 deg away. Kinematic loop; returns the guidance, the
    boresight path and the Sun direction."""
    cfg = _cfg(initial_mode="SAFE", pointing={"zones": zones},
               safe={"sun_axis_B": [0, 0, -1], "damping_exit_rate_deg_s": 0.05, "max_rate_deg_s": 0.5})
    g = Guidance(cfg)
    sun = g.ephem.directions(0.0)["sun"]
    e = np.cross(sun, [0.0, 0.0, 1.0])
    e /= np.linalg.norm(e)
    y0 = math.cos(math.radians(60)) * sun + math.sin(math.radians(60)) * e
    q = _q(Rotation.align_vectors([y0], [[0.0, 0.0, 1.0]])[0])
    path = []
    for k in range(steps):
        out = g.step(0.1 * k, 0.1, q, np.zeros(3))
        q = _propagate(q, out.omega_cmd_BN_B, 0.1)
        path.append(_rot(q).apply([0.0, 0.0, 1.0]))
    return g, out, np.array(path), sun, e


def test_safe_mode_reaches_the_sun_safe_attitude_round_a_zone_on_its_way() -> None:
    """A zone on the SAFE slew's way: without keep-out SAFE would cross it (checked first, so the test can
    fail); SAFE with the zone goes round it and still ends with the Sun axis on the Sun."""
    _, _, _, sun, e = _safe_slew([], 1)
    mid = math.cos(math.radians(120)) * sun + math.sin(math.radians(120)) * e  # on the straight way
    zone = [{"name": "block", "body": "inertial", "direction_N": mid.tolist(),
             "geometry": {"shape": "cone", "half_angle_deg": 10.0}}]
    _, _, straight, _, _ = _safe_slew([], 3500)
    assert np.degrees(np.arccos(np.clip(straight @ mid, -1, 1))).min() < 10.0  # the old SAFE went through
    g, out, path, sun, _ = _safe_slew(zone, 5000)
    margin = np.degrees(np.arccos(np.clip(path @ mid, -1, 1))) - 10.0  # independent of the guidance's own
    assert margin.min() > 0.0
    assert out.mode == "SAFE" and out.safe_phase == "SUN_POINTING"
    assert math.degrees(math.acos(np.clip(path[-1] @ -sun, -1, 1))) < 1.0


def test_safe_aims_back_at_the_commanded_target_when_pointing_resumes() -> None:
    cfg = _cfg(initial_mode="POINTING", pointing={"target_N": [0.0, 0.6, 0.8]})
    g = Guidance(cfg)
    g.set_mode("SAFE")
    g.set_target_direction(np.array([0.0, 1.0, 0.0]))  # commanded during SAFE: held for POINTING
    g.set_mode("POINTING")
    np.testing.assert_allclose(g.target_N, [0.0, 1.0, 0.0])


def test_ephemeris_nodes_evaluated_in_blocks_are_each_node_s_own_numbers() -> None:
    """`SkyEphemeris._geocentric` evaluates the series for a block of nodes at once: every node, in any
    order of access (forwards as a run goes, backwards, jumps), is bit for bit the single evaluation."""
    from gnc.sky_ephemeris import EPHEMERIS_BLOCK_NODES, EPHEMERIS_NODE_S, SkyEphemeris
    from gnc.ephemeris import moon_position_N_km, sun_position_N_km

    rng = np.random.default_rng(17)
    for epoch in ("2026-04-25T12:00:00+00:00", "2030-03-29T12:00:00+00:00", "2035-11-02T03:17:00+00:00"):
        e = SkyEphemeris(_epoch_cfg(epoch, [MOON_CONE], [1.0, 0.0, 0.0]))
        nodes = list(range(-2, 3 * EPHEMERIS_BLOCK_NODES)) + list(range(40, 0, -1))
        nodes += [int(k) for k in rng.integers(-1000, 10**6, 40)]
        for k in nodes:
            for node in (k, k + 1):
                sun, moon = e._geocentric(node)
                jd = e.jd0 + node * EPHEMERIS_NODE_S / 86400.0
                assert np.array_equal(sun, np.asarray(sun_position_N_km(jd), dtype=float))
                assert np.array_equal(moon, np.asarray(moon_position_N_km(jd), dtype=float))
