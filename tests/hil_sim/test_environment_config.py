"""The environment torques as a mission configures them: refused at load with the file position and the fix
when unphysical, off by default (no rows in the dynamics, the budget and the truth file as before), and, on,
recorded by `keepout truth` and counted by `keepout budget` with the simulator's own kernels."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.world import dynamics as dyn
from hil_sim.mission.model import Mission, load_mission, world_params
from hil_sim.mission.loader import ConfigError

ROOT = Path(__file__).resolve().parents[2]
SMALLSAT = ROOT / "config" / "missions" / "smallsat-example.yaml"
# a 20 kg 12U-like box, its centre of mass 2 cm off the middle along z (what makes a torque)
BOX = [{"area_m2": a, "normal_B": n, "centre_of_pressure_B_m": c, "specular": s, "diffuse": d}
       for a, n, c, s, d in (
           (0.06, [1, 0, 0], [0.113, 0.0, 0.02], 0.1, 0.3), (0.06, [-1, 0, 0], [-0.113, 0.0, 0.02], 0.1, 0.3),
           (0.08, [0, 1, 0], [0.0, 0.113, 0.02], 0.1, 0.3), (0.08, [0, -1, 0], [0.0, -0.113, 0.02], 0.1, 0.3),
           (0.05, [0, 0, 1], [0.0, 0.0, 0.19], 0.0, 0.4), (0.05, [0, 0, -1], [0.0, 0.0, -0.15], 0.0, 0.4))]


def _smallsat(**disturbance) -> dict:
    data = yaml.safe_load(SMALLSAT.read_text())
    data["spacecraft"]["disturbance"].update(disturbance)
    data["spacecraft"]["facets"] = [dict(f) for f in BOX]
    return data


def _problems(data: dict, tmp_path: Path) -> list[str]:
    path = tmp_path / "mission.yaml"
    with pytest.raises(ConfigError) as info:
        load_mission(path, text=yaml.safe_dump(data, sort_keys=False))
    lines = str(info.value).splitlines()
    assert all(line.startswith(f"{path}:") for line in lines), lines
    return lines


@pytest.mark.parametrize("key, value, says", [
    ("area_m2", 0.0, "facets[1].area_m2: Input should be greater than 0 m^2"),
    ("area_m2", -0.2, "facets[1].area_m2: Input should be greater than 0 m^2"),
    ("normal_B", [0.0, 0.9, 0.0], "facets[1].normal_B: the normal's norm is 0.9; give the outward unit normal"),
    ("specular", 0.8, "facets[1]: specular + diffuse = 1.1 exceeds 1"),
    ("drag_coefficient", -1.0, "facets[1].drag_coefficient: Input should be greater than or equal to 0"),
])
def test_an_unphysical_facet_is_refused_at_its_key(tmp_path, key, value, says) -> None:
    data = _smallsat(solar_radiation_pressure=True)
    data["spacecraft"]["facets"][1][key] = value
    if key == "specular":
        data["spacecraft"]["facets"][1]["diffuse"] = 0.3
    (line,) = _problems(data, tmp_path)
    assert says in line
    assert line.split(":")[1].isdigit() and line.split(":")[2].split()[0].isdigit()  # file:line:col


@pytest.mark.parametrize("key", ["solar_radiation_pressure", "aerodynamic_drag"])
def test_an_effect_on_facets_without_facets_is_refused_with_the_fix(tmp_path, key) -> None:
    data = _smallsat(**{key: True})
    data["spacecraft"]["facets"] = []
    (line,) = _problems(data, tmp_path)
    assert f"spacecraft.disturbance.{key}" in line and "give them as spacecraft.facets" in line


def test_a_dipole_of_nan_and_an_orbit_in_the_atmosphere_are_refused(tmp_path) -> None:
    data = _smallsat()
    data["spacecraft"]["disturbance"]["constant_B_Nm"] = [math.nan, 0.0, 0.0]
    data["orbit"]["semi_major_axis_km"] = 6400.0
    lines = _problems(data, tmp_path)
    assert any("constant_B_Nm[0]: Input should be a finite number" in line for line in lines)
    assert any("orbit.semi_major_axis_km: Input should be greater than" in line for line in lines)
    data = _smallsat()
    data["orbit"]["semi_major_axis_km"] = 6378.137 + 120.0
    data["flight_software"] = {**data["flight_software"], "orbit": {"radius_km": 6378.137 + 120.0}}
    assert any("below" in line and "150 km" in line for line in _problems(data, tmp_path))


def test_off_by_default_the_dynamics_get_no_rows() -> None:
    for name in ("smallsat-example.yaml", "demo-pointing.yaml"):
        mission = load_mission(ROOT / "config" / "missions" / name)
        assert not mission.spacecraft.disturbance.solar_radiation_pressure
        _, _, B, _ = dyn.pack_spacecraft([world_params(mission).spacecraft])
        assert B.shape[0] == dyn.B_FIELDS


def test_the_budget_row_is_the_kernel_and_the_kernel_the_formula() -> None:
    """The budget's SRP torque at a few times against the facet formula written out here (Sun from the truth
    ephemeris, full Sun at these times), and its momentum against the trapezoid sum of the torque."""
    from hil_sim.world.budget import _environment_torques, budget
    from gnc.eclipse import sunlit_fraction
    from hil_sim.world.orbit import orbit_elements_array, orbit_position_N_km
    from hil_sim.world.world import WorldBatch

    mission = Mission.model_validate(_smallsat(solar_radiation_pressure=True))
    wp = world_params(mission)
    t = np.array([0.0, 600.0, 1200.0])
    sun_km, _ = WorldBatch([wp]).ephemeris.positions_N_km(t)
    q0, *qv = wp.spacecraft.q_NB0
    qv = np.asarray(qv)
    R = (q0 * q0 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) + 2 * q0 * np.array(
        [[0, -qv[2], qv[1]], [qv[2], 0, -qv[0]], [-qv[1], qv[0], 0]])  # body -> N
    ours = _environment_torques(mission, t)[:, 0]
    for k in range(t.size):
        r = np.empty(3)
        orbit_position_N_km(orbit_elements_array(wp.orbit), float(t[k]), r)
        assert sunlit_fraction(r, sun_km[k]) == 1.0
        s = R.T @ (sun_km[k] - r)
        pressure = 1361.0 / 299_792_458.0 * (149_597_870.7 / np.linalg.norm(s)) ** 2
        s /= np.linalg.norm(s)
        tau = np.zeros(3)
        for f in BOX:
            n, c = np.asarray(f["normal_B"], float), np.asarray(f["centre_of_pressure_B_m"])
            cos = n @ s
            if cos > 0:
                force = -pressure * f["area_m2"] * cos * ((1 - f["specular"]) * s
                                                         + 2 * (f["diffuse"] / 3 + f["specular"] * cos) * n)
                tau += np.cross(c, force)
        np.testing.assert_allclose(ours[k], tau, rtol=1e-10, atol=1e-22)
    assert np.linalg.norm(ours, axis=1).min() > 1e-9
    rows = {(r.effect, r.span): r for r in budget(mission)}
    orbit = rows[("solar radiation pressure", "orbit")]
    ts = np.linspace(0.0, orbit.span_s, int(math.ceil(orbit.span_s / 10.0)) + 1)
    tau = _environment_torques(mission, ts)[:, 0]
    h = np.sum(0.5 * (tau[1:] + tau[:-1]) * np.diff(ts)[:, None], axis=0)
    np.testing.assert_allclose(orbit.momentum_end_B_Nms, h, rtol=1e-12)
    assert ("solar radiation pressure", "day") in rows
    off = {r.effect for r in budget(Mission.model_validate(_smallsat()))}
    assert "solar radiation pressure" not in off and "aerodynamic drag" not in off


def test_the_budget_drag_row_is_the_formula_in_co_rotating_air() -> None:
    from hil_sim.world.budget import _environment_torques, budget
    from hil_sim.world.orbit import KeplerOrbit

    mission = Mission.model_validate(_smallsat(aerodynamic_drag=True))
    wp = world_params(mission)
    t = np.array([0.0, 2000.0])
    ours = _environment_torques(mission, t)[:, 1]
    q0, *qv = wp.spacecraft.q_NB0
    qv = np.asarray(qv)
    R = (q0 * q0 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) + 2 * q0 * np.array(
        [[0, -qv[2], qv[1]], [qv[2], 0, -qv[0]], [-qv[1], qv[0], 0]])  # body -> N
    orbit = KeplerOrbit(wp.orbit)
    for k, tk in enumerate(t.tolist()):
        r, v = orbit.position_N_km(tk), orbit.velocity_N_km_s(tk)
        v_rel = 1e3 * (v - np.cross([0.0, 0.0, 7.292115e-5], r))
        rho = 6.967e-13 * np.exp(-(np.linalg.norm(r) - 6378.137 - 500.0) / 63.822)
        u = R.T @ v_rel / np.linalg.norm(v_rel)
        tau = sum(np.cross(f["centre_of_pressure_B_m"], -0.5 * rho * (v_rel @ v_rel) * 2.2 * f["area_m2"]
                           * (np.asarray(f["normal_B"]) @ u) * u) for f in BOX if np.asarray(f["normal_B"]) @ u > 0)
        np.testing.assert_allclose(ours[k], tau, rtol=1e-10, atol=1e-22)
    assert np.linalg.norm(ours, axis=1).min() > 1e-9
    assert {("aerodynamic drag", "orbit"), ("aerodynamic drag", "day")} <= {(r.effect, r.span) for r in budget(mission)}


def test_truth_records_the_torque_the_world_applies(tmp_path) -> None:
    from cli.truth import propagate, summary

    on = Mission.model_validate(_smallsat(solar_radiation_pressure=True, aerodynamic_drag=True))
    truth = propagate(on, 60.0, 10.0)
    assert np.linalg.norm(truth["drag_torque_B_Nm"], axis=1).min() > 1e-9
    assert truth["srp_torque_B_Nm"].shape == (7, 3) and np.linalg.norm(truth["srp_torque_B_Nm"], axis=1).min() > 1e-9
    assert summary(truth)["srp_torque_B_Nm_peak"] == pytest.approx(np.linalg.norm(truth["srp_torque_B_Nm"], axis=1).max())
    # the torque changes the motion: without it the momentum differs by about its integral
    off = propagate(Mission.model_validate(_smallsat()), 60.0, 10.0)
    assert "srp_torque_B_Nm" not in off
    dh = np.linalg.norm(truth["H_N_Nms"][-1] - off["H_N_Nms"][-1])
    tau = truth["srp_torque_B_Nm"] + truth["drag_torque_B_Nm"]
    assert dh == pytest.approx(60.0 * np.linalg.norm(tau.mean(axis=0)), rel=0.05)


def test_a_residual_dipole_of_nan_is_refused_and_zero_is_off(tmp_path) -> None:
    data = _smallsat()
    data["spacecraft"]["disturbance"]["residual_dipole_B_Am2"] = [0.1, math.nan, 0.0]
    (line,) = _problems(data, tmp_path)
    assert "spacecraft.disturbance.residual_dipole_B_Am2[1]: Input should be a finite number" in line
    mission = Mission.model_validate(_smallsat())
    assert world_params(mission).spacecraft.disturbance.geomagnetic_dipole_T == (0.0, 0.0, 0.0)
    on = world_params(Mission.model_validate(_smallsat(residual_dipole_B_Am2=[0.05, 0.0, 0.0])))
    assert -3.1e-5 < on.spacecraft.disturbance.geomagnetic_dipole_T[0] < -2.8e-5  # g10 ~ -29,300 nT in 2026


def test_truth_records_the_dipole_torque_m_cross_b() -> None:
    from hil_sim.world import environment as env
    from cli.truth import propagate
    from hil_sim.world.world import WorldBatch

    mission = Mission.model_validate(_smallsat(residual_dipole_B_Am2=[0.02, -0.01, 0.03]))
    truth = propagate(mission, 20.0, 10.0)
    batch = WorldBatch([world_params(mission)])
    for k, t in enumerate(truth["t_s"].tolist()):
        q = truth["q_NB"][k]
        b_N = np.array(env.dipole_field_N(batch.B, 0, *truth["r_sc_N_km"][k], t))
        assert 1e-5 < np.linalg.norm(b_N) < 6e-5  # T: the Earth's field at 550 km
        q0, qv = q[0], q[1:]
        R = (q0 * q0 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) + 2 * q0 * np.array(
            [[0, -qv[2], qv[1]], [qv[2], 0, -qv[0]], [-qv[1], qv[0], 0]])  # body -> N
        np.testing.assert_allclose(truth["dipole_torque_B_Nm"][k], np.cross([0.02, -0.01, 0.03], R.T @ b_N),
                                   rtol=1e-9, atol=1e-20)
