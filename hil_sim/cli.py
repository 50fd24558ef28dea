"""The ``keepout`` command line.

Each area of the project owns its subcommands: a module listed in ``_COMMAND_MODULES`` exposes
``add_cli(subparsers)``, which adds its parsers and sets ``func`` on them. This file only assembles
them, so adding a command never means editing another area's code.
"""
from __future__ import annotations

import argparse
import importlib
import sys

_COMMAND_MODULES = (
    "gnc.paper",          # keepout paper
    "hil_sim.mission_cli",  # keepout config schema|validate|check
    "hil_sim.sil_cli",    # keepout sil run
    "fsw.__main__",       # keepout fsw MISSION (HIL bench: the flight software alone)
    "hil_sim.sim_cli",    # keepout sim MISSION (HIL bench: the simulator alone)
    "hil_sim.bus_cli",    # keepout bus monitor|log
    "ground.cli",         # keepout ground [send ...]
    "hil_sim.campaign_cli",  # keepout campaign run|rerun|baseline|compare|shrink
    "hil_sim.init_cli",   # keepout init DIR
    "hil_sim.export_cli",  # keepout export RUN --format csv|mat|parquet
    "hil_sim.sky_cli",    # keepout sky MISSION --at T | --from T0 --to T1 --step S
    "hil_sim.budget",     # keepout budget MISSION
    "hil_sim.truth_cli",  # keepout truth MISSION --duration D --out FILE.npz
)

def description_of(doc: str) -> str:
    """A subcommand module's docstring after its first paragraph, for ``--help``: reST literals (double
    backticks) shown as plain text."""
    return doc.split("\n\n", 1)[1].replace("``", "")


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
    for name in _COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue  # area not built yet in this checkout
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
