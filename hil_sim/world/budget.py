"""``keepout budget MISSION``: the disturbance and momentum budget a GNC engineer makes when sizing wheels.

Per effect the mission's truth models apply (the constant torque, the random torque, the gravity gradient
when ``spacecraft.disturbance.gravity_gradient`` is on), over one orbit and over a day, with the attitude
held inertially at the mission's initial attitude (the worst case for the secular part of the gravity
gradient is an attitude fixed in inertial space; a pointing timeline changes it): the peak torque, the
momentum accumulated per body axis at the end of the span and the largest it reaches, and the wheel speed
that momentum implies when the wheels absorb it with the minimum-norm allocation, as a fraction of each
wheel's limit. The random torque (first-order Gauss-Markov, std sigma, correlation time tau) is given as the
1-sigma momentum of its random walk, sigma sqrt(2 tau t) for t >> tau. Solar radiation pressure and drag on
the spacecraft's facets, when the mission turns them on, get their rows (the Sun from the truth ephemeris,
zero in the Earth's shadow; the co-rotating exponential atmosphere), and so does a residual magnetic dipole in
the Earth's field (a centred dipole from IGRF at the epoch, turning with the Earth, or IGRF to degree N:
``spacecraft.disturbance.magnetic_field``).

The torques are the simulator's own (`hil_sim.world.dynamics` and `hil_sim.world.environment`: the same kernels, the same
Keplerian orbit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np


DAY_S = 86_400.0
SAMPLE_S = 10.0


@dataclass
class Row:
    effect: str
    span: str
    span_s: float
    peak_torque_Nm: float
    momentum_end_B_Nms: list[float]  # accumulated over the span, body axes (inertial hold)
    momentum_peak_Nms: float  # the largest |H| reached within the span
    wheel_speed_fraction: float  # of the worst wheel's limit, for momentum_peak with the minimum-norm allocation
    note: str = ""


def _gravity_gradient_torques(mission, t: np.ndarray) -> np.ndarray:
    """(len(t), 3) gravity-gradient torque [N m] in body axes at times ``t``, attitude held at the initial one:
    the simulator's own kernel (`hil_sim.world.dynamics._add_gravity_gradient`) on the mission's packed spacecraft."""
    from hil_sim.world import dynamics as dyn
    from hil_sim.mission.model import world_params
    from hil_sim.world.orbit import orbit_elements_array

    wp = world_params(mission)
    _, _, B, X = dyn.pack_spacecraft([wp.spacecraft])
    B[dyn.B_GG] = 1.0
    orbit = orbit_elements_array(wp.orbit)[None, :]
    r = np.empty(3)
    tau = np.zeros((3, 1))
    out = np.empty((t.size, 3))
    for k, tk in enumerate(t.tolist()):
        tau[:] = 0.0
        dyn._add_gravity_gradient(X, B, orbit, 0, tk, r, tau)
        out[k] = tau[:, 0]
    return out


def _environment_torques(mission, t: np.ndarray) -> np.ndarray:
    """(len(t), len(EFFECTS), 3) environment torques [N m] in body axes at times ``t``, attitude held at the
    initial one: the simulator's own kernels (`hil_sim.world.environment.environment_torques_B`) on the mission's
    world, the Sun from its truth ephemeris."""
    from hil_sim.world import environment as env
    from hil_sim.mission.model import world_params
    from hil_sim.world.world import WorldBatch

    batch = WorldBatch([world_params(mission)], seed=mission.seed)
    sun_km, _ = batch.ephemeris.positions_N_km(t)
    out = np.zeros((t.size, len(env.EFFECTS), 3))
    tau = np.zeros((1, len(env.EFFECTS), 3))
    for k, tk in enumerate(t.tolist()):
        env.hold_sun(batch.B, sun_km[k])
        env.environment_torques_B(batch.X, batch.B, batch.ORB, tk, tau)
        out[k] = tau[0]
    return out


def _wheel_fraction(mission, h_B: np.ndarray) -> float:
    """The worst wheel's speed for the wheels to absorb ``h_B`` (minimum norm), as a fraction of its limit."""
    wheels = mission.spacecraft.wheels
    G = np.array([w.axis_B for w in wheels], dtype=float).T
    js = np.array([w.spin_inertia_kgm2 for w in wheels])
    limit = np.array([w.max_speed_rad_s for w in wheels])
    speeds = (np.linalg.pinv(G) @ h_B) / js
    return float(np.max(np.abs(speeds) / limit))


def _row(mission, effect: str, span: str, t: np.ndarray, tau: np.ndarray, note: str = "") -> Row:
    h = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (tau[1:] + tau[:-1]) * np.diff(t)[:, None], axis=0)])
    worst = int(np.argmax(np.linalg.norm(h, axis=1)))
    return Row(effect, span, float(t[-1]), float(np.max(np.linalg.norm(tau, axis=1))), h[-1].tolist(),
               float(np.linalg.norm(h[worst])), _wheel_fraction(mission, h[worst]), note)


def budget(mission) -> list[Row]:
    """The budget rows of ``mission`` (see the module docstring)."""
    from hil_sim.world.environment import EFFECTS, environment_effects
    from hil_sim.mission.model import world_params

    wp = world_params(mission)
    orbit_s = 2.0 * math.pi * math.sqrt(wp.orbit.semi_major_axis_km**3 / wp.orbit.mu_km3_s2)
    dist = mission.spacecraft.disturbance
    rows: list[Row] = []
    for span, span_s in (("orbit", orbit_s), ("day", DAY_S)):
        t = np.linspace(0.0, span_s, int(math.ceil(span_s / SAMPLE_S)) + 1)
        const = np.tile(np.asarray(dist.constant_B_Nm, dtype=float), (t.size, 1))
        total = const.copy()
        rows.append(_row(mission, "constant torque", span, t, const))
        if dist.gravity_gradient:
            gg = _gravity_gradient_torques(mission, t)
            total += gg
            rows.append(_row(mission, "gravity gradient", span, t, gg, "attitude held at the initial one"))
        effects = environment_effects(mission)
        if effects:
            env_tau = _environment_torques(mission, t)
            for k, name in enumerate(EFFECTS):
                if name in effects:
                    total += env_tau[:, k]
                    rows.append(_row(mission, name, span, t, env_tau[:, k], "attitude held at the initial one"))
        rows.append(_row(mission, "total (deterministic)", span, t, total))
        if dist.random_std_Nm > 0:
            sigma_h = dist.random_std_Nm * math.sqrt(2.0 * max(dist.random_correlation_time_s, SAMPLE_S) * span_s)
            h_axis = np.full(3, sigma_h)
            rows.append(Row("random torque (1 sigma)", span, span_s, 3.0 * dist.random_std_Nm, h_axis.tolist(),
                            float(np.linalg.norm(h_axis)), _wheel_fraction(mission, h_axis),
                            "random walk sigma sqrt(2 tau t); peak torque shown at 3 sigma"))
    return rows
