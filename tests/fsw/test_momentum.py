"""Magnetic momentum management (fsw.momentum): the stage on its own against hand-derived cases, and a
fast-mode run on a 550 km Sun-synchronous orbit with every environment torque on, with and without it."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig, FswConfigError, MomentumManagementConfig, parse_fsw_config
from fsw.momentum import MomentumManager

ROOT = Path(__file__).resolve().parents[2]
G_XYZ, JS_1 = np.eye(3), np.ones(3)  # three wheels on the body axes, 1 kg m^2: h_w = Omega


def _manager(**keys) -> MomentumManager:
    return MomentumManager(MomentumManagementConfig(enabled=True, **keys), G_XYZ, JS_1)


def test_the_field_torque_of_the_command_opposes_the_excess_normal_to_the_field() -> None:
    # h along x and y, B along z: the whole excess is normal to B; m = (B x (-k h)) / |B|^2 by hand
    mm = _manager(gain_1_s=0.01, max_dipole_Am2=[30.0] * 3)
    b = np.array([0.0, 0.0, 3e-5])
    m = mm.step(b, np.array([0.02, -0.01, 0.0]))
    assert m == pytest.approx([-0.01 * 0.01 / 3e-5, -0.01 * 0.02 / 3e-5, 0.0], rel=1e-12)
    assert np.cross(m, b) == pytest.approx([-0.01 * 0.02, 0.01 * 0.01, 0.0], rel=1e-12)  # = -k h
    # a bias the wheels should keep is not dumped
    biased = _manager(gain_1_s=0.01, wheel_momentum_bias_Nms=[0.02, -0.01, 0.0])
    assert biased.step(b, np.array([0.02, -0.01, 0.0])) == pytest.approx(np.zeros(3), abs=1e-15)


def test_the_magnetometer_mounting_and_skewed_rods_are_used() -> None:
    q_BS = Rotation.from_euler("zyx", [30.0, -20.0, 10.0], degrees=True)  # scipy: scalar last
    axes = np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.3], [0.1, 0.0, 1.0]])
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    mm = _manager(gain_1_s=0.005, max_dipole_Am2=[30.0] * 3, rod_axes_B=axes.tolist(),
                  magnetometer_q_BS=np.roll(q_BS.as_quat(), 1).tolist())
    b_B, h = np.array([1e-5, -2e-5, 2.5e-5]), np.array([0.03, 0.01, -0.02])
    rods = mm.step(q_BS.inv().apply(b_B), h)
    m_B = axes.T @ rods  # the rods' dipoles add up in body axes
    tau = np.cross(m_B, b_B)
    wanted = -0.005 * h
    normal = wanted - (wanted @ b_B) / (b_B @ b_B) * b_B
    assert tau == pytest.approx(normal, rel=1e-9, abs=1e-15)


def test_rods_saturate_together_keeping_the_direction() -> None:
    mm = _manager(gain_1_s=1.0, max_dipole_Am2=[0.2, 0.1, 0.2])
    m = mm.step(np.array([0.0, 0.0, 3e-5]), np.array([0.5, 0.2, 0.0]))
    unsat = np.array([0.2, -0.5, 0.0]) / 3e-5  # B x (-k h) by hand
    assert np.max(np.abs(m) / [0.2, 0.1, 0.2]) == pytest.approx(1.0)
    assert m / np.linalg.norm(m) == pytest.approx(unsat / np.linalg.norm(unsat))


def test_without_a_field_the_command_is_held_one_cycle_then_zero() -> None:
    mm = _manager(gain_1_s=0.01)
    b, h, nan3 = np.array([2e-5, 0.0, 1e-5]), np.array([0.0, 0.001, 0.0]), np.full(3, math.nan)
    first = mm.step(b, h).copy()
    assert np.linalg.norm(first) > 0
    assert mm.step(nan3, h) == pytest.approx(first)
    assert np.all(mm.step(nan3, h) == 0.0)
    assert np.all(mm.step(nan3, h) == 0.0)
    assert mm.step(b, h) == pytest.approx(first)  # the field is back
    assert mm.step(b, np.array([0.0, math.nan, 0.0])) == pytest.approx(first)  # a wheel speed unknown: held too


def test_enabled_needs_the_magnetometer_and_the_rods() -> None:
    assert FswConfig().momentum_management.enabled is False
    with pytest.raises(FswConfigError, match="momentum_management.enabled needs"):
        parse_fsw_config({"momentum_management": {"enabled": True},
                          "magnetic_devices": {"magnetometer": True, "magnetorquers": False}})
    with pytest.raises(FswConfigError, match="span 3-D"):
        parse_fsw_config({"momentum_management": {"rod_axes_B": [[1, 0, 0], [1, 0, 0], [0, 0, 1]]}})


def test_housekeeping_carries_the_command_and_the_excess(tmp_path) -> None:
    import yaml

    from comms.bus import Icd, open_bus
    from fsw.assembly import build_flight_software
    from hil_sim.mission.model import load_mission

    data = yaml.safe_load((ROOT / "config" / "missions" / "smallsat-example.yaml").read_text())
    data["spacecraft"].update(magnetometer={}, magnetorquers={"max_dipole_Am2": [0.2, 0.2, 0.2]})
    path = tmp_path / "m.yaml"
    for enabled in (False, True):
        data["flight_software"]["momentum_management"] = {"enabled": enabled}
        path.write_text(yaml.safe_dump(data))
        cfg = load_mission(path).flight_software
        cfg = cfg.model_copy(update={"law": cfg.law.model_copy(update={"assumption_check": "off"})})
        bus = open_bus(f"virtual:momentumhk{int(enabled)}", light=True)
        fsw = build_flight_software(cfg, bus, Icd())
        try:
            if enabled:
                fsw.mtq_command_Am2 = fsw.momentum.step(np.array([2e-5, 0.0, 1e-5]), np.array([30.0, 0.0, 0.0, 0.0]))
            hk = fsw.hk_values()
        finally:
            fsw.shutdown()
            bus.shutdown()
        assert hk["mtq_dipole_cmd_Am2"] is fsw.mtq_command_Am2
        if enabled:
            h = fsw.momentum.wheel_momentum_B(np.array([30.0, 0.0, 0.0, 0.0]))
            assert hk["h_excess_Nms"] == pytest.approx(np.linalg.norm(h)) and np.linalg.norm(h) > 0
            assert np.any(fsw.mtq_command_Am2 != 0.0)
        else:
            assert hk["h_excess_Nms"] is None and np.all(hk["mtq_dipole_cmd_Am2"] == 0.0)


# ------------------------------------------------------------------------------------------ closed loop
# demo-pointing's telescope on a 550 km SSO (bench/vs_basilisk.py's environment row) with a magnetometer and
# 15 A m^2 rods, starting with 0.32 N m s stored along body z (its null-space spin [30, -30, 30, -30] plus
# 40 rad/s on every wheel); docs/environment.md has the three-hour figure of bench/momentum.py
STORED_START_RAD_S = [70.0, 10.0, 70.0, 10.0]
SPAN_S = 2500.0


def test_the_devices_knowledge_comes_from_the_truth_when_the_mission_does_not_give_it(tmp_path) -> None:
    import yaml

    from hil_sim.mission.model import load_mission

    data = yaml.safe_load((ROOT / "config" / "missions" / "smallsat-example.yaml").read_text())
    q_BS = [0.0, 0.0, 1.0, 0.0]
    data["spacecraft"].update(magnetometer={"q_BS": q_BS}, magnetorquers={
        "axes_B": [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], "max_dipole_Am2": [1.0, 2.0, 3.0]})
    data["flight_software"]["momentum_management"] = {"enabled": True}
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data))
    known = load_mission(path).flight_software.momentum_management
    assert known.magnetometer_q_BS == q_BS and known.max_dipole_Am2 == [1.0, 2.0, 3.0]
    assert known.rod_axes_B[0] == [0.0, 1.0, 0.0]
    # a mission with the devices and without the section: the section's defaults, unloading off
    del data["flight_software"]["momentum_management"]
    path.write_text(yaml.safe_dump(data))
    assert load_mission(path).flight_software.momentum_management.enabled is False


@pytest.fixture(scope="module")
def runs() -> dict:
    sys.path.append(str(ROOT / "bench"))  # after the packages: bench/fsw.py must not shadow fsw
    try:
        from momentum import fly, momentum_mission
        return {managed: fly(momentum_mission(SPAN_S, managed, wheel_speeds_rad_s=STORED_START_RAD_S))
                for managed in (False, True)}
    finally:
        sys.path.remove(str(ROOT / "bench"))


def test_unloading_drains_the_wheels_while_keeping_out(runs) -> None:
    off, on = runs[False], runs[True]
    assert off["h_Nms"][0] == pytest.approx(0.32, rel=0.01)
    assert on["sim_time_s"] == pytest.approx(SPAN_S, abs=0.2)
    # without unloading the stored momentum stays (the environment adds to it); with it, it drains
    assert off["h_Nms"][-1] > 0.25
    assert on["h_Nms"][-1] < 0.3 * off["h_Nms"][-1]
    for run in (off, on):
        assert run["margins_deg"]["min_margin_deg"] > 0.0
        assert run["unexpected_fdir_events"] == 0.0


def test_the_compiled_cycle_is_the_numpy_law() -> None:
    """fsw._momentum_nb.unloading_step_nb against gnc.magnetic's unloading_dipole and saturate_dipole onto the
    rods (tests/reference/magnetic.py), random wheels, mountings and fields, saturated or not, and fields or
    speeds that are not finite."""
    from reference.magnetic import unloading_step

    from fsw._momentum_nb import unloading_step_nb
    from gnc.attitude import quat_to_dcm

    rng = np.random.default_rng(7)
    saturated = 0
    for k in range(3000):
        G, Js, w = rng.normal(size=(3, 4)), rng.uniform(1e-3, 3e-3, 4), rng.normal(size=4) * 10.0 ** rng.uniform(-1.0, 3.0)
        bias, q = rng.normal(size=3) * 0.01, rng.normal(size=4)
        R_BS, b_S = quat_to_dcm(q / np.linalg.norm(q)), rng.normal(size=3) * 3e-5
        pinv, max_Am2 = np.linalg.pinv(rng.normal(size=(3, 3)).T), rng.uniform(1.0, 10.0, 3)
        if k % 10 == 0:
            (b_S if k % 20 else w)[rng.integers(0, 3)] = np.nan
        out = np.full(3, -1.0)
        norm, finite = unloading_step_nb(G, Js, w, bias, R_BS, b_S, 0.01, pinv, max_Am2, out)
        norm_ref, finite_ref, rods_ref = unloading_step(G, Js, w, bias, R_BS, b_S, 0.01, pinv, max_Am2)
        assert finite == finite_ref
        assert norm == pytest.approx(norm_ref, rel=1e-14, nan_ok=True)
        if not finite:
            np.testing.assert_array_equal(out, -1.0)  # left as it was
            continue
        saturated += np.max(np.abs(rods_ref) / max_Am2) >= 1.0 - 1e-12
        # the cross product cancels where B and h line up: equal to the vector's size, not each element's
        assert np.max(np.abs(out - rods_ref)) <= 1e-12 * np.max(np.abs(rods_ref))
    assert 300 < saturated < 2400, saturated  # both branches of the saturation taken
