"""``keepout warmup [MISSION...] [--prune]``: compile every numerical kernel once, so the first run afterwards
starts flying at once.

  keepout warmup            # `make setup` runs it after `pip install`
  keepout warmup --prune    # `make wheel`: then drop cache files no current kernel loads

It runs, briefly, what a run runs on every shipped mission (the load-time physics check and a few seconds of
the fast-mode closed loop), so every kernel is compiled with the argument types a run uses
(hil_sim/warmup.py); a wheel built afterwards ships them.
"""
from __future__ import annotations

import argparse

from cli import description_of


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("warmup", help="compile the numerical kernels once (make setup runs it)",
                              description=description_of(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("missions", nargs="*", metavar="MISSION", help="mission YAMLs (default: every shipped mission)")
    p.add_argument("--prune", action="store_true",
                   help="then delete cache files of older sources (before building a wheel that ships them)")
    p.set_defaults(func=_warmup)


def _warmup(args: argparse.Namespace) -> int:
    from hil_sim.warmup import prune, warm

    print("compiling the numerical kernels once (later runs load them from the kernel cache)", flush=True)
    total = warm(args.missions)
    print(f"kernels ready in {total:.1f} s", flush=True)
    if args.prune:
        prune()
    return 0
