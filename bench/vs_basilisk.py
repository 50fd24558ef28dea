"""keepout's closed loop against Basilisk's, on one core, in one run: simulated seconds per wall second.

    .venv/bin/pip install -e '.[bench]'        # Basilisk (PyPI package `bsk`)
    .venv/bin/python bench/vs_basilisk.py [--duration 120] [--repeat 5] [--cpu 0] [--rows wheels environment]

Both loops fly the same spacecraft (the inertia and the four wheels of config/missions/demo-pointing.yaml) for
the same simulated time, alternated (keepout, Basilisk, keepout, ... over every row) in this one process pinned
to one core, so both see the same host load; the table gives medians and the ratio keepout / Basilisk (goal
>= 1.0), per row:

* ``wheels``: the loops below as they are (keepout's truth: a constant torque).
* ``environment``: both on a 550 km Sun-synchronous orbit with every environment torque on, the same on both
  sides: gravity gradient, solar radiation pressure and drag on the same eight facets (the same exponential
  atmosphere, air turning with the Earth), the same residual dipole in the same centred-dipole field (IGRF-14's
  degree 1 at the epoch), the constant torque (ENV_* below; Basilisk's modules in _basilisk_environment).

* keepout: one ``fast`` campaign run (``hil_sim.campaign.fast.run_fast``) of demo-pointing: the real flight
  software (MEKF, constrained guidance over moving Sun/Moon zones, rate control, FDIR, telemetry) at 10 Hz,
  every sample and command as an E2E-protected ICD frame on a virtual CAN bus, the world at 100 Hz (RK4,
  wheels, sensors, Sun/Moon/Earth), judged on truth at the end. Timed from the call to its result: set-up,
  loop and judging, as a campaign run pays them.
* Basilisk (the AVS Lab's scenarioAttitudeFeedbackRW, two rates): a 100 Hz task with the spacecraft hub (RK4,
  Earth point-mass gravity), the reaction-wheel state effector and simpleNav; a 10 Hz FSW task with inertial3D,
  attTrackingError, mrpFeedback and rwMotorTorque, regulating to a fixed inertial attitude (no slews, no
  keep-out). Timed from building the simulation to the end of ``ExecuteSimulation``; the environment row's
  Sun position and field coefficients are computed before (environment_inputs), keepout's inside its run.

Writes bench/results/vs_basilisk.json with the host load. Without Basilisk it says so in one line and exits 0.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

from _results import write_result  # bench/_results.py: this script's folder is on sys.path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MISSION = ROOT / "config" / "missions" / "demo-pointing.yaml"
GNC_RATE_HZ, DYNAMICS_RATE_HZ = 10.0, 100.0
ROWS = ("wheels", "environment")  # the loops as they stand, then with every environment torque on both sides
# what each side computes, per row (table and JSON)
PER_STEP = {
    "wheels": {"keepout": "100 Hz: RK4 rigid body + 4 wheels (friction), IMU, star tracker, Sun/Moon/Earth, constant "
                          "torque; 10 Hz: the full flight software (MEKF, keep-out guidance over Sun/Moon zones, rate "
                          "control, FDIR, telemetry), every sample and command an E2E-protected ICD frame",
               "basilisk": "100 Hz: spacecraft hub (RK4, point-mass Earth) + RW state effector + simpleNav; 10 Hz: "
                           "inertial3D, attTrackingError, mrpFeedback, rwMotorTorque"},
    "environment": {"keepout": "as the wheels row, plus at every RK4 stage gravity gradient, SRP on 8 facets (conical "
                               "shadow), drag on 8 facets (exponential atmosphere, co-rotating air), residual dipole "
                               "in a centred dipole field turning with the Earth; the Sun from the ephemeris each step",
                    "basilisk": "as the wheels row, plus GravityGradientEffector, facetSRPDynamicEffector + eclipse, "
                                "facetDragDynamicEffector + exponentialAtmosphere + zeroWindModel, "
                                "magneticFieldCenteredDipole + MtbEffector, extForceTorque; Sun and Earth messages "
                                "written once"},
}

# The environment row's changes to demo-pointing: a 550 km Sun-synchronous orbit (the flight software's orbit
# knowledge follows it), the telescope's outer surfaces (a 1.2 x 1.2 x 2.0 m bus, centre of mass 5 cm below
# its middle, and a 3 m^2 solar panel on +y, sun side +z) and every environment torque on. The solar flux is
# Basilisk's facetSRPDynamicEffector constant (1368 W/m^2); the atmosphere is keepout's default, the same law
# as Basilisk's exponentialAtmosphere.
ENV_ALTITUDE_KM, ENV_INCLINATION_DEG = 550.0, 97.6
BUS_HALF_M, CM_OFFSET_B_M = (0.6, 0.6, 1.0), (0.0, 0.0, 0.05)  # the bus's half sizes, its middle from the CM
BUS_OPTICS = ((0.1, 0.3), (0.2, 0.2), (0.0, 0.5))  # (specular, diffuse) of the faces across x, y, z
ENV_FACETS = [  # the bus's six faces (drag coefficient 2.2, the default), then the panel's two sides
    {"area_m2": 4.0 * BUS_HALF_M[(k + 1) % 3] * BUS_HALF_M[(k + 2) % 3],
     "normal_B": [sign * (i == k) for i in range(3)],
     "centre_of_pressure_B_m": [sign * BUS_HALF_M[i] * (i == k) + CM_OFFSET_B_M[i] for i in range(3)],
     "specular": BUS_OPTICS[k][0], "diffuse": BUS_OPTICS[k][1]} for k in range(3) for sign in (1, -1)
] + [{"area_m2": 3.0, "normal_B": [0, 0, sign], "centre_of_pressure_B_m": [0.0, 1.6, 0.0], "specular": specular,
      "diffuse": 0.1, "drag_coefficient": 2.0} for sign, specular in ((1, 0.05), (-1, 0.6))]
ENV_DISTURBANCE = {"gravity_gradient": True, "solar_radiation_pressure": True, "solar_flux_W_m2": 1368.0,
                   "aerodynamic_drag": True, "residual_dipole_B_Am2": [0.5, -0.3, 0.8]}


def demo_mission(duration_s: float, row: str = "wheels"):
    """demo-pointing for ``duration_s``, as written (row "wheels") or with the environment row's changes."""
    import yaml
    from gnc.ephemeris import EARTH_RADIUS_KM
    from hil_sim.mission.model import load_mission
    data = yaml.safe_load(MISSION.read_text())
    if row == "environment":
        data["orbit"] = {"semi_major_axis_km": EARTH_RADIUS_KM + ENV_ALTITUDE_KM,
                         "inclination_deg": ENV_INCLINATION_DEG, "raan_deg": 40.0}
        del data["flight_software"]["orbit"]  # then taken from the truth orbit
        data["spacecraft"]["facets"] = ENV_FACETS
        data["spacecraft"]["disturbance"].update(ENV_DISTURBANCE)
    # the duration after validation: a short warm-up run ends before the timeline's last command
    return load_mission(MISSION, text=yaml.safe_dump(data)).model_copy(update={"duration_s": duration_s})


def run_keepout(mission) -> float:
    """Wall seconds of one fast-mode closed-loop run of ``mission``."""
    from hil_sim.campaign.fast import run_fast
    t0 = time.perf_counter()
    result = run_fast(mission, 1, "fast", [])
    wall = time.perf_counter() - t0
    if abs(result.sim_time_s - mission.duration_s) > 0.2:
        raise RuntimeError(f"keepout flew {result.sim_time_s} s of {mission.duration_s}")
    return wall


def environment_inputs(mission) -> tuple:
    """What Basilisk's environment modules are given rather than compute (so not timed on its side): the Sun's
    position [m] from keepout's ephemeris at the epoch, the Earth rotation angle at the epoch and the Earth's
    dipole (g10, g11, h11) [T] of IGRF-14 at the epoch, keepout's own."""
    from gnc.ephemeris import julian_date_tdb, sun_position_N_km
    from hil_sim.world.geomagnetic import dipole_coefficients_T, earth_rotation_angle_rad
    sun_m = [1e3 * float(x) for x in sun_position_N_km(julian_date_tdb(mission.epoch_utc))]
    return sun_m, earth_rotation_angle_rad(mission.epoch_utc), dipole_coefficients_T(mission.epoch_utc)


def _basilisk_environment(sim, sc, earth, mission, inputs) -> tuple:
    """Basilisk's side of the environment row, as tests/data/basilisk/*_reference.py set it up, on the 100 Hz
    task: GravityGradientEffector; facetSRPDynamicEffector with the eclipse module's shadow; facetDragDynamicEffector
    with exponentialAtmosphere and zeroWindModel; magneticFieldCenteredDipole and an MtbEffector holding the
    residual dipole; extForceTorque for the constant torque. The Sun and the Earth are messages written once
    (the Sun where keepout's ephemeris puts it at the epoch, the Earth turned by the rotation angle at the epoch
    and held). Returns what must outlive the run (the messages) and the effectors."""
    import numpy as np
    from Basilisk.architecture import messaging
    from Basilisk.simulation import (GravityGradientEffector, MtbEffector, extForceTorque, facetDragDynamicEffector,
                                     facetSRPDynamicEffector)

    d, facets = mission.spacecraft.disturbance, mission.spacecraft.facets

    def effector(module, tag: str):
        module.ModelTag = tag
        sim.AddModelToTask("dynTask", module, 0)  # after the environment modules and the hub
        sc.addDynamicEffector(module)
        return module

    shadow, atmo, air, field, messages = _basilisk_surroundings(sim, sc, d, inputs)
    gg = effector(GravityGradientEffector.GravityGradientEffector(), sc.ModelTag)
    gg.addPlanetName(earth.planetName)
    srp = effector(facetSRPDynamicEffector.FacetSRPDynamicEffector(), "srp")
    srp.setNumFacets(len(facets))
    srp.setNumArticulatedFacets(0)
    drag = effector(facetDragDynamicEffector.FacetDragDynamicEffector(), "drag")
    for f in facets:  # the facet frame is the body frame
        srp.addFacet(f.area_m2, np.eye(3).tolist(), f.normal_B, [0.0, 0.0, 1.0], f.centre_of_pressure_B_m,
                     f.diffuse, f.specular)
        drag.addFacet(f.area_m2, f.drag_coefficient, f.normal_B, f.centre_of_pressure_B_m)
    srp.sunInMsg.subscribeTo(messages[0])
    srp.sunEclipseInMsg.subscribeTo(shadow.eclipseOutMsgs[0])
    drag.atmoDensInMsg.subscribeTo(atmo.envOutMsgs[0])
    drag.windVelInMsg.subscribeTo(air.envOutMsgs[0])
    config = messaging.MTBArrayConfigMsgPayload()
    config.numMTB = 3
    config.GtMatrix_B = np.eye(3).flatten().tolist()  # rod i along body axis i
    config.maxMtbDipoles = [1e4, 1e4, 1e4]
    command = messaging.MTBCmdMsgPayload()
    command.mtbDipoleCmds = list(d.residual_dipole_B_Am2)
    config_msg, command_msg = messaging.MTBArrayConfigMsg().write(config), messaging.MTBCmdMsg().write(command)
    mtb = effector(MtbEffector.MtbEffector(), "dipole")
    mtb.mtbCmdInMsg.subscribeTo(command_msg)
    mtb.mtbParamsInMsg.subscribeTo(config_msg)
    mtb.magInMsg.subscribeTo(field.envOutMsgs[0])
    constant = effector(extForceTorque.ExtForceTorque(), "constant")
    constant.extTorquePntB_B = [[x] for x in d.constant_B_Nm]
    return (*messages, config_msg, command_msg, gg, srp, drag, mtb, constant)


def _basilisk_surroundings(sim, sc, disturbance, inputs) -> tuple:
    """The environment modules the effectors read, run before the hub (priority 3 > the wheels' 2 > the hub's
    1): eclipse, exponentialAtmosphere, zeroWindModel and magneticFieldCenteredDipole on the spacecraft's state,
    and the Sun and Earth messages (inputs: environment_inputs()) they need."""
    import math
    from Basilisk.architecture import messaging
    from Basilisk.simulation import eclipse, exponentialAtmosphere, magneticFieldCenteredDipole, zeroWindModel
    from gnc.ephemeris import EARTH_RADIUS_KM
    from hil_sim.world.environment import EARTH_ROTATION_RAD_S
    from hil_sim.world.geomagnetic import IGRF_REFERENCE_RADIUS_KM

    sun_m, era, (g10, g11, h11) = inputs
    d = disturbance

    def planet(name: str, position_m: list[float], theta: float = 0.0):
        state = messaging.SpicePlanetStateMsgPayload()
        state.PositionVector, state.PlanetName = position_m, name
        c, s = math.cos(theta), math.sin(theta)
        state.J20002Pfix = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
        return messaging.SpicePlanetStateMsg().write(state)

    def around(module, tag: str):
        module.ModelTag = tag
        sim.AddModelToTask("dynTask", module, 3)
        module.addSpacecraftToModel(sc.scStateOutMsg)
        return module

    sun_msg, earth_msg = planet("sun", sun_m), planet("earth", [0.0, 0.0, 0.0], era)
    shadow = around(eclipse.Eclipse(), "eclipse")
    shadow.sunInMsg.subscribeTo(sun_msg)
    shadow.addPlanetToModel(earth_msg)
    atmo = around(exponentialAtmosphere.ExponentialAtmosphere(), "atmosphere")
    atmo.planetRadius = EARTH_RADIUS_KM * 1e3
    atmo.scaleHeight = d.atmosphere_scale_height_km * 1e3
    atmo.baseDensity = d.atmosphere_density_kg_m3 * math.exp(d.atmosphere_reference_altitude_km
                                                             / d.atmosphere_scale_height_km)
    air = around(zeroWindModel.ZeroWindModel(), "wind")
    air.planetPosInMsg.subscribeTo(earth_msg)
    air.setPlanetOmega_N([0.0, 0.0, EARTH_ROTATION_RAD_S])
    field = around(magneticFieldCenteredDipole.MagneticFieldCenteredDipole(), "magfield")
    field.g10, field.g11, field.h11 = g10, g11, h11
    field.planetRadius = IGRF_REFERENCE_RADIUS_KM * 1e3
    field.planetPosInMsg.subscribeTo(earth_msg)
    return shadow, atmo, air, field, (sun_msg, earth_msg)


def run_basilisk(mission, environment: tuple | None = None) -> float:
    """Wall seconds of Basilisk's two-rate RW closed loop for ``mission.duration_s`` (same inertia, wheels);
    with ``environment`` (environment_inputs(mission)) on the mission's orbit with every environment torque."""
    import numpy as np
    from Basilisk.architecture import messaging
    from Basilisk.fswAlgorithms import attTrackingError, inertial3D, mrpFeedback, rwMotorTorque
    from Basilisk.simulation import reactionWheelStateEffector, simpleNav, spacecraft
    from Basilisk.utilities import (SimulationBaseClass, macros, orbitalMotion, simHelpers, simIncludeGravBody,
                                    simIncludeRW)

    t0 = time.perf_counter()
    sim = SimulationBaseClass.SimBaseClass()
    dyn, fsw = sim.CreateNewProcess("dynProcess"), sim.CreateNewProcess("fswProcess")
    dyn.addTask(sim.CreateNewTask("dynTask", macros.sec2nano(1.0 / DYNAMICS_RATE_HZ)))
    fsw.addTask(sim.CreateNewTask("fswTask", macros.sec2nano(1.0 / GNC_RATE_HZ)))

    J = np.asarray(mission.spacecraft.inertia_B_kgm2, dtype=float)
    sc = spacecraft.Spacecraft()  # RK4 is the spacecraft's default integrator
    sc.ModelTag = "bsk-sat"
    sc.hub.mHub = 150.0
    sc.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    sc.hub.IHubPntBc_B = simHelpers.np2EigenMatrix3d(J.flatten().tolist())
    sim.AddModelToTask("dynTask", sc, 1)
    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()
    earth.isCentralBody = True
    grav.addBodiesTo(sc)

    rw_factory = simIncludeRW.rwFactory()
    for w in mission.spacecraft.wheels:
        rw_factory.create("custom", list(map(float, w.axis_B)), Js=float(w.spin_inertia_kgm2), u_max=float(w.max_torque_Nm),
                          Omega_max=float(w.max_speed_rad_s) / macros.RPM, Omega=0.0)
    wheels = reactionWheelStateEffector.ReactionWheelStateEffector()
    wheels.ModelTag = "rw-cluster"
    rw_factory.addToSpacecraft(wheels.ModelTag, wheels, sc)
    sim.AddModelToTask("dynTask", wheels, 2)
    nav = simpleNav.SimpleNav()
    nav.ModelTag = "simpleNav"
    sim.AddModelToTask("dynTask", nav)

    reference = inertial3D.inertial3D()
    reference.ModelTag = "inertial3D"
    reference.sigma_R0N = [0.0, 0.0, 0.0]
    sim.AddModelToTask("fswTask", reference)
    error = attTrackingError.attTrackingError()
    error.ModelTag = "attTrackingError"
    sim.AddModelToTask("fswTask", error)
    control = mrpFeedback.mrpFeedback()
    control.ModelTag = "mrpFeedback"
    control.K, control.Ki, control.P = 3.5, -1.0, 30.0
    sim.AddModelToTask("fswTask", control)
    torque = rwMotorTorque.rwMotorTorque()
    torque.ModelTag = "rwMotorTorque"
    torque.controlAxes_B = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    sim.AddModelToTask("fswTask", torque)

    config_msg = messaging.VehicleConfigMsg().write(messaging.VehicleConfigMsgPayload(ISCPntB_B=J.flatten().tolist()))
    rw_params = rw_factory.getConfigMessage()
    nav.scStateInMsg.subscribeTo(sc.scStateOutMsg)
    error.attNavInMsg.subscribeTo(nav.attOutMsg)
    error.attRefInMsg.subscribeTo(reference.attRefOutMsg)
    control.guidInMsg.subscribeTo(error.attGuidOutMsg)
    control.vehConfigInMsg.subscribeTo(config_msg)
    control.rwParamsInMsg.subscribeTo(rw_params)
    control.rwSpeedsInMsg.subscribeTo(wheels.rwSpeedOutMsg)
    torque.rwParamsInMsg.subscribeTo(rw_params)
    torque.vehControlInMsg.subscribeTo(control.cmdTorqueOutMsg)
    wheels.rwMotorCmdInMsg.subscribeTo(torque.rwMotorTorqueOutMsg)

    oe = orbitalMotion.ClassicElements()
    if environment is None:
        oe.a, oe.e, oe.i = 6_878_137.0, 0.001, 97.4 * macros.D2R
        oe.Omega, oe.omega, oe.f = 0.0, 0.0, 0.0
    else:
        keep = _basilisk_environment(sim, sc, earth, mission, environment)  # noqa: F841 (alive until the run ends)
        o = mission.orbit
        oe.a, oe.e, oe.i = o.semi_major_axis_km * 1e3, o.eccentricity, o.inclination_deg * macros.D2R
        oe.Omega, oe.omega = o.raan_deg * macros.D2R, o.arg_perigee_deg * macros.D2R
        oe.f = orbitalMotion.E2f(orbitalMotion.M2E(o.mean_anomaly_deg * macros.D2R, o.eccentricity), o.eccentricity)
    r_N, v_N = orbitalMotion.elem2rv(earth.mu, oe)
    sc.hub.r_CN_NInit, sc.hub.v_CN_NInit = r_N, v_N
    sc.hub.sigma_BNInit = [[0.1], [0.2], [-0.3]]
    sc.hub.omega_BN_BInit = [[0.001], [-0.01], [0.03]]
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(float(mission.duration_s)))
    sim.ExecuteSimulation()
    return time.perf_counter() - t0


def _torques(mission) -> list[str]:
    """The external torques keepout's truth applies in ``mission``."""
    from hil_sim.world.environment import environment_effects
    d = mission.spacecraft.disturbance
    return [name for name, on in (("constant", any(d.constant_B_Nm)), ("gravity gradient", d.gravity_gradient)) if on] \
        + environment_effects(mission)


def _stats(duration_s: float, walls: dict[str, list[float]]) -> dict:
    """One row's figures from its wall times: sim-s per wall-s per run, medians, ms per 10 Hz tick, ratios."""
    speed = {k: [duration_s / w for w in v] for k, v in walls.items()}
    med = {k: statistics.median(v) for k, v in speed.items()}
    pairs = [k / b for k, b in zip(speed["keepout"], speed["basilisk"])]
    return {"sim_s_per_wall_s": speed, "median_sim_s_per_wall_s": med,
            "ms_per_gnc_tick": {k: 1e3 / (v * GNC_RATE_HZ) for k, v in med.items()},
            "ratio_keepout_over_basilisk": med["keepout"] / med["basilisk"],
            "median_pair_ratio": statistics.median(pairs)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=120.0, help="simulated seconds per run (default 120)")
    ap.add_argument("--repeat", type=int, default=5, help="runs of each loop, alternated (default 5)")
    ap.add_argument("--cpu", type=int, default=None, help="pin to this core (default: the first allowed)")
    ap.add_argument("--rows", nargs="+", choices=ROWS, default=list(ROWS), help="rows to run (default: both)")
    args = ap.parse_args(argv)
    try:
        import Basilisk
    except ImportError:
        print("bench/vs_basilisk.py: skipped, Basilisk is not installed (pip install 'keepout[bench]', i.e. bsk)")
        return 0
    from gnc.ephemeris import EARTH_RADIUS_KM
    cpu = args.cpu if args.cpu is not None else min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})  # one core for both loops
    missions = {row: demo_mission(args.duration, row) for row in args.rows}
    inputs = {row: environment_inputs(m) if row == "environment" else None for row, m in missions.items()}
    load_before = os.getloadavg()[0]
    for row in args.rows:  # warm-up: imports, numba caches, the ICD, Basilisk's libraries (not timed)
        run_keepout(demo_mission(5.0, row))
        run_basilisk(demo_mission(5.0, row), inputs[row])
    walls = {row: {"keepout": [], "basilisk": []} for row in args.rows}
    for _ in range(args.repeat):  # every loop of every row in turn: all see the same host load
        for row, mission in missions.items():
            walls[row]["keepout"].append(run_keepout(mission))
            walls[row]["basilisk"].append(run_basilisk(mission, inputs[row]))
    load_after = os.getloadavg()[0]
    rows = {row: {"keepout_torques": _torques(m), "orbit_altitude_km": m.orbit.semi_major_axis_km - EARTH_RADIUS_KM,
                  "per_step": PER_STEP[row], **_stats(args.duration, walls[row])} for row, m in missions.items()}

    print(f"\nclosed loop, {args.duration:.0f} s simulated per run, {args.repeat} runs each, alternated, core {cpu} "
          f"(load avg {load_before:.2f} -> {load_after:.2f}, {os.cpu_count()} cores shared)")
    print(f"{'row':12s} {'loop':10s} {'median sim-s/wall-s':>20s} {'min':>8s} {'max':>8s} {'ms per 10 Hz tick':>18s}")
    for row, r in rows.items():
        for k in ("keepout", "basilisk"):
            med, speed = r["median_sim_s_per_wall_s"][k], r["sim_s_per_wall_s"][k]
            print(f"{row:12s} {k:10s} {med:20.1f} {min(speed):8.1f} {max(speed):8.1f} {r['ms_per_gnc_tick'][k]:18.3f}")
        print(f"{row:12s} ratio keepout / Basilisk: {r['ratio_keepout_over_basilisk']:.3f} "
              f"(median of the pairs {r['median_pair_ratio']:.3f}); goal >= 1.0")

    result = {"bench": "vs_basilisk", "mission": str(MISSION.relative_to(ROOT)), "duration_s": args.duration,
              "repeat": args.repeat, "cpu": cpu, "cores": os.cpu_count(),
              "load_avg_1min_before": load_before, "load_avg_1min_after": load_after,
              "python": platform.python_version(), "basilisk": getattr(Basilisk, "__version__", "?"),
              "rows": rows, "goal_ratio": 1.0}
    dest = ROOT / "bench" / "results" / "vs_basilisk.json"
    print(f"wrote {write_result(dest, result).relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
