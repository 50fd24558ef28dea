"""Basilisk 2.12.1 reference for aerodynamic drag on a facet model: facetDragDynamicEffector with the
exponentialAtmosphere's density and the zeroWindModel's co-rotating air. The spacecraft, its facets and the
orbit are srp_reference.py's (imported from beside this file), each facet with a drag coefficient. Writes

* drag_reference_torques.csv: 600 geometries (attitude, a position on a 550 km sphere, a circular-orbit
  velocity across it in a random direction), each with Basilisk's density, air velocity and the effector's
  torque and force in body axes, from computeForceTorque on the hub's states set to that geometry;
* drag_reference.csv / drag_reference_still.csv: the rigid spacecraft for one orbit with point-mass gravity
  and the drag effector alone (RK4, 0.1 s), sampled every 5 s, with the co-rotating air and with still air
  (no wind message): time, q (Euler parameters of sigma_BN, scalar first), omega_BN_B, r_N [m];
* drag_reference.json: every input and the provenance.

    python tests/data/basilisk/drag_reference.py     # where Basilisk is installed (pip install bsk==2.12.1)
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from Basilisk.architecture import messaging
from Basilisk.simulation import exponentialAtmosphere, facetDragDynamicEffector, zeroWindModel
from Basilisk.utilities import RigidBodyKinematics as rbk

from srp_reference import (FACETS, N_GEOMETRIES, STEP_S, TRAJECTORY_HEADER, base_sim, fly, provenance,
                           write_csv)

HERE = Path(__file__).resolve().parent
DRAG_COEFFICIENTS = [2.2, 2.2, 2.1, 2.1, 2.3, 2.3, 2.0, 2.0]  # one per facet of FACETS
# the atmosphere: rho = rho_ref exp(-(h - h_ref) / H) above a sphere of PLANET_RADIUS_M (keepout's WGS-84
# equatorial radius); Basilisk's baseDensity is the same law's density at h = 0
RHO_REF_KG_M3, H_REF_KM, SCALE_HEIGHT_KM = 6.967e-13, 500.0, 63.822
PLANET_RADIUS_M = 6_378_137.0
OMEGA_EARTH_RAD_S = 7.292115e-5
MASS_KG = 5e9


def _sim(wind: bool):
    sim, sc, earth, grav = base_sim()
    # a hub so heavy that the drag force leaves the orbit Keplerian, as keepout's truth orbit is (with 50 kg the
    # orbit would sink ~4 m in one orbit and the density rise ~6e-5); the rotation does not depend on the mass
    sc.hub.mHub = MASS_KG
    atmo = exponentialAtmosphere.ExponentialAtmosphere()
    atmo.ModelTag = "atmosphere"
    atmo.planetRadius = PLANET_RADIUS_M
    atmo.scaleHeight = SCALE_HEIGHT_KM * 1e3
    atmo.baseDensity = RHO_REF_KG_M3 * math.exp(H_REF_KM / SCALE_HEIGHT_KM)
    atmo.addSpacecraftToModel(sc.scStateOutMsg)
    sim.AddModelToTask("task", atmo, 20)
    drag = facetDragDynamicEffector.FacetDragDynamicEffector()
    drag.ModelTag = "drag"
    for f, cd in zip(FACETS, DRAG_COEFFICIENTS):
        drag.addFacet(f["area_m2"], cd, f["normal_B"], f["centre_of_pressure_B_m"])
    drag.atmoDensInMsg.subscribeTo(atmo.envOutMsgs[0])
    air = None
    earth_state = messaging.SpicePlanetStateMsgPayload()
    earth_state.PositionVector = [0.0, 0.0, 0.0]
    earth_state.J20002Pfix = np.eye(3).tolist()
    earth_state.PlanetName = "earth"
    earth_msg = messaging.SpicePlanetStateMsg().write(earth_state)
    if wind:
        air = zeroWindModel.ZeroWindModel()
        air.ModelTag = "wind"
        air.planetPosInMsg.subscribeTo(earth_msg)
        air.setPlanetOmega_N([0.0, 0.0, OMEGA_EARTH_RAD_S])
        air.addSpacecraftToModel(sc.scStateOutMsg)
        sim.AddModelToTask("task", air, 20)
        drag.windVelInMsg.subscribeTo(air.envOutMsgs[0])
    sc.addDynamicEffector(drag)
    sim.AddModelToTask("task", drag, 5)
    return sim, sc, drag, atmo, air, earth, (grav, earth_msg)


def torque_table() -> list[list[float]]:
    sim, sc, drag, atmo, air, earth, keep = _sim(wind=True)
    radius_m = earth.radEquator + 550e3
    sc.hub.r_CN_NInit = [[radius_m], [0.0], [0.0]]
    sc.hub.v_CN_NInit = [[0.0], [7.6e3], [0.0]]
    sim.InitializeSimulation()
    sigma_state = sc.dynManager.getStateObject(sc.hub.nameOfHubSigma)
    r_state = sc.dynManager.getStateObject(sc.hub.nameOfHubPosition)
    v_state = sc.dynManager.getStateObject(sc.hub.nameOfHubVelocity)
    rng = np.random.default_rng(20261129)
    rows = []
    speed = math.sqrt(earth.mu / radius_m)
    for _ in range(N_GEOMETRIES):
        sigma = rng.uniform(-1.0, 1.0, 3)
        sigma *= rng.uniform(0.0, 1.0) / np.linalg.norm(sigma)
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        w = rng.normal(size=3)
        w -= (w @ u) * u
        r_m, v_m_s = radius_m * u, speed * w / np.linalg.norm(w)
        sigma_state.setState([[x] for x in sigma])
        r_state.setState([[x] for x in r_m])
        v_state.setState([[x] for x in v_m_s])
        state = messaging.SCStatesMsgPayload()
        state.r_BN_N, state.v_BN_N = r_m.tolist(), v_m_s.tolist()
        state_msg = messaging.SCStatesMsg().write(state)
        # the atmosphere and the wind at this geometry, as their modules compute them at a task step
        atmo_here, air_here = exponentialAtmosphere.ExponentialAtmosphere(), zeroWindModel.ZeroWindModel()
        atmo_here.planetRadius, atmo_here.scaleHeight, atmo_here.baseDensity = (atmo.planetRadius, atmo.scaleHeight,
                                                                                atmo.baseDensity)
        air_here.setPlanetOmega_N([0.0, 0.0, OMEGA_EARTH_RAD_S])
        air_here.planetPosInMsg.subscribeTo(keep[1])
        for module in (atmo_here, air_here):
            module.addSpacecraftToModel(state_msg)
            module.Reset(0)
            module.UpdateState(0)
        drag.atmoDensInMsg.subscribeTo(atmo_here.envOutMsgs[0])
        drag.windVelInMsg.subscribeTo(air_here.envOutMsgs[0])
        drag.ReadInputs()
        drag.computeForceTorque(0.0, STEP_S)
        q = np.asarray(rbk.MRP2EP(sigma))
        rows.append([*q, *(r_m / 1e3), *(v_m_s / 1e3), atmo_here.envOutMsgs[0].read().neutralDensity,
                     *air_here.envOutMsgs[0].read().v_air_N, *np.asarray(drag.torqueExternalPntB_B).ravel(),
                     *np.asarray(drag.forceExternal_B).ravel()])
    return rows


def main() -> None:
    write_csv("drag_reference_torques.csv", ["q0", "q1", "q2", "q3", "r_x_km", "r_y_km", "r_z_km", "v_x_km_s",
                                             "v_y_km_s", "v_z_km_s", "density_kg_m3", "v_air_x_m_s", "v_air_y_m_s",
                                             "v_air_z_m_s", "tau_x", "tau_y", "tau_z", "f_x", "f_y", "f_z"],
              torque_table())
    for name, wind in (("drag_reference.csv", True), ("drag_reference_still.csv", False)):
        sim, sc, drag, atmo, air, earth, keep = _sim(wind)
        rows, earth_constants = fly(sim, sc, earth)
        write_csv(name, TRAJECTORY_HEADER, rows)
    (HERE / "drag_reference.json").write_text(json.dumps({
        **provenance("drag_reference.py", "Spacecraft hub (rigid, no wheels), point-mass Earth gravity, "
                     "facetDragDynamicEffector (atmoDensInMsg from exponentialAtmosphere, windVelInMsg from "
                     "zeroWindModel)"),
        "facets": [{**f, "drag_coefficient": cd} for f, cd in zip(FACETS, DRAG_COEFFICIENTS)],
        "reference_density_kg_m3": RHO_REF_KG_M3, "reference_altitude_km": H_REF_KM,
        "scale_height_km": SCALE_HEIGHT_KM, "planet_radius_m": PLANET_RADIUS_M,
        "earth_rotation_rad_s": OMEGA_EARTH_RAD_S, "mass_kg": MASS_KG, **earth_constants,
    }, indent=1) + "\n")


if __name__ == "__main__":
    main()
