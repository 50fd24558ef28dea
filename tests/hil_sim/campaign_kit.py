"""Test-only stand-ins for the campaign machinery: a small mission model and a deterministic run function.

The run function is a real (if small) closed loop: a boresight y on S^2 steered by
ydot = P(y) u toward a target with a conic keep-out zone, u = k1 (x_d - y) plus a repulsion of gain
kappa inside an eps-layer around the cone, integrated with explicit Euler at 10 Hz, with a seeded
measurement noise. Its metrics have the names the campaigns use (min_margin_deg, settling_time_s,
final_error_deg), so runner, report, baseline and shrink are exercised on genuine dynamics.
Never imported by product code.
"""
from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Annotated, Any, Literal, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from hil_sim.campaign.execute import RunResult

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


class _M(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ToyLaw(_M):
    k1: float = Field(0.2, gt=0)
    kappa: float = Field(2.0, gt=0)
    eps: float = Field(0.05, gt=0, lt=1)


class ToySpacecraft(_M):
    inertia_B_kgm2: list[list[float]] = [[20.0, 0.0, 0.0], [0.0, 25.0, 0.0], [0.0, 0.0, 15.0]]
    q_NB: list[float] = [1.0, 0.0, 0.0, 0.0]
    boresight_B: Vec3 = [0.0, 0.0, 1.0]
    noise_deg: float = Field(0.01, ge=0)


class ToyMission(_M):
    schema_version: Literal[1]
    name: str
    seed: int = 0
    duration_s: float = 200.0
    epoch_utc: str = "2026-03-20T12:00:00Z"
    target_N: Vec3 = [1.0, 0.0, 0.0]
    zone_axis_N: Vec3 = [0.0, 1.0, 0.0]
    zone_half_angle_deg: float = 20.0
    disturbance: float = 0.0
    mode_name: Literal["POINTING", "SAFE"] = "POINTING"
    law: ToyLaw = ToyLaw()
    spacecraft: ToySpacecraft = ToySpacecraft()


def _unit(v: Any) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    eta, qv = q[0], q[1:]
    return v + 2.0 * eta * np.cross(qv, v) + 2.0 * np.cross(qv, np.cross(qv, v))


def simulate(m: ToyMission, seed: int, clamp_k1: float | None = None) -> tuple[dict[str, float], dict[str, np.ndarray], float]:
    rng = np.random.default_rng(seed)
    k1 = m.law.k1 if clamp_k1 is None else min(m.law.k1, clamp_k1)
    dt = 0.1
    q = _unit(m.spacecraft.q_NB)
    y = _unit(_quat_rotate(q, _unit(m.spacecraft.boresight_B)))
    xd, a = _unit(m.target_N), _unit(m.zone_axis_N)
    cos_half = math.cos(math.radians(m.zone_half_angle_deg))
    scale = float(np.trace(np.asarray(m.spacecraft.inertia_B_kgm2))) / 60.0  # heavier: slower response
    n = int(round(m.duration_s / dt))
    ys = np.empty((n + 1, 3))
    ys[0] = y
    margins = np.empty(n + 1)
    for k in range(n + 1):
        margins[k] = math.degrees(math.acos(np.clip(y @ a, -1, 1))) - m.zone_half_angle_deg
        if k == n:
            break
        y_meas = _unit(y + rng.normal(0.0, math.radians(m.spacecraft.noise_deg), 3))
        u = k1 * (xd - y_meas)
        layer = (y_meas @ a) - cos_half  # > -eps: inside the layer around the cone
        if layer > -m.law.eps:
            u = u - m.law.kappa * k1 * (layer + m.law.eps) / m.law.eps * a
        u = u + m.disturbance * np.cross(a, xd)
        y = _unit(y + dt / scale * (u - (y @ u) * y))
        ys[k + 1] = y
    err = np.degrees(np.arccos(np.clip(ys @ xd, -1, 1)))
    above = np.nonzero(err > 1.0)[0]
    settle = 0.0 if above.size == 0 else (above[-1] + 1) * dt
    if above.size and above[-1] == n:
        settle = math.inf
    metrics = {"min_margin_deg": float(margins.min()), "settling_time_s": float(settle),
               "final_error_deg": float(err[-1])}
    t = np.arange(n + 1) * dt
    boundary = _cone_boundary(a, m.zone_half_angle_deg)
    return metrics, {"t_s": t, "x": ys, "target": xd, "zone_0": boundary}, n * dt


def _cone_boundary(axis: np.ndarray, half_angle_deg: float, num: int = 90) -> np.ndarray:
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    th = math.radians(half_angle_deg)
    phi = np.linspace(0, 2 * math.pi, num)
    return (math.cos(th) * axis[None, :] + math.sin(th) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2))


def _used(m: ToyMission, paths: Sequence[str], overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    from hil_sim.campaign.dispersions import parse_path, read_path
    out = {p: read_path(m, parse_path(p)) for p in paths}
    out.update(overrides or {})
    return out


def toy_run(mission: ToyMission, seed: int, mode: str, paths: Sequence[str]) -> RunResult:
    metrics, traj, t = simulate(mission, seed)
    return RunResult(metrics=metrics, used=_used(mission, paths), trajectory=traj, sim_time_s=t)


def toy_run_clamping(mission: ToyMission, seed: int, mode: str, paths: Sequence[str]) -> RunResult:
    """A faulty set-up: silently clamps k1 to 0.25 (a dispersion that does not land)."""
    metrics, traj, t = simulate(mission, seed, clamp_k1=0.25)
    used = _used(mission, paths, {"law.k1": min(mission.law.k1, 0.25)} if "law.k1" in paths else None)
    return RunResult(metrics=metrics, used=used, trajectory=traj, sim_time_s=t)


def toy_run_threshold(mission: ToyMission, seed: int, mode: str, paths: Sequence[str]) -> RunResult:
    """Injected failure: the keep-out margin collapses when the disturbance exceeds 0.03 (the disturbance
    has no other effect here, so it is the only cause)."""
    metrics, traj, t = simulate(mission.model_copy(update={"disturbance": 0.0}), seed)
    if mission.disturbance > 0.03:
        metrics["min_margin_deg"] = -1.0 - mission.disturbance
    return RunResult(metrics=metrics, used=_used(mission, paths), trajectory=traj, sim_time_s=t)


TOY_MISSION_YAML = textwrap.dedent("""\
    schema_version: 1
    name: toy
    duration_s: 80.0
    target_N: [1.0, 0.0, 0.0]
    zone_axis_N: [0.6, 0.8, 0.0]
    zone_half_angle_deg: 15.0
    law: {k1: 0.2, kappa: 2.0, eps: 0.05}
    spacecraft:
      q_NB: [1.0, 0.0, 0.0, 0.0]
      boresight_B: [0.0, 0.0, 1.0]
""")

TOY_CAMPAIGN_YAML = textwrap.dedent("""\
    schema_version: 1
    name: toy-campaign
    base_mission: toy-mission.yaml
    runs: {runs}
    master_seed: 12345
    mode: fast
    dispersions:
      - {{name: attitude, path: spacecraft.q_NB, kind: attitude}}
      - name: inertia
        path: spacecraft.inertia_B_kgm2
        kind: inertia
        scale: {{dist: clipped_normal, mean: 1.0, sigma: 0.1, low: 0.8, high: 1.2}}
        misalignment_sigma_deg: 1.0
      - name: gain
        path: law.k1
        kind: scalar
        distribution: {{dist: uniform, low: 0.8, high: 1.2}}
        apply: multiply
      - name: disturbance
        path: disturbance
        kind: scalar
        distribution: {{dist: normal, mean: 0.0, sigma: 0.002}}
      - {{name: epoch, path: epoch_utc, kind: epoch, start_utc: "2026-01-01T00:00:00Z", end_utc: "2027-01-01T00:00:00Z"}}
      - {{name: target, path: target_N, kind: direction, cone_half_angle_deg: 10.0}}
    criteria:
      - {{name: keep_out, metric: min_margin_deg, op: ">", limit: 0.0}}
      - {{name: settling, metric: settling_time_s, op: "<=", limit: {settle_limit}}}
      - {{name: final_error, metric: final_error_deg, op: "<", limit: 1.0}}
    baseline:
      alpha: 0.01
      tolerances:
        settling_time_s: {{abs: 0.5}}
""")


def write_toy(tmp: Path, runs: int = 12, settle_limit: float = 60.0, campaign_text: str | None = None) -> Path:
    (tmp / "toy-mission.yaml").write_text(TOY_MISSION_YAML)
    path = tmp / "toy-campaign.yaml"
    path.write_text(campaign_text or TOY_CAMPAIGN_YAML.format(runs=runs, settle_limit=settle_limit))
    return path


def toy_plan(campaign_path: Path, run_function=toy_run, **kw):
    from hil_sim.campaign.runner import build_plan
    return build_plan(campaign_path, run_function=run_function, model_class=ToyMission, **kw)
