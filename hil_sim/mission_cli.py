"""``keepout config schema | validate FILE... | check FILE...``: editor schema, validation, physics report.

Imports stay light at module level (the CLI imports every area on start); pydantic models and the
maths load inside the handlers.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    config = subparsers.add_parser("config", help="mission files: JSON schema, validation, physics checks",
                                   description="Mission configuration tools.")
    sub = config.add_subparsers(dest="config_command", metavar="SUBCOMMAND")
    config.set_defaults(func=lambda args: (config.print_help(), 2)[1])

    schema = sub.add_parser("schema", help="write config/schema/mission.schema.json (draft-07) for editors")
    schema.add_argument("--out", type=Path, default=None,
                        help="where to write it (default: config/schema/mission.schema.json); '-' for stdout")
    schema.add_argument("--check", action="store_true",
                        help="do not write: exit 1 when the committed schema differs from the models")
    schema.set_defaults(func=_schema)

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

    from hil_sim.mission import SCHEMA_PATH, mission_json_schema, write_json_schema

    if args.check:
        path = args.out or SCHEMA_PATH
        try:
            committed = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            print(f"{path}: cannot read: {exc}", file=sys.stderr)
            return 1
        if committed != mission_json_schema():
            print(f"{path}: out of date with hil_sim/mission.py; run `keepout config schema`", file=sys.stderr)
            return 1
        print(f"{path}: up to date")
        return 0
    if args.out is not None and str(args.out) == "-":
        json.dump(mission_json_schema(), sys.stdout, indent=2)
        print()
        return 0
    path = write_json_schema(args.out) if args.out else write_json_schema()
    print(f"wrote {path}")
    return 0


def _validate(args: argparse.Namespace) -> int:
    from hil_sim.mission import load_mission_marked
    from hil_sim.physics_checks import check_mission
    from hil_sim.yaml_loader import ConfigError, ConfigFileError

    status = 0
    for path in args.files:
        try:
            mission, doc = load_mission_marked(path)
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            if not isinstance(exc, ConfigFileError):
                print(f"{path}: {len(exc.problems)} problem(s)", file=sys.stderr)
            status = max(status, _status(exc))
            continue
        # the physics errors that need no numerical sweep (targets, initial state, zone shapes, merges,
        # wheels): the same errors `config check` reports for them
        report = check_mission(mission, quick=True)
        if report.errors:
            print(report.format(doc, errors_only=True), file=sys.stderr)
            print(f"{path}: {len(report.errors)} problem(s)", file=sys.stderr)
            status = max(status, 1)
        else:
            for warning in mission.flight_software.tmtc.warnings():
                print(f"{path}: warning: {warning}", file=sys.stderr)
            print(f"{path}: valid")
    return status


def _status(exc: Exception) -> int:
    """Exit status for a file that failed to load: 2 when it cannot be read at all, 1 for its content."""
    from hil_sim.yaml_loader import ConfigFileError

    return 2 if isinstance(exc, ConfigFileError) else 1


def _check(args: argparse.Namespace) -> int:
    from hil_sim.mission import load_mission_marked
    from hil_sim.physics_checks import check_mission
    from hil_sim.yaml_loader import ConfigError

    status = 0
    for path in args.files:
        try:
            mission, doc = load_mission_marked(path)
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            status = max(status, _status(exc))
            continue
        report = check_mission(mission, step_s=args.step_s)
        print(f"== {path}")
        print(report.format(doc))
        if not report.ok:
            status = 1
    return status
