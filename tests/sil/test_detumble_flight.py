"""DETUMBLE flown in fast mode (the simulator and the flight software in lockstep in one process): the mode's
transitions (SAFE after the dwell below the rate threshold, not before), the B-dot dipole on the truth taking
rotational energy away while the wheels get zero torque and the door stays shut, the mission keys refused
with the key and the fix named, and the shipped detumble mission reaching DETUMBLE_COMPLETE."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import hil_sim.campaign.fast as fast
from hil_sim.campaign.fast import run_fast
from hil_sim.mission.loader import ConfigError
from hil_sim.mission.model import load_mission

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "config" / "missions" / "detumble.yaml"


def _data() -> dict:
    return yaml.safe_load(MISSION.read_text())


def _load(tmp_path: Path, data: dict):
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_mission(path)


def _short(tmp_path: Path, duration_s: float, omega_deg_s, **detumble):
    data = _data()
    data["duration_s"], data["timeline"] = duration_s, []
    data["initial_state"]["omega_BN_B_rad_s"] = [math.radians(w) for w in omega_deg_s]
    data["flight_software"]["detumble"].update(detumble)
    data["requirements"].pop("max_detumble_time_s")
    return _load(tmp_path, data)


@pytest.fixture
def all_events(monkeypatch):
    """Every event of a fast run in its result (fast mode keeps only the FDIR ones)."""
    monkeypatch.setattr(fast, "_RESULT_EVENTS", ("DETUMBLE_STARTED", "DETUMBLE_COMPLETE", "MODE_CHANGED",
                                                  "DOOR_OPENING", "DOOR_CLOSING", "FDIR_TRIPPED"))


def _named(result, name: str) -> list[tuple[float, str]]:
    return [(float(e.split(" ", 1)[0]), e) for e in result.events if e.split(" ")[1] == name]


def test_safe_after_the_dwell_below_the_threshold_not_before(tmp_path, all_events) -> None:
    # 0.3 deg/s at separation: below the 0.5 deg/s threshold from the first gyro sample
    mission = _short(tmp_path, 12.0, [0.2, -0.2, 0.1], dwell_s=5.0)
    result = run_fast(mission, seed=1)
    assert _named(result, "DETUMBLE_STARTED")
    (t_done, done), = _named(result, "DETUMBLE_COMPLETE")
    assert 5.0 <= t_done <= 5.3, done  # the dwell from the first cycles' samples, not earlier
    (t_mode, mode), = _named(result, "MODE_CHANGED")
    assert t_mode == t_done and "'to_mode': 'SAFE'" in mode and "AUTONOMOUS" in mode
    assert result.metrics["detumble_time_s"] == pytest.approx(t_done)
    # a longer dwell than the run: still detumbling at the end, nothing raised
    longer = run_fast(_short(tmp_path, 12.0, [0.2, -0.2, 0.1], dwell_s=20.0), seed=1)
    assert not _named(longer, "DETUMBLE_COMPLETE") and not _named(longer, "MODE_CHANGED")
    assert longer.metrics["detumble_time_s"] == math.inf


def test_bdot_takes_energy_away_with_the_wheels_idle_and_the_door_shut(tmp_path, all_events) -> None:
    mission = _short(tmp_path, 120.0, [4.0, -5.0, 3.0])
    result = run_fast(mission, seed=2)
    assert not _named(result, "DETUMBLE_COMPLETE") and not _named(result, "DOOR_OPENING")
    traj = result.trajectory
    q = traj["q_NB"]
    assert len(q) > 1000
    J = np.array(mission.spacecraft.inertia_B_kgm2)
    # the truth's rate is not in the fast-mode trajectory: the recorded attitudes' change over a tick
    from scipy.spatial.transform import Rotation

    r = Rotation.from_quat(np.roll(q, -1, axis=1))  # scipy is scalar last
    w = (r[:-1].inv() * r[1:]).as_rotvec() / np.diff(traj["t_s"])[:, None]
    energy = 0.5 * np.einsum("ij,jk,ik->i", w, J, w)
    first, last = energy[:100].mean(), energy[-100:].mean()
    assert last < 0.95 * first  # the rods (1 A m^2, ~30 uT) remove several percent in two minutes
    # zero motor torque: the wheels keep their inertial spin (zero); what they show is the body's own rate
    # change seen from the body (0.15 rad/s, 0.02 % of their limit), not momentum taken from it
    assert result.metrics["peak_wheel_speed_fraction"] < 0.001
    assert result.metrics["instrument_exposure_s"] == 0.0


@pytest.mark.parametrize("section, key, words", [
    ("spacecraft", "magnetorquers", ("detumble", "magnetorquers")),           # B-dot needs the rods
    ("spacecraft", "door", ("spacecraft.door", "cannot steer")),              # and, with zones, the door
    ("flight_software", "detumble", ("initial_mode", "flight_software.detumble")),
])
def test_detumble_mission_keys_refused_with_the_key_and_the_fix(tmp_path, section, key, words) -> None:
    data = _data()
    del data[section][key]
    with pytest.raises(ConfigError) as info:
        _load(tmp_path, data)
    assert all(w in str(info.value) for w in words), str(info.value)


def test_set_mode_detumble_needs_the_section(tmp_path) -> None:
    data = yaml.safe_load((ROOT / "config" / "missions" / "smallsat-example.yaml").read_text())
    data["timeline"].append({"t_s": 100.0, "command": "SET_MODE", "mode": "DETUMBLE"})
    with pytest.raises(ConfigError) as info:
        _load(tmp_path, data)
    assert any(p.path == "timeline[1].mode" and "flight_software.detumble" in str(p) for p in info.value.problems), \
        str(info.value)


@pytest.mark.slow
def test_the_detumble_mission_detumbles_then_points(all_events) -> None:
    mission = load_mission(MISSION)
    result = run_fast(mission, seed=mission.seed)
    m = result.metrics
    assert m["detumble_time_s"] <= mission.requirements.max_detumble_time_s
    assert m["instrument_exposure_s"] == 0.0 and m["unexpected_fdir_events"] == 0
    assert m["final_error_deg"] < mission.requirements.max_final_pointing_error_deg
    assert m["settling_time_s"] <= mission.requirements.max_settling_time_s
