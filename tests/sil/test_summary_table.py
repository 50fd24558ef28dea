"""The requirement table a person reads after `keepout sil run`: units, limits in the value's unit, rounded
numbers, no Python reprs; the printed wall time includes start-up."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from hil_sim.mission.model import load_mission, world_params
from hil_sim.sil.orchestrator import TruthRecorder
from hil_sim.sil.judge import _rounded, evaluate, format_summary
from hil_sim.world.world import World

ROOT = Path(__file__).resolve().parents[2]


def _drifting_run(tmp_path: Path, mission_name: str, duration_s: float = 20.0):
    """A run folder as the SIL writes it, of a spacecraft that never acts (a slew never settles, the
    expected FDIR trip never comes): the rows that print None or lists on the old table."""
    mission = load_mission(ROOT / "config" / "missions" / f"{mission_name}.yaml").model_copy(
        update={"duration_s": duration_s})
    world = World(world_params(mission), seed=1)
    n = int(duration_s)
    recorder = TruthRecorder(n, len(mission.spacecraft.wheels))
    zero = np.zeros(len(mission.spacecraft.wheels))
    recorder.record(world, zero, True)
    for _ in range(n):
        world.step(1.0, zero)
        recorder.record(world, zero, True)
    run_dir = tmp_path / mission_name
    run_dir.mkdir()
    recorder.save(run_dir / "truth.npz")
    (run_dir / "simulator.json").write_text(json.dumps({"wall_s": 0.7, "sim_s": duration_s, "clock": "lockstep"}))
    return run_dir, mission


@pytest.mark.parametrize("mission_name", ["demo-pointing", "fault-imu-dropout"])
def test_requirement_rows_have_units_rounded_values_and_limits_in_the_same_unit(tmp_path, mission_name):
    run_dir, mission = _drifting_run(tmp_path, mission_name)
    summary, _ = evaluate(run_dir, mission)
    rows = summary["requirements"]
    names = [r["name"] for r in rows]
    assert any(n.startswith("settling") for n in names) and "expected FDIR events" in names
    for r in rows:
        assert "unit" in r, r
        assert r["value"] is not None and not isinstance(r["value"], (list, dict)), r
        assert isinstance(r["limit"], str), r
        if isinstance(r["value"], float):
            assert float(f"{r['value']:.4g}") == r["value"], r  # rounded, no float noise
    units = {r["name"]: r["unit"] for r in rows}
    assert units["final pointing error"] == "deg" and units["peak wheel speed"].startswith("%")
    assert all(units[n] == "s" for n in names if n.startswith("settling"))

    table = format_summary(summary, total_wall_s=3.25)
    assert not re.search(r"\d\.\d{8,}", table), table  # float noise such as 139.90000000000865
    for row in rows:
        line = next(x for x in table.splitlines() if x.startswith(row["name"][:38]))
        cells = line[38:]  # value, limit, result
        assert "None" not in cells and "[" not in cells and "{" not in cells and "'" not in cells, line
        if row["unit"] and isinstance(row["value"], (int, float)):
            # "<value> <unit>  <op> <limit> <unit>": the limit is written in the value's unit
            assert line.count(row["unit"]) == 2, line
    assert "3.2 s wall including start-up (0.7 s flying" in table.splitlines()[-1]


def test_rounding_keeps_four_significant_digits():
    assert _rounded(139.90000000000865) == 139.9
    assert _rounded(0.000123456) == 0.0001235
    assert _rounded(np.float64(2.5)) == 2.5 and _rounded(np.int64(3)) == 3 and _rounded(True) is True
    assert _rounded(float("inf")) == float("inf")


def test_a_shortened_run_does_not_judge_targets_past_its_end_but_still_judges_the_rest(tmp_path):
    # demo-pointing commands its first slew at 10 s and allows it until the second target at 300 s: a run
    # shortened to 20 s (`--duration 20`) cannot have settled it, so the row is shown as not reached and
    # kept out of the verdict; the same run judged as the mission's whole duration fails that row.
    run_dir, mission = _drifting_run(tmp_path, "demo-pointing")
    shortened, _ = evaluate(run_dir, mission, planned_duration_s=600.0)
    full, _ = evaluate(run_dir, mission)
    rows = {r["name"]: r for r in shortened["requirements"]}
    settling = rows["settling (timeline[0])"]
    assert settling["judged"] is False and settling["value"] == "not reached"
    assert "shortened to 20 s" in settling["detail"] and "deadline at 600 s" in settling["detail"]
    final = rows["final pointing error"]
    assert final["judged"] is False and final["value"].startswith("not reached (")  # the error at the end shown
    assert final["value"].endswith(" deg at the end)") and float(final["value"].split("(")[1].split()[0]) > 1.0
    assert "peak wheel speed" in rows and "peak body rate" in rows and "keep-out margin sun" in rows
    full_rows = {r["name"]: r for r in full["requirements"]}
    assert full_rows["settling (timeline[0])"]["pass"] is False
    assert "n/a" in format_summary(shortened, total_wall_s=1.0)
