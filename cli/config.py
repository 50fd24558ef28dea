"""``keepout config schema | docs | validate FILE... | check FILE...``: editor schema, reference, validation,
physics report.

Imports stay light at module level (the CLI imports every area on start); pydantic models and the
maths load inside the handlers.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable


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

    docs = sub.add_parser("docs", help="write docs/missions.md, the mission-file reference, from the schema")
    docs.add_argument("--out", type=Path, default=None, help="where to write it (default: docs/missions.md); "
                      "'-' for stdout")
    docs.add_argument("--check", action="store_true",
                      help="do not write: exit 1 when the committed reference differs from the models")
    docs.set_defaults(func=_docs)

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


def _generated(args: argparse.Namespace, default: Path, text: Callable[[], str], command: str) -> int:
    """Write (``--out``, '-' for stdout) or ``--check`` a file generated from the mission models."""
    path = Path(args.out or default)
    if args.check:
        try:
            committed = path.read_text(encoding="utf-8")
        except OSError as exc:
            print(f"{path}: cannot read: {exc.strerror or exc}", file=sys.stderr)
            return 1
        if committed != text():
            print(f"{path}: out of date with the mission models; run `keepout config {command}`", file=sys.stderr)
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
    from hil_sim.mission.model import load_mission_marked, unit_warnings
    from hil_sim.mission.physics_checks import check_mission
    from hil_sim.mission.loader import ConfigError, ConfigFileError, format_path

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
            for loc, warning in unit_warnings(doc):  # sizes that suggest another unit
                line, col = doc.mark_for(loc)
                print(f"{doc.file}:{line}:{col} {format_path(loc)}: warning: {warning}", file=sys.stderr)
            print(f"{path}: valid")
    return status


def _status(exc: Exception) -> int:
    """Exit status for a file that failed to load: 2 when it cannot be read at all, 1 for its content."""
    from hil_sim.mission.loader import ConfigFileError

    return 2 if isinstance(exc, ConfigFileError) else 1


def _check(args: argparse.Namespace) -> int:
    from hil_sim.mission.model import load_mission_marked
    from hil_sim.mission.physics_checks import check_mission
    from hil_sim.mission.loader import ConfigError

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
