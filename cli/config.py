"""``keepout config schema | docs | dictionary | validate FILE... | check FILE...``: editor schema, reference,
telemetry dictionary, validation, physics report.

Imports stay light at module level (the CLI imports every area on start); pydantic models and the
maths load inside the handlers.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    config = subparsers.add_parser(
        "config", help="mission schema, validation, physics checks; the TM/TC dictionary",
        description="Configuration tools: mission files and the telemetry dictionary.")
    sub = config.add_subparsers(dest="config_command", metavar="SUBCOMMAND")
    config.set_defaults(func=lambda args: (config.print_help(), 2)[1])

    for name, helptext, default, what, func in (
        ("schema", "write config/schema/mission.schema.json (draft-07) for editors",
         "config/schema/mission.schema.json", "schema differs from the models", _schema),
        ("docs", "write docs/missions.md, the mission-file reference, from the schema",
         "docs/missions.md", "reference differs from the models", _docs),
        ("dictionary", "write config/telemetry_dictionary.json, the TM/TC dictionary the ground reads",
         "config/telemetry_dictionary.json", "dictionary differs from comms/dictionary.py", _dictionary),
    ):
        generated = sub.add_parser(name, help=helptext)
        generated.add_argument("--out", type=Path, default=None,
                               help=f"where to write it (default: {default}); '-' for stdout")
        generated.add_argument("--check", action="store_true", help=f"do not write: exit 1 when the committed {what}")
        generated.set_defaults(func=func)

    validate = sub.add_parser("validate", help="check mission files against the schema; every problem as "
                              "file:line:col key.path: message")
    validate.add_argument("files", nargs="+", type=Path, metavar="FILE")
    validate.set_defaults(func=_validate)

    check = sub.add_parser("check", help="validate, then the physics checks (paper's assumptions over the "
                           "whole run as zones move, kappa, wheel authority) with the numbers")
    check.add_argument("files", nargs="+", type=Path, metavar="FILE")
    check.add_argument("--step-s", type=float, default=None,
                       help="time step of the sweep over the run [s] (default: duration/200, at most 60 s)")
    check.set_defaults(func=_check)


def _schema(args: argparse.Namespace) -> int:
    import json

    from hil_sim.mission.model import SCHEMA_PATH, mission_json_schema

    return _generated(args, SCHEMA_PATH, lambda: json.dumps(mission_json_schema(), indent=2) + "\n", "schema")


def _docs(args: argparse.Namespace) -> int:
    from hil_sim.mission.docs import DOCS_PATH, mission_docs

    return _generated(args, DOCS_PATH, mission_docs, "docs")


def _dictionary(args: argparse.Namespace) -> int:
    from comms.dictionary import DICTIONARY
    from keepout_config import config_path

    return _generated(args, config_path("telemetry_dictionary.json"), DICTIONARY.to_json, "dictionary",
                      source="comms/dictionary.py")


def _generated(args: argparse.Namespace, default: Path, text: Callable[[], str], command: str,
               source: str = "the mission models") -> int:
    """Write (``--out``, '-' for stdout) or ``--check`` a file generated from ``source``."""
    path = Path(args.out or default)
    if args.check:
        try:
            committed = path.read_text(encoding="utf-8")
        except OSError as exc:
            print(f"{path}: cannot read: {exc.strerror or exc}", file=sys.stderr)
            return 1
        if committed != text():
            print(f"{path}: out of date with {source}; run `keepout config {command}`", file=sys.stderr)
            return 1
        print(f"{path}: up to date")
        return 0
    if str(args.out) == "-":
        sys.stdout.write(text())
        return 0
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text(), encoding="utf-8")
    print(f"wrote {path}")
    return 0


def _validate(args: argparse.Namespace) -> int:
    return _each_mission(args.files, _validate_one, count_problems=True)


def _validate_one(path: Path, mission: Any, doc: Any) -> int:
    from hil_sim.mission.loader import format_path
    from hil_sim.mission.model import unit_warnings
    from hil_sim.mission.physics_checks import check_mission

    # the physics errors that need no numerical sweep (targets, initial state, zone shapes, merges,
    # wheels): the same errors `config check` reports for them
    report = check_mission(mission, quick=True)
    if report.errors:
        print(report.format(doc, errors_only=True), file=sys.stderr)
        print(f"{path}: {len(report.errors)} problem(s)", file=sys.stderr)
        return 1
    for warning in mission.flight_software.tmtc.warnings():
        print(f"{path}: warning: {warning}", file=sys.stderr)
    for loc, warning in unit_warnings(doc):  # sizes that suggest another unit
        line, col = doc.mark_for(loc)
        print(f"{doc.file}:{line}:{col} {format_path(loc)}: warning: {warning}", file=sys.stderr)
    print(f"{path}: valid")
    return 0


def _check(args: argparse.Namespace) -> int:
    from hil_sim.mission.physics_checks import check_mission

    def check_one(path: Path, mission: Any, doc: Any) -> int:
        report = check_mission(mission, step_s=args.step_s)
        print(f"== {path}")
        print(report.format(doc))
        return 0 if report.ok else 1

    return _each_mission(args.files, check_one)


def _each_mission(files: list[Path], judge: Callable[[Path, Any, Any], int], count_problems: bool = False) -> int:
    """Load each mission file (with its marks) and ``judge(path, mission, doc)`` it; returns the worst exit
    status: 2 for a file that cannot be read at all, 1 for its content, else the judge's.

    A file that fails to load is reported and skipped; count_problems adds a line with its number of problems.
    """
    from hil_sim.mission.loader import ConfigError, ConfigFileError
    from hil_sim.mission.model import load_mission_marked

    status = 0
    for path in files:
        try:
            mission, doc = load_mission_marked(path)
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            unreadable = isinstance(exc, ConfigFileError)
            if count_problems and not unreadable:
                print(f"{path}: {len(exc.problems)} problem(s)", file=sys.stderr)
            status = max(status, 2 if unreadable else 1)
            continue
        status = max(status, judge(path, mission, doc))
    return status
