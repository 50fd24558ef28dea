"""The magnetometer, sun sensors and magnetorquer rods as CAN devices in the lockstep tick: their frames counted
in SYNC, the rods' command applied to the truth as m x B, their field in the magnetometer, and nothing of them
without the mission keys."""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import yaml

from comms.bus import Icd, open_bus
from comms.bus.icd import E2ESender
from gnc.attitude import quat_to_dcm
from hil_sim.mission.model import load_mission, magnetic_device_params, world_params
from hil_sim.sil.lockstep import Simulator
from hil_sim.world.magnetic_devices import body_dipole
from hil_sim.world.world import World

ROOT = Path(__file__).resolve().parents[2]
_channels = itertools.count()
DEVICE_FRAMES = ("MAG_FIELD", "CSS_CURRENTS", "MTQ_STATUS")
COUPLING = [[2e-6, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1e-6]]  # T per A m^2: rods 1 and 3 seen by the sensor


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


def _mission(tmp_path: Path, devices: bool = True):
    data = yaml.safe_load((ROOT / "config" / "missions" / "smallsat-example.yaml").read_text())
    if devices:
        data["spacecraft"].update(magnetometer={"noise_std_T": 5e-8}, sun_sensors={"noise_std_mA": 0.0},
                                  magnetorquers={"max_dipole_Am2": [0.2, 0.2, 0.2],
                                                 "magnetometer_coupling_T_per_Am2": COUPLING})
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_mission(path)


def _fly(icd: Icd, mission, n_ticks: int, command=None, until: int | None = None):
    """Lockstep ticks with a minimal flight side: MTQ_COMMAND ``command`` (up to tick ``until``), CYCLE_DONE.
    Returns the simulator and the frames heard per tick ([(name, signals, frames_following)])."""
    channel = f"virtual:mag{next(_channels)}"
    sim_bus, fsw_bus = open_bus(channel), open_bus(channel)
    world = World(world_params(mission), seed=3)
    sim = Simulator(world, sim_bus, icd, gnc_period_s=0.1, magnetic=magnetic_device_params(mission))
    tx = E2ESender(icd)
    heard = []
    try:
        for k in range(n_ticks):
            sim.begin_tick()
            frames = []
            while (msg := fsw_bus.recv(0.0)) is not None:
                frames.append(icd.decode(msg))
            heard.append(frames)
            if command is not None and (until is None or k < until):
                fsw_bus.send(tx.frame("MTQ_COMMAND", dict(zip(("dipole_1", "dipole_2", "dipole_3"), command))))
            fsw_bus.send(tx.frame("CYCLE_DONE", {"tick": k}))
            sim.end_tick(wait_s=0.0)
    finally:
        sim_bus.shutdown()
        fsw_bus.shutdown()
    return sim, heard


def test_every_tick_carries_the_three_frames_counted_in_sync(icd: Icd, tmp_path) -> None:
    sim, heard = _fly(icd, _mission(tmp_path), 5, command=(0.1, 0.0, 0.0))
    for frames in heard:
        names = [n for n, _ in frames]
        assert [n for n in names if n in DEVICE_FRAMES] == list(DEVICE_FRAMES)
        sync = dict(frames)["SYNC"]
        assert sync["frames_following"] == len(frames) - 1
    css = dict(heard[-1])["CSS_CURRENTS"]
    cells = np.array([css[f"cell_{i}"] for i in range(1, 7)])
    # a cube of noiseless cosine cells in full Sun: opposite faces never both lit, the lit ones a unit vector
    assert css["n_cells"] == 6 and np.all(cells[0::2] * cells[1::2] == 0.0)
    assert np.linalg.norm(cells) == pytest.approx(1.0, abs=0.02)


def test_without_the_keys_nothing_of_them_is_on_the_bus(icd: Icd, tmp_path) -> None:
    sim, heard = _fly(icd, _mission(tmp_path, devices=False), 3)
    assert sim.magnetic is None
    assert not {n for frames in heard for n, _ in frames} & set(DEVICE_FRAMES)


def test_a_commanded_dipole_turns_the_truth_by_m_cross_b(icd: Icd, tmp_path) -> None:
    """Two runs alike but for the rods' command: the difference of their inertial angular momentum after one
    period is the rods' torque m x B (rod 2 clipped at 0.2 A m^2) over that period."""
    mission = _mission(tmp_path)
    command = (0.15, -0.5, 0.05)
    quiet, _ = _fly(icd, mission, 1, command=(0.0, 0.0, 0.0))
    active, heard = _fly(icd, mission, 1, command=command)
    world = active.world
    m_B = body_dipole(magnetic_device_params(mission).magnetorquers, np.array(command))
    assert m_B == pytest.approx([0.15, -0.2, 0.05])
    # the field at the period's start (the state is the same in both runs then)
    start = World(world_params(mission), seed=3)
    b_B = active.magnetic.field_B_T(start)
    expected_N = quat_to_dcm(start.batch.q_NB[0]) @ np.cross(m_B, b_B) * 0.1
    dh = world.angular_momentum_N() - quiet.world.angular_momentum_N()
    assert np.linalg.norm(expected_N) > 1e-7
    assert dh == pytest.approx(expected_N, rel=0.02, abs=1e-3 * np.linalg.norm(expected_N))
    status = dict(heard[0])["MTQ_STATUS"]  # sent before the first command: the rods hold nothing yet
    assert (status["dipole_1"], status["dipole_2"], status["saturated"]) == (0.0, 0.0, 0)


def test_the_magnetometer_reads_the_field_plus_the_rods_own_then_the_rods_time_out(icd: Icd, tmp_path) -> None:
    mission = _mission(tmp_path)
    command = (0.2, 0.1, 0.2)
    sim, heard = _fly(icd, mission, 12, command=command, until=6)
    mag = magnetic_device_params(mission).magnetometer
    rods_T = np.asarray(COUPLING) @ np.array(command)
    # tick 3: the truth's field (rods on since tick 0) against the reading, within 5 sigma of noise + an LSB
    truth = _replay_field(icd, mission, 3)
    reading = np.array([dict(heard[3])["MAG_FIELD"][f"b_{a}"] for a in "xyz"]) * 1e-6
    assert np.abs(reading - (truth + rods_T)) == pytest.approx(np.zeros(3), abs=5 * mag.noise_std_T + 5e-9)
    status = dict(heard[3])["MTQ_STATUS"]
    assert (status["dipole_1"], status["dipole_2"], status["dipole_3"], status["saturated"]) == (0.2, 0.1, 0.2, 0)
    # the last command came in tick 5; 0.3 s later the drive has zeroed the rods
    late = dict(heard[11])["MTQ_STATUS"]
    assert (late["dipole_1"], late["dipole_2"], late["dipole_3"]) == (0.0, 0.0, 0.0)
    assert sim.magnetic.rods_dipole_B(sim.t_s) == pytest.approx(np.zeros(3))


def _replay_field(icd: Icd, mission, tick: int) -> np.ndarray:
    """The field in body axes at tick ``tick`` of the same run (replayed to that tick's start)."""
    sim, _ = _fly(icd, mission, tick, command=(0.2, 0.1, 0.2))
    return sim.magnetic.field_B_T(sim.world)
