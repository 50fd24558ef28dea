"""Rigid body + reaction wheels: Basilisk reference, conventions, conservation laws, wheel limits, failures."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gnc.attitude import attitude_error_angle, quat_to_dcm
from hil_sim.world.params import DisturbanceParams, SpacecraftParams, WheelParams, WorldParams
from hil_sim.world.world import World, WorldBatch

REF_DIR = Path(__file__).resolve().parents[1] / "data" / "basilisk"  # provenance: its README.md


@pytest.fixture(scope="module")
def reference():
    inputs = json.loads((REF_DIR / "rw_reference_inputs.json").read_text())
    with open(REF_DIR / "rw_reference.csv") as f:
        rows = list(csv.DictReader(f))
    table = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    return inputs, table


def _unlimited_wheel(axis, Js, speed0=0.0, **kw) -> WheelParams:
    return WheelParams(axis_B=tuple(axis), Js_kgm2=Js, max_torque_Nm=1e9, max_speed_rad_s=1e9,
                       initial_speed_rad_s=speed0, **kw)


def _reference_world(inputs) -> World:
    wheels = tuple(_unlimited_wheel(g, js, om) for g, js, om in
                   zip(inputs["wheel_spin_axes_B"], inputs["wheel_Js_kgm2"], inputs["Omega0_rad_s"]))
    sc = SpacecraftParams(inertia_B_kgm2=tuple(map(tuple, inputs["I_hub_B_kgm2"])), wheels=wheels,
                          q_NB0=tuple(inputs["q_BN0"]), omega_BN_B0_rad_s=tuple(inputs["omega_BN_B0_rad_s"]))
    return World(WorldParams(spacecraft=sc, max_integration_step_s=0.01), seed=0)


def _torque_profile(inputs, t: float) -> np.ndarray:
    """The reference's zero-order-held torque formula f_i(t), written from the JSON text."""
    p = inputs["torque_profile"]
    A, PA, phi = np.array(p["A_Nm"]), np.array(p["PA_s"]), np.array(p["phiA_rad"])
    Bc, PB = np.array(p["B_Nm"]), np.array(p["PB_s"])
    if t < 100.0:
        return A * np.sin(2 * np.pi * t / PA + phi)
    if t < 200.0:
        return Bc * np.cos(2 * np.pi * t / PB)
    return np.zeros(4)


def test_basilisk_reference_run_matches(reference):
    inputs, ref = reference
    world = _reference_world(inputs)
    n_rows = ref["t"].size
    att_err = np.zeros(n_rows)
    rate_err = np.zeros(n_rows)
    wheel_err = np.zeros(n_rows)
    for k in range(n_rows):
        t_k = 0.1 * k
        assert world.t == pytest.approx(ref["t"][k], abs=1e-9)
        truth = world.truth
        q_ref = np.array([ref[f"q{i}"][k] for i in range(4)])
        att_err[k] = attitude_error_angle(truth.q_NB, q_ref)
        rate_err[k] = np.abs(truth.omega_BN_B - np.array([ref[c][k] for c in ("omega_x", "omega_y", "omega_z")])).max()
        wheel_err[k] = np.abs(truth.wheel_speeds_rad_s - np.array([ref[f"Omega{i}"][k] for i in range(1, 5)])).max()
        u = _torque_profile(inputs, t_k)
        # our transcription of the formula equals the torque Basilisk applied on [t_k, t_k + 0.1)
        np.testing.assert_allclose(u, [ref[f"u{i}"][k] for i in range(1, 5)], rtol=0, atol=1e-15)
        if k < n_rows - 1:
            world.step(0.1, u)  # 10 RK4 sub-steps of 0.01 s, command held: Basilisk's setup
    assert att_err.max() < 1e-9, f"max attitude error {att_err.max():.3e} rad"
    assert rate_err.max() < 1e-10, f"max body-rate error {rate_err.max():.3e} rad/s"
    assert wheel_err.max() < 1e-8, f"max wheel-speed error {wheel_err.max():.3e} rad/s"


def test_basilisk_quaternion_convention_equals_project_convention(reference):
    """Basilisk's q_BN numbers (with [BN] mapping N vectors into B) are the Hamilton q_NB of DESIGN.md."""
    _, ref = reference
    for k in range(0, ref["t"].size, 250):
        q = np.array([ref[f"q{i}"][k] for i in range(4)])
        q0, qv = q[0], q[1:]
        skew = np.array([[0, -qv[2], qv[1]], [qv[2], 0, -qv[0]], [-qv[1], qv[0], 0]])
        BN = (q0**2 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) - 2 * q0 * skew  # the JSON's formula
        # the same attitude from Basilisk's MRP column (independent parametrisation)
        s = np.array([ref[f"sigma{i}"][k] for i in range(1, 4)])
        S = np.array([[0, -s[2], s[1]], [s[2], 0, -s[0]], [-s[1], s[0], 0]])
        BN_mrp = np.eye(3) + (8 * S @ S - 4 * (1 - s @ s) * S) / (1 + s @ s) ** 2
        np.testing.assert_allclose(BN, BN_mrp, atol=1e-12)
        R_NB = quat_to_dcm(q)  # project: v_N = R_NB v_B
        np.testing.assert_allclose(R_NB, BN.T, atol=1e-14)
        # scipy's scalar-last active rotation matrix of the same numbers maps body into inertial
        np.testing.assert_allclose(Rotation.from_quat(np.r_[qv, q0]).as_matrix(), BN.T, atol=1e-14)


def _random_spacecraft(rng, friction: bool) -> SpacecraftParams:
    axes = rng.normal(size=(5, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    wheels = tuple(WheelParams(axis_B=tuple(a), Js_kgm2=float(rng.uniform(0.03, 0.08)), max_torque_Nm=0.2,
                               max_speed_rad_s=600.0, initial_speed_rad_s=float(rng.uniform(-300, 300)),
                               viscous_friction_Nm_per_rad_s=1e-5 if friction else 0.0,
                               coulomb_friction_Nm=2e-3 if friction else 0.0) for a in axes)
    L = rng.normal(size=(3, 3))
    inertia = np.diag([12.0, 15.0, 9.0]) + 0.5 * (L + L.T)
    return SpacecraftParams(inertia_B_kgm2=tuple(map(tuple, inertia)), wheels=wheels,
                            omega_BN_B0_rad_s=tuple(rng.uniform(-0.05, 0.05, 3)))


@pytest.mark.parametrize("friction", [False, True])
def test_inertial_angular_momentum_conserved(friction):
    """Wheel torques and friction are internal: H_N = R_NB (I w + sum Js Omega g) must stay constant."""
    rng = np.random.default_rng(7)
    world = World(WorldParams(spacecraft=_random_spacecraft(rng, friction)), seed=1)
    H0 = world.angular_momentum_N()
    worst = 0.0
    for k in range(600):  # 60 s with commands changing every 0.1 s, some saturating
        world.step(0.1, rng.uniform(-0.3, 0.3, world.n_wheels))
        worst = max(worst, np.linalg.norm(world.angular_momentum_N() - H0) / np.linalg.norm(H0))
    assert worst < 1e-12, f"relative |H_N - H_N(0)| reached {worst:.2e}"


def test_energy_conserved_without_torque_and_dissipated_by_friction():
    from hil_sim.world.dynamics import rotational_energy

    rng = np.random.default_rng(3)
    for friction in (False, True):
        world = World(WorldParams(spacecraft=_random_spacecraft(rng, friction)), seed=1)
        b = world.batch
        energies = [rotational_energy(b.X, b.G, b.W, b.B)[0]]
        for _ in range(200):
            world.step(0.1, np.zeros(world.n_wheels))
            energies.append(rotational_energy(b.X, b.G, b.W, b.B)[0])
        energies = np.array(energies)
        if friction:
            assert np.all(np.diff(energies) < 0.0) and energies[-1] < 0.99 * energies[0]
        else:
            assert np.abs(energies / energies[0] - 1).max() < 1e-12


def _single_wheel_world(**wheel_kw) -> World:
    """Huge hub, one wheel on body z, so the body barely moves and the wheel's motion is analytic."""
    wheel = WheelParams(axis_B=(0.0, 0.0, 1.0), Js_kgm2=0.05, **wheel_kw)
    sc = SpacecraftParams(inertia_B_kgm2=((1e9, 0, 0), (0, 1e9, 0), (0, 0, 1e9)), wheels=(wheel,))
    return World(WorldParams(spacecraft=sc), seed=0)


def _wheel_axial_momentum(world: World) -> float:
    """Js (g.omega + Omega): changes only by the net internal torque on the rotor."""
    t = world.truth
    return 0.05 * (t.omega_BN_B[2] + t.wheel_speeds_rad_s[0])


def test_torque_saturation_applies_the_limit():
    world = _single_wheel_world(max_torque_Nm=0.1)
    h0 = _wheel_axial_momentum(world)
    for _ in range(100):
        world.step(0.01, [0.5])
    status = world.wheel_status()[0]
    assert status.torque_Nm == 0.1 and status.fault & 8
    assert _wheel_axial_momentum(world) - h0 == pytest.approx(0.1 * 1.0, rel=1e-12)
    assert status.current_A == pytest.approx(0.1 / 0.03)


def test_speed_limit_cuts_accelerating_torque_only():
    world = _single_wheel_world(max_torque_Nm=0.2, max_speed_rad_s=100.0, initial_speed_rad_s=99.9)
    for _ in range(200):
        world.step(0.01, [0.2])
    speed = world.truth.wheel_speeds_rad_s[0]
    # one 10 ms step of 0.2 N m on Js 0.05 adds 0.04 rad/s: the wheel stops within one step past the limit
    assert 100.0 <= speed < 100.0 + 0.2 * 0.01 / 0.05 + 1e-9
    assert world.wheel_status()[0].torque_Nm == 0.0 and world.wheel_status()[0].fault & 4
    world.step(0.01, [-0.2])  # decelerating torque is allowed
    assert world.wheel_status()[0].torque_Nm == -0.2
    assert world.truth.wheel_speeds_rad_s[0] < speed


def test_viscous_friction_spin_down_matches_exponential():
    c, Js, w0 = 2e-4, 0.05, 300.0
    world = _single_wheel_world(viscous_friction_Nm_per_rad_s=c, initial_speed_rad_s=w0)
    for _ in range(1000):
        world.step(0.01, [0.0])
    assert world.truth.wheel_speeds_rad_s[0] == pytest.approx(w0 * math.exp(-c / Js * 10.0), rel=1e-6)


def test_coulomb_friction_decelerates_linearly_away_from_zero():
    tc, Js, w0 = 1e-3, 0.05, 100.0
    world = _single_wheel_world(coulomb_friction_Nm=tc, initial_speed_rad_s=w0)
    for _ in range(1000):
        world.step(0.01, [0.0])
    # tanh(100/0.05) = 1 to double precision: constant deceleration tc/Js
    assert world.truth.wheel_speeds_rad_s[0] == pytest.approx(w0 - tc / Js * 10.0, rel=1e-9)


def test_no_torque_failure_ignores_commands():
    world = _single_wheel_world(initial_speed_rad_s=50.0, failure="no_torque")
    h0 = _wheel_axial_momentum(world)
    for _ in range(100):
        world.step(0.01, [0.1])
    assert _wheel_axial_momentum(world) == pytest.approx(h0, rel=1e-14)
    assert world.wheel_status()[0].torque_Nm == 0.0 and world.wheel_status()[0].fault & 2


def test_stuck_wheel_hands_momentum_to_hub_and_stays_locked():
    rng = np.random.default_rng(11)
    world = World(WorldParams(spacecraft=_random_spacecraft(rng, friction=False)), seed=0)
    H0 = world.angular_momentum_N()
    world.set_wheel_failure(2, "stuck")
    assert world.truth.wheel_speeds_rad_s[2] == 0.0
    # the seizure itself is an exact momentum transfer
    assert np.linalg.norm(world.angular_momentum_N() - H0) / np.linalg.norm(H0) < 1e-14
    for _ in range(100):
        world.step(0.1, rng.uniform(-0.2, 0.2, world.n_wheels))
    assert world.truth.wheel_speeds_rad_s[2] == 0.0
    assert world.wheel_status()[2].fault & 1
    # the hub now tumbles at ~1 rad/s, where RK4 at 10 ms drifts ~1e-9 relative over 10 s
    assert np.linalg.norm(world.angular_momentum_N() - H0) / np.linalg.norm(H0) < 1e-8


def test_constant_disturbance_spins_up_principal_axis_analytically():
    sc = SpacecraftParams(inertia_B_kgm2=((10, 0, 0), (0, 20, 0), (0, 0, 30)), wheels=(),
                          disturbance=DisturbanceParams(constant_B_Nm=(0.0, 0.0, 3e-3)))
    world = World(WorldParams(spacecraft=sc), seed=0)
    for _ in range(1000):
        world.step(0.01, np.zeros(0))
    t = world.truth
    assert t.omega_BN_B[2] == pytest.approx(3e-3 / 30 * 10.0, rel=1e-12)
    angle = 0.5 * 3e-3 / 30 * 10.0**2  # rotation about z by 1/2 alpha t^2
    expected = Rotation.from_rotvec([0, 0, angle])
    q = t.q_NB
    assert (Rotation.from_quat(np.r_[q[1:], q[0]]) * expected.inv()).magnitude() < 1e-12


def test_random_disturbance_has_configured_stationary_std():
    sc = SpacecraftParams(wheels=(), disturbance=DisturbanceParams(random_std_Nm=1e-4, random_correlation_time_s=0.5))
    world = World(WorldParams(spacecraft=sc), seed=5)
    samples = []
    for k in range(20000):
        world.step(0.01, np.zeros(0))
        if k % 100 == 0:  # 1 s apart = 2 correlation times: nearly independent
            samples.append(world.truth.disturbance_B_Nm)
    samples = np.array(samples[5:])
    std = samples.std(axis=0)
    # 195 samples x 3 axes, correlation exp(-2) between neighbours: 15 % is > 4 sigma of the estimator
    np.testing.assert_allclose(std, 1e-4, rtol=0.15)


def test_batch_equals_individual_worlds():
    rng = np.random.default_rng(21)
    params = [WorldParams(spacecraft=_random_spacecraft(rng, friction=True)) for _ in range(3)]
    batch = WorldBatch(params, seed=0)
    singles = [World(p, seed=0) for p in params]
    cmds = rng.uniform(-0.3, 0.3, (50, 3, 5))
    for k in range(50):
        batch.step(0.1, cmds[k])
        for m, w in enumerate(singles):
            w.step(0.1, cmds[k, m])
    for m, w in enumerate(singles):
        np.testing.assert_array_equal(batch.X[:, m], w.batch.X[:, 0])


def test_bad_inputs_raise_clear_errors():
    world = World(WorldParams(), seed=0)
    with pytest.raises(ValueError, match="wheel_torque_cmd_Nm"):
        world.step(0.01, [0.0, 0.0])
    with pytest.raises(ValueError, match="finite"):
        world.step(0.01, [0.0, float("nan"), 0.0, 0.0])
    with pytest.raises(ValueError, match="mode"):
        world.set_wheel_failure(0, "exploded")
    with pytest.raises(ValueError, match="axis_B"):
        WheelParams(axis_B=(1.0, 1.0, 0.0))
    with pytest.raises(ValueError, match="positive definite"):
        SpacecraftParams(inertia_B_kgm2=((0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01)))


def test_winding_temperature_follows_first_order_thermal_model():
    """dT/dt = (i^2 R - (T - T_amb) / R_th) / C_th with i = u / k_t: after one time constant R_th C_th the rise
    is (1 - 1/e) of i^2 R R_th."""
    world = _single_wheel_world(max_torque_Nm=0.1, max_speed_rad_s=1e6, motor_constant_Nm_per_A=0.05,
                                winding_resistance_ohm=1.5, thermal_resistance_K_per_W=2.0,
                                thermal_capacity_J_per_K=50.0, ambient_temp_C=10.0)
    for _ in range(1000):  # tau = 100 s
        world.step(0.1, [0.1])
    rise = (0.1 / 0.05) ** 2 * 1.5 * 2.0
    assert world.wheel_status()[0].temp_C == pytest.approx(10.0 + rise * (1 - math.exp(-1.0)), rel=1e-6)
