"""Basilisk 2.12.1 reference for the gravity-gradient torque: a rigid spacecraft (no wheels) tumbling slowly in
a circular 550 km orbit for one orbit, with Basilisk's GravityGradientEffector on. Writes gg_reference.csv
(1 Hz: time, q_BN scalar-first, omega_BN_B, the effector's torque in body axes, r_N) and gg_reference.json
(every input). Run it where Basilisk is installed (`pip install bsk==2.12.1`):

    python tests/data/basilisk/gg_reference.py
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
from Basilisk.simulation import GravityGradientEffector, spacecraft
from Basilisk.utilities import RigidBodyKinematics as rbk
from Basilisk.utilities import SimulationBaseClass, macros, orbitalMotion, simHelpers, simIncludeGravBody

HERE = Path(__file__).resolve().parent
INERTIA = [[15.0, 0.5, -0.3], [0.5, 22.0, 0.4], [-0.3, 0.4, 9.0]]
SIGMA0 = [0.1, -0.2, 0.25]
OMEGA0 = [0.001, -0.0005, 0.0008]
ORBIT = {"altitude_km": 550.0, "eccentricity": 0.0, "inclination_deg": 97.6, "raan_deg": 30.0, "arg_perigee_deg": 0.0,
         "true_anomaly_deg": 40.0}
STEP_S = 0.1
DURATION_S = 5740.0  # about one orbit
SAMPLE_S = 5.0


def main() -> None:
    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("dyn")
    proc.addTask(sim.CreateNewTask("task", macros.sec2nano(STEP_S)))
    sc = spacecraft.Spacecraft()  # RK4
    sc.ModelTag = "gg-sat"
    sc.hub.mHub = 50.0
    sc.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    sc.hub.IHubPntBc_B = simHelpers.np2EigenMatrix3d(np.asarray(INERTIA).flatten().tolist())
    sim.AddModelToTask("task", sc, 2)
    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()
    earth.isCentralBody = True
    grav.addBodiesTo(sc)
    gg = GravityGradientEffector.GravityGradientEffector()
    gg.ModelTag = sc.ModelTag
    gg.addPlanetName(earth.planetName)
    sc.addDynamicEffector(gg)
    sim.AddModelToTask("task", gg, 1)

    oe = orbitalMotion.ClassicElements()
    oe.a = (earth.radEquator + ORBIT["altitude_km"] * 1e3)
    oe.e = ORBIT["eccentricity"]
    oe.i = ORBIT["inclination_deg"] * macros.D2R
    oe.Omega = ORBIT["raan_deg"] * macros.D2R
    oe.omega = ORBIT["arg_perigee_deg"] * macros.D2R
    oe.f = ORBIT["true_anomaly_deg"] * macros.D2R
    r_N, v_N = orbitalMotion.elem2rv(earth.mu, oe)
    sc.hub.r_CN_NInit, sc.hub.v_CN_NInit = r_N, v_N
    sc.hub.sigma_BNInit = [[x] for x in SIGMA0]
    sc.hub.omega_BN_BInit = [[x] for x in OMEGA0]

    state_log = sc.scStateOutMsg.recorder(macros.sec2nano(SAMPLE_S))
    gg_log = gg.gravityGradientOutMsg.recorder(macros.sec2nano(SAMPLE_S))
    sim.AddModelToTask("task", state_log)
    sim.AddModelToTask("task", gg_log)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(DURATION_S))
    sim.ExecuteSimulation()

    t = state_log.times() * macros.NANO2SEC
    rows = []
    q_prev = None
    for k in range(len(t)):
        q = np.asarray(rbk.MRP2EP(state_log.sigma_BN[k]))
        if q_prev is not None and q @ q_prev < 0:
            q = -q  # sign-continuous
        q_prev = q
        rows.append([t[k], *q, *state_log.omega_BN_B[k], *gg_log.gravityGradientTorque_B[k], *state_log.r_BN_N[k]])
    with open(HERE / "gg_reference.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t_s", "q0", "q1", "q2", "q3", "wx", "wy", "wz", "tau_x", "tau_y", "tau_z", "r_x_m", "r_y_m",
                    "r_z_m"])
        w.writerows([[f"{v:.17g}" for v in row] for row in rows])
    (HERE / "gg_reference.json").write_text(json.dumps({
        "generator": "gg_reference.py (Basilisk 2.12.1)",
        "inertia_B_kgm2": INERTIA, "mass_kg": 50.0, "sigma_BN0": SIGMA0, "omega_BN_B0_rad_s": OMEGA0,
        "orbit": ORBIT, "earth_mu_m3_s2": earth.mu, "earth_radius_m": earth.radEquator,
        "integrator": f"RK4, {STEP_S} s", "duration_s": DURATION_S, "sample_s": SAMPLE_S,
        "models": "Spacecraft hub (rigid, no wheels), point-mass Earth gravity, GravityGradientEffector (Earth)",
        "frames": "q is the Euler parameter set of sigma_BN (scalar first), the same four numbers as keepout's "
                  "q_NB (see rw_reference_inputs.json); omega_BN_B and the torque in body axes; r_N in metres",
    }, indent=1) + "\n")


if __name__ == "__main__":
    main()
