"""The instrument's exposure (inside a physical sky zone with the door not fully closed, from truth), its
requirement row, the door's mission keys, and the door as the last line when every wheel is lost."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import door_params, load_mission, world_params
from hil_sim.sil.orchestrator import TruthRecorder
from hil_sim.sil.judge import ZoneSeries, evaluate, instrument_exposure
from hil_sim.world.world import World
from hil_sim.mission.loader import ConfigError

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = ROOT / "config" / "missions"


def _zone(margins) -> ZoneSeries:
    return ZoneSeries("sun", "sky", np.asarray(margins, dtype=float), [])


def test_exposure_is_time_and_depth_inside_with_the_door_not_shut() -> None:
    t = np.arange(8) * 0.5
    sun = _zone([3.0, 1.0, -0.5, -2.0, -1.0, 0.5, 2.0, 3.0])
    moon = _zone([9.0, 9.0, 9.0, 9.0, 9.0, 9.0, -0.2, 9.0])
    # no door: every sample inside a zone counts, 0.5 s each
    free = instrument_exposure(t, [sun, moon], None)
    assert free["exposure_s"] == pytest.approx(2.0) and free["inside_s"] == pytest.approx(2.0)
    assert free["depth_deg"] == pytest.approx(2.0) and free["first_t_s"] == 1.0 and not free["door"]
    # a door closing (0.3 open counts as open) and shut while the boresight is deepest
    door = np.array([1.0, 1.0, 0.3, 0.0, 0.0, 0.0, 1.0, 1.0])
    shut = instrument_exposure(t, [sun, moon], door)
    assert shut["exposure_s"] == pytest.approx(1.0) and shut["inside_s"] == pytest.approx(2.0)
    assert shut["depth_deg"] == pytest.approx(0.5) and shut["first_t_s"] == 1.0 and shut["door"]
    closed = instrument_exposure(t, [sun, moon], np.zeros(8))
    assert closed["exposure_s"] == 0.0 and closed["depth_deg"] == 0.0 and closed["first_t_s"] is None
    assert instrument_exposure(t, [], None)["exposure_s"] == 0.0


class _Door:
    position = 1.0


def _run_dir(where: Path, mission, door) -> Path:
    """A run folder as the SIL writes it, of a spacecraft that never acts, with the door truth of ``door``
    (an object with a ``position``; None: none recorded)."""
    world = World(world_params(mission), seed=1)
    zero = np.zeros(len(mission.spacecraft.wheels))
    recorder = TruthRecorder(10, len(zero), door=door)
    recorder.record(world, zero, True)
    for _ in range(10):
        world.step(1.0, zero)
        recorder.record(world, zero, True)
    where.mkdir(parents=True)
    recorder.save(where / "truth.npz")
    (where / "simulator.json").write_text(json.dumps({"wall_s": 1.0, "sim_s": 10.0, "clock": "lockstep"}))
    return where


def test_requirement_row_only_with_a_door(tmp_path: Path) -> None:
    with_door = load_mission(MISSIONS / "demo-pointing-door.yaml").model_copy(update={"duration_s": 10.0})
    run_dir = _run_dir(tmp_path / "door", with_door, _Door())
    with np.load(run_dir / "truth.npz") as truth:
        assert truth["door_position"].tolist() == [1.0] * 11
    summary, _ = evaluate(run_dir, with_door)
    row = next(r for r in summary["requirements"] if r["name"] == "instrument exposure")
    assert row["value"] == 0.0 and row["pass"] and row["unit"] == "s" and row["limit"] == "<= 0"
    assert summary["exposure"]["door"] and summary["exposure"]["exposure_s"] == 0.0
    # a door mission whose run recorded no door truth cannot pass the row
    summary, _ = evaluate(_run_dir(tmp_path / "bare", with_door, None), with_door)
    row = next(r for r in summary["requirements"] if r["name"] == "instrument exposure")
    assert not row["pass"] and "no door truth" in row["detail"]
    # without a door: no row, no door truth in the file, the exposure reported all the same
    without = load_mission(MISSIONS / "demo-pointing.yaml").model_copy(update={"duration_s": 10.0})
    run_dir = _run_dir(tmp_path / "none", without, None)
    with np.load(run_dir / "truth.npz") as truth:
        assert "door_position" not in truth.files
    summary, _ = evaluate(run_dir, without)
    assert "instrument exposure" not in [r["name"] for r in summary["requirements"]]
    assert summary["exposure"] == {"door": False, "exposure_s": 0.0, "depth_deg": 0.0, "inside_s": 0.0,
                                   "first_t_s": None}


def _mission_data(name: str) -> dict:
    return yaml.safe_load((MISSIONS / f"{name}.yaml").read_text())


def test_door_keys_are_checked_where_they_are_written() -> None:
    data = _mission_data("demo-pointing")
    data["faults"] = [{"kind": "door_stuck_open", "message": "DOOR_STATUS", "start_s": 1.0, "end_s": 2.0}]
    with pytest.raises(ConfigError, match=r"faults\[0\]\.kind.*no door"):
        load_mission("m.yaml", text=yaml.safe_dump(data))
    data = _mission_data("demo-pointing")
    data["flight_software"]["door"] = {"close_time_s": 1.0, "open_time_s": 1.0}
    with pytest.raises(ConfigError, match=r"flight_software\.door.*does not have"):
        load_mission("m.yaml", text=yaml.safe_dump(data))
    data = _mission_data("demo-pointing-door")
    data["faults"] = [{"kind": "door_slow", "message": "IMU_RATE", "start_s": 1.0, "end_s": 2.0}]
    with pytest.raises(ConfigError) as err:
        load_mission("m.yaml", text=yaml.safe_dump(data))
    assert "a door failure names a door frame" in str(err.value) and "needs delay_s" in str(err.value)


def test_the_flight_software_knows_the_door_as_built_unless_told_otherwise() -> None:
    mission = load_mission(MISSIONS / "demo-pointing-door.yaml")
    door = mission.flight_software.door
    assert (door.close_time_s, door.open_time_s) == (1.0, 2.0)
    assert door_params(mission).close_time_s == 1.0 and not door_params(mission).initially_open
    data = _mission_data("demo-pointing-door")
    data["flight_software"]["door"] = {"close_time_s": 1.5, "guard_deg": 1.0}
    mission = load_mission("m.yaml", text=yaml.safe_dump(data))
    assert (mission.flight_software.door.close_time_s, mission.flight_software.door.open_time_s) == (1.5, 2.0)
    assert mission.flight_software.door.guard_deg == 1.0
    assert load_mission(MISSIONS / "demo-pointing.yaml").flight_software.door is None
    assert door_params(load_mission(MISSIONS / "demo-pointing.yaml")) is None


def _wheels_lost(name: str, duration_s: float = 240.0):
    data = _mission_data(name)
    data["duration_s"] = duration_s
    data["timeline"] = data["timeline"][:1]
    data["faults"] = [{"kind": "drop", "message": f"RW{n}_CMD", "start_s": 40.0, "end_s": 600.0} for n in range(1, 5)]
    return load_mission("m.yaml", text=yaml.safe_dump(data))


def test_every_wheel_lost_mid_slew_the_door_keeps_the_exposure_at_zero() -> None:
    from hil_sim.campaign.fast import run_fast

    # at 40 s the slew runs at 1 deg/s toward the Sun zone 18 deg away: with no wheel left the boresight
    # coasts on, 5 deg past the Sun zone and then 10 deg deep through the Moon cone (182-212 s). Without a
    # door that is exposure; with one, the door shuts first (and reopens between the zones)
    bare = run_fast(_wheels_lost("demo-pointing"), 20260425).metrics
    assert bare["min_margin_deg"] < -5.0 and bare["instrument_exposure_s"] > 10.0
    assert bare["instrument_exposure_depth_deg"] == pytest.approx(-bare["min_margin_deg"])
    doored = run_fast(_wheels_lost("demo-pointing-door"), 20260425).metrics
    assert doored["min_margin_deg"] == bare["min_margin_deg"]  # the same flight: the door moves no body
    assert doored["instrument_exposure_s"] == 0.0 and doored["instrument_exposure_depth_deg"] == 0.0
    assert doored["door_closes"] >= 1


def _fly_with_events(mission, seed: int) -> tuple[dict, list]:
    """A fast-mode run's metrics and every event its flight software raised, as (name, arguments)."""
    from hil_sim.campaign import fast

    events: list = []
    recorder = fast._EventRecorder.event

    def keep(self, name, /, time_s=None, **args):
        events.append((name, args))
        return recorder(self, name, time_s=time_s, **args)

    fast._EventRecorder.event = keep
    try:
        return fast.run_fast(mission, seed).metrics, events
    finally:
        fast._EventRecorder.event = recorder


def test_a_door_stuck_open_is_reported_and_its_exposure_judged() -> None:
    from hil_sim.campaign import fast

    mission = _wheels_lost("demo-pointing-door")
    # the door jams open at 30 s, before the wheels are lost: the flight software commands it shut and
    # reports the stall; the exposure is what it is without a door
    stuck = mission.faults[0].model_copy(update={"kind": "door_stuck_open", "message": "DOOR_STATUS",
                                                 "start_s": 30.0, "end_s": 600.0})
    mission = mission.model_copy(update={"faults": [stuck, *mission.faults]})
    metrics, events = _fly_with_events(mission, 20260425)
    bare = fast.run_fast(_wheels_lost("demo-pointing"), 20260425).metrics
    assert metrics["door_closes"] >= 1
    assert {"fault": "STALLED"} in [{"fault": a["fault"]} for n, a in events if n == "DOOR_FAULT"]
    assert bare["instrument_exposure_s"] > 10.0
    assert metrics["instrument_exposure_s"] == pytest.approx(bare["instrument_exposure_s"])


@pytest.mark.slow
def test_sil_run_shuts_the_door_over_the_bus(tmp_path: Path) -> None:
    """`keepout sil run` (simulator, flight software and ground as three processes on one bus) of every wheel
    lost: DOOR_CMD and DOOR_STATUS on the bus every tick, the door shut before the Moon cone, exposure 0."""
    import subprocess
    import sys

    path = tmp_path / "door-wheels-lost.yaml"
    path.write_text(yaml.safe_dump(_wheels_lost("demo-pointing-door").model_dump(mode="json")))
    proc = subprocess.run([sys.executable, "-m", "cli", "sil", "run", str(path), "--bus", "udp_multicast",
                           "--out", str(tmp_path / "runs"), "--no-progress"], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    run_dir = next((tmp_path / "runs").glob("demo-pointing-door-*"))
    summary = json.loads((run_dir / "summary.json").read_text())
    rows = {r["name"]: r for r in summary["requirements"]}
    assert rows["instrument exposure"]["pass"] and rows["instrument exposure"]["value"] == 0.0, proc.stdout
    assert not rows["keep-out margin moon"]["pass"]  # the boresight went in: the door kept the instrument out
    assert summary["exposure"]["inside_s"] > 10.0
    assert summary["events"]["by_name"].get("DOOR_CLOSING", 0) >= 1
    ids = [line.split()[2].split("#")[0] for line in (run_dir / "bus.candump.log").read_text().splitlines()]
    assert ids.count("010") == 2400  # SYNC: 240 s of 0.1 s ticks
    assert ids.count("030") == 2400 and ids.count("068") == 2400  # DOOR_CMD and DOOR_STATUS every tick


def test_in_quaternion_mode_the_door_watches_the_sky_zones() -> None:
    data = _mission_data("demo-quaternion")
    data["duration_s"] = 30.0
    data["timeline"] = [e for e in data["timeline"] if e["t_s"] <= 30.0]
    data["spacecraft"]["door"] = {"close_time_s": 1.0, "open_time_s": 2.0}
    data["flight_software"].setdefault("pointing", {})["zones"] = [
        {"name": "sun", "body": "sun", "geometry": {"shape": "cone", "half_angle_deg": 30.0}}]
    mission = load_mission("m.yaml", text=yaml.safe_dump(data))
    metrics, events = _fly_with_events(mission, 1)
    # the attitude zones are the guidance's margins there; the door opened on the boresight's sky margin
    opening = [a for n, a in events if n == "DOOR_OPENING"]
    assert len(opening) == 1 and opening[0]["margin_deg"] == pytest.approx(metrics["margin_sun_deg"], abs=3.0)
