"""Each kind of mission-file error gives `file:line:col key.path: message`, all of them in one report.

Expected positions are found independently: by searching the edited text for the offending token,
not by asking the loader.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from hil_sim.mission.model import load_mission
from hil_sim.mission.loader import ConfigError

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "config" / "missions" / "demo-pointing.yaml"


def _position(text: str, needle: str, occurrence: int = 0) -> tuple[int, int]:
    """1-based (line, col) of the start of ``needle`` in ``text``."""
    starts = [m.start() for m in re.finditer(re.escape(needle), text)]
    offset = starts[occurrence]
    line = text.count("\n", 0, offset) + 1
    col = offset - (text.rfind("\n", 0, offset) + 1) + 1
    return line, col


def _load_edited(tmp_path: Path, *edits: tuple[str, str]) -> tuple[str, Path, ConfigError]:
    text = DEMO.read_text()
    for old, new in edits:
        assert old in text, f"test edit target {old!r} not in the demo mission"
        text = text.replace(old, new, 1)
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_mission(path)
    return text, path, info.value


def _line_for(err: ConfigError, key_path: str) -> str:
    lines = [str(p) for p in err.problems if p.path == key_path]
    assert lines, f"no problem at {key_path}; got:\n{err}"
    return lines[0]


def test_demo_mission_is_valid():
    mission = load_mission(DEMO)
    assert mission.name == "demo-pointing"
    assert len(mission.spacecraft.wheels) == len(mission.flight_software.spacecraft.wheels) == 4


def test_unknown_key_names_position_suggestion_and_allowed_keys(tmp_path):
    text, path, err = _load_edited(tmp_path, ("  rate_hz: 100\n", "  rate_hz: 100\n    rate_hzz: 5\n"))
    line, col = _position(text, "rate_hzz")
    msg = _line_for(err, "spacecraft.imu.rate_hzz")
    assert msg.startswith(f"{path}:{line}:{col} spacecraft.imu.rate_hzz: unknown key 'rate_hzz'")
    assert "did you mean 'rate_hz'?" in msg
    assert "saturation_rad_s" in msg  # the allowed keys are listed


def test_out_of_range_value_points_at_the_value(tmp_path):
    text, path, err = _load_edited(tmp_path, ("half_angle_deg: 15.0", "half_angle_deg: 95.0"))
    line, col = _position(text, "half_angle_deg: 95.0")
    col += len("half_angle_deg: ")
    msg = _line_for(err, "flight_software.pointing.zones[1].geometry.half_angle_deg")
    assert msg.startswith(f"{path}:{line}:{col} ")
    assert "less than 90" in msg and "(got 95.0)" in msg


def test_wrong_type(tmp_path):
    text, path, err = _load_edited(tmp_path, ("max_rate_deg_s: 1.0", "max_rate_deg_s: fast"))
    line, col = _position(text, "fast")
    msg = _line_for(err, "flight_software.spacecraft.max_rate_deg_s")
    assert msg.startswith(f"{path}:{line}:{col} ") and "valid number" in msg


def test_missing_required_key_points_at_its_parent(tmp_path):
    text, path, err = _load_edited(tmp_path, ("  instrument_boresight_B: [0.0, 0.0, 1.0]\n", ""))
    line, col = _position(text, "inertia_B_kgm2")  # first key of the spacecraft mapping
    msg = _line_for(err, "spacecraft.instrument_boresight_B")
    assert msg == (f"{path}:{line}:{col} spacecraft.instrument_boresight_B: "
                   "required key 'instrument_boresight_B' is missing")


def test_unknown_command_in_timeline_suggests_the_right_one(tmp_path):
    text, path, err = _load_edited(tmp_path, ("command: SET_TARGET, ra_dec_deg: [200.0", "command: SET_TARGT, "
                                                                                     "ra_dec_deg: [200.0"))
    line, col = _position(text, "SET_TARGT")
    msg = _line_for(err, "timeline[1].command")
    assert msg.startswith(f"{path}:{line}:{col} timeline[1].command: unknown command 'SET_TARGT'")
    assert "did you mean 'SET_TARGET'?" in msg and "SET_MODE" in msg


def test_duplicate_key_is_an_error_not_silently_overwritten(tmp_path):
    text, path, err = _load_edited(tmp_path, ("duration_s: 600\n", "duration_s: 600\nduration_s: 900\n"))
    first, _ = _position(text, "duration_s")
    line, col = _position(text, "duration_s", occurrence=1)
    msg = _line_for(err, "duration_s")
    assert msg.startswith(f"{path}:{line}:{col} duration_s: duplicate key (first given at line {first})")


def test_yaml_syntax_error_has_a_position(tmp_path):
    text, path, err = _load_edited(tmp_path, ("  semi_major_axis_km: 42164.0\n", "  semi_major_axis_km: [42164.0\n"))
    assert len(err.problems) == 1
    problem = err.problems[0]
    assert problem.file == str(path) and "is not closed" in problem.message
    bad_line, _ = _position(text, "[42164.0")
    assert bad_line <= problem.line <= bad_line + 2  # the parser notices at or just after the bracket


def test_non_unit_quaternion(tmp_path):
    text, path, err = _load_edited(tmp_path, ("q_NB: [0.166366,", "q_NB: [0.5,"))
    line, col = _position(text, "[0.5,")
    msg = _line_for(err, "initial_state.q_NB")
    assert msg.startswith(f"{path}:{line}:{col} ") and "quaternion norm is" in msg


def test_unphysical_inertia(tmp_path):
    text, path, err = _load_edited(tmp_path, ("- [-0.3, 0.4, 31.0]", "- [-0.3, 0.4, 120.0]"))
    msg = _line_for(err, "spacecraft.inertia_B_kgm2")
    assert "triangle inequality" in msg
    line, col = _position(text, "- [42.0, 0.6")
    assert msg.startswith(f"{path}:{line}:{col} ")


def test_cross_field_problems_are_reported_with_their_key_paths(tmp_path):
    text, path, err = _load_edited(
        tmp_path,
        ("wheel_speeds_rad_s: [30.0, -30.0, 30.0, -30.0]", "wheel_speeds_rad_s: [30.0, -30.0, 30.0]"),
        ("{t_s: 300.0,", "{t_s: 900.0,"),
        ("  epoch_utc: 2026-04-25T12:00:00Z\n  initial_mode", "  epoch_utc: 2026-04-25T12:00:05Z\n  initial_mode"),
    )
    assert "3 speeds given for 4 wheels" in _line_for(err, "initial_state.wheel_speeds_rad_s")
    line, col = _position(text, "900.0")
    assert _line_for(err, "timeline[1].t_s").startswith(f"{path}:{line}:{col} timeline[1].t_s: t_s = 900.0 s is after")
    assert "differs from the mission epoch" in _line_for(err, "flight_software.epoch_utc")


def test_every_problem_in_one_report(tmp_path):
    text = DEMO.read_text()
    for old, new in (("duration_s: 600\n", "duration_s: 600\nseedd: 3\n"),
                     ("  rate_hz: 100\n", "  rate_hz: -3\n"),
                     ("half_angle_deg: 15.0", "half_angle_deg: 15.0, radius: 3"),
                     ("max_rate_deg_s: 1.0", "max_rate_deg_s: fast")):
        text = text.replace(old, new, 1)
    path = tmp_path / "many.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_mission(path)
    paths = {p.path for p in info.value.problems}
    assert {"seedd", "spacecraft.imu.rate_hz", "flight_software.pointing.zones[1].geometry.radius",
            "flight_software.spacecraft.max_rate_deg_s"} <= paths
    # one line per problem, each clickable file:line:col
    rendered = str(info.value).splitlines()
    assert len(rendered) == len(info.value.problems) >= 4
    assert all(re.match(rf"{re.escape(str(path))}:\d+:\d+ \S+: ", line) for line in rendered)


@pytest.mark.parametrize("content, expected", [
    ("", "the file is empty"),
    ("- just\n- a list\n", "the top level must be a mapping"),
    ("name: a\n---\nname: b\n", "more than one YAML document"),
])
def test_file_level_problems(tmp_path, content, expected):
    path = tmp_path / "m.yaml"
    path.write_text(content)
    with pytest.raises(ConfigError) as info:
        load_mission(path)
    assert expected in str(info.value)
    assert str(info.value).startswith(f"{path}:")


def test_missing_file():
    with pytest.raises(ConfigError, match="file not found"):
        load_mission("/nonexistent/mission.yaml")


def test_config_validate_cli_prints_every_problem(tmp_path, capsys):
    from cli.main import main

    text = DEMO.read_text().replace("duration_s: 600\n", "duration_s: -1\nseedd: 3\n", 1)
    path = tmp_path / "cli.yaml"
    path.write_text(text)
    assert main(["config", "validate", str(path)]) == 1
    err = capsys.readouterr().err
    assert f"{path}:" in err and "duration_s: Input should be greater than 0" in err and "seedd" in err
    assert main(["config", "validate", str(DEMO)]) == 0


# -- YAML syntax errors in plain words, with the fix -------------------------------

def _syntax_error(tmp_path: Path, old: str, new: str) -> tuple[str, Path, str]:
    text, path, err = _load_edited(tmp_path, (old, new))
    assert len(err.problems) == 1, str(err)
    return text, path, str(err.problems[0])


def test_a_tab_says_use_spaces(tmp_path):
    text, path, msg = _syntax_error(tmp_path, "  inclination_deg: 5.0\n", "\tinclination_deg: 5.0\n")
    line, col = _position(text, "\tinclination_deg")
    assert msg == f"{path}:{line}:{col}: a tab character: YAML does not allow tabs here; use spaces for " \
                  "indentation (and after ':')"


def test_a_key_indented_more_than_its_neighbour_names_both(tmp_path):
    text, path, msg = _syntax_error(tmp_path, "  inclination_deg: 5.0\n", "   inclination_deg: 5.0\n")
    line, col = _position(text, "inclination_deg: 5.0")
    prev_line, _ = _position(text, "semi_major_axis_km")
    assert msg == (f"{path}:{line}:{col}: 'inclination_deg' is indented 3 spaces, more than 'semi_major_axis_km' on "
                   f"line {prev_line} (2 spaces), which already has a value, so YAML reads this line as part of "
                   "that value; indent it 2 spaces to line up with 'semi_major_axis_km'")


def test_a_key_between_two_columns_names_the_keys_it_could_line_up_with(tmp_path):
    text, path, msg = _syntax_error(tmp_path, "    bias_B_rad_s:", "   bias_B_rad_s:")
    line, col = _position(text, "bias_B_rad_s")
    sibling_line, _ = _position(text, "    bias_random_walk_rad_s_per_sqrt_s")
    parent_line, _ = _position(text, "  imu:")
    assert msg.startswith(f"{path}:{line}:{col}: 'bias_B_rad_s' is indented 3 spaces, which lines up with nothing "
                          f"above it ('bias_random_walk_rad_s_per_sqrt_s' (line {sibling_line}) at 4 spaces, 'imu' (line {parent_line}) at 2 spaces)")
    assert msg.endswith("indent it 4 spaces to line up with 'bias_random_walk_rad_s_per_sqrt_s' or 2 spaces to "
                        "line up with 'imu'")


def test_an_unclosed_list_points_at_its_bracket(tmp_path):
    text, path, msg = _syntax_error(tmp_path, "  semi_major_axis_km: 42164.0\n", "  semi_major_axis_km: [42164.0\n")
    line, col = _position(text, "[42164.0")
    assert f"the '[' opened at line {line}, column {col} is not closed" in msg and msg.startswith(f"{path}:")
