"""``keepout paper``: reproduce the paper's three simulation studies (gnc.paper) and write their table,
``results.json`` and figures (hil_sim.paper_figures) into ``--out`` (default docs/paper)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

STUDIES = ("s3_cones", "s3_star", "s3_star_literal", "s2_star")


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("paper", help="reproduce the paper's simulation studies (table + figures)")
    p.add_argument("--out", default="docs/paper", help="output folder (default: docs/paper)")
    p.add_argument("--quick", action="store_true", help="shorter horizons (for tests)")
    p.add_argument("--no-figures", action="store_true", help="only the table and JSON")
    p.add_argument("--study", action="append", choices=STUDIES, help="run only this study (repeatable)")
    p.set_defaults(func=_paper)


def _paper(args: argparse.Namespace) -> int:
    from gnc.paper import run_studies
    from hil_sim.paper_figures import write_outputs

    out = Path(args.out)
    t0 = time.perf_counter()
    results, sims = run_studies(quick=args.quick, only=args.study or None, clock=time.perf_counter)
    write_outputs(out, results, sims, figures=not args.no_figures)
    failed = [key for key, st in results["studies"].items() if not _report(key, st)]
    print(f"wrote {out / 'table.md'}, {out / 'results.json'} and figures in {time.perf_counter() - t0:.1f} s")
    return 1 if failed else 0


def _report(key: str, st: dict) -> bool:
    """Print the study's line; False when a run entered a zone or a study expected to converge did not."""
    mins = [r["min_signed_separation"] for r in st["runs"]]
    conv = [r["time_to_ds_below_1e-4_s"] is not None for r in st["runs"]]
    ok = True
    status = "ok"
    if min(mins) <= 0.0:
        status, ok = "UNSAFE", False
    elif st["expect_convergence"] and not all(conv):
        status, ok = "NOT CONVERGED", False
    elif not st["expect_convergence"]:
        status = f"rejected by check_assumptions as expected ({sum(conv)}/{len(conv)} runs converged)"
    print(f"{key:18s} runs={len(mins):2d} min signed d_s={min(mins):.5f}  converged={sum(conv)}/{len(conv)}  {status}")
    return ok
