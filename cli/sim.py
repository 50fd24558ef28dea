"""``keepout sim MISSION --bus SPEC``: the simulator alone, for a processor-in-the-loop bench.

The flight software runs as ``keepout fsw MISSION --bus SPEC`` (on this computer or another one joined
by a real CAN bus); this command runs the world: the devices on the bus (IMU, star tracker, wheels), the
truth dynamics, the SYNC ticks and the fault injector, exactly as in ``keepout sil run``, plus the
mission's telecommand timeline sent to the flight software's telecommand port. Clocks (docs/hil-bench.md):

- lockstep (default): each tick waits for the flight software's CYCLE_DONE; start ``keepout fsw`` first.
  The first tick waits up to ``--wait-s`` for the flight software to answer.
- ``--realtime``: SYNC paced to this computer's monotonic clock, never waiting; run the flight software
  with ``--realtime`` too (it ticks on its own clock; late answers are counted).

Writes ``OUT/truth.npz``, ``OUT/bus.candump.log``, ``OUT/simulator.json`` and ``OUT/truth_check.json``
(the mission's truth requirements: keep-out margins, settling, final error, wheel speeds). Exit codes: 0
every truth requirement passes, 1 one fails or the flight software stopped answering, 2 the mission or an
option is rejected, 3 the bus cannot be opened or no flight software answered the first SYNC, 130 Ctrl-C.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cli import description_of

EXIT_PASS, EXIT_FAIL, EXIT_REJECTED, EXIT_NOT_STARTED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
TRUTH_CHECK_FILE = "truth_check.json"
# requirements judged on truth alone (the rest need the flight software's telemetry, which a bench ground
# archives separately: `keepout ground --config MISSION`)
TRUTH_REQUIREMENTS = ("truth recorded", "run completed", "keep-out margin", "settling", "final pointing error",
                      "peak wheel speed")


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "sim", help="run the simulator alone on a bus (HIL bench; pair with `keepout fsw`)",
        description=description_of(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mission", type=Path, help="mission YAML")
    p.add_argument("--bus", default=None, help="bus spec (default: the mission's bus): socketcan:can0 | "
                   "udp_multicast:GROUP:PORT | INTERFACE:CHANNEL[,KEY=VALUE...] for any python-can interface")
    p.add_argument("--realtime", action="store_true", help="pace SYNC to the clock (default: lockstep)")
    p.add_argument("--duration", type=float, default=None, metavar="SECONDS", help="override the mission's duration")
    p.add_argument("--wait-s", type=float, default=120.0,
                   help="lockstep: how long the first tick waits for the flight software (default 120 s)")
    p.add_argument("--tc", default=None, metavar="HOST:PORT",
                   help="send the mission's telecommand timeline here (default: 127.0.0.1 and the mission's "
                        "flight_software.tmtc.telecommand_port)")
    p.add_argument("--no-timeline", action="store_true", help="send no telecommands (an operator commands)")
    p.add_argument("--key-file", default=None, help="link key to sign the telecommands with, the one `keepout fsw` "
                   "uses (default: the mission's flight_software.tmtc.security.key_file)")
    p.add_argument("--out", type=Path, default=None,
                   help="output folder (default: runs/<mission>-sim-<timestamp>)")
    p.set_defaults(func=_run)


def result_lines(results: list[dict[str, Any]]) -> list[str]:
    """One line per truth requirement: verdict, name, value and limit with the unit (as `keepout sil run`)."""
    from hil_sim.sil.judge import _cell

    return [f"  {'PASS' if r['pass'] else 'FAIL'}  {r['name']}: {_cell(r['value'], r.get('unit', ''))} "
            f"(limit {_cell(r['limit'], r.get('unit', ''))})" for r in results]


def _tc_address(text: str | None, mission) -> tuple[str, int]:
    if text is None:
        return "127.0.0.1", mission.flight_software.tmtc.telecommand_port
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"--tc {text!r}: give HOST:PORT with a port in 1..65535, e.g. 127.0.0.1:50101")
    return host, int(port)


@dataclass(frozen=True)
class _Resync:
    """A SEC_RESYNC first in the timeline: the flight software may have restarted (its anti-replay window
    back at 0) while the key's sequence file went on, so the session starts by moving the window."""

    t_s: float = 0.0
    command: str = "SEC_RESYNC"


def _key_file(args: argparse.Namespace, mission, purpose: str) -> str:
    """The link key file (raises ValueError naming what is missing)."""
    from comms.link_security import mission_key_path

    key_file = args.key_file or mission_key_path(mission.flight_software.tmtc.security.key_file, args.mission)
    if key_file is None:
        raise ValueError(f"{args.mission}: no link key to {purpose}: pass --key-file FILE (the one "
                         "`keepout fsw` uses) or name flight_software.tmtc.security.key_file")
    return str(key_file)


def _signing(args: argparse.Namespace, mission) -> dict[str, Any]:
    """CommandSender arguments that sign with the link key (raises ValueError naming what is missing)."""
    from ground.commanding import signing_sender_args

    return signing_sender_args(_key_file(args, mission, "sign telecommands"))


def _link_key(args: argparse.Namespace, mission) -> bytes:
    """The link key the bus's SecOC keys come from (mission bus_authentication: true)."""
    from comms.link_security import load_key_file

    return load_key_file(_key_file(args, mission, "authenticate the bus (bus_authentication: true)"))


def _run(args: argparse.Namespace) -> int:
    from comms.bus.icd import Icd
    from comms.bus.transport import BusSpecError, BusUnavailableError, open_bus, resolve_spec
    from ground.commanding import CommandSender
    from hil_sim.sil.lockstep import Simulator
    from hil_sim.mission.model import door_params, magnetic_device_params, world_params
    from hil_sim.sil.orchestrator import (CANDUMP_FILE, SIM_STATS_FILE, TRUTH_FILE, CandumpLog, MissionRejected, RunOptions,
                             Timeline, TruthRecorder, _plain, _run_dir, auth_stats, prepare)
    from hil_sim.world.world import World

    try:
        options = RunOptions(mission=args.mission, bus=args.bus, duration_s=args.duration)
        mission, _ = prepare(options)
        info = resolve_spec(mission.bus)
        tc_host, tc_port = _tc_address(args.tc, mission)
        # (KeyFileError is a ValueError); no key needed when nothing is sent
        signing = _signing(args, mission) if mission.timeline and not args.no_timeline else {}
        link_key = _link_key(args, mission) if mission.bus_authentication else None
    except (MissionRejected, BusSpecError, ValueError) as exc:
        print(f"keepout sim: {exc}", file=sys.stderr)
        return EXIT_REJECTED
    try:
        bus = open_bus(info.spec, bitrate=mission.bus_bitrate_bps)
    except (BusUnavailableError, OSError) as exc:
        print(f"keepout sim: bus {info.spec} cannot be opened: {exc}", file=sys.stderr)
        return EXIT_NOT_STARTED
    if link_key is not None:
        from comms.bus.secoc import secure

        bus = secure(bus, Icd(), link_key, "SIM")
    out = args.out if args.out is not None else _run_dir(Path("runs"), f"{mission.name}-sim")
    out.mkdir(parents=True, exist_ok=True)
    world = World(world_params(mission), seed=mission.seed)
    gnc_period = 1.0 / mission.flight_software.rates.gnc_rate_hz
    candump = CandumpLog(out / CANDUMP_FILE, info.channel if info.interface == "socketcan" else "can0")
    sim = Simulator(world, bus, Icd(), gnc_period_s=gnc_period, dynamics_dt_s=1.0 / mission.simulation.dynamics_rate_hz,
                    faults=mission.faults, fault_seed=mission.seed, on_frame=candump,
                    on_burst=candump.log_burst, door=door_params(mission),
                    magnetic=magnetic_device_params(mission))
    n_ticks = int(round(mission.duration_s / gnc_period))
    recorder = TruthRecorder(n_ticks, len(mission.spacecraft.wheels), door=sim.devices.door)
    recorder.record(world, np.zeros(len(mission.spacecraft.wheels)), True)
    sender = CommandSender(host=tc_host, port=tc_port, **signing)
    timeline = Timeline(mission, sender)
    if args.no_timeline:
        timeline.entries = []
    elif timeline.entries:
        timeline.entries.insert(0, _Resync())
    print(f"keepout sim: {mission.name} on {info.note}, {'real time' if args.realtime else 'lockstep'}, "
          f"{n_ticks} ticks; telecommands to {tc_host}:{tc_port}; output {out}", flush=True)
    code, aborted = EXIT_PASS, ""
    started = time.monotonic()
    try:
        code, aborted = _loop(sim, world, recorder, timeline, n_ticks, args)
    except KeyboardInterrupt:
        code, aborted = EXIT_INTERRUPTED, "interrupted"
    finally:
        wall_s = time.monotonic() - started
        bus.shutdown()
        candump.close()
        sender.close()
        recorder.save(out / TRUTH_FILE)
        stats = {**sim.stats.__dict__, "aborted": aborted, "clock": "realtime" if args.realtime else "lockstep",
                 "bus": info.spec, "bus_note": info.note, "bitrate_bps": mission.bus_bitrate_bps, "wall_s": wall_s,
                 "sim_s": sim.t_s - sim.t0_s, "candump_frames": candump.frames,
                 "bus_decode_errors": int(getattr(bus, "decode_errors", 0)), **auth_stats(bus),
                 "telecommands": timeline.sent, "telecommand_errors": timeline.errors}
        (out / SIM_STATS_FILE).write_text(json.dumps(_plain(stats), indent=1) + "\n")
    if code == EXIT_NOT_STARTED:
        return code
    passed, results = _truth_check(out, mission, options.planned_duration_s)
    for line in result_lines(results):
        print(line)
    print(f"keepout sim: {sim.tick} ticks in {wall_s:.1f} s wall, {sim.stats.cycle_done_timeouts} unanswered; "
          f"{'truth requirements pass' if passed else 'a truth requirement FAILED'}; {out}")
    return code if code != EXIT_PASS else (EXIT_PASS if passed else EXIT_FAIL)


def _loop(sim, world, recorder, timeline, n_ticks: int, args: argparse.Namespace) -> tuple[int, str]:
    """Run the ticks; returns (exit code, why the run ended early or "")."""
    missed_in_row = 0
    for k in range(n_ticks):
        timeline.release(sim.t_s)
        done = sim.run_tick(args.realtime, wait_s=args.wait_s if k == 0 else None)
        if k == 0 and not done and not args.realtime:
            print(f"keepout sim: no flight software answered SYNC(0) within {args.wait_s:.0f} s on "
                  f"{args.bus or 'the mission bus'}: start `keepout fsw MISSION --bus SPEC` first (it waits for the "
                  "simulator)", file=sys.stderr)
            return EXIT_NOT_STARTED, "no flight software"
        recorder.record(world, sim.devices.wheel_torques(sim.t_s), done)
        missed_in_row = 0 if done else missed_in_row + 1
        if not args.realtime and missed_in_row >= 3:
            return EXIT_FAIL, f"the flight software answered none of the last 3 ticks (t = {sim.t_s:.1f} s)"
    return EXIT_PASS, ""


def _truth_check(out: Path, mission, planned_duration_s: float | None = None) -> tuple[bool, list[dict[str, Any]]]:
    """The mission's requirements that truth alone decides, written to ``truth_check.json``: the SIL's
    judge, rows, limits and verdict (``planned_duration_s``: the mission file's duration when --duration
    shortened the run, so targets past the end are "not reached", as `keepout sil run` says)."""
    from hil_sim.sil.judge import evaluate

    summary, _ = evaluate(out, mission, status="completed", planned_duration_s=planned_duration_s)
    results = [r for r in summary["requirements"] if r["name"].startswith(TRUTH_REQUIREMENTS)]
    passed = bool(results) and all(r["pass"] for r in results)
    (out / TRUTH_CHECK_FILE).write_text(json.dumps({"pass": passed, "requirements": results}, indent=1,
                                                   default=str) + "\n")
    return passed, results
