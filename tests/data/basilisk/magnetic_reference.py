"""Basilisk 2.12.1 reference for a residual magnetic dipole in the Earth's field: magneticFieldCenteredDipole
(the Gauss coefficients g10, g11, h11 of IGRF-14 at EPOCH, from hil_sim.world.geomagnetic, recorded in the JSON)
and MtbEffector (three rods along the body axes holding the dipole: torque m x B). The spacecraft and the
orbit are srp_reference.py's (imported from beside this file). Writes

* magnetic_reference_torques.csv: 600 geometries (attitude, a position on a 550 km sphere, the Earth turned by
  a random angle about z), each with Basilisk's field in N and the effector's torque in body axes, from
  computeForceTorque on the hub's states set to that geometry;
* magnetic_reference.csv: the rigid spacecraft for one orbit with point-mass gravity and the dipole torque
  alone (RK4, 0.1 s; the Earth not turning: J20002Pfix the identity), sampled every 5 s: time, q (Euler
  parameters of sigma_BN, scalar first), omega_BN_B, r_N [m];
* magnetic_reference.json: every input and the provenance.

    python tests/data/basilisk/magnetic_reference.py     # with Basilisk (pip install bsk==2.12.1) and keepout
"""
from __future__ import annotations

import datetime
import json
import math
from pathlib import Path

import numpy as np
from Basilisk.architecture import messaging
from Basilisk.simulation import MtbEffector, magneticFieldCenteredDipole
from Basilisk.utilities import RigidBodyKinematics as rbk

from hil_sim.world.geomagnetic import IGRF_REFERENCE_RADIUS_KM, dipole_coefficients_T
from srp_reference import N_GEOMETRIES, STEP_S, TRAJECTORY_HEADER, base_sim, fly, provenance, write_csv

HERE = Path(__file__).resolve().parent
EPOCH = datetime.datetime(2026, 4, 25, 12, 0, tzinfo=datetime.timezone.utc)
RESIDUAL_DIPOLE_B_AM2 = [0.8, -0.5, 1.2]


def _earth_message(theta_rad: float):
    """The Earth at the origin, turned by theta about z (J20002Pfix maps N vectors into the Earth-fixed frame)."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    state = messaging.SpicePlanetStateMsgPayload()
    state.PositionVector = [0.0, 0.0, 0.0]
    state.J20002Pfix = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
    state.PlanetName = "earth"
    return messaging.SpicePlanetStateMsg().write(state)


def _field_module(g10: float, g11: float, h11: float, earth_msg, sc_msg):
    field = magneticFieldCenteredDipole.MagneticFieldCenteredDipole()
    field.ModelTag = "magfield"
    field.g10, field.g11, field.h11 = g10, g11, h11
    field.planetRadius = IGRF_REFERENCE_RADIUS_KM * 1e3
    field.planetPosInMsg.subscribeTo(earth_msg)
    field.addSpacecraftToModel(sc_msg)
    return field


def _sim(coefficients):
    sim, sc, earth, grav = base_sim()
    earth_msg = _earth_message(0.0)
    field = _field_module(*coefficients, earth_msg, sc.scStateOutMsg)
    sim.AddModelToTask("task", field, 20)
    config = messaging.MTBArrayConfigMsgPayload()
    config.numMTB = 3
    config.GtMatrix_B = np.eye(3).flatten().tolist()  # rod i along body axis i
    config.maxMtbDipoles = [1e4, 1e4, 1e4]
    config_msg = messaging.MTBArrayConfigMsg().write(config)
    command = messaging.MTBCmdMsgPayload()
    command.mtbDipoleCmds = RESIDUAL_DIPOLE_B_AM2
    command_msg = messaging.MTBCmdMsg().write(command)
    mtb = MtbEffector.MtbEffector()
    mtb.ModelTag = "dipole"
    mtb.mtbCmdInMsg.subscribeTo(command_msg)
    mtb.mtbParamsInMsg.subscribeTo(config_msg)
    mtb.magInMsg.subscribeTo(field.envOutMsgs[0])
    sc.addDynamicEffector(mtb)
    sim.AddModelToTask("task", mtb, 5)
    return sim, sc, mtb, earth, (grav, earth_msg, field, config_msg, command_msg)


def torque_table(coefficients) -> list[list[float]]:
    sim, sc, mtb, earth, keep = _sim(coefficients)
    radius_m = earth.radEquator + 550e3
    sc.hub.r_CN_NInit = [[radius_m], [0.0], [0.0]]
    sc.hub.v_CN_NInit = [[0.0], [7.6e3], [0.0]]
    sim.InitializeSimulation()
    sigma_state = sc.dynManager.getStateObject(sc.hub.nameOfHubSigma)
    rng = np.random.default_rng(20261129)
    rows = []
    for _ in range(N_GEOMETRIES):
        sigma = rng.uniform(-1.0, 1.0, 3)
        sigma *= rng.uniform(0.0, 1.0) / np.linalg.norm(sigma)
        u = rng.normal(size=3)
        r_m = radius_m * u / np.linalg.norm(u)
        theta = rng.uniform(0.0, 2.0 * math.pi)
        sigma_state.setState([[x] for x in sigma])
        state = messaging.SCStatesMsgPayload()
        state.r_BN_N = r_m.tolist()
        state_msg = messaging.SCStatesMsg().write(state)
        earth_msg = _earth_message(theta)
        field = _field_module(*coefficients, earth_msg, state_msg)
        field.Reset(0)
        field.UpdateState(0)
        mtb.magInMsg.subscribeTo(field.envOutMsgs[0])
        mtb.computeForceTorque(0.0, STEP_S)
        q = np.asarray(rbk.MRP2EP(sigma))
        rows.append([*q, *(r_m / 1e3), theta, *field.envOutMsgs[0].read().magField_N,
                     *np.asarray(mtb.torqueExternalPntB_B).ravel()])
    return rows


def main() -> None:
    coefficients = dipole_coefficients_T(EPOCH)  # (g10, g11, h11) [T]
    write_csv("magnetic_reference_torques.csv", ["q0", "q1", "q2", "q3", "r_x_km", "r_y_km", "r_z_km", "theta_rad",
                                                 "b_x_T", "b_y_T", "b_z_T", "tau_x", "tau_y", "tau_z"],
              torque_table(coefficients))
    sim, sc, mtb, earth, keep = _sim(coefficients)
    rows, earth_constants = fly(sim, sc, earth)
    write_csv("magnetic_reference.csv", TRAJECTORY_HEADER, rows)
    (HERE / "magnetic_reference.json").write_text(json.dumps({
        **provenance("magnetic_reference.py", "Spacecraft hub (rigid, no wheels), point-mass Earth gravity, "
                     "magneticFieldCenteredDipole (planetPosInMsg: the Earth turned by theta), MtbEffector (three "
                     "rods along the body axes)"),
        "epoch_utc": EPOCH.isoformat(), "g10_T": coefficients[0], "g11_T": coefficients[1],
        "h11_T": coefficients[2], "coefficients_from": "IGRF-14 via ppigrf (hil_sim.world.geomagnetic)",
        "planet_radius_m": IGRF_REFERENCE_RADIUS_KM * 1e3, "residual_dipole_B_Am2": RESIDUAL_DIPOLE_B_AM2,
        **earth_constants,
    }, indent=1) + "\n")


if __name__ == "__main__":
    main()
