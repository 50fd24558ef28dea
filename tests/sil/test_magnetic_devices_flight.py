"""The magnetometer, sun sensors and magnetorquers end to end in one process (the fast mode's lockstep on a
virtual bus): the flight software's snapshot carries the field and the cells as the truth makes them, its
MTQ_COMMAND reaches the rods, and their torque m x B acts on the truth."""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import yaml

from comms.bus import Icd, open_bus
from fsw.assembly import build_flight_software
from gnc.attitude import quat_to_dcm
from gnc.magnetic import css_sun_direction
from hil_sim.campaign.fast import run_fast
from hil_sim.mission.model import load_mission, magnetic_device_params, world_params
from hil_sim.sil.lockstep import Simulator
from hil_sim.world import environment as env
from hil_sim.world.world import World

ROOT = Path(__file__).resolve().parents[2]
_channels = itertools.count()
NOISE_T = 5e-8


def _mission(tmp_path: Path, devices: bool = True):
    data = yaml.safe_load((ROOT / "config" / "missions" / "smallsat-example.yaml").read_text())
    if devices:
        data["spacecraft"].update(magnetometer={"noise_std_T": NOISE_T}, sun_sensors={"noise_std_mA": 0.002},
                                  magnetorquers={"max_dipole_Am2": [0.2, 0.2, 0.2]})
    data["duration_s"], data["timeline"] = 3.0, []
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_mission(path)


def _fly(mission, n_ticks: int, command_Am2=(0.0, 0.0, 0.0)):
    """Lockstep ticks of the simulator and the flight software in this process (as hil_sim.campaign.fast):
    per tick the truth's field and Sun in body axes at the tick, the snapshot the flight software made, and
    the dipole the rods held over the period."""
    icd = Icd()
    channel = f"virtual:magfsw{next(_channels)}"
    sim_bus, fsw_bus = open_bus(channel, light=True), open_bus(channel, light=True)
    world = World(world_params(mission), seed=5)
    sim = Simulator(world, sim_bus, icd, gnc_period_s=0.1, magnetic=magnetic_device_params(mission))
    now = [sim.t_s]
    cfg = mission.flight_software
    cfg = cfg.model_copy(update={"law": cfg.law.model_copy(update={"assumption_check": "off"})})
    fsw = build_flight_software(cfg, fsw_bus, icd, clock=lambda: now[0])
    fsw.mtq_command_Am2 = np.array(command_Am2, dtype=float)
    snapshots = []
    take = fsw.intake.snapshot
    fsw.intake.snapshot = lambda inputs, cycle: snapshots.append(take(inputs, cycle)) or snapshots[-1]
    rows = []
    try:
        for _ in range(n_ticks):
            now[0] = sim.t_s
            field = sim.magnetic.field_B_T(world) if sim.magnetic is not None else None
            sun_B = quat_to_dcm(world.batch.q_NB[0]).T @ world.batch.sun_N[0]
            sim.begin_tick()
            inputs = fsw.driver.collect_tick(0.0)
            fsw.run_cycle(inputs)
            sim.end_tick(wait_s=0.0)
            held = world.batch.B[env.ENV_DIPOLE:env.ENV_DIPOLE + 3, 0].copy() if sim.magnetic is not None else None
            rows.append((field, sun_B, snapshots[-1], held))
    finally:
        now[0] = sim.t_s
        fsw.shutdown()
        sim_bus.shutdown()
        fsw_bus.shutdown()
    return sim, fsw, rows


def test_the_snapshot_carries_the_field_and_the_cells_as_the_truth_makes_them(tmp_path) -> None:
    sim, fsw, rows = _fly(_mission(tmp_path), 10)
    fixed = 0
    for field, sun_B, snap, _ in rows:
        # the magnetometer's axes are the body's: the reading is the field within 5 sigma of noise and an LSB
        assert np.all(np.abs(snap.mag_S_T - field) < 5 * NOISE_T + 5e-9), (snap.mag_S_T, field)
        assert snap.css_mA.shape == (6,)
        sun_est = css_sun_direction(np.array(sim.magnetic.params.sun_sensors.normals_B), snap.css_mA)
        if sun_est is not None:  # three lit faces of the cube: the Sun within a couple of degrees
            assert np.degrees(np.arccos(np.clip(sun_est @ sun_B, -1, 1))) < 3.0
            fixed += 1
    assert fixed == len(rows)
    assert fsw.driver.sent["MTQ_COMMAND"] == 10
    # no rods command from the flight software (zero unless a law asks): the truth holds no rod dipole
    assert all(np.all(held == 0.0) for *_, held in rows)


def test_a_flight_software_dipole_reaches_the_rods_and_the_truth(tmp_path) -> None:
    mission = _mission(tmp_path)
    sim, fsw, rows = _fly(mission, 4, command_Am2=(0.1, -0.25, 0.05))
    # rod 2 clipped at its 0.2 A m^2; body axes are the rods' (default); held from the first tick on
    for *_, held in rows:
        assert held == pytest.approx([0.1, -0.2, 0.05], abs=1e-3)
    torque = sim.world.batch.environment_torques_B()[0, 2]
    expected = np.cross(held, sim.magnetic.field_B_T(sim.world))
    assert np.linalg.norm(expected) > 1e-7 and torque == pytest.approx(expected, rel=1e-9)


def test_without_the_keys_the_snapshot_has_no_magnetic_data_and_nothing_is_sent(tmp_path) -> None:
    mission = _mission(tmp_path, devices=False)
    assert mission.flight_software.magnetic_devices is None
    sim, fsw, rows = _fly(mission, 3)
    assert sim.magnetic is None and fsw.driver.sent["MTQ_COMMAND"] == 0
    assert all(np.all(np.isnan(snap.mag_S_T)) and snap.css_mA.shape == (0,) for _, _, snap, _ in rows)


def test_a_fast_mode_run_with_the_devices_completes(tmp_path) -> None:
    result = run_fast(_mission(tmp_path), seed=2)
    assert result.sim_time_s == pytest.approx(3.0, abs=0.11)
    assert result.metrics["unexpected_fdir_events"] == 0.0
