"""keepout's closed loop against Basilisk's, on one core, in one run: simulated seconds per wall second.

    .venv/bin/pip install -e '.[bench]'        # Basilisk (PyPI package `bsk`)
    .venv/bin/python bench/vs_basilisk.py [--duration 120] [--repeat 5] [--cpu 0]

Both loops fly the same spacecraft (the inertia and the four wheels of config/missions/demo-pointing.yaml) for
the same simulated time, alternated (keepout, Basilisk, keepout, ...) in this one process pinned to one core,
so both see the same host load; the table gives medians and the ratio keepout / Basilisk (goal >= 1.0).

* keepout: one ``fast`` campaign run (``hil_sim.campaign.fast.run_fast``) of demo-pointing: the real flight
  software (MEKF, constrained guidance over moving Sun/Moon zones, rate control, FDIR, telemetry) at 10 Hz,
  every sample and command as an E2E-protected ICD frame on a virtual CAN bus, the world at 100 Hz (RK4,
  wheels, sensors, Sun/Moon/Earth), judged on truth at the end. Timed from the call to its result: set-up,
  loop and judging, as a campaign run pays them.
* Basilisk (the AVS Lab's scenarioAttitudeFeedbackRW, two rates): a 100 Hz task with the spacecraft hub (RK4,
  Earth point-mass gravity), the reaction-wheel state effector and simpleNav; a 10 Hz FSW task with inertial3D,
  attTrackingError, mrpFeedback and rwMotorTorque. Timed from building the simulation to the end of
  ``ExecuteSimulation``.

Writes bench/results/vs_basilisk.json with the host load. Without Basilisk it says so in one line and exits 0.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MISSION = ROOT / "config" / "missions" / "demo-pointing.yaml"
GNC_RATE_HZ, DYNAMICS_RATE_HZ = 10.0, 100.0


def _mission(duration_s: float):
    from hil_sim.mission import load_mission
    return load_mission(MISSION).model_copy(update={"duration_s": duration_s})


def run_keepout(mission) -> float:
    """Wall seconds of one fast-mode closed-loop run of ``mission``."""
    from hil_sim.campaign.fast import run_fast
    t0 = time.perf_counter()
    result = run_fast(mission, 1, "fast", [])
    wall = time.perf_counter() - t0
    if abs(result.sim_time_s - mission.duration_s) > 0.2:
        raise RuntimeError(f"keepout flew {result.sim_time_s} s of {mission.duration_s}")
    return wall


def run_basilisk(mission) -> float:
    """Wall seconds of Basilisk's two-rate RW closed loop for ``mission.duration_s`` (same inertia, wheels)."""
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
    oe.a, oe.e, oe.i = 6_878_137.0, 0.001, 97.4 * macros.D2R
    oe.Omega, oe.omega, oe.f = 0.0, 0.0, 0.0
    r_N, v_N = orbitalMotion.elem2rv(earth.mu, oe)
    sc.hub.r_CN_NInit, sc.hub.v_CN_NInit = r_N, v_N
    sc.hub.sigma_BNInit = [[0.1], [0.2], [-0.3]]
    sc.hub.omega_BN_BInit = [[0.001], [-0.01], [0.03]]
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(float(mission.duration_s)))
    sim.ExecuteSimulation()
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=120.0, help="simulated seconds per run (default 120)")
    ap.add_argument("--repeat", type=int, default=5, help="runs of each loop, alternated (default 5)")
    ap.add_argument("--cpu", type=int, default=None, help="pin to this core (default: the first allowed)")
    args = ap.parse_args(argv)
    try:
        import Basilisk  # noqa: F401
    except ImportError:
        print("bench/vs_basilisk.py: skipped, Basilisk is not installed (pip install 'keepout[bench]', i.e. bsk)")
        return 0
    cpu = args.cpu if args.cpu is not None else min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})  # one core for both loops
    mission = _mission(args.duration)
    load_before = os.getloadavg()[0]
    # warm-up: imports, numba caches, the ICD, Basilisk's libraries (not timed)
    run_keepout(_mission(5.0))
    run_basilisk(_mission(5.0))
    walls: dict[str, list[float]] = {"keepout": [], "basilisk": []}
    for _ in range(args.repeat):
        walls["keepout"].append(run_keepout(mission))
        walls["basilisk"].append(run_basilisk(mission))
    load_after = os.getloadavg()[0]
    speed = {k: [args.duration / w for w in v] for k, v in walls.items()}
    med = {k: statistics.median(v) for k, v in speed.items()}
    ratio = med["keepout"] / med["basilisk"]
    per_pair = [k / b for k, b in zip(speed["keepout"], speed["basilisk"])]

    print(f"\nclosed loop, {args.duration:.0f} s simulated per run, {args.repeat} runs each, alternated, core {cpu} "
          f"(load avg {load_before:.2f} -> {load_after:.2f}, {os.cpu_count()} cores shared)")
    print(f"{'loop':10s} {'median sim-s/wall-s':>20s} {'min':>8s} {'max':>8s} {'ms per 10 Hz tick':>18s}")
    for k in ("keepout", "basilisk"):
        ms_tick = 1e3 / (med[k] * GNC_RATE_HZ)
        print(f"{k:10s} {med[k]:20.1f} {min(speed[k]):8.1f} {max(speed[k]):8.1f} {ms_tick:18.3f}")
    print(f"ratio keepout / Basilisk: {ratio:.3f} (median of the pairs {statistics.median(per_pair):.3f}); goal >= 1.0")

    import Basilisk
    result = {"bench": "vs_basilisk", "mission": str(MISSION.relative_to(ROOT)), "duration_s": args.duration,
              "repeat": args.repeat, "cpu": cpu, "cores": os.cpu_count(),
              "load_avg_1min_before": load_before, "load_avg_1min_after": load_after,
              "python": platform.python_version(), "basilisk": getattr(Basilisk, "__version__", "?"),
              "sim_s_per_wall_s": speed, "median_sim_s_per_wall_s": med,
              "ms_per_gnc_tick": {k: 1e3 / (v * GNC_RATE_HZ) for k, v in med.items()},
              "ratio_keepout_over_basilisk": ratio, "median_pair_ratio": statistics.median(per_pair),
              "goal_ratio": 1.0}
    dest = ROOT / "bench" / "results" / "vs_basilisk.json"
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {dest.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
