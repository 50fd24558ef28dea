"""``keepout campaign run|rerun|report|baseline save|compare|shrink``.

Top-level imports stay light: every ``keepout`` start imports this module to build the parser.

Exit codes of ``run`` and ``report``: 0 PASS, 1 FAIL, 2 not started (bad input), 4 INCONCLUSIVE (no run
failed, but too few runs to show the required success probability), 130 interrupted.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

BASELINES = "baselines"  # a campaign's baselines: <folder of its YAML>/baselines/<campaign name>
DEFAULT_BASELINES = f"<folder of the campaign YAML>/{BASELINES}"  # for the help texts
CAMPAIGN_COPY_HEADER = "# campaign as run, from "  # first line of <out>/campaign.yaml (runner.prepare_out_dir)
EXIT_CODES = ("exit codes of run and report: 0 PASS, 1 FAIL, 2 not started, 4 INCONCLUSIVE (no failure, but "
              "too few runs to show the required success probability), 130 interrupted")


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("campaign", help="dispersed Monte Carlo campaigns: run, rerun, baselines, shrink",
                              description="Dispersed campaigns of a mission (config/campaigns/*.yaml).",
                              epilog=EXIT_CODES)
    sub = p.add_subparsers(dest="campaign_command", metavar="ACTION")

    run = sub.add_parser("run", help="run a campaign (resumable)", epilog=EXIT_CODES)
    run.add_argument("campaign", help="campaign YAML, e.g. config/campaigns/regression.yaml")
    run.add_argument("--runs", type=int, help="number of runs (default: the campaign's)")
    run.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    run.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786 (default: local pool)")
    run.add_argument("--mode", choices=("fast", "sil"), help="execution mode (default: the campaign's)")
    run.add_argument("--duration", type=float, help="shorten every run to this many simulated seconds "
                     "(commands and faults after it are dropped), e.g. for CI")
    run.add_argument("--out", type=Path, help="output folder; an existing one is resumed (finished runs skipped)")
    run.add_argument("--resume", action="store_true", help="resume the newest campaigns/<name>-* folder")
    run.add_argument("--no-report", action="store_true", help="tables and JUnit only, no plots")
    run.set_defaults(func=_cmd_run)

    rerun = sub.add_parser("rerun", help="reproduce one run exactly and compare it with the stored one")
    rerun.add_argument("campaign", help="a campaign output folder (or a campaign YAML: its newest folder)")
    rerun.add_argument("--run", type=int, required=True, help="run index")
    rerun.set_defaults(func=_cmd_rerun)

    rep = sub.add_parser("report", help="regenerate the tables, JUnit XML and report of a campaign folder",
                         epilog=EXIT_CODES)
    rep.add_argument("campaign", help="a campaign output folder (or a campaign YAML: its newest folder)")
    rep.set_defaults(func=_cmd_report)

    base = sub.add_parser("baseline", help="store a campaign's results as the baseline")
    bsub = base.add_subparsers(dest="baseline_command", metavar="ACTION")
    save = bsub.add_parser("save", help="save RESULTS_DIR as the baseline of its campaign")
    save.add_argument("results", type=Path, help="campaign output folder")
    save.add_argument("--to", type=Path, help=f"baseline folder (default: {DEFAULT_BASELINES}/<name>)")
    save.set_defaults(func=_cmd_baseline_save)
    base.set_defaults(func=lambda args: (base.print_help(), 2)[1])

    cmp_ = sub.add_parser("compare", help="compare a campaign's results with its baseline")
    cmp_.add_argument("results", type=Path, help="campaign output folder")
    cmp_.add_argument("--baseline", type=Path, help=f"baseline folder (default: {DEFAULT_BASELINES}/<name>)")
    cmp_.set_defaults(func=_cmd_compare)

    shr = sub.add_parser("shrink", help="move a failing run's dispersions toward nominal while it still fails")
    shr.add_argument("campaign", help="a campaign output folder (or a campaign YAML: its newest folder)")
    shr.add_argument("--run", type=int, required=True, help="run index")
    shr.add_argument("--max-evaluations", type=int, default=80)
    shr.add_argument("--criterion", action="append", help="shrink while this criterion fails (repeatable; "
                     "default: the criteria the run failed)")
    shr.set_defaults(func=_cmd_shrink)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


# ---------------------------------------------------------------------------------------------

def _console():
    from rich.console import Console
    return Console(stderr=True, soft_wrap=True)  # messages stay one line (pasted paths and commands)


def plan_from_results(results_dir: Path, **kw):
    """Rebuild the plan of a campaign output folder from the inputs copied into it."""
    from hil_sim.campaign.runner import PLAN_FILE, build_plan
    from hil_sim.campaign.spec import load_campaign
    meta = json.loads((results_dir / PLAN_FILE).read_text())
    campaign = load_campaign(results_dir / "campaign.yaml").model_copy(
        update={"base_mission": "mission.yaml", "runs": int(meta["runs"])})
    plan, _ = build_plan(results_dir / "campaign.yaml", campaign=campaign, mode=meta["mode"], **kw)
    if campaign.fingerprint() != meta["fingerprint"]:
        raise RuntimeError(f"{results_dir}: campaign.yaml no longer matches the runs (fingerprint changed)")
    return plan


def _results_dir(arg: str) -> Path:
    path = Path(arg)
    if path.is_dir():
        return path
    from hil_sim.campaign.runner import latest_out_dir
    from hil_sim.campaign.spec import load_campaign
    found = latest_out_dir(load_campaign(path))
    if found is None:
        raise FileNotFoundError(f"no output folder of campaign {arg} under campaigns/; run it first")
    return found


def _plan(campaign_file: str | Path, args: argparse.Namespace, runs: int | None):
    from hil_sim.campaign.runner import build_plan
    campaign = None
    if args.duration is not None:
        from hil_sim.campaign.spec import load_campaign
        campaign = load_campaign(campaign_file).model_copy(update={"duration_s": args.duration})
    return build_plan(campaign_file, mode=args.mode, runs=runs, campaign=campaign)


def _cmd_run(args: argparse.Namespace) -> int:
    from hil_sim.campaign.runner import default_out_dir, latest_out_dir
    from hil_sim.campaign.suite import is_suite
    from hil_sim.mission.loader import ConfigError
    console = _console()
    try:
        if is_suite(args.campaign):
            return _cmd_run_suite(args, console)
        plan, base_path = _plan(args.campaign, args, args.runs)
    except (ConfigError, FileNotFoundError, ValueError) as exc:
        console.print(f"[red]campaign not started:[/red]\n{exc}")
        return 2
    out = args.out or (latest_out_dir(plan.campaign) if args.resume else None) or default_out_dir(plan.campaign)
    results, interrupted = _fly(plan, base_path, args.campaign, out, args, console)
    if results is None:
        return 130
    code = _print_results(console, results)
    return 130 if interrupted else code


def _cmd_run_suite(args: argparse.Namespace, console) -> int:
    """A suite (hil_sim.campaign.suite): every member campaign into its folder, one verdict over all runs."""
    from datetime import datetime, timezone

    from hil_sim.campaign.suite import load_suite, member_paths, run_suite, suite_text
    suite = load_suite(args.campaign)
    # every member planned before any flies (a bad member loses no hour of runs), each plan then flown
    plans = {path: _plan(path, args, args.runs or member.runs)
             for member, path in zip(suite.suite, member_paths(suite, args.campaign))}
    if args.out is not None:
        out = args.out
    else:
        found = sorted(Path("campaigns").glob(f"{suite.name}-*/suite.json")) if args.resume else []
        out = found[-1].parent if found else Path("campaigns") / (
            f"{suite.name}-{datetime.now(timezone.utc).strftime('%Y%m%dT%H%M%SZ')}")

    def member(campaign_file: Path, runs: int | None, folder: Path):
        plan, base_path = plans[campaign_file]
        results, stopped = _fly(plan, base_path, campaign_file, folder, args, console)
        if results is None or stopped:
            raise KeyboardInterrupt
        console.print(results["verdict"].text())
        return results

    console.print(f"suite [bold]{suite.name}[/bold]: {len(suite.suite)} campaigns -> {out}")
    try:
        outcome = run_suite(suite, args.campaign, out, member)
    except KeyboardInterrupt:
        console.print(f"[yellow]interrupted: finished runs kept in {out}; `keepout campaign run {args.campaign} "
                      f"--out {out}` resumes[/yellow]")
        return 130
    total = outcome.verdict()
    for m in outcome.members:
        console.print(f"  {m.name}: {m.runs} runs, {m.failures} failed ({m.errors} errors), {m.wall_s:.0f} s")
    colour = "[green]" if total.passed else ("[yellow]" if total.inconclusive else "[red]")
    console.print(colour + suite_text(total))
    console.print(f"results: {out / 'suite.json'}, {out / 'junit.xml'}")
    return total.exit_code


def _fly(plan, base_path: Path, campaign_file: str | Path, out: Path, args: argparse.Namespace, console):
    """Run one campaign's plan into ``out`` and tabulate it: (results or None when interrupted while
    tabulating, whether the runs were interrupted)."""
    from hil_sim.campaign.runner import finalize, prepare_out_dir
    if args.scheduler:
        # before the output folder exists: a refused campaign leaves nothing behind (the ModuleNotFoundError
        # becomes one line with the pip command, cli/main.py)
        import distributed  # noqa: F401
    # the campaign file's absolute path, so `baseline save` finds its folder from anywhere
    prepare_out_dir(out, plan, Path(campaign_file).resolve(), base_path)
    where = f"Dask {args.scheduler}" if args.scheduler else f"{args.workers or 'all'} local workers"
    console.print(f"campaign [bold]{plan.campaign.name}[/bold]: {plan.campaign.runs} runs, mode {plan.mode}, "
                  f"{where} -> {out}")
    outcome = _run_with_progress(plan, out, args.workers, args.scheduler, console)
    if outcome.interrupted:
        console.print(f"[yellow]interrupted: {len(outcome.records)} finished runs kept in {out}; "
                      f"`keepout campaign run {args.campaign} --out {out}` resumes[/yellow]")
    try:
        return finalize(plan, out, outcome.records, report=not args.no_report), outcome.interrupted
    except KeyboardInterrupt:
        # Ctrl-C after the last run, while tabulating: the runs' records are on disk, nothing is lost
        console.print(f"[yellow]interrupted while tabulating: {len(outcome.records)} finished runs kept in "
                      f"{out}; `keepout campaign report {out}` tabulates them[/yellow]")
        return None, outcome.interrupted


def _print_results(console, results) -> int:
    verdict = results["verdict"]
    colour = "[green]" if verdict.passed else ("[yellow]" if verdict.inconclusive else "[red]")
    console.print(colour + verdict.text())
    console.print(f"results: {results['parquet']}, {results['csv']}, {results['junit']}"
                  + (f", {results['report']['html']}" if "report" in results else ""))
    return verdict.exit_code


def _cmd_report(args: argparse.Namespace) -> int:
    from hil_sim.campaign.runner import finalize, load_records
    console = _console()
    try:
        out, plan = _folder_and_plan(args.campaign)
    except ValueError as exc:
        console.print(f"[red]no report:[/red] {exc}")
        return 2
    records = load_records(out)
    if not records:
        console.print(f"[red]no report:[/red] {out} holds no finished run (runs/run-*.json)")
        return 2
    return _print_results(console, finalize(plan, out, records))


def _run_with_progress(plan, out, workers, scheduler, console):
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)
    from hil_sim.campaign.runner import run_campaign
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TextColumn("failures [red]{task.fields[failures]}"), TimeElapsedColumn(),
                  TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=False) as bar:
        task = bar.add_task(plan.campaign.name, total=plan.campaign.runs, failures=0)

        def update(progress, record):
            bar.update(task, completed=progress.done, failures=progress.failures)

        return run_campaign(plan, out, workers=workers, scheduler=scheduler, on_progress=update)


def _cmd_rerun(args: argparse.Namespace) -> int:
    from hil_sim.campaign import dispersions as dsp
    from hil_sim.campaign.execute import execute_run
    from hil_sim.campaign.runner import load_records
    console = _console()
    try:
        out, plan = _folder_and_plan(args.campaign, args.run)
    except ValueError as exc:
        console.print(f"[red]not rerun:[/red] {exc}")
        return 2
    stored = {r.run: r for r in load_records(out)}.get(args.run)
    record = execute_run(plan, args.run)
    console.print(f"run {args.run}: {record.status}  metrics {record.metrics}")
    if record.error:
        console.print(record.error)
    if stored is None:
        console.print(f"(run {args.run} not stored in {out}: nothing to compare)")
        return 0 if record.status == "pass" else 1
    fields = ("status", "params", "values", "used", "metrics", "verdicts", "sim_seed")
    new, old = record.to_json(), stored.to_json()
    diffs = [f for f in fields if not dsp.same_value(old[f], new[f], rtol=0.0, atol=0.0)]
    if diffs:
        console.print(f"[red]NOT reproduced: {', '.join(diffs)} differ from the stored run[/red]")
        for f in diffs:
            console.print(f"  {f}: stored {old[f]}\n  {' ' * len(f)}  now    {new[f]}")
        return 1
    console.print(f"[green]reproduced exactly[/green] (same inputs, seeds, metrics and verdicts as in {out})")
    return 0


def _folder_and_plan(arg: str, run: int | None = None):
    """(output folder, plan) of a campaign folder or YAML; a ``ValueError`` with one clear line otherwise,
    also when ``run`` is not one of the campaign's run indices."""
    from hil_sim.mission.loader import ConfigError
    try:
        out = _results_dir(arg)
        if not (out / "plan.json").is_file():
            raise FileNotFoundError(f"{out} is not a campaign output folder (no plan.json)")
        plan = plan_from_results(out)
    except (OSError, RuntimeError, KeyError, ConfigError) as exc:
        raise ValueError(str(exc)) from None
    runs = plan.campaign.runs
    if run is not None and not 0 <= run < runs:
        raise ValueError(f"run {run} is not a run of {out}: campaign {plan.campaign.name} has runs 0 to {runs - 1}")
    return out, plan


def _baseline_dir(results: Path, given: Path | None) -> Path:
    """``given``, else ``baselines/<campaign name>`` beside the campaign YAML the folder was run from (not
    the current folder: a baseline belongs with its campaign, wherever the command is typed)."""
    if given:
        return given
    plan = results / "plan.json"
    if not plan.is_file():
        raise FileNotFoundError(f"{results} is not a campaign output folder (no plan.json)")
    name = json.loads(plan.read_text())["campaign"]
    source = campaign_source(results)
    if source is None or not source.parent.is_dir():
        raise FileNotFoundError(f"{results}: the campaign file it was run from ({source or 'not recorded'}) is not "
                                "here; give the baseline folder with --to (save) or --baseline (compare)")
    return source.parent / BASELINES / name


def campaign_source(results: Path) -> Path | None:
    """The campaign YAML a campaign output folder was run from (recorded on the first line of its copy);
    a relative path, as older folders recorded it, is taken from the current folder."""
    try:
        with open(results / "campaign.yaml", encoding="utf-8") as f:
            first = f.readline().rstrip("\n")
    except OSError:
        return None
    if not first.startswith(CAMPAIGN_COPY_HEADER):
        return None
    return Path(first[len(CAMPAIGN_COPY_HEADER):]).absolute()


def _cmd_baseline_save(args: argparse.Namespace) -> int:
    from hil_sim.campaign.baseline import save_baseline
    try:
        dest = save_baseline(args.results, _baseline_dir(args.results, args.to))
    except (OSError, ValueError, KeyError) as exc:
        print(f"baseline not saved: {exc}", file=sys.stderr)
        return 2
    _console().print(f"baseline saved to {dest}")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    import pandas as pd
    from hil_sim.campaign.baseline import better_sides, compare, load_baseline
    from hil_sim.campaign.fast import metric_better
    from hil_sim.campaign.spec import load_campaign
    from hil_sim.mission.loader import ConfigError
    try:
        if not (args.results / "plan.json").is_file():
            raise FileNotFoundError(f"{args.results} is not a campaign output folder (no plan.json)")
        base_df, meta = load_baseline(_baseline_dir(args.results, args.baseline))
        campaign = load_campaign(args.results / "campaign.yaml")
        table = args.results / "results.parquet"
        if not table.is_file():
            raise FileNotFoundError(f"{args.results} has no results.parquet: run the campaign (or "
                                    f"`keepout campaign report {args.results}`) first")
        new_df = pd.read_parquet(table)
    except (OSError, ValueError, KeyError, ConfigError) as exc:
        print(f"no comparison: {exc}", file=sys.stderr)
        return 2
    known = {c[2:]: metric_better(c[2:]) for c in new_df.columns if c.startswith("m.") and metric_better(c[2:])}
    result = compare(base_df, new_df, campaign.baseline, better=better_sides(campaign.criteria, known))
    print(f"baseline: {meta.get('source')} ({meta.get('runs_in_table')} runs); new: {args.results} ({len(new_df)} runs)")
    print(result.text())
    return 1 if result.regressed else 0


def _cmd_shrink(args: argparse.Namespace) -> int:
    import yaml
    from hil_sim.campaign.shrink import shrink_run, shrunk_mission
    try:
        out, plan = _folder_and_plan(args.campaign, args.run)
    except ValueError as exc:
        print(f"not shrunk: {exc}", file=sys.stderr)
        return 2
    try:
        result = shrink_run(plan, args.run, max_evaluations=args.max_evaluations,
                            criteria=set(args.criterion) if args.criterion else None)
    except ValueError as exc:
        print(exc, file=sys.stderr)
        return 2
    print(result.text(plan))
    dest = out / f"shrink-run-{args.run:06d}.yaml"
    dest.write_text("# smallest failing case found by `keepout campaign shrink`\n"
                    + yaml.safe_dump(shrunk_mission(plan, result), sort_keys=False), encoding="utf-8")
    print(f"mission of the smallest failing case: {dest}")
    return 0
