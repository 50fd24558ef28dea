"""spacecraft.magnetometer, .sun_sensors and .magnetorquers: optional, absent by default, mapped onto the truth
models' parameters, and refused at their key (file:line:col) when unphysical."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from hil_sim.mission.loader import ConfigError
from hil_sim.mission.model import load_mission, magnetic_device_params, world_params

ROOT = Path(__file__).resolve().parents[2]
SMALLSAT = ROOT / "config" / "missions" / "smallsat-example.yaml"
DEVICES = {"magnetometer": {"noise_std_T": 5e-8, "bias_S_T": [1e-7, 0.0, -2e-7]},
           "sun_sensors": {"full_scale_mA": 1.5, "noise_std_mA": 0.01},
           "magnetorquers": {"max_dipole_Am2": [0.2, 0.3, 0.4],
                             "axes_B": [[0.0, 0.6, 0.8], [1.0, 0.0, 0.0], [0.0, 0.8, -0.6]]}}


def _mission(tmp_path: Path, **devices):
    data = yaml.safe_load(SMALLSAT.read_text())
    data["spacecraft"].update(devices)
    path = tmp_path / "mission.yaml"
    return path, yaml.safe_dump(data, sort_keys=False)


def test_absent_by_default_in_every_shipped_mission() -> None:
    """A shipped mission has the devices only where its spacecraft names them (detumble.yaml)."""
    for path in sorted((ROOT / "config" / "missions").glob("*.yaml")):
        mission = load_mission(path)
        named = any(getattr(mission.spacecraft, k) is not None
                    for k in ("magnetometer", "sun_sensors", "magnetorquers"))
        assert (magnetic_device_params(mission) is not None) == named, path.name
    assert magnetic_device_params(load_mission(ROOT / "config" / "missions" / "smallsat-example.yaml")) is None


def test_the_keys_map_onto_the_truth_models(tmp_path) -> None:
    path, text = _mission(tmp_path, **DEVICES)
    p = magnetic_device_params(load_mission(path, text=text))
    assert p.magnetometer.noise_std_T == 5e-8 and p.magnetometer.bias_S_T == (1e-7, 0.0, -2e-7)
    assert p.sun_sensors.full_scale == 1.5 and len(p.sun_sensors.normals_B) == 6
    assert p.magnetorquers.max_dipole_Am2 == (0.2, 0.3, 0.4)
    assert p.magnetorquers.axes_B[0] == (0.0, 0.6, 0.8)
    # the Earth's field the devices see is the IGRF dipole at the epoch: |g10| about 29.4 uT in 2025
    assert 2.8e-5 < abs(p.geomagnetic_dipole_T[0]) < 3.1e-5


def test_devices_alone_leave_the_world_as_it_was(tmp_path) -> None:
    """The magnetometer and the sun sensors do not touch the truth's parameters."""
    path, text = _mission(tmp_path, magnetometer={}, sun_sensors={})
    with_devices = world_params(load_mission(path, text=text))
    assert with_devices == world_params(load_mission(SMALLSAT))


@pytest.mark.parametrize("device, key, value, says", [
    ("magnetorquers", "max_dipole_Am2", [0.2, 0.0, 0.2], "max_dipole_Am2[1]: Input should be greater than 0"),
    ("magnetorquers", "axes_B", [[1.0, 0.0, 0.0], [0.0, 0.9, 0.0], [0.0, 0.0, 1.0]], "rod axis 2 has norm 0.9"),
    ("sun_sensors", "normals_B", [[1.0, 0.0, 0.0], [0.0, 1.1, 0.0], [0.0, 0.0, 1.0]], "cell normal 2 has norm 1.1"),
    ("sun_sensors", "normals_B", [[1.0, 0.0, 0.0]] * 7, "normals_B: List should have at most 6 items"),
    ("sun_sensors", "full_scale_mA", 3.0, "full_scale_mA: Input should be less than or equal to 2.5"),
    ("magnetometer", "full_scale_T", 0.0, "full_scale_T: Input should be greater than 0"),
])
def test_an_unphysical_device_is_refused_at_its_key(tmp_path, device, key, value, says) -> None:
    path, text = _mission(tmp_path, **{device: {key: value}})
    with pytest.raises(ConfigError) as info:
        load_mission(path, text=text)
    (line,) = str(info.value).splitlines()
    assert line.startswith(f"{path}:") and says in line and f"spacecraft.{device}" in line, line
    assert line.split(":")[1].isdigit() and line.split(":")[2].split()[0].isdigit()  # file:line:col


def test_the_flight_software_knows_the_devices_from_the_truth_and_cannot_claim_others(tmp_path) -> None:
    path, text = _mission(tmp_path, magnetometer={}, magnetorquers={})
    known = load_mission(path, text=text).flight_software.magnetic_devices
    assert (known.magnetometer, known.sun_sensors, known.magnetorquers) == (True, False, True)
    assert load_mission(SMALLSAT).flight_software.magnetic_devices is None
    data = yaml.safe_load(text)
    data["flight_software"]["magnetic_devices"] = {"sun_sensors": True}
    with pytest.raises(ConfigError) as info:
        load_mission(path, text=yaml.safe_dump(data, sort_keys=False))
    (line,) = str(info.value).splitlines()
    assert "flight_software.magnetic_devices.sun_sensors" in line and "add spacecraft.sun_sensors" in line, line
