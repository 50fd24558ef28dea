"""The telemetry dictionary: contents required by the brief, consistency, JSON export, arg coding."""
from __future__ import annotations

import json
import math
import string
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from comms import dictionary as d
from comms.dictionary import (
    DICTIONARY,
    Arg,
    ArgError,
    ArgTruncatedError,
    Channel,
    CommandDef,
    DictionaryError,
    LimitState,
    Limits,
    PacketDef,
    TelemetryDictionary,
    coerce_arg,
    decode_args,
    encode_args,
)

REPO = Path(__file__).resolve().parents[2]
COMMITTED_JSON = REPO / "config" / "telemetry_dictionary.json"


def test_committed_json_equals_generated() -> None:
    assert COMMITTED_JSON.exists(), "run `keepout config dictionary --out config/telemetry_dictionary.json`"
    assert COMMITTED_JSON.read_text() == DICTIONARY.to_json(), (
        "config/telemetry_dictionary.json is stale: regenerate with `keepout config dictionary`"
    )


def test_config_dictionary_writes_the_json_and_checks_a_stale_copy(tmp_path: Path, capsys) -> None:
    from cli.main import main

    out = tmp_path / "dictionary.json"
    assert main(["config", "dictionary", "--out", str(out)]) == 0
    assert out.read_text() == DICTIONARY.to_json()
    assert main(["config", "dictionary", "--check"]) == 0  # the committed file
    out.write_text(DICTIONARY.to_json().replace('"margin_min_deg"', '"margin_deg"', 1))
    assert main(["config", "dictionary", "--check", "--out", str(out)]) == 1
    assert "out of date with comms/dictionary.py; run `keepout config dictionary`" in capsys.readouterr().err


def test_json_round_trip_rebuilds_an_equal_dictionary() -> None:
    rebuilt = TelemetryDictionary.from_dict(json.loads(COMMITTED_JSON.read_text()))
    assert rebuilt.to_json() == DICTIONARY.to_json()
    assert rebuilt.channel("margin_min_deg").limits == DICTIONARY.channel("margin_min_deg").limits
    assert rebuilt.command("SET_GAINS").args == DICTIONARY.command("SET_GAINS").args


def test_load_reports_the_file_when_malformed(tmp_path: Path) -> None:
    bad = tmp_path / "dict.json"
    bad.write_text('{"version": "1.0", "packets": [{"name": "X"}]}')
    with pytest.raises(DictionaryError, match="malformed"):
        TelemetryDictionary.load(bad)
    with pytest.raises(DictionaryError, match=str(tmp_path / "missing.json")):
        TelemetryDictionary.load(tmp_path / "missing.json")


# The minimum channel set named in the team brief (vectors as _x/_y/_z, quaternions/arrays indexed).
BRIEF_GNC_CHANNELS = (
    ["mode"]
    + [f"q_est_NB_{i}" for i in range(4)]
    + [f"omega_est_BN_B_{a}" for a in "xyz"]
    + [f"omega_cmd_BN_B_{a}" for a in "xyz"]
    + [f"bias_est_B_{a}" for a in "xyz"]
    + ["cov_trace"]
    + [f"boresight_N_{a}" for a in "xyz"]
    + [f"target_N_{a}" for a in "xyz"]
    + ["pointing_error_deg", "att_error_deg", "active_zone"]
    + [f"margin_deg_{i}" for i in range(6)] + ["margin_min_deg"]
    + ["eps", "kappa"]
    + [f"wheel_speed_rad_s_{i}" for i in range(6)]
    + [f"wheel_torque_cmd_Nm_{i}" for i in range(6)]
    + ["st_valid", "imu_valid", "st_blind_source", "cycle", "exec_time_ms"]
)
BRIEF_HK_CHANNELS = ["cycles", "slips_gnc", "exec_max_ms_gnc", "exec_mean_ms_gnc", "bus_crc_errors",
                     "bus_alive_errors", "tc_accepted", "tc_rejected", "fdir_trips"]


@pytest.mark.parametrize("name", BRIEF_GNC_CHANNELS)
def test_brief_gnc_channels_present(name: str) -> None:
    assert DICTIONARY.channel_packet(name).name == "GNC"


@pytest.mark.parametrize("name", BRIEF_HK_CHANNELS)
def test_housekeeping_channels_present(name: str) -> None:
    assert DICTIONARY.channel_packet(name).name == "HK"


def test_units_follow_the_names() -> None:
    for name in DICTIONARY.channel_names:
        unit = DICTIONARY.channel(name).unit
        if "_deg_s" in name:
            assert unit == "deg/s", name
        elif name.endswith("_deg") or "_deg_" in name:
            assert unit == "deg", name
        elif "_rad_s" in name:
            assert unit == "rad/s", name
        elif "_Nms" in name:
            assert unit == "N*m*s", name
        elif "_Nm" in name:
            assert unit == "N*m", name
        elif name.endswith("_ms") or "_ms_" in name:
            assert unit == "ms", name


def test_severities_are_the_f_prime_set_in_order() -> None:
    assert [s.value for s in d.Severity] == [
        "FATAL", "WARNING_HI", "WARNING_LO", "COMMAND", "ACTIVITY_HI", "ACTIVITY_LO", "DIAGNOSTIC"]
    assert d.Severity.from_code(3) is d.Severity.COMMAND
    with pytest.raises(ValueError):
        d.Severity.from_code(7)


def test_required_commands_and_typed_args() -> None:
    names = {c.name for c in DICTIONARY.commands}
    assert {"NOOP", "RESET_COUNTERS", "SET_MODE", "SET_TARGET", "SET_GAINS"} <= names
    set_mode = DICTIONARY.command("SET_MODE")
    assert [(a.name, a.type) for a in set_mode.args] == [("mode", "ENUM")]
    assert set(set_mode.args[0].enum or ()) == {"SAFE", "POINTING", "QUATERNION", "DETUMBLE"}
    gains = DICTIONARY.command("SET_GAINS")
    assert [a.name for a in gains.args] == ["k1", "kappa", "eps", "rate_limit_deg_s"]
    assert all(a.type == "F64" and a.min is not None and a.max is not None for a in gains.args)
    target = DICTIONARY.command("SET_TARGET")
    assert target.args[0].enum == ("DIRECTION", "QUATERNION", "NADIR", "GROUND")  # appended: old codes kept
    assert len(target.args) == 5 and target.args[-1].default == 0.0
    assert DICTIONARY.command(target.opcode) is target


def test_ids_fit_their_fields_and_packets_fit_a_datagram() -> None:
    apids = [p.apid for p in DICTIONARY.packets] + [DICTIONARY.event_apid, DICTIONARY.tc_apid]
    assert len(set(apids)) == len(apids) and all(0 <= a < 2**11 for a in apids)
    assert all(0 <= c.opcode < 2**16 for c in DICTIONARY.commands)
    assert all(0 <= e.id < 2**16 for e in DICTIONARY.events)
    for packet in DICTIONARY.packets:
        size = d.packet_struct(packet).size + 6 + 8 + 2
        assert size < 1400, f"{packet.name} ({size} B) would fragment on a 1500-byte MTU"


def test_every_event_format_renders_with_its_args() -> None:
    samples = {"F32": 1.5, "F64": 2.5, "U8": 3, "I8": -1, "U16": 4, "I16": -2, "U32": 5, "I32": -3,
               "BOOL": True, "STRING": "text"}
    for event in DICTIONARY.events:
        args = {a.name: (a.enum[0] if a.enum else samples[a.type]) for a in event.args}
        message = event.format.format(**args)
        fields = {f for _, f, _, _ in string.Formatter().parse(event.format) if f}
        assert fields <= set(args), f"{event.name} format names {fields - set(args)}"
        assert message


def test_limits_margin_and_wheel_speed() -> None:
    margin = DICTIONARY.channel("margin_min_deg").limits
    assert margin is not None
    assert margin.check(5.0) is LimitState.GREEN
    assert margin.check(1.0) is LimitState.YELLOW
    assert margin.check(-0.01) is LimitState.RED
    assert margin.check(math.nan) is LimitState.GREEN  # unused slot: no value, not a violation
    wheel = DICTIONARY.channel("wheel_speed_rad_s_3").limits
    assert wheel is not None
    assert wheel.check(-550.0) is LimitState.YELLOW and wheel.check(650.0) is LimitState.RED
    assert Limits(yellow=(None, 0)).check(1) is LimitState.YELLOW


def test_inconsistent_definitions_are_refused() -> None:
    ch = Channel("a", "F32", "", "")
    with pytest.raises(DictionaryError, match="twice"):
        TelemetryDictionary((PacketDef("P", 1, "", "", (ch,)), PacketDef("Q", 2, "", "", (ch,))), (), ())
    with pytest.raises(DictionaryError, match="type"):
        TelemetryDictionary((PacketDef("P", 1, "", "", (Channel("b", "F16", "", ""),)),), (), ())
    with pytest.raises(DictionaryError, match="ENUM"):
        TelemetryDictionary((), (), (CommandDef("C", 1, "", (Arg("m", "ENUM"),)),))
    with pytest.raises(DictionaryError, match="opcode"):
        TelemetryDictionary((), (), (CommandDef("C", 1, ""), CommandDef("D", 1, "")))
    with pytest.raises(DictionaryError, match="known"):
        DICTIONARY.event("NOT_AN_EVENT")


def test_coerce_arg_errors_name_the_argument() -> None:
    k1 = DICTIONARY.command("SET_GAINS").args[0]
    with pytest.raises(ArgError, match="k1.*below minimum"):
        coerce_arg(k1, 0.0)
    with pytest.raises(ArgError, match="k1.*not finite"):
        coerce_arg(k1, math.nan)
    with pytest.raises(ArgError, match="k1.*not a number"):
        coerce_arg(k1, "fast")
    assert coerce_arg(k1, "0.5") == 0.5
    assert coerce_arg(k1, 1e9, check_range=False) == 1e9
    mode = DICTIONARY.command("SET_MODE").args[0]
    assert coerce_arg(mode, "pointing") == "POINTING"
    assert coerce_arg(mode, 2) == "QUATERNION"
    with pytest.raises(ArgError, match="mode.*not one of"):
        coerce_arg(mode, "SPIN")
    with pytest.raises(ArgError, match="U8 range"):
        coerce_arg(Arg("w", "U8"), 256)


def test_truncated_args_raise_the_truncation_error() -> None:
    args = DICTIONARY.command("SET_GAINS").args
    data = encode_args(args, {"k1": 1.0, "kappa": 2.0, "eps": 0.1, "rate_limit_deg_s": 1.0})
    assert len(data) == 32
    with pytest.raises(ArgTruncatedError):
        decode_args(args, data[:-1])


_ARG_TYPES = ["BOOL", "U8", "I8", "U16", "I16", "U32", "I32", "F64", "STRING", "ENUM"]


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_arg_encoding_round_trips(data: st.DataObject) -> None:
    types = data.draw(st.lists(st.sampled_from(_ARG_TYPES), min_size=1, max_size=6))
    args = tuple(Arg(f"a{i}", t, enum=("X", "Y", "Z") if t == "ENUM" else None) for i, t in enumerate(types))
    values = {}
    for arg in args:
        if arg.type in d._INT_RANGES:
            low, high = d._INT_RANGES[arg.type]
            values[arg.name] = data.draw(st.integers(low, high))
        elif arg.type == "F64":
            values[arg.name] = data.draw(st.floats(allow_nan=False))
        elif arg.type == "BOOL":
            values[arg.name] = data.draw(st.booleans())
        elif arg.type == "ENUM":
            values[arg.name] = data.draw(st.sampled_from(["X", "Y", "Z"]))
        else:
            values[arg.name] = data.draw(st.text(max_size=40))
    decoded, end = decode_args(args, encode_args(args, values))
    assert decoded == values
    assert end == len(encode_args(args, values))


def _event_calls_in_flight_code() -> list[tuple[str, int, str, set[str] | None]]:
    """(file, line, event name, keyword names or None if **kwargs) for every literal event call in fsw/."""
    import ast

    calls = []
    for path in sorted((REPO / "fsw").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("event", "_event") and node.args
                    and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
                continue
            receiver = node.func.value
            if isinstance(receiver, ast.Attribute) and receiver.attr.lower() == "dictionary":
                continue  # a dictionary lookup, not an emission
            if any(k.arg is None for k in node.keywords):
                keywords = None
            else:
                keywords = {k.arg for k in node.keywords if k.arg != "time_s"}
            calls.append((str(path.relative_to(REPO)), node.lineno, node.args[0].value, keywords))
    return calls


def test_flight_code_emits_only_dictionary_events_with_their_declared_args() -> None:
    problems = []
    for where, line, name, keywords in _event_calls_in_flight_code():
        try:
            declared = {a.name for a in DICTIONARY.event(name).args}
        except DictionaryError:
            problems.append(f"{where}:{line}: unknown event {name}")
            continue
        if keywords is not None and keywords != declared:
            problems.append(f"{where}:{line}: {name} args {sorted(keywords)} != declared {sorted(declared)}")
    assert not problems, "\n".join(problems)
