"""Rate loop and wheel allocation: minimum norm, limits by scaling, isolation, tracking on the truth model."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import null_space

from fsw.config import FswConfig
from fsw.control import RateController, allocate_min_norm, allocation_matrix

S3 = 1 / math.sqrt(3)
G = np.array([[S3, S3, S3], [-S3, S3, S3], [-S3, -S3, S3], [S3, -S3, S3]]).T


def test_allocation_is_the_minimum_norm_solution() -> None:
    rng = np.random.default_rng(1)
    active = np.ones(4, dtype=bool)
    for _ in range(20):
        T = rng.normal(scale=0.01, size=3)
        tau, scale = allocate_min_norm(G, active, T, np.full(4, 1.0))
        assert scale == 1.0
        np.testing.assert_allclose(-G @ tau, T, atol=1e-12)  # the body feels -G tau
        # minimum norm <=> no component in the null space of G (independent: scipy null_space)
        assert abs(float((null_space(G).T @ tau)[0])) < 1e-12
        ref, *_ = np.linalg.lstsq(G, -T, rcond=None)
        np.testing.assert_allclose(tau, ref, atol=1e-12)


def test_torque_limits_scale_the_whole_vector() -> None:
    T = np.array([0.3, -0.1, 0.2])
    limits = np.array([0.05, 0.05, 0.05, 0.05])
    tau, scale = allocate_min_norm(G, np.ones(4, dtype=bool), T, limits)
    assert scale < 1.0
    assert np.max(np.abs(tau) / limits) == pytest.approx(1.0)
    body = -G @ tau
    np.testing.assert_allclose(body / np.linalg.norm(body), T / np.linalg.norm(T), atol=1e-12)  # direction kept


def test_isolated_wheel_gets_no_torque_and_the_rest_still_deliver() -> None:
    active = np.array([True, False, True, True])
    T = np.array([0.01, 0.02, -0.01])
    tau, _ = allocate_min_norm(G, active, T, np.ones(4), allocation_matrix(G, active))
    assert tau[1] == 0.0
    np.testing.assert_allclose(-G @ tau, T, atol=1e-12)


def test_isolation_refuses_to_lose_three_axis_control() -> None:
    cfg = FswConfig()
    ctrl = RateController(cfg)
    assert ctrl.isolate(0) and ctrl.isolated_mask == 0b1
    assert not ctrl.isolate(1)  # two pyramid wheels left would span only a plane
    assert ctrl.isolated_mask == 0b1


def _world(initial_wheel_speed: float = 0.0):
    from hil_sim.world.params import SpacecraftParams, WheelParams, WorldParams
    from hil_sim.world.world import World

    wheels = tuple(WheelParams(axis_B=tuple(G[:, i]), initial_speed_rad_s=initial_wheel_speed * (1 if i % 2 else -1))
                   for i in range(4))
    wp = WorldParams(spacecraft=SpacecraftParams(wheels=wheels))
    return World(wp, seed=0), wp


def _controller_for(wp, bandwidth: float):
    from closed_loop_kit import fsw_config_for

    # no jerk limit: these tests measure the loop's own bandwidth, not the command shaping
    cfg = fsw_config_for(wp, control={"rate_bandwidth_rad_s": bandwidth, "max_command_accel_deg_s2": 5.0,
                                      "max_command_jerk_deg_s3": 0.0})
    return RateController(cfg)


@pytest.mark.parametrize("wheel_speed", [0.0, 300.0])
def test_rate_loop_tracks_a_rate_command_on_the_truth_model(wheel_speed: float) -> None:
    """Closed loop on hil_sim truth (Basilisk-validated dynamics): the body rate converges to the
    command with the configured bandwidth, also with large stored wheel momentum (gyroscopic
    feed-forward: without it the coupling omega x h would leave a steady-state error)."""
    world, wp = _world(wheel_speed)
    ctrl = _controller_for(wp, bandwidth=1.0)
    cmd = np.radians([0.5, -0.3, 0.2])
    dt = 0.1
    errs = []
    for k in range(200):
        tr = world.truth
        out = ctrl.step(dt, cmd, tr.omega_BN_B, tr.wheel_speeds_rad_s)
        world.step(dt, out.wheel_torque_cmd_Nm)
        errs.append(np.linalg.norm(world.truth.omega_BN_B - cmd))
    assert errs[-1] < 1e-3 * np.linalg.norm(cmd)
    # first-order response: after the command ramp, the error decays about e-fold per 1/bandwidth
    assert errs[60] < errs[40] * math.exp(-1.0)


def test_command_slew_rate_limit_and_feed_forward() -> None:
    cfg = FswConfig(control={"max_command_accel_deg_s2": 1.0, "rate_bandwidth_rad_s": 1.0, "max_command_jerk_deg_s3": 0.0})
    ctrl = RateController(cfg)
    out1 = ctrl.step(0.1, np.radians([10.0, 0, 0]), np.zeros(3))
    assert math.degrees(np.linalg.norm(out1.omega_cmd_shaped_BN_B)) == pytest.approx(0.1)
    out2 = ctrl.step(0.1, np.radians([10.0, 0, 0]), out1.omega_cmd_shaped_BN_B)
    J = np.asarray(cfg.spacecraft.inertia_B_kgm2)
    # body rate equal to the (previous) shaped command: torque = J (kp * 0.1 deg/s + 1 deg/s^2) about x
    expected = J @ np.radians([1.0 * 0.1 + 1.0, 0, 0])
    np.testing.assert_allclose(out2.torque_cmd_B_Nm, expected, rtol=1e-9)


def _reference_step(ctrl: RateController, prev_cmd, prev_accel, dt, cmd, omega, speeds):
    """The rate loop in numpy, for comparison with the compiled ``_rate_loop``: returns
    (torque, tau, scale, shaped, acceleration of the shaped command)."""
    ws = np.asarray(speeds, dtype=float)
    wheel_speed = np.where(np.isfinite(ws), ws, ctrl.wheel_speed)
    prev = np.asarray(omega, dtype=float) if prev_cmd is None else prev_cmd
    if ctrl.max_jerk > 0.0:
        a_des = ctrl.kp * (cmd - prev)
        a_des *= min(1.0, ctrl.max_accel / max(float(np.linalg.norm(a_des)), 1e-300))
        da = a_des - prev_accel
        da *= min(1.0, ctrl.max_jerk * dt / max(float(np.linalg.norm(da)), 1e-300))
        step = (prev_accel + da) * dt
    else:
        step = cmd - prev
        max_step = ctrl.max_accel * dt
        norm = float(np.linalg.norm(step))
        if norm > max_step:
            step *= max_step / norm
    shaped = prev + step
    cmd_dot = step / dt if (ctrl.ff and prev_cmd is not None) else np.zeros(3)
    w = np.asarray(omega, dtype=float)
    h = ctrl.J @ w + ctrl.G @ (ctrl.Js * wheel_speed)
    torque = ctrl.J @ (ctrl.kp * (shaped - w) + cmd_dot) + np.cross(w, h)
    tau, scale = allocate_min_norm(ctrl.G, ctrl.active, torque, ctrl.max_torque, ctrl.M)
    return torque, tau, scale, shaped, step / dt


@pytest.mark.parametrize("isolate,jerk", [(None, 0.0), (2, 0.0), (None, "auto"), (2, 3.0)])
def test_compiled_rate_loop_matches_the_numpy_reference(isolate, jerk) -> None:
    rng = np.random.default_rng(7)
    ctrl = RateController(FswConfig(control={"max_command_accel_deg_s2": 0.5, "max_command_jerk_deg_s3": jerk}))
    if isolate is not None:
        assert ctrl.isolate(isolate)
    prev, accel = None, np.zeros(3)
    saturated = limited = 0
    for k in range(300):
        cmd = rng.normal(scale=0.05 if k % 3 else 2.0, size=3)
        omega = rng.normal(scale=0.05, size=3)
        speeds = rng.normal(scale=200.0, size=4)
        if k % 7 == 0:
            speeds[rng.integers(4)] = np.nan  # a missing wheel report keeps the last speed
        ref = _reference_step(ctrl, prev, accel, 0.1, cmd, omega, speeds)
        out = ctrl.step(0.1, cmd, omega, speeds)
        np.testing.assert_allclose(out.torque_cmd_B_Nm, ref[0], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(out.wheel_torque_cmd_Nm, ref[1], rtol=1e-12, atol=1e-15)
        assert out.torque_scale == pytest.approx(ref[2], rel=1e-12)
        np.testing.assert_allclose(out.omega_cmd_shaped_BN_B, ref[3], rtol=1e-12, atol=1e-15)
        prev, accel = ref[3], ref[4]
        saturated += ref[2] < 1.0
        limited += not np.allclose(ref[3], cmd)
    assert saturated > 10 and limited > 10  # both limiters were exercised
    if isolate is not None:
        assert np.all(out.wheel_torque_cmd_Nm[isolate] == 0.0)


def test_jerk_limit_bounds_the_torque_change_when_the_command_swings_every_cycle() -> None:
    """The law's command inside an eps-layer can swing by ten degrees of direction from one cycle to the
    next (the demo's Sun-zone passage). Without a jerk limit the shaped command's acceleration reverses
    every cycle and the feed-forward J omega_cmd_dot throws the torque from one side to the other; with
    the automatic limit (full acceleration in one loop time constant) the torque changes by at most
    J max_jerk dt plus the feedback's share, and the command is still followed on average."""
    rng = np.random.default_rng(3)
    base = np.radians([0.8, 0.6, 0.0])
    swing = [base + np.radians(0.17) * np.array([math.cos(a), math.sin(a), 0.0])
             for a in rng.uniform(-math.pi, math.pi, size=300)]
    tv, mean_rate = {}, {}
    for jerk in (0.0, "auto"):
        ctrl = RateController(FswConfig(control={"max_command_accel_deg_s2": 0.15, "rate_bandwidth_rad_s": 1.0,
                                                 "max_command_jerk_deg_s3": jerk}))
        omega, torques, rates = base.copy(), [], []
        for cmd in swing:
            out = ctrl.step(0.1, cmd, omega)
            omega = out.omega_cmd_shaped_BN_B  # perfect tracking of the shaped command
            torques.append(out.torque_cmd_B_Nm)
            rates.append(omega)
        steps = np.linalg.norm(np.diff(torques[10:], axis=0), axis=1)
        tv[jerk], mean_rate[jerk] = float(steps.sum()), np.mean(rates[50:], axis=0)
        if jerk == "auto":
            J = np.asarray(ctrl.J)
            bound = np.linalg.norm(J, 2) * (ctrl.max_jerk * 0.1 + ctrl.kp * ctrl.max_accel * 0.1)
            assert steps.max() <= bound * (1 + 1e-9)
    assert tv["auto"] < 0.2 * tv[0.0], tv
    np.testing.assert_allclose(mean_rate["auto"], np.mean(swing[50:], axis=0), atol=math.radians(0.03))
