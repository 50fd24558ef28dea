"""The ``keepout`` command line.

Each subcommand's module exposes ``add_cli(subparsers)``, which adds its parsers and sets ``func`` on
them; this file lists them (``_COMMAND_MODULES``) and runs the one asked for.
"""
from __future__ import annotations

import argparse
import sys

from cli import budget, bus, campaign, config, export, ground, init, paper, sil, sim, sky, truth, warmup
from cli import fsw as fsw_main

# Each module's add_cli(subparsers) adds its subcommand, in the order `keepout --help` lists them.
_COMMAND_MODULES = (
    paper,          # keepout paper
    config,         # keepout config schema|docs|dictionary|validate|check
    sil,            # keepout sil run
    fsw_main,       # keepout fsw MISSION (HIL bench: the flight software alone)
    sim,            # keepout sim MISSION (HIL bench: the simulator alone)
    bus,            # keepout bus monitor|log|respond
    ground,         # keepout ground [send ...]
    campaign,       # keepout campaign run|rerun|baseline|compare|shrink
    init,           # keepout init DIR
    warmup,         # keepout warmup [--prune] (make setup, make wheel)
    export,         # keepout export RUN --format csv|mat|parquet
    sky,            # keepout sky MISSION --at T | --from T0 --to T1 --step S
    budget,         # keepout budget MISSION
    truth,          # keepout truth MISSION --duration D --out FILE.npz
)

EXIT_CANNOT_START = 3  # as `keepout sil run`: a part this command needs is missing (docs/running.md)
# optional parts and the extra that installs them
_EXTRAS = {"dask": "dask", "distributed": "dask"}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="keepout",
        description="Constrained attitude GNC: flight software, SIL simulator and campaigns.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in _COMMAND_MODULES:
        module.add_cli(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        result = args.func(args)
    except ModuleNotFoundError as exc:  # an optional part that is not installed: one line, not a traceback
        name = (exc.name or "?").split(".")[0]
        extra = _EXTRAS.get(name)
        hint = f"pip install 'keepout[{extra}]'" if extra else f"pip install {name}"
        print(f"keepout: this command needs the Python package '{name}', which is not installed ({hint})",
              file=sys.stderr)
        return EXIT_CANNOT_START
    return int(result or 0)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("keepout")
    except PackageNotFoundError:  # running from a checkout that was never installed
        return "unknown (not installed)"


if __name__ == "__main__":
    sys.exit(main())
