"""`keepout budget`: the momentum budget per effect, with the simulator's own torques."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import yaml

from hil_sim.world.budget import _gravity_gradient_torques, budget
from cli.main import main
from hil_sim.mission.model import Mission, world_params
from hil_sim.world.orbit import orbit_elements_array

ROOT = Path(__file__).resolve().parents[2]


def _smallsat(gravity_gradient: bool) -> dict:
    data = yaml.safe_load((ROOT / "config" / "missions" / "smallsat-example.yaml").read_text())
    data["spacecraft"]["disturbance"]["gravity_gradient"] = gravity_gradient
    data["spacecraft"]["inertia_B_kgm2"] = [[0.28, 0.01, 0.0], [0.01, 0.30, 0.0], [0.0, 0.0, 0.17]]
    return data


def test_the_constant_torque_row_is_torque_times_time_and_its_wheel_speed() -> None:
    mission = Mission.model_validate(_smallsat(False))
    rows = {(r.effect, r.span): r for r in budget(mission)}
    assert not any(effect == "gravity gradient" for effect, _ in rows)  # off: no row
    day = rows[("constant torque", "day")]
    tau = np.asarray(mission.spacecraft.disturbance.constant_B_Nm)
    np.testing.assert_allclose(day.momentum_end_B_Nms, tau * 86_400.0, rtol=1e-12)
    G = np.array([w.axis_B for w in mission.spacecraft.wheels]).T
    speeds = np.linalg.pinv(G) @ (tau * 86_400.0) / np.array([w.spin_inertia_kgm2 for w in mission.spacecraft.wheels])
    limits = np.array([w.max_speed_rad_s for w in mission.spacecraft.wheels])
    assert math.isclose(day.wheel_speed_fraction, float(np.max(np.abs(speeds) / limits)), rel_tol=1e-9)


def test_the_gravity_gradient_row_integrates_the_torque_written_out_by_hand() -> None:
    """The budget's torque (the simulator's kernel) against 3 mu / r^3 (u x I u) written out here, and the
    row's momentum against the trapezoid sum of it."""
    from hil_sim.world.orbit import orbit_position_N_km

    mission = Mission.model_validate(_smallsat(True))
    wp = world_params(mission)
    J = np.asarray(wp.spacecraft.inertia_B_kgm2)
    q0, *qv = wp.spacecraft.q_NB0
    qv = np.asarray(qv)
    R = (q0 * q0 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) + 2 * q0 * np.array(
        [[0, -qv[2], qv[1]], [qv[2], 0, -qv[0]], [-qv[1], qv[0], 0]])  # body -> N
    t = np.array([0.0, 1234.5, 4000.0])
    r = np.empty(3)
    for k, tk in enumerate(t.tolist()):
        orbit_position_N_km(orbit_elements_array(wp.orbit), tk, r)
        u = R.T @ (r / np.linalg.norm(r))
        by_hand = 3 * wp.orbit.mu_km3_s2 / np.linalg.norm(r) ** 3 * np.cross(u, J @ u)
        np.testing.assert_allclose(_gravity_gradient_torques(mission, t)[k], by_hand, rtol=1e-9, atol=1e-20)
    assert np.max(np.abs(_gravity_gradient_torques(mission, t))) > 1e-9  # an inertia with products: a torque
    orbit = next(r for r in budget(mission) if r.effect == "gravity gradient" and r.span == "orbit")
    ts = np.linspace(0.0, orbit.span_s, int(math.ceil(orbit.span_s / 10.0)) + 1)
    tau = _gravity_gradient_torques(mission, ts)
    np.testing.assert_allclose(orbit.momentum_end_B_Nms, np.trapezoid(tau, ts, axis=0), rtol=1e-9, atol=1e-15)


def test_budget_command_prints_the_table_and_writes_json(tmp_path, capsys) -> None:
    path = tmp_path / "gg.yaml"
    path.write_text(yaml.safe_dump(_smallsat(True), sort_keys=False))
    assert main(["budget", str(path), "--json", str(tmp_path / "b.json")]) == 0
    out = capsys.readouterr().out
    assert "gravity" in out and "off in this mission (not counted)" in out and "residual magnetic dipole" in out
    record = json.loads((tmp_path / "b.json").read_text())
    assert record["off"] == ["solar radiation pressure", "aerodynamic drag", "residual magnetic dipole"]
    assert {r["effect"] for r in record["rows"]} >= {"constant torque", "gravity gradient", "total (deterministic)"}
    assert main(["budget", str(tmp_path / "missing.yaml")]) == 2
