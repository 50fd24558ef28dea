"""Basilisk 2.12.1 reference for solar radiation pressure on a facet model: facetSRPDynamicEffector with the
eclipse module's shadow factor. Writes

* srp_reference_torques.csv: 600 geometries (attitude, a position on a 550 km sphere, some in the Earth's
  shadow; the Sun 1 AU away along a fixed direction), each with Basilisk's shadow factor and the effector's
  torque and force in body axes, from computeForceTorque called on the hub's states set to that geometry;
* srp_reference.csv: a rigid spacecraft (no wheels) in a circular 550 km orbit through the Earth's shadow
  for one orbit, with point-mass gravity and the SRP effector alone (RK4, 0.1 s), sampled every 5 s: time,
  q (the Euler parameters of sigma_BN, scalar first, sign-continuous), omega_BN_B, r_N [m], shadow factor;
* srp_reference.json: every input (facets, inertia, orbit, Sun, Basilisk's constants) and the provenance.

Run it where Basilisk is installed (`pip install bsk==2.12.1`):

    python tests/data/basilisk/srp_reference.py
"""
from __future__ import annotations

import csv
import datetime
import json
import math
from pathlib import Path

import numpy as np
from Basilisk import __version__ as bsk_version
from Basilisk.architecture import astroConstants, messaging
from Basilisk.simulation import eclipse, facetSRPDynamicEffector, spacecraft
from Basilisk.utilities import RigidBodyKinematics as rbk
from Basilisk.utilities import SimulationBaseClass, macros, orbitalMotion, simHelpers, simIncludeGravBody

HERE = Path(__file__).resolve().parent
AU_M = 149_597_870_700.0
SUN_DIR = np.array([0.6, -0.7, 0.3]) / np.linalg.norm([0.6, -0.7, 0.3])
INERTIA = [[12.0, 0.3, -0.2], [0.3, 15.0, 0.25], [-0.2, 0.25, 8.0]]
SIGMA0 = [0.1, -0.2, 0.25]
OMEGA0 = [0.0005, -0.0003, 0.0004]
# the orbit plane contains the Sun direction (noon-midnight: the normal [sin O sin i, -cos O sin i, cos i] is
# orthogonal to SUN_DIR): the spacecraft crosses the middle of the shadow
ORBIT = {"altitude_km": 550.0, "eccentricity": 0.0, "inclination_deg": 97.6, "raan_deg": 313.0897,
         "arg_perigee_deg": 0.0, "true_anomaly_deg": 20.0}
# a 0.3 x 0.3 x 0.6 m bus (centre of mass 5 cm off its middle) and one solar panel on +y, sun side +z
FACETS = [
    {"area_m2": 0.18, "normal_B": [1, 0, 0], "centre_of_pressure_B_m": [0.15, 0.0, 0.05], "specular": 0.1, "diffuse": 0.3},
    {"area_m2": 0.18, "normal_B": [-1, 0, 0], "centre_of_pressure_B_m": [-0.15, 0.0, 0.05], "specular": 0.1, "diffuse": 0.3},
    {"area_m2": 0.18, "normal_B": [0, 1, 0], "centre_of_pressure_B_m": [0.0, 0.15, 0.05], "specular": 0.2, "diffuse": 0.2},
    {"area_m2": 0.18, "normal_B": [0, -1, 0], "centre_of_pressure_B_m": [0.0, -0.15, 0.05], "specular": 0.2, "diffuse": 0.2},
    {"area_m2": 0.09, "normal_B": [0, 0, 1], "centre_of_pressure_B_m": [0.0, 0.0, 0.35], "specular": 0.0, "diffuse": 0.5},
    {"area_m2": 0.09, "normal_B": [0, 0, -1], "centre_of_pressure_B_m": [0.0, 0.0, -0.25], "specular": 0.0, "diffuse": 0.5},
    {"area_m2": 0.6, "normal_B": [0, 0, 1], "centre_of_pressure_B_m": [0.0, 0.65, 0.0], "specular": 0.05, "diffuse": 0.1},
    {"area_m2": 0.6, "normal_B": [0, 0, -1], "centre_of_pressure_B_m": [0.0, 0.65, 0.0], "specular": 0.6, "diffuse": 0.1},
]
STEP_S = 0.1
DURATION_S = 5740.0
SAMPLE_S = 5.0
N_GEOMETRIES = 600


def _add_facets(srp) -> None:
    srp.setNumFacets(len(FACETS))
    srp.setNumArticulatedFacets(0)
    for f in FACETS:
        # the facet frame is the body frame: nHat_F is the body normal
        srp.addFacet(f["area_m2"], np.eye(3).tolist(), f["normal_B"], [0.0, 0.0, 1.0], f["centre_of_pressure_B_m"],
                     f["diffuse"], f["specular"])


def base_sim():
    """A Basilisk simulation with the rigid spacecraft (RK4, STEP_S) about a point-mass Earth."""
    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("dyn")
    proc.addTask(sim.CreateNewTask("task", macros.sec2nano(STEP_S)))
    sc = spacecraft.Spacecraft()  # RK4
    sc.ModelTag = "env-sat"
    sc.hub.mHub = 50.0
    sc.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    sc.hub.IHubPntBc_B = simHelpers.np2EigenMatrix3d(np.asarray(INERTIA).flatten().tolist())
    sim.AddModelToTask("task", sc, 10)
    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()
    earth.isCentralBody = True
    grav.addBodiesTo(sc)
    return sim, sc, earth, grav


def _sim():
    sim, sc, earth, grav = base_sim()
    sun = messaging.SpicePlanetStateMsgPayload()
    sun.PositionVector = (AU_M * SUN_DIR).tolist()
    sun.PlanetName = "sun"
    earth_state = messaging.SpicePlanetStateMsgPayload()
    earth_state.PositionVector = [0.0, 0.0, 0.0]
    earth_state.PlanetName = "earth"
    sun_msg = messaging.SpicePlanetStateMsg().write(sun)
    earth_msg = messaging.SpicePlanetStateMsg().write(earth_state)
    shadow = eclipse.Eclipse()
    shadow.ModelTag = "eclipse"
    shadow.sunInMsg.subscribeTo(sun_msg)
    shadow.addPlanetToModel(earth_msg)
    shadow.addSpacecraftToModel(sc.scStateOutMsg)
    sim.AddModelToTask("task", shadow, 20)
    srp = facetSRPDynamicEffector.FacetSRPDynamicEffector()
    srp.ModelTag = "srp"
    _add_facets(srp)
    srp.sunInMsg.subscribeTo(sun_msg)
    srp.sunEclipseInMsg.subscribeTo(shadow.eclipseOutMsgs[0])
    sc.addDynamicEffector(srp)
    sim.AddModelToTask("task", srp, 5)
    keep = (sun_msg, earth_msg, grav)  # the messages must outlive the simulation
    return sim, sc, srp, shadow, earth, keep


def torque_table() -> list[list[float]]:
    sim, sc, srp, shadow, earth, keep = _sim()
    sc.hub.r_CN_NInit = [[earth.radEquator + 550e3], [0.0], [0.0]]
    sc.hub.v_CN_NInit = [[0.0], [7.6e3], [0.0]]
    sim.InitializeSimulation()
    sigma_state = sc.dynManager.getStateObject(sc.hub.nameOfHubSigma)
    r_state = sc.dynManager.getStateObject(sc.hub.nameOfHubPosition)
    rng = np.random.default_rng(20261129)
    rows = []
    radius_m = earth.radEquator + 550e3
    for k in range(N_GEOMETRIES):
        sigma = rng.uniform(-1.0, 1.0, 3)
        sigma *= rng.uniform(0.0, 1.0) / np.linalg.norm(sigma)
        u = rng.normal(size=3)
        if k % 3 == 0:  # a third of the cases across the shadow's edge (umbra, penumbra, full Sun)
            side = u - (u @ SUN_DIR) * SUN_DIR
            side /= np.linalg.norm(side)
            th = math.asin(earth.radEquator / radius_m) + rng.uniform(-0.015, 0.015)  # from the anti-Sun line
            u = -math.cos(th) * SUN_DIR + math.sin(th) * side
        r_m = radius_m * u / np.linalg.norm(u)
        sigma_state.setState([[x] for x in sigma])
        r_state.setState([[x] for x in r_m])
        sc_state = messaging.SCStatesMsgPayload()
        sc_state.r_BN_N = r_m.tolist()
        shadow_msg = messaging.SCStatesMsg().write(sc_state)
        table_shadow = eclipse.Eclipse()
        table_shadow.sunInMsg.subscribeTo(keep[0])
        table_shadow.addPlanetToModel(keep[1])
        table_shadow.addSpacecraftToModel(shadow_msg)
        table_shadow.Reset(0)
        table_shadow.UpdateState(0)
        factor = table_shadow.eclipseOutMsgs[0].read().shadowFactor
        srp.sunEclipseInMsg.subscribeTo(table_shadow.eclipseOutMsgs[0])
        srp.computeForceTorque(0.0, STEP_S)
        q = np.asarray(rbk.MRP2EP(sigma))
        rows.append([*q, *(r_m / 1e3), *(AU_M * SUN_DIR / 1e3), factor,
                     *np.asarray(srp.torqueExternalPntB_B).ravel(), *np.asarray(srp.forceExternal_B).ravel()])
    return rows


def initial_state(sc, earth) -> None:
    """The trajectory's initial orbit (ORBIT) and attitude (SIGMA0, OMEGA0)."""
    oe = orbitalMotion.ClassicElements()
    oe.a = earth.radEquator + ORBIT["altitude_km"] * 1e3
    oe.e = ORBIT["eccentricity"]
    oe.i = ORBIT["inclination_deg"] * macros.D2R
    oe.Omega = ORBIT["raan_deg"] * macros.D2R
    oe.omega = ORBIT["arg_perigee_deg"] * macros.D2R
    oe.f = ORBIT["true_anomaly_deg"] * macros.D2R
    r_N, v_N = orbitalMotion.elem2rv(earth.mu, oe)
    sc.hub.r_CN_NInit, sc.hub.v_CN_NInit = r_N, v_N
    sc.hub.sigma_BNInit = [[x] for x in SIGMA0]
    sc.hub.omega_BN_BInit = [[x] for x in OMEGA0]


def sign_continuous_q(sigma_log) -> list[np.ndarray]:
    """The Euler parameters of each logged sigma_BN, scalar first, signs kept continuous."""
    out, q_prev = [], None
    for sigma in sigma_log:
        q = np.asarray(rbk.MRP2EP(sigma))
        if q_prev is not None and q @ q_prev < 0:
            q = -q
        out.append(q)
        q_prev = q
    return out


def fly(sim, sc, earth, extra: tuple = ()) -> tuple[list[list[float]], dict]:
    """One orbit from initial_state(): rows of t, q, omega_BN_B, r_N [m] every SAMPLE_S, then one column per
    (message, field) of ``extra``; and the Earth's mu and radius."""
    initial_state(sc, earth)
    state_log = sc.scStateOutMsg.recorder(macros.sec2nano(SAMPLE_S))
    logs = [message.recorder(macros.sec2nano(SAMPLE_S)) for message, _ in extra]
    for log in (state_log, *logs):
        sim.AddModelToTask("task", log)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(DURATION_S))
    sim.ExecuteSimulation()
    t = state_log.times() * macros.NANO2SEC
    rows = [[t[k], *q, *state_log.omega_BN_B[k], *state_log.r_BN_N[k],
             *(getattr(log, field)[k] for log, (_, field) in zip(logs, extra))]
            for k, q in enumerate(sign_continuous_q(state_log.sigma_BN))]
    return rows, {"earth_mu_m3_s2": earth.mu, "earth_radius_m": earth.radEquator}


TRAJECTORY_HEADER = ["t_s", "q0", "q1", "q2", "q3", "wx", "wy", "wz", "r_x_m", "r_y_m", "r_z_m"]


def write_csv(name: str, header: list[str], rows: list[list[float]]) -> None:
    with open(HERE / name, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(header)
        out.writerows([[repr(float(v)) for v in row] for row in rows])


def provenance(generator: str, modules: str) -> dict:
    """The JSON's common part: where the data came from and the spacecraft, orbit and integrator."""
    return {"basilisk": bsk_version, "generator": f"tests/data/basilisk/{generator}",
            "generated_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"), "modules": modules,
            "inertia_B_kgm2": INERTIA, "sigma_BN0": SIGMA0, "omega_BN_B0_rad_s": OMEGA0, "orbit": ORBIT,
            "integrator": f"RK4, {STEP_S} s", "duration_s": DURATION_S, "sample_s": SAMPLE_S,
            "frames": "q is the Euler parameter set of sigma_BN (scalar first), the same four numbers as keepout's "
                      "q_NB; vectors in body axes but the field (N); r_N in metres (trajectory) or km (table)"}


def main() -> None:
    write_csv("srp_reference_torques.csv", ["q0", "q1", "q2", "q3", "r_x_km", "r_y_km", "r_z_km", "sun_x_km",
                                            "sun_y_km", "sun_z_km", "shadow_factor", "tau_x", "tau_y", "tau_z",
                                            "f_x", "f_y", "f_z"], torque_table())
    sim, sc, srp, shadow, earth, keep = _sim()
    rows, earth_constants = fly(sim, sc, earth, ((shadow.eclipseOutMsgs[0], "shadowFactor"),))
    write_csv("srp_reference.csv", TRAJECTORY_HEADER + ["shadow_factor"], rows)
    (HERE / "srp_reference.json").write_text(json.dumps({
        **provenance("srp_reference.py", "Spacecraft hub (rigid, no wheels), point-mass Earth gravity, "
                     "facetSRPDynamicEffector (sunInMsg, sunEclipseInMsg from the eclipse module)"),
        "solar_flux_W_m2": 1368.0, "speed_of_light_m_s": 299792458.0, "au_m": AU_M,
        "note": "facetSRPDynamicEffector.cpp's constants (solarRadFlux 1368 W/m^2, speedLight, AstU)",
        "facets": FACETS, "mass_kg": 50.0, **earth_constants, "sun_N_km": (AU_M * SUN_DIR / 1e3).tolist(),
        "earth_radius_km_eclipse": astroConstants.REQ_EARTH, "sun_radius_km_eclipse": astroConstants.REQ_SUN,
    }, indent=1) + "\n")


if __name__ == "__main__":
    main()
