"""``keepout sil run [MISSION]``: run one mission in the SIL and judge it (see hil_sim.sil.orchestrator)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hil_sim.sil.orchestrator import DEFAULT_RT_PRIORITY


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    sil = subparsers.add_parser("sil", help="software-in-the-loop runs", description="Software-in-the-loop runs.")
    sub = sil.add_subparsers(dest="sil_command", metavar="SUBCOMMAND")
    sil.set_defaults(func=lambda args: (sil.print_help(), 2)[1])
    run = sub.add_parser(
        "run", help="run a mission: simulator, flight software and ground monitor on one bus",
        description="Run a mission: simulator (devices on the bus), flight software and ground monitor as three "
                    "processes on one bus; writes runs/<name>-<timestamp>/ with the config used, telemetry "
                    "archive, events, candump log, summary.json (with the run's status) and plots. Exit code 0 "
                    "when every requirement passes, 1 when one fails, 2 when the mission is rejected, 3 when "
                    "the run cannot start, 4 when a process crashed mid-run, 5 when the ground's telemetry is "
                    "incomplete, 130 on Ctrl-C, 143 on SIGTERM (what was recorded is still judged; see "
                    "docs/running.md).")
    run.add_argument("mission", nargs="?", type=Path, default=None,
                     help="mission YAML (default: the packaged demo-pointing mission)")
    run.add_argument("--realtime", action="store_true", help="pace the simulator to the clock (default: lockstep)")
    run.add_argument("--bus", default=None,
                     help="override the mission's bus: auto | socketcan[:IFACE] | udp_multicast[:GROUP:PORT] | "
                          "INTERFACE:CHANNEL[,KEY=VALUE...] for any python-can interface (pcan, kvaser, vector, "
                          "slcan, socketcand, gs_usb, ...); the flight software runs in a process of its own, so "
                          "python-can's in-process virtual bus does not reach it (docs/bus.md)")
    run.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                     help="override the simulated duration [s]")
    run.add_argument("--out", type=Path, default=Path("runs"), help="parent folder of run folders (default: runs)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar (CI logs)")
    run.add_argument("--rt-priority", type=int, default=None, metavar="N",
                     help="real time: SCHED_FIFO priority of the simulator's tick loop (default "
                          f"{DEFAULT_RT_PRIORITY}; 0: the host's normal scheduler; needs root or CAP_SYS_NICE, else "
                          "the run says so and goes on best effort); the flight software's is its mission's "
                          "rates.realtime_priority")
    run.add_argument("--max-missed-ticks", type=_positive_int, default=3, metavar="N",
                     help="ticks in a row the flight software may leave unanswered before the run is ended as "
                          "hung (default 3; in real time a late answer is a cycle slip, not silence)")
    run.set_defaults(func=_run)


def _positive_int(text: str) -> int:
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive whole number")
    return int(text)


def _run(args: argparse.Namespace) -> int:
    from hil_sim.sil.orchestrator import (DEFAULT_MISSION, EXIT_NOT_STARTED, EXIT_REJECTED, MissionRejected, RunNotStarted,
                             RunOptions, run_sil)
    from hil_sim.sil.judge import format_summary

    options = RunOptions(mission=args.mission or DEFAULT_MISSION, bus=args.bus, duration_s=args.duration,
                         realtime=args.realtime, out_root=args.out,
                         progress=not args.no_progress and sys.stdout.isatty(), announce=True,
                         max_consecutive_missed=args.max_missed_ticks,
                         rt_priority=DEFAULT_RT_PRIORITY if args.rt_priority is None else max(0, min(99, args.rt_priority)))
    try:
        result = run_sil(options)
    except MissionRejected as exc:
        print(f"mission rejected, no run started:\n{exc}", file=sys.stderr)
        return EXIT_REJECTED
    except RunNotStarted as exc:
        print(f"run could not start: {exc}", file=sys.stderr)
        return EXIT_NOT_STARTED
    if "requirements" not in result.summary:  # nothing could be judged (the run folder's disk filled up)
        print(f"{result.summary['status']} -> {result.run_dir}", file=sys.stderr)
        return result.exit_code
    print(format_summary(result.summary, total_wall_s=_since_process_start()))
    hint = slip_hint(result.summary, args.realtime, _rt_scheduling(result.run_dir))
    if hint:
        print(hint)
    return result.exit_code


def _rt_scheduling(run_dir: Path) -> str:
    """What the run's tick loop got from the scheduler (simulator.json), or '' when it was not recorded."""
    import json

    from hil_sim.sil.orchestrator import SIM_STATS_FILE
    try:
        return str(json.loads((run_dir / SIM_STATS_FILE).read_text()).get("rt_scheduling", ""))
    except (OSError, ValueError, AttributeError):
        return ""


def slip_hint(summary: dict, realtime: bool, got: str) -> str:
    """What to do when a real-time run failed on cycle slips (docs/operations.md, real time)."""
    failed = [r for r in summary.get("requirements", [])
              if r.get("name") in ("cycle slips", "ticks lost on the host") and r.get("pass") is False]
    if not realtime or not failed:
        return ""
    return (f"{failed[0]['name']}: the host delayed the paced loop ({got or 'scheduling unknown'}). Give the run "
            f"SCHED_FIFO (root or CAP_SYS_NICE; --rt-priority), an idle core (taskset), or fly it lockstep, "
            f"where host time cannot hurt the loop; see docs/operations.md (real time)")


def _since_process_start() -> float | None:
    """Wall time since this process started (interpreter, imports, set-up and the run: what a user waits)."""
    import time

    import psutil
    try:
        return max(0.0, time.time() - psutil.Process().create_time())
    except psutil.Error:
        return None
