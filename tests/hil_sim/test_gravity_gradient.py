"""The gravity-gradient torque (spacecraft.disturbance.gravity_gradient) against Basilisk 2.12.1's
GravityGradientEffector: a rigid spacecraft tumbling slowly for one 550 km orbit (tests/data/basilisk/
gg_reference.py wrote the reference; its inputs are in gg_reference.json). Off, nothing changes."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from gnc.attitude import attitude_error_angle
from hil_sim.world.params import DisturbanceParams, OrbitParams, SpacecraftParams, WheelParams, WorldParams
from hil_sim.world.world import World

DATA = Path(__file__).resolve().parents[1] / "data" / "basilisk"


@pytest.fixture(scope="module")
def reference():
    inputs = json.loads((DATA / "gg_reference.json").read_text())
    with open(DATA / "gg_reference.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return inputs, {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def _mrp_to_q(sigma) -> tuple[float, float, float, float]:
    s = np.asarray(sigma, dtype=float)
    s2 = float(s @ s)
    return ((1 - s2) / (1 + s2), *(2 * s / (1 + s2)))


def _world(inputs, gravity_gradient: bool) -> World:
    orbit = inputs["orbit"]
    # a wheel of negligible spin inertia that is never commanded: the reference has none
    wheel = WheelParams(axis_B=(1.0, 0.0, 0.0), Js_kgm2=1e-12, max_torque_Nm=1e-9, max_speed_rad_s=1e3,
                        viscous_friction_Nm_per_rad_s=0.0, coulomb_friction_Nm=0.0)
    sc = SpacecraftParams(inertia_B_kgm2=tuple(map(tuple, inputs["inertia_B_kgm2"])), wheels=(wheel,),
                          disturbance=DisturbanceParams(gravity_gradient=gravity_gradient),
                          q_NB0=_mrp_to_q(inputs["sigma_BN0"]), omega_BN_B0_rad_s=tuple(inputs["omega_BN_B0_rad_s"]))
    # circular: the true anomaly is the mean anomaly
    op = OrbitParams(semi_major_axis_km=inputs["earth_radius_m"] / 1e3 + orbit["altitude_km"],
                     eccentricity=0.0, inclination_deg=orbit["inclination_deg"], raan_deg=orbit["raan_deg"],
                     arg_perigee_deg=orbit["arg_perigee_deg"], mean_anomaly_deg=orbit["true_anomaly_deg"],
                     mu_km3_s2=inputs["earth_mu_m3_s2"] / 1e9)
    return World(WorldParams(spacecraft=sc, orbit=op, max_integration_step_s=0.01), seed=0)


def test_gravity_gradient_matches_basilisk_over_an_orbit(reference) -> None:
    inputs, ref = reference
    world = _world(inputs, gravity_gradient=True)
    step = float(inputs["sample_s"])
    att_err, rate_err, pos_err = [], [], []
    for k in range(ref["t_s"].size):
        assert world.t == pytest.approx(ref["t_s"][k], abs=1e-6)
        q_ref = np.array([ref[f"q{i}"][k] for i in range(4)])
        att_err.append(attitude_error_angle(world.truth.q_NB, q_ref))
        rate_err.append(np.abs(world.truth.omega_BN_B - [ref["wx"][k], ref["wy"][k], ref["wz"][k]]).max())
        r_ref_km = np.array([ref["r_x_m"][k], ref["r_y_m"][k], ref["r_z_m"][k]]) / 1e3
        pos_err.append(np.linalg.norm(world.truth.r_sc_N_km - r_ref_km))
        if k < ref["t_s"].size - 1:
            world.step(step, np.zeros(1))
    # the orbit: Kepler here, Basilisk's RK4 of point-mass gravity there
    assert max(pos_err) < 1e-3, f"orbit position differs by {max(pos_err):.3e} km"
    # the same model, evaluated at every RK4 stage on both sides: agreement to the integrators' accuracy
    # (measured 2026-11-29: 4.8e-13 rad and 1.0e-15 rad/s after one orbit)
    assert max(att_err) < 1e-10, f"max attitude error {max(att_err):.3e} rad"
    assert max(rate_err) < 1e-13, f"max body-rate error {max(rate_err):.3e} rad/s"
    # and the effect is there to see: without it the attitude is off by far more
    plain = _world(inputs, gravity_gradient=False)
    plain.step(float(ref["t_s"][-1]), np.zeros(1))
    q_end = np.array([ref[f"q{i}"][-1] for i in range(4)])
    assert attitude_error_angle(plain.truth.q_NB, q_end) > 1e3 * max(att_err)


def test_the_torque_is_three_mu_over_r_cubed_u_cross_i_u(reference) -> None:
    """The torque at the reference's first sample, written out by hand, equals Basilisk's."""
    inputs, ref = reference
    J = np.asarray(inputs["inertia_B_kgm2"])
    q = np.array([ref[f"q{i}"][0] for i in range(4)])
    r_N = np.array([ref["r_x_m"][0], ref["r_y_m"][0], ref["r_z_m"][0]])
    q0, qv = q[0], q[1:]
    R = (q0 * q0 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) + 2 * q0 * np.array(
        [[0, -qv[2], qv[1]], [qv[2], 0, -qv[0]], [-qv[1], qv[0], 0]])  # body -> N
    u = R.T @ (r_N / np.linalg.norm(r_N))
    tau = 3 * inputs["earth_mu_m3_s2"] / np.linalg.norm(r_N) ** 3 * np.cross(u, J @ u)
    np.testing.assert_allclose(tau, [ref["tau_x"][0], ref["tau_y"][0], ref["tau_z"][0]], rtol=1e-9)
