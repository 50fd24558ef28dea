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
    from hil_sim.params import SpacecraftParams, WheelParams, WorldParams
    from hil_sim.world import World

    wheels = tuple(WheelParams(axis_B=tuple(G[:, i]), initial_speed_rad_s=initial_wheel_speed * (1 if i % 2 else -1))
                   for i in range(4))
    wp = WorldParams(spacecraft=SpacecraftParams(wheels=wheels))
    return World(wp, seed=0), wp


def _controller_for(wp, bandwidth: float):
    from closed_loop_kit import fsw_config_for

    cfg = fsw_config_for(wp, control={"rate_bandwidth_rad_s": bandwidth, "max_command_accel_deg_s2": 5.0})
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
    cfg = FswConfig(control={"max_command_accel_deg_s2": 1.0, "rate_bandwidth_rad_s": 1.0})
    ctrl = RateController(cfg)
    out1 = ctrl.step(0.1, np.radians([10.0, 0, 0]), np.zeros(3))
    assert math.degrees(np.linalg.norm(out1.omega_cmd_shaped_BN_B)) == pytest.approx(0.1)
    out2 = ctrl.step(0.1, np.radians([10.0, 0, 0]), out1.omega_cmd_shaped_BN_B)
    J = np.asarray(cfg.spacecraft.inertia_B_kgm2)
    # body rate equal to the (previous) shaped command: torque = J (kp * 0.1 deg/s + 1 deg/s^2) about x
    expected = J @ np.radians([1.0 * 0.1 + 1.0, 0, 0])
    np.testing.assert_allclose(out2.torque_cmd_B_Nm, expected, rtol=1e-9)


def _reference_step(ctrl: RateController, prev_cmd, dt, cmd, omega, speeds):
    """The numpy rate loop the compiled ``_rate_loop`` replaced (as it was), for comparison."""
    ws = np.asarray(speeds, dtype=float)
    wheel_speed = np.where(np.isfinite(ws), ws, ctrl.wheel_speed)
    prev = np.asarray(omega, dtype=float) if prev_cmd is None else prev_cmd
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
    return torque, tau, scale, shaped


@pytest.mark.parametrize("isolate", [None, 2])
def test_compiled_rate_loop_matches_the_numpy_reference(isolate) -> None:
    rng = np.random.default_rng(7)
    ctrl = RateController(FswConfig(control={"max_command_accel_deg_s2": 0.5}))
    if isolate is not None:
        assert ctrl.isolate(isolate)
    prev = None
    saturated = limited = 0
    for k in range(300):
        cmd = rng.normal(scale=0.05 if k % 3 else 2.0, size=3)
        omega = rng.normal(scale=0.05, size=3)
        speeds = rng.normal(scale=200.0, size=4)
        if k % 7 == 0:
            speeds[rng.integers(4)] = np.nan  # a missing wheel report keeps the last speed
        ref = _reference_step(ctrl, prev, 0.1, cmd, omega, speeds)
        out = ctrl.step(0.1, cmd, omega, speeds)
        np.testing.assert_allclose(out.torque_cmd_B_Nm, ref[0], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(out.wheel_torque_cmd_Nm, ref[1], rtol=1e-12, atol=1e-15)
        assert out.torque_scale == pytest.approx(ref[2], rel=1e-12)
        np.testing.assert_allclose(out.omega_cmd_shaped_BN_B, ref[3], rtol=1e-12, atol=1e-15)
        prev = ref[3]
        saturated += ref[2] < 1.0
        limited += not np.allclose(ref[3], cmd)
    assert saturated > 10 and limited > 10  # both limiters were exercised
    if isolate is not None:
        assert np.all(out.wheel_torque_cmd_Nm[isolate] == 0.0)
