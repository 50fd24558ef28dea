"""``keepout truth MISSION --duration D --out FILE.npz``: the truth models alone, no flight software.

Propagates the mission's spacecraft (attitude, rates, wheels, orbit, ephemeris, every disturbance the
mission turns on) from its initial state for D seconds with the wheel motors commanding zero torque: what
the spacecraft does when nobody flies it, as a GNC engineer looks at a disturbance environment before any
control loop exists. Writes the truth in the SIL run's truth.npz layout (``t_s``, ``q_NB``,
``omega_BN_B``, ``wheel_speed_rad_s``, ``wheel_torque_Nm``, ``sun_N``, ``moon_N``, ``earth_N``,
``r_sc_N_km``, ``cycle_done`` all false: no flight software answered) plus ``H_N_Nms``, the total angular
momentum in inertial axes, each environment torque the mission turns on in body axes (``srp_torque_B_Nm``:
solar radiation pressure, hil_sim.world.environment), and ``sunlit_fraction``, the share of the Sun's disc seen past the Earth (0 in
the umbra, 1 in full Sun: the conical shadow of gnc.eclipse), and prints a summary: the attitude drift,
the largest body rate, the change of angular momentum (what the disturbances put in) and the time in the
Earth's shadow. ``keepout export`` and the plots read the file as a
run's truth.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from cli import description_of

EXIT_REJECTED = 2


def propagate(mission, duration_s: float, step_s: float) -> dict[str, np.ndarray]:
    """The truth of ``mission`` over ``duration_s``, recorded every ``step_s``, wheels commanding zero."""
    from hil_sim.world.environment import EFFECT_KEYS, EFFECTS, environment_effects
    from hil_sim.mission.model import world_params
    from hil_sim.sil.orchestrator import TruthRecorder
    from hil_sim.world.world import World

    world = World(world_params(mission), seed=mission.seed)
    n_steps = int(math.ceil(duration_s / step_s - 1e-9))
    n_wheels = len(mission.spacecraft.wheels)
    recorder = TruthRecorder(n_steps, n_wheels)
    zero = np.zeros(n_wheels)
    momentum = np.empty((n_steps + 1, 3))
    momentum[0] = world.batch.angular_momentum_N()[0]
    effects = [k for k, name in enumerate(EFFECTS) if name in environment_effects(mission)]
    env_torque = np.zeros((n_steps + 1, len(EFFECTS), 3))
    env_torque[0] = world.batch.environment_torques_B()[0]
    recorder.record(world, zero, False)
    for k in range(1, n_steps + 1):
        world.step(min(step_s, duration_s - (k - 1) * step_s), zero)
        recorder.record(world, zero, False)
        momentum[k] = world.batch.angular_momentum_N()[0]
        if effects:
            env_torque[k] = world.batch.environment_torques_B()[0]
    n = recorder.n
    from gnc.eclipse import sunlit_fraction

    sun_km, _ = world.batch.ephemeris.positions_N_km(recorder.t_s[:n])
    return {"sunlit_fraction": sunlit_fraction(recorder.r_sc_N_km[:n], sun_km), "t_s": recorder.t_s[:n], "q_NB": recorder.q_NB[:n], "omega_BN_B": recorder.omega_BN_B[:n],
            "wheel_speed_rad_s": recorder.wheel_speed_rad_s[:n], "wheel_torque_Nm": recorder.wheel_torque_Nm[:n],
            "sun_N": recorder.sun_N[:n], "moon_N": recorder.moon_N[:n], "earth_N": recorder.earth_N[:n],
            "r_sc_N_km": recorder.r_sc_N_km[:n], "cycle_done": recorder.cycle_done[:n], "H_N_Nms": momentum[:n],
            **{EFFECT_KEYS[k]: env_torque[:n, k] for k in effects}}


def summary(truth: dict[str, np.ndarray]) -> dict[str, float]:
    """Attitude drift from the initial attitude [deg], largest body rate [deg/s], |H_end - H_start| [N m s],
    the share of the time in the Earth's shadow (umbra, and penumbra) and the number of eclipses begun."""
    q = truth["q_NB"]
    drift = 2.0 * np.degrees(np.arccos(np.clip(np.abs(q @ q[0]), 0.0, 1.0)))
    lit = truth["sunlit_fraction"]
    shadow = lit < 1.0
    from hil_sim.world.environment import EFFECT_KEYS

    peaks = {f"{key}_peak": float(np.linalg.norm(truth[key], axis=1).max()) for key in EFFECT_KEYS if key in truth}
    return {**peaks, "umbra_fraction": float(np.mean(lit == 0.0)), "penumbra_fraction": float(np.mean(shadow & (lit > 0.0))),
            "eclipses": int(np.count_nonzero(shadow[1:] & ~shadow[:-1])),
            "duration_s": float(truth["t_s"][-1] - truth["t_s"][0]),
            "attitude_drift_deg": float(drift[-1]), "attitude_drift_max_deg": float(drift.max()),
            "body_rate_max_deg_s": float(np.degrees(np.linalg.norm(truth["omega_BN_B"], axis=1)).max()),
            "momentum_change_Nms": float(np.linalg.norm(truth["H_N_Nms"][-1] - truth["H_N_Nms"][0]))}


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("truth", help="propagate the truth models alone (no flight software, wheels held)",
                              description=description_of(__doc__),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mission", type=Path, help="mission YAML")
    p.add_argument("--duration", type=_positive, default=None, metavar="S",
                   help="seconds to propagate (default: the mission's duration_s)")
    p.add_argument("--step", type=_positive, default=None, metavar="S",
                   help="recording step [s] (default: the GNC period); the integrator keeps its own step")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.npz", help="where to write the truth")
    p.set_defaults(func=_truth)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of seconds")
    return value


def _truth(args: argparse.Namespace) -> int:
    from hil_sim.world.environment import EFFECT_KEYS, EFFECTS
    from hil_sim.mission.model import load_mission_or_report

    mission = load_mission_or_report(args.mission)
    if mission is None:
        return EXIT_REJECTED
    if args.out.suffix != ".npz":
        print(f"keepout truth: --out {args.out}: the truth is written as .npz (e.g. truth.npz)", file=sys.stderr)
        return EXIT_REJECTED
    duration = args.duration if args.duration is not None else mission.duration_s
    step = args.step if args.step is not None else 1.0 / mission.flight_software.rates.gnc_rate_hz
    truth = propagate(mission, duration, step)
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(args.out, **truth)
    except OSError as exc:
        print(f"keepout truth: cannot write {args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 4
    s = summary(truth)
    print(f"{mission.name}: {s['duration_s']:.0f} s of truth, wheels held, no flight software -> {args.out}\n"
          f"  attitude drift {s['attitude_drift_deg']:.3f} deg at the end ({s['attitude_drift_max_deg']:.3f} max), "
          f"body rate up to {s['body_rate_max_deg_s']:.4f} deg/s, angular momentum changed by "
          f"{s['momentum_change_Nms']:.3e} N m s\n"
          f"  in the Earth's shadow {100 * s['umbra_fraction']:.1f} % of the time (umbra) + "
          f"{100 * s['penumbra_fraction']:.2f} % (penumbra), {s['eclipses']} eclipse(s) begun")
    field = mission.spacecraft.disturbance.magnetic_field.summary()
    for key, name in zip(EFFECT_KEYS, EFFECTS):
        if f"{key}_peak" in s:
            where = f" in {field}" if name == "residual magnetic dipole" else ""
            print(f"  {name}{where}: torque up to {s[f'{key}_peak']:.3e} N m ({key} in the file)")
    return 0
