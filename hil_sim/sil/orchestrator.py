"""The SIL orchestrator: simulator, flight software and ground monitor as three processes on one bus.

``run_sil(RunOptions(...))``:

1. loads the mission (every problem as file:line:col) and runs the physics checks: a bad mission never
   starts a run;
2. creates ``runs/<run id>/`` (`run_id`: name, time and a random part) and writes the config actually used (bus, ports, clock and
   duration overrides applied) with its sha256;
3. starts the ground monitor (its own process: archives every telemetry packet, raw and decoded), writes
   ``endpoints.json`` (``ground.link``: the run's telemetry multicast group and port, telecommand port,
   bus, pids) so that any number of other ground clients can attach (``keepout ground --run RUN_DIR``), then
   the flight software (``python -m fsw --config fsw.yaml``: its configuration resolved from the mission,
   bus and ports included, nothing of the truth; its own process and session), and waits for the flight
   software's FSW_STARTED event to reach the ground, so its bus is
   open before the first SYNC;
4. runs the simulator in this process: devices on the bus (`hil_sim.sil.lockstep.Simulator`), lockstep by
   default (each tick waits for the flight software's CYCLE_DONE) or paced to the clock; the ground's
   telecommand timeline is released at its simulated times, just before the SYNC of the tick it falls
   in (so lockstep runs stay deterministic); truth is recorded every tick and every frame goes to a
   candump log;
5. stops the flight software, lets the last telemetry drain, stops the ground, and writes
   ``summary.json`` (requirements judged on truth) and the plots, also after Ctrl-C (with what was
   recorded).

Exit code and the summary's ``status``: see ``EXIT_*`` below and docs/running.md.
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import errno
import hashlib
import ipaddress
import json
import math
import multiprocessing as mp
import os
import queue
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import yaml

from fsw.lifetime import PARENT_PID_ENV, die_with_parent
from comms.link_security import LINK_KEY_FILE, write_key_file
from ground.link import ENDPOINTS_FILE, settle_orphaned_runs
from keepout_config import config_path

DEFAULT_MISSION = config_path("missions", "demo-pointing.yaml")
# the run folder may be anywhere: its config names the installed schema by URI
MODELINE = f"# yaml-language-server: $schema={config_path('schema', 'mission.schema.json').as_uri()}"

DEFAULT_RT_PRIORITY = 20  # real time: SCHED_FIFO priority of the simulator's tick loop
BUS_DRAWS = 8  # udp_multicast endpoints drawn at random before a run gives up (see _open_simulator_bus)
LOCKSTEP_TIMEOUT_S = 60.0  # flight software: end of run when no SYNC for this long
FSW_POLL_TICKS = 20  # the simulator checks that the flight software is alive every this many ticks
GROUND_BATCH_S = 0.02  # the ground sleeps this long after a read, so a wake-up takes ~10 packets, not 1
# Exit codes (docs/running.md): 0 every requirement passed; 1 a requirement failed; 2 the mission was
# rejected; 3 the run could not start; 4 a process crashed (fsw, ground or simulator); 5 the run ended
# but the ground's telemetry is incomplete; 130 Ctrl-C (SIGINT), 143 SIGTERM. 1, 4, 5, 130, 143 come
# with a judged summary.json.
EXIT_PASS, EXIT_FAIL, EXIT_REJECTED, EXIT_NOT_STARTED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
EXIT_CRASHED, EXIT_INCOMPLETE_TELEMETRY, EXIT_TERMINATED = 4, 5, 143
STATUS_COMPLETED, STATUS_INTERRUPTED, STATUS_INCOMPLETE = "completed", "interrupted", "incomplete telemetry"

CONFIG_FILE = "mission.yaml"
FSW_CONFIG_FILE = "fsw.yaml"  # the flight software's own configuration, resolved from CONFIG_FILE
TRUTH_FILE = "truth.npz"
CANDUMP_FILE = "bus.candump.log"
SIM_STATS_FILE = "simulator.json"
GROUND_DIR = "ground"
FSW_LOG = "fsw.log"


class MissionRejected(Exception):
    """The mission failed validation or the physics checks (the message says why, with positions)."""


class RunNotStarted(RuntimeError):
    """A process of the SIL could not be started (the message says which and why)."""


class ProcessCrashed(RuntimeError):
    """A process of the SIL ended mid-run; the message is the run's status (``crashed: fsw at t = ...``)."""


class Terminated(BaseException):
    """SIGTERM reached the orchestrator: the run ends as after Ctrl-C (summary written, children stopped)."""


@dataclass
class RunOptions:
    mission: Path = DEFAULT_MISSION
    bus: str | None = None  # override the mission's bus
    duration_s: float | None = None  # override the mission's duration
    planned_duration_s: float | None = None  # set by prepare(): the mission file's duration when overridden
    realtime: bool = False
    out_root: Path = Path("runs")
    progress: bool = True
    announce: bool = False  # print the line to attach a ground to this run as soon as it starts
    skip_physics_checks: bool = False
    fsw_start_timeout_s: float = 600.0  # the first start on a fresh machine compiles (and caches) numba kernels
    cycle_done_timeout_s: float = 30.0  # lockstep: a tick unanswered this long counts as missed
    max_consecutive_missed: int = 3  # then the flight software is taken as hung and the run ends
    # real time: SCHED_FIFO priority asked for the simulator's tick loop (0: the host's normal scheduler); the
    # flight software's is the mission's rates.realtime_priority
    rt_priority: int = DEFAULT_RT_PRIORITY


@dataclass
class RunResult:
    run_dir: Path
    exit_code: int
    summary: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------
# Preparation
# ---------------------------------------------------------------------------------------------

def prepare(options: RunOptions):
    """Load + check the mission; return (mission, physics report). Raises MissionRejected."""
    from hil_sim.mission.model import load_mission_marked
    from hil_sim.mission.physics_checks import check_mission_cached
    from hil_sim.mission.loader import ConfigError

    try:
        mission, doc = load_mission_marked(options.mission)
    except ConfigError as exc:
        raise MissionRejected(str(exc)) from None
    updates: dict[str, Any] = {}
    if options.bus is not None:
        updates["bus"] = options.bus
    if options.duration_s is not None:
        updates["duration_s"] = float(options.duration_s)
        options.planned_duration_s = mission.duration_s  # the judge needs it: targets past a shortened end
    if updates:
        data = mission.model_dump(mode="json")
        data.update(updates)
        data["timeline"] = [e for e in data["timeline"] if e["t_s"] <= data["duration_s"]]
        try:
            mission = type(mission).model_validate(data)
        except Exception as exc:  # pydantic ValidationError: bad override value
            raise MissionRejected(f"command-line override rejected: {exc}") from None
    report = None
    if not options.skip_physics_checks:
        report = check_mission_cached(mission)  # a verdict kept per mission content and code, or the checks
        if not report.ok:
            raise MissionRejected(f"{options.mission}: physics checks failed:\n{report.format(doc, errors_only=True)}")
    return mission, report


def _reserve_tc_socket(host: str, port: int) -> socket.socket:
    """The flight software's telecommand socket, bound here on ``host``:``port`` (0: any free port) and handed
    to it (`python -m fsw --tc-fd`). Its port is then known before the flight software starts and stays
    taken until it does: a port probed free and bound only later could be taken in between by any process
    on the host binding an ephemeral port (another run's ground, a bus socket), and the run would not start.
    Raises RunNotStarted when the address cannot be bound."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise RunNotStarted(f"the telecommand port {host}:{port} cannot be bound: {exc.strerror or exc}") from None
    return sock


def _config_used(mission, *, bus_spec: str, tm_host: str, tm_port: int | None, tc_port: int | None,
                 realtime: bool) -> dict:
    data = mission.model_dump(mode="json")
    data["bus"] = bus_spec
    fsw = data["flight_software"]
    fsw["rates"]["tick_source"] = "clock" if realtime else "sync"
    # a loaded host can stall the simulator for seconds (other runs, plotting): the flight software
    # should not take that for the end of the run
    fsw["rates"]["lockstep_timeout_s"] = max(fsw["rates"]["lockstep_timeout_s"], LOCKSTEP_TIMEOUT_S)
    fsw["tmtc"]["telemetry_host"] = tm_host
    if tm_port is not None:
        fsw["tmtc"]["telemetry_port"] = tm_port
    if tc_port is not None:
        fsw["tmtc"]["telecommand_port"] = tc_port
    return data


def write_config(run_dir: Path, data: dict, source: Path) -> str:
    """Write the config used (YAML) and its sha256; keep a copy of the source file. Returns the hash."""
    text = (f"{MODELINE}\n# config used by this run (from {source}), with the run's bus, ports, clock and "
            f"duration applied\n" + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110))
    path = run_dir / CONFIG_FILE
    path.write_text(text, encoding="utf-8")
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
    (run_dir / (CONFIG_FILE + ".sha256")).write_text(f"{digest}  {CONFIG_FILE}\n")
    shutil.copyfile(source, run_dir / "mission.source.yaml")
    return digest


def _write_fsw_config(run_dir: Path, mission, data: dict) -> None:
    """The flight software's file (FSW_CONFIG_FILE) from the config used: its bus and its section, resolved."""
    from hil_sim.mission.flight import bus_config, write_flight_config

    write_flight_config(run_dir / FSW_CONFIG_FILE, bus_config(mission, data["bus"]), data["flight_software"],
                        header=f"# the flight software's configuration, resolved from {CONFIG_FILE} (the run's "
                        "bus, ports and clock applied)\n")


# ---------------------------------------------------------------------------------------------
# The ground process
# ---------------------------------------------------------------------------------------------

STATUS_CHANNELS = ("mode", "pointing_error_deg", "att_error_deg", "margin_min_deg", "active_zone", "cycle")


def ground_process(archive_dir: str, endpoints: dict, port: int, port_queue, ready, fsw_started, stop_event,
                   status_queue, parent_pid: int | None = None, key_file: str | None = None) -> None:
    """Entry point of the ground process: archive telemetry until told to stop (verified with the run's
    link key ``key_file``: forged or replayed packets are counted, never archived).

    It opens the run's telemetry as every other ground client does (``ground.link.open_telemetry``);
    ``port`` 0 lets the kernel choose the run's port, which goes back on ``port_queue`` (or the reason
    the socket could not be opened, as a string). Ctrl-C is ignored here: the orchestrator stops the
    ground last, after the flight software, so the final packets are archived. Killed with the orchestrator, whatever kills it.
    """
    die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from comms.link_security import downlink_receiver, load_key_file
    from ground.link import Endpoints, LinkError, open_telemetry
    from ground.monitor import GroundMonitor

    try:
        sock = open_telemetry(Endpoints.from_json_dict(endpoints), port=port)
    except LinkError as exc:
        port_queue.put(str(exc))
        ready.set()
        return
    security = downlink_receiver(load_key_file(key_file)) if key_file else None
    monitor = GroundMonitor(port=None, archive_dir=archive_dir, sock=sock, security=security)
    port_queue.put(monitor.address[1])
    ready.set()
    failure: OSError | None = None
    try:
        _ground_loop(monitor, fsw_started, stop_event, status_queue)
    except OSError as exc:  # its archive cannot be written (disk full): one line, and the parent judges
        failure = exc
    finally:
        try:
            monitor.close()
        except OSError as exc:
            failure = failure or exc
    if failure is not None:
        if getattr(failure, "errno", None) != errno.ENOSPC:  # a full disk is said once, in the run's status
            print(f"keepout ground: {archive_dir}: cannot write the telemetry archive: {failure.strerror or failure}",
                  file=sys.stderr)
        sys.exit(GROUND_EXIT_CANNOT_WRITE)


GROUND_EXIT_CANNOT_WRITE = 5  # the ground process's exit code when its archive cannot be written


def _ground_loop(monitor, fsw_started, stop_event, status_queue) -> None:
    last_status = 0.0
    parent = os.getppid()
    while not stop_event.is_set() and os.getppid() == parent:  # an orphaned ground stops by itself
        if monitor.poll(0.05):
            # Packets come every few ms in a lockstep run: reading them as they come costs a wake-up
            # and ~5 system calls each, taken from the simulator and flight software on a 1-CPU host.
            # The socket holds far more than arrives in GROUND_BATCH_S.
            time.sleep(GROUND_BATCH_S)
        if not fsw_started.is_set() and any(e.event == "FSW_STARTED" for e in monitor.events
                                            if getattr(e, "kind", "") == "event"):
            fsw_started.set()
        now = time.monotonic()
        if now - last_status > 0.25:
            last_status = now
            monitor.flush()
            snapshot = {k: monitor.latest.get(k) for k in STATUS_CHANNELS}
            try:
                status_queue.put_nowait(snapshot)
            except queue.Full:
                pass
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline and monitor.poll(0.1):
        pass  # drain what is still in flight


# ---------------------------------------------------------------------------------------------
# Truth recording and the telecommand timeline
# ---------------------------------------------------------------------------------------------

class TruthRecorder:
    """Truth at every tick, kept in preallocated arrays (cheap in the loop), saved as an .npz."""

    def __init__(self, n_ticks: int, n_wheels: int, door=None):
        n = n_ticks + 1
        self.n = 0
        # the aperture door's truth (hil_sim.devices.nodes.DoorNode: its position, 0 closed .. 1 open), when there is one
        self.door = door
        self.door_position = np.zeros(n) if door is not None else None
        self.t_s = np.zeros(n)
        self.q_NB = np.zeros((n, 4))
        self.omega_BN_B = np.zeros((n, 3))
        self.wheel_speed_rad_s = np.zeros((n, n_wheels))
        self.wheel_torque_Nm = np.zeros((n, n_wheels))
        self.sun_N = np.zeros((n, 3))
        self.moon_N = np.zeros((n, 3))
        self.earth_N = np.zeros((n, 3))
        self.r_sc_N_km = np.zeros((n, 3))
        self.cycle_done = np.zeros(n, dtype=bool)

    def record(self, world, torque_Nm: np.ndarray, cycle_done: bool) -> None:
        if self.n >= len(self.t_s):
            return
        truth = world.truth
        i = self.n
        self.t_s[i] = truth.t
        self.q_NB[i] = truth.q_NB
        self.omega_BN_B[i] = truth.omega_BN_B
        self.wheel_speed_rad_s[i] = truth.wheel_speeds_rad_s
        self.wheel_torque_Nm[i] = torque_Nm
        self.sun_N[i] = truth.sun_N
        self.moon_N[i] = truth.moon_N
        self.earth_N[i] = truth.earth_N
        self.r_sc_N_km[i] = truth.r_sc_N_km
        self.cycle_done[i] = cycle_done
        if self.door is not None:
            self.door_position[i] = self.door.position
        self.n += 1

    def save(self, path: Path) -> None:
        n = self.n
        door = {} if self.door_position is None else {"door_position": self.door_position[:n]}
        np.savez_compressed(path, t_s=self.t_s[:n], q_NB=self.q_NB[:n], omega_BN_B=self.omega_BN_B[:n],
                            wheel_speed_rad_s=self.wheel_speed_rad_s[:n], wheel_torque_Nm=self.wheel_torque_Nm[:n],
                            sun_N=self.sun_N[:n], moon_N=self.moon_N[:n], earth_N=self.earth_N[:n], r_sc_N_km=self.r_sc_N_km[:n],
                            cycle_done=self.cycle_done[:n], **door)


class CandumpLog:
    """Every frame the simulator sends or receives, in candump's log format (``candump -l``), which
    ``cantools decode`` and ``canplayer`` read. Timestamps are simulated seconds.

    Called per frame (``log(direction, t_s, msg)``: the simulator's ``on_frame``) or per burst
    (:meth:`log_burst`: its ``on_burst``, which keeps the simulator on its compiled send and receive
    paths); both write the same line for the same frame."""

    def __init__(self, path: Path, channel: str):
        self._file = open(path, "w", encoding="ascii", buffering=1 << 16)
        self.channel = channel.replace(":", "_") or "can0"
        self.frames = 0
        # ~22 frames a tick share one time stamp and a dozen identifiers: both are formatted once
        self._t_s: float | None = None
        self._stamp = ""
        self._prefix: dict[tuple[int, bool], str] = {}
        self._std_prefix: dict[int, str] = {}  # (id, False) of ``_prefix``, keyed by the id alone (bursts)

    def __call__(self, direction: str, t_s: float, msg) -> None:
        if t_s != self._t_s:
            self._t_s, self._stamp = t_s, f"({t_s:.6f}) {self.channel} "
        self._file.write(self._line(msg))
        self.frames += 1

    def _line(self, msg) -> str:
        """The line of ``msg`` (time stamp ``_stamp``)."""
        key = (msg.arbitration_id, msg.is_extended_id)
        ident = self._prefix.get(key)
        if ident is None:
            ident = self._prefix[key] = (f"{msg.arbitration_id:08X}#" if msg.is_extended_id
                                         else f"{msg.arbitration_id:03X}#")
        data = msg.data
        # bytearray (every received and encoded frame) has hex() itself: no copy into bytes first
        return self._stamp + ident + (data if type(data) is bytearray else bytes(data)).hex().upper() + "\n"

    def log_burst(self, direction: str, t_s: float, burst, rows: Iterable[int] | None = None) -> None:
        """Frames ``rows`` (indices, in order; None: all) of a ``comms.bus.burst.FrameBurst`` sent or received
        at ``t_s``: the lines the per-frame call writes for ``burst.message(i)``, formatted from the burst's
        arrays (one hex string of the whole data block) and written at once. A frame with id -1 (not a plain
        classic data frame: extended, remote, error, FD) is formatted from its message."""
        if t_s != self._t_s:
            self._t_s, self._stamp = t_s, f"({t_s:.6f}) {self.channel} "
        ids = burst.ids.tolist()
        lengths = burst.lengths.tolist()
        data = burst.data
        width = 2 * data.shape[1]  # hex digits per frame row
        hexed = data.tobytes().hex().upper()
        stamp, prefixes = self._stamp, self._std_prefix
        lines = []
        for i in range(len(ids)) if rows is None else rows:
            fid = ids[i]
            if fid < 0:
                lines.append(self._line(burst.message(i)))
                continue
            ident = prefixes.get(fid)
            if ident is None:
                ident = prefixes[fid] = f"{fid:03X}#"
            at = width * i
            lines.append(stamp + ident + hexed[at:at + 2 * lengths[i]] + "\n")
        self._file.write("".join(lines))
        self.frames += len(lines)

    def close(self) -> None:
        self._file.close()


class Timeline:
    """Releases the mission's telecommands at their simulated times through the ground's CommandSender."""

    def __init__(self, mission, sender):
        self.entries = list(mission.timeline)
        self.sender = sender
        law = mission.flight_software.law
        self.gains = {"k1": law.k1, "kappa": law.kappa, "eps": 0.0 if law.eps == "auto" else float(law.eps),
                      "rate_limit_deg_s": mission.flight_software.spacecraft.max_rate_deg_s}
        self.sent: list[dict[str, Any]] = []
        self.errors: list[str] = []

    def release(self, t_s: float) -> None:
        while self.entries and self.entries[0].t_s <= t_s + 1e-9:
            entry = self.entries.pop(0)
            name, args = self._encode(entry)
            try:
                self.sender.send(name, **args)
                self.sent.append({"t_s": t_s, "scheduled_t_s": entry.t_s, "command": name, "args": args})
            except Exception as exc:  # an unsendable command is reported, the run goes on
                self.errors.append(f"t = {t_s:.1f} s: {name} not sent: {exc}")

    def _encode(self, entry) -> tuple[str, dict[str, Any]]:
        from hil_sim.mission.model import SetGainsCommand, SetModeCommand, SetTargetCommand

        if isinstance(entry, SetModeCommand):
            return "SET_MODE", {"mode": entry.mode}
        if isinstance(entry, SetTargetCommand):
            if entry.nadir:
                return "SET_TARGET", {"kind": "NADIR", "c0": 0.0, "c1": 0.0, "c2": 0.0, "c3": 0.0}
            if entry.ground is not None:
                from comms.telecommand import ground_target_args

                g = entry.ground
                return "SET_TARGET", ground_target_args(g.latitude_deg, g.longitude_deg, g.altitude_m)
            direction = entry.target_direction_N()
            if direction is not None:
                c = [float(v) for v in direction]
                return "SET_TARGET", {"kind": "DIRECTION", "c0": c[0], "c1": c[1], "c2": c[2], "c3": 0.0}
            q = [float(v) for v in entry.q_target_NB]
            return "SET_TARGET", {"kind": "QUATERNION", "c0": q[0], "c1": q[1], "c2": q[2], "c3": q[3]}
        if isinstance(entry, SetGainsCommand):
            for key in self.gains:
                value = getattr(entry, key)
                if value is not None:
                    self.gains[key] = float(value)
            return "SET_GAINS", dict(self.gains)
        return entry.command, {}


# ---------------------------------------------------------------------------------------------
# The run
# ---------------------------------------------------------------------------------------------

def run_id(name: str) -> str:
    """``<name>-<date>-<time>-<6 hex>``: unique per run, not per second (many runs start at once); the
    random part also keeps concurrent runs' derived bus endpoints apart."""
    return f"{name}-{dt.datetime.now().strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(3)}"


def _run_dir(out_root: Path, name: str) -> Path:
    """Create the run folder (absolute: the children get absolute paths, whatever their working folder).
    Raises RunNotStarted, before anything starts, when ``out_root`` cannot take it."""
    out_root = Path(out_root).absolute()
    try:
        out_root.mkdir(parents=True, exist_ok=True)
        while True:
            path = out_root / run_id(name)
            try:
                path.mkdir()
                break
            except FileExistsError:
                continue
        (path / ".write-test").write_bytes(b"x" * 4096)  # a full disk or a quota shows here, not mid-run
        (path / ".write-test").unlink()
    except OSError as exc:
        raise RunNotStarted(f"--out {out_root}: cannot write the run folder there: "
                            f"{exc.strerror or exc}") from None
    return path


class _Progress:
    """rich progress bar with simulated time, speed and key channels (truth and the FSW's view)."""

    def __init__(self, enabled: bool, duration_s: float, bus_note: str):
        self.enabled = enabled
        self.status: dict[str, Any] = {}
        self._last = 0.0
        if not enabled:
            return
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                                 TextColumn("t={task.completed:7.1f}/{task.total:.0f} s"),
                                 TextColumn("{task.fields[speed]}"), TimeElapsedColumn(),
                                 TextColumn("{task.fields[channels]}"), refresh_per_second=5)
        self.progress.start()
        self.progress.console.print(f"bus: {bus_note}")
        self.task = self.progress.add_task("SIL", total=duration_s, speed="", channels="")

    def due(self) -> bool:
        """Whether ``update`` would redraw now (enabled, and 0.2 s since the last redraw)."""
        return self.enabled and time.monotonic() - self._last >= 0.2

    def update(self, t_s: float, wall_s: float, truth_error_deg: float, status_queue, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.2 and not force:
            return
        self._last = now
        try:
            while True:
                self.status = status_queue.get_nowait()
        except (queue.Empty, OSError, ValueError):
            pass
        s = self.status
        fsw = ""
        if s:
            fsw = (f"FSW {s.get('mode') or '-'} err {_fmt(s.get('pointing_error_deg'))} deg "
                   f"margin {_fmt(s.get('margin_min_deg'))} deg zone {s.get('active_zone')}")
        speed = f"x{t_s / wall_s:5.1f}" if wall_s > 0 else ""
        self.progress.update(self.task, completed=t_s, speed=speed,
                             channels=f"truth err {truth_error_deg:7.3f} deg | {fsw}")

    def stop(self) -> None:
        if self.enabled:
            self.progress.stop()


def _fmt(value: Any) -> str:
    try:
        return f"{float(value):.3f}"
    except (TypeError, ValueError):
        return "-"


def run_sil(options: RunOptions) -> RunResult:
    """Run one SIL mission end to end (see the module docstring). Raises MissionRejected, RunNotStarted.

    Once the flight software has started, whatever ends the run (the end of the mission, Ctrl-C,
    SIGTERM, a crash of any of the three processes, a full disk) ends it here with a judged
    ``summary.json`` whose ``status`` says which, and the matching exit code."""
    mission, report = prepare(options)
    _shutdown_errors.clear()
    settle_orphaned_runs(options.out_root)  # earlier runs here whose orchestrator was killed get their end
    run_dir = _run_dir(Path(options.out_root), mission.name)
    _reserve_summary(run_dir)
    if report is not None:
        (run_dir / "physics_checks.txt").write_text(report.format() + "\n")
    main_thread = threading.current_thread() is threading.main_thread()
    previous_sigterm = signal.signal(signal.SIGTERM, _raise_terminated) if main_thread else None
    try:
        try:
            status, code = _run(options, mission, run_dir)
        except (RunNotStarted, MissionRejected) as exc:  # the folder's summary must not say 'running'
            _quietly(lambda: _write_reserved_summary(run_dir, {"mission": mission.name, "run_dir": str(run_dir),
                                                               "status": f"not started: {exc}", "pass": False}))
            raise
        if main_thread:  # the run is over: a SIGTERM now must not cut its judgement short
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        try:
            return _judge(run_dir, mission, status, code, options.planned_duration_s)
        except (OSError, EOFError, ValueError, KeyError) as exc:  # what was recorded is unreadable
            reason = _disk_full(exc) or f"{type(exc).__name__}: {exc}"
            crashed = {"mission": mission.name, "run_dir": str(run_dir), "pass": False,
                       "status": f"crashed: the run's records could not be written or read: {reason}"}
            _quietly(lambda: _write_reserved_summary(run_dir, crashed))
            return RunResult(run_dir, EXIT_CRASHED, crashed)
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous_sigterm)


def auth_stats(bus) -> dict:
    """simulator.json's ``bus_authentication`` entry: what the simulator's SecOC layer accepted and refused
    (nothing when the mission does not authenticate its bus)."""
    counters = getattr(bus, "counters", None)
    return {"bus_authentication": counters.as_dict()} if hasattr(counters, "as_dict") else {}


class SilenceWatch:
    """Counts the ticks in a row in which the flight software was not heard from, to end a run whose flight
    software hung. In lockstep a tick is heard when its CYCLE_DONE came. In real time a CYCLE_DONE that
    came late (after the next tick began: a cycle slip, which the judge counts) still shows the flight
    software alive: on a loaded host three late answers in a row used to end the run as "answered none of
    the last 3 ticks", which was not true."""

    def __init__(self, realtime: bool) -> None:
        self.realtime = realtime
        self.missed_in_row = 0

    def after_tick(self, answered_in_time: bool, any_answer_came: bool) -> int:
        heard = answered_in_time or (self.realtime and any_answer_came)
        self.missed_in_row = 0 if heard else self.missed_in_row + 1
        return self.missed_in_row


def _raise_terminated(signum, frame) -> None:  # noqa: ARG001
    raise Terminated()


@dataclass
class _RunParts:
    """What one run has started or built so far: each part stays None until it exists, so that the shutdown
    stops, closes and saves exactly what there is, however far the run got."""

    options: RunOptions
    mission: Any
    run_dir: Path
    bus_info: Any  # comms.bus.transport's resolved bus spec
    endpoints: Any  # ground.link endpoints, rewritten as ports and pids become known
    ground: Any = None  # the ground monitor's process
    port_queue: Any = None
    status_queue: Any = None
    ready: Any = None
    fsw_started: Any = None
    stop_event: Any = None
    key_path: Path | None = None
    link_key: bytes | None = None
    tc_port: int | None = None
    tc_sock: socket.socket | None = None  # reserved for the flight software until it has taken it over
    fsw_proc: subprocess.Popen | None = None
    bus: Any = None
    candump: CandumpLog | None = None
    recorder: TruthRecorder | None = None
    world: Any = None
    sim: Any = None
    timeline: Timeline | None = None
    n_ticks: int = 0
    abort_reason: str = ""
    rt_scheduling: str = ""  # real time: what the tick loop got (SCHED_FIFO, or why not)
    started_wall: float = field(default_factory=time.monotonic)
    cpu_at_start: dict | None = None
    progress: _Progress = field(default_factory=lambda: _Progress(False, 0.0, ""))
    running: bool = False  # the flight software has started: from here on every end of the run is judged


def _run(options: RunOptions, mission, run_dir: Path) -> tuple[str, int | None]:
    """Start the ground and the flight software, run the simulator; returns (status, exit code or None
    for 'judge the requirements'). Raises RunNotStarted until the flight software has started."""
    from comms.bus.transport import BusSpecError, resolve_spec

    try:
        info = resolve_spec(mission.bus, run_id=run_dir.name)
    except BusSpecError as exc:
        raise MissionRejected(f"bus {mission.bus!r}: {exc}") from None
    run = _RunParts(options, mission, run_dir, info, _endpoints(mission, run_dir.name, info.spec, options.realtime))
    _open_simulator_bus(run)
    try:
        _prepare_ground(run)
    except BaseException:
        run.bus.shutdown()
        raise
    status, code = STATUS_COMPLETED, None
    try:
        _start_ground(run)
        _build_simulator(run)
        _start_flight_software(run)
        _simulate(run)
    except KeyboardInterrupt:
        status, code = STATUS_INTERRUPTED, EXIT_INTERRUPTED
    except Terminated:
        status, code = STATUS_INTERRUPTED, EXIT_TERMINATED
    except ProcessCrashed as exc:
        status, code = str(exc), EXIT_CRASHED
    except Exception as exc:  # noqa: BLE001 - after the start, a failure here is the simulator's crash
        if not run.running:
            raise
        where = f"t = {run.sim.t_s:.1f} s" if run.sim is not None else "start"
        reason = f"{exc.strerror} ({exc.filename})" if isinstance(exc, OSError) and exc.strerror else \
            f"{type(exc).__name__}: {exc}"
        status, code = f"crashed: simulator at {where}: {reason}", EXIT_CRASHED
    finally:
        _shut_down(run)
    return status, code


def _prepare_ground(run: _RunParts) -> None:
    """The ground monitor's process (not started yet), its queues and events, and the run's link key."""
    ctx = mp.get_context("spawn")
    run.port_queue, run.status_queue = ctx.Queue(), ctx.Queue(maxsize=4)
    run.ready, run.fsw_started, run.stop_event = ctx.Event(), ctx.Event(), ctx.Event()
    # The run's own link key (0600, in the run folder): the flight software, the ground and the timeline
    # sign and verify with it; no key is ever shared between runs or written into a YAML.
    run.key_path = run.run_dir / LINK_KEY_FILE
    run.link_key = write_key_file(run.key_path)
    tmtc = run.mission.flight_software.tmtc
    run.ground = ctx.Process(target=ground_process, name="keepout-ground",
                             args=(str(run.run_dir / GROUND_DIR), run.endpoints.to_json_dict(),
                                   tmtc.telemetry_port if run.mission.tmtc_ports == "fixed" else 0,
                                   run.port_queue, run.ready, run.fsw_started, run.stop_event, run.status_queue,
                                   os.getpid()),
                             kwargs={"key_file": str(run.key_path)})


def _open_simulator_bus(run: _RunParts) -> None:
    """Open the simulator's end of the run's bus, first of all (the ground and the flight software are told
    its spec). A udp_multicast endpoint drawn at random is drawn again when it cannot be opened: its port
    lies among the host's ephemeral ports, and a socket that took the same port on every address (any client
    socket that sent without binding) blocks the group's bind. Once the simulator holds the port, no
    ephemeral bind can take it. Raises RunNotStarted when the bus cannot be opened."""
    import can

    from comms.bus.transport import BusUnavailableError, open_bus, resolve_spec

    asked = (run.mission.bus or "auto").strip()
    for draw in range(1, BUS_DRAWS + 1):
        info = run.bus_info
        try:
            run.bus = open_bus(info.spec, run_id=run.run_dir.name, bitrate=run.mission.bus_bitrate_bps)
            return
        except (BusUnavailableError, OSError, can.CanError) as exc:
            drawn = info.interface == "udp_multicast" and info.spec != asked
            if not drawn or draw == BUS_DRAWS:
                raise RunNotStarted(f"bus {info.spec} cannot be opened: {exc}") from None
        run.bus_info = resolve_spec(asked, run_id=run.run_dir.name)
        run.endpoints = dataclasses.replace(run.endpoints, bus=run.bus_info.spec)


def _start_ground(run: _RunParts) -> None:
    """Start the ground monitor, then write the config used and the endpoints with the ports it took."""
    options, mission, run_dir = run.options, run.mission, run.run_dir
    run.ground.start()
    if not run.ready.wait(60.0):
        raise RunNotStarted("the ground monitor did not start within 60 s")
    tm_port = run.port_queue.get(timeout=10.0)
    if isinstance(tm_port, str):
        raise RunNotStarted(f"the ground monitor could not start: {tm_port}")
    tmtc = mission.flight_software.tmtc
    run.tc_sock = _reserve_tc_socket(tmtc.telecommand_bind_host,
                                     tmtc.telecommand_port if mission.tmtc_ports == "fixed" else 0)
    run.tc_port = int(run.tc_sock.getsockname()[1])
    data = _config_used(mission, bus_spec=run.bus_info.spec, tm_host=run.endpoints.tm_host, tm_port=tm_port,
                        tc_port=run.tc_port, realtime=options.realtime)
    data["flight_software"]["tmtc"]["security"]["key_file"] = LINK_KEY_FILE  # beside the config used
    write_config(run_dir, data, Path(options.mission))
    _write_fsw_config(run_dir, mission, data)
    run.endpoints = dataclasses.replace(run.endpoints, tm_port=tm_port, tc_port=run.tc_port,
                                        pids={"sil": os.getpid(), "ground": run.ground.pid})
    run.endpoints.write(run_dir)
    if options.announce:
        print(f"run {run_dir}: attach with `keepout ground --run {run_dir}` or "
              f"`keepout ground web --run {run_dir}`", flush=True)


def _build_simulator(run: _RunParts) -> None:
    """Build the world, the simulator on its end of the bus, the telecommand timeline and the recorders. Done before the flight software starts (astropy ephemeris nodes take a few seconds): it
    waits only lockstep_timeout_s for SYNC(0)."""
    from comms.bus.icd import Icd
    from ground.commanding import CommandSender, signing_sender_args
    from hil_sim.sil.lockstep import Simulator
    from hil_sim.mission.model import door_params, magnetic_device_params, world_params
    from hil_sim.world.world import World

    mission, info = run.mission, run.bus_info
    if mission.bus_authentication:
        from comms.bus.secoc import secure

        run.bus = secure(run.bus, Icd(), run.link_key, "SIM")
    sender = CommandSender(host=run.endpoints.tc_host, port=run.tc_port, **signing_sender_args(run.key_path))
    run.timeline = Timeline(mission, sender)
    run.world = World(world_params(mission), seed=mission.seed)
    run.world.truth  # noqa: B018  (evaluates the ephemeris at t = 0 now, not during the first tick)
    run.candump = CandumpLog(run.run_dir / CANDUMP_FILE, info.channel if info.interface == "socketcan" else "vcan0")
    gnc_period = 1.0 / mission.flight_software.rates.gnc_rate_hz
    run.sim = Simulator(run.world, run.bus, Icd(), gnc_period_s=gnc_period,
                        dynamics_dt_s=1.0 / mission.simulation.dynamics_rate_hz, faults=mission.faults,
                        fault_seed=mission.seed, cycle_done_timeout_s=run.options.cycle_done_timeout_s,
                        on_frame=run.candump, on_burst=run.candump.log_burst, door=door_params(mission),
                        magnetic=magnetic_device_params(mission))
    run.n_ticks = int(round(mission.duration_s / gnc_period))
    run.recorder = TruthRecorder(run.n_ticks, len(mission.spacecraft.wheels), door=run.sim.devices.door)
    run.recorder.record(run.world, np.zeros(len(mission.spacecraft.wheels)), True)


def _start_flight_software(run: _RunParts) -> None:
    """Start the flight software and wait for its FSW_STARTED event to reach the ground."""
    run_dir = run.run_dir
    run.fsw_proc = _start_fsw(run_dir, run.tc_sock)
    run.tc_sock.close()  # the flight software holds its own copy now
    if not run.options.realtime:
        _no_wakeup_preemption(run.fsw_proc.pid)
    run.endpoints = dataclasses.replace(run.endpoints, pids={**run.endpoints.pids, "fsw": run.fsw_proc.pid})
    run.endpoints.write(run_dir)
    deadline = time.monotonic() + run.options.fsw_start_timeout_s
    while not run.fsw_started.wait(0.2):
        if run.fsw_proc.poll() is not None:
            raise RunNotStarted(f"the flight software exited with code {run.fsw_proc.returncode} before it "
                                f"started; see {run_dir / FSW_LOG}:\n" + _tail(run_dir / FSW_LOG))
        if not run.ground.is_alive():
            raise RunNotStarted(f"the ground monitor exited (code {run.ground.exitcode}) before the flight "
                                f"software started")
        if time.monotonic() > deadline:
            raise RunNotStarted(f"no FSW_STARTED event from the flight software within "
                                f"{run.options.fsw_start_timeout_s:.0f} s; see {run_dir / FSW_LOG}")
    run.running = True


def _simulate(run: _RunParts) -> None:
    """The simulator's ticks: telecommands released, truth recorded, the flight software watched."""
    options, sim, world = run.options, run.sim, run.world
    run.progress = _Progress(options.progress, run.mission.duration_s, run.bus_info.note)
    error_of = _truth_error_function(run.mission, np.asarray(run.mission.spacecraft.instrument_boresight_B))
    run.started_wall = time.monotonic()
    run.cpu_at_start = _loop_cpu_s(run.fsw_proc, run.ground)
    if options.realtime:
        run.rt_scheduling = _pace_this_thread(options.rt_priority)
        if options.announce and not run.rt_scheduling.startswith("SCHED_FIFO"):
            print(f"real time on the host's normal scheduler ({run.rt_scheduling}): on a busy host cycles can "
                  f"start late and count as slips; give the run SCHED_FIFO (root or CAP_SYS_NICE, "
                  f"--rt-priority) or an idle core", file=sys.stderr, flush=True)
    silence = SilenceWatch(options.realtime)
    for _ in range(run.n_ticks):
        run.timeline.release(sim.t_s)
        answers = sim.stats.cycle_done
        done = sim.run_tick(options.realtime)
        run.recorder.record(world, sim.devices.wheel_torques(sim.t_s), done)
        missed_in_row = silence.after_tick(done, sim.stats.cycle_done > answers)
        # a crash shows within FSW_POLL_TICKS ticks (waitpid is a system call: ~15 us in the vcan-vm guest)
        if not done or sim.tick % FSW_POLL_TICKS == 0:
            _check_alive(run.fsw_proc, run.ground, sim.t_s, run.run_dir)
        if missed_in_row >= options.max_consecutive_missed:
            run.abort_reason = (f"the flight software answered none of the last {missed_in_row} ticks "
                                f"(t = {sim.t_s:.1f} s): run ended early")
            break
        if run.progress.enabled and run.progress.due():  # the truth error only for a redraw (5 a second)
            run.progress.update(sim.t_s, time.monotonic() - run.started_wall, error_of(world.truth, sim.t_s),
                                run.status_queue)
    run.progress.update(sim.t_s, time.monotonic() - run.started_wall, error_of(world.truth, sim.t_s),
                        run.status_queue, force=True)
    _check_alive(run.fsw_proc, run.ground, sim.t_s, run.run_dir)


def _shut_down(run: _RunParts) -> None:
    """Stop the children, close the bus and the candump log, save the truth and the simulator's statistics:
    whatever of them the run got to."""
    # neither a second Ctrl-C nor a SIGTERM may cut the orderly shutdown short
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    previous_term = (signal.signal(signal.SIGTERM, signal.SIG_IGN)
                     if threading.current_thread() is threading.main_thread() else None)
    if run.rt_scheduling.startswith("SCHED_FIFO priority"):  # only what _simulate raised, never a caller's own policy
        _unpace_this_thread()
    wall_s = time.monotonic() - run.started_wall
    loop_cpu_s = _loop_cpu_s(run.fsw_proc, run.ground, since=run.cpu_at_start) if run.cpu_at_start else {}
    run.progress.stop()
    _stop_children(run.fsw_proc, run.ground, run.stop_event)
    if (run.run_dir / ENDPOINTS_FILE).exists():
        _quietly(lambda: dataclasses.replace(run.endpoints, state="finished").write(run.run_dir))
    for close in (run.bus.shutdown if run.bus is not None else None,
                  run.candump.close if run.candump is not None else None,
                  run.tc_sock.close if run.tc_sock is not None else None):
        _quietly(close)
    if run.recorder is not None:
        _quietly(lambda: run.recorder.save(run.run_dir / TRUTH_FILE))
    if run.sim is not None:
        stats = _simulator_stats(run, wall_s, loop_cpu_s)
        _quietly(lambda: (run.run_dir / SIM_STATS_FILE).write_text(json.dumps(_plain(stats), indent=1) + "\n"))
    signal.signal(signal.SIGINT, previous)
    if previous_term is not None:
        signal.signal(signal.SIGTERM, previous_term)


def _simulator_stats(run: _RunParts, wall_s: float, loop_cpu_s: dict) -> dict[str, Any]:
    """simulator.json: the simulator's counters, how the run ended and what it injected and sent."""
    sim, bus, candump, timeline = run.sim, run.bus, run.candump, run.timeline
    return {**sim.stats.__dict__, "aborted": run.abort_reason, "clock": "realtime" if run.options.realtime else "lockstep",
            **({"rt_scheduling": run.rt_scheduling, "rt_phase_shift_ms": None if sim.rt_phase_shift_s is None
                else round(1e3 * sim.rt_phase_shift_s, 3)} if run.options.realtime else {}),
            "bus": run.bus_info.spec, "bus_note": run.bus_info.note, "wall_s": wall_s,
            "loop_cpu_s": loop_cpu_s, "sim_s": sim.t_s - sim.t0_s, "candump_frames": candump.frames if candump else 0,
            "receiver_counters": _plain(getattr(sim.receiver, "counters", {})),
            "bus_decode_errors": int(getattr(bus, "decode_errors", 0)),
            **auth_stats(bus),
            "faults_injected": [list(map(_plain, e)) if isinstance(e, tuple) else _plain(e)
                                for e in getattr(sim.injector, "log", [])],
            "telecommands": timeline.sent if timeline else [],
            "telecommand_errors": timeline.errors if timeline else []}


def _process_cpu_s(pid: int | None) -> float | None:
    """CPU time [s] (user + system) process ``pid`` has used so far, from /proc (None where unreadable)."""
    if pid is None:
        return None
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime
    except (OSError, ValueError, IndexError):
        return None


def _loop_cpu_s(fsw_proc, ground, since: dict | None = None) -> dict[str, float | None]:
    """CPU time [s] of the simulator (this process), the flight software and the ground monitor: so far,
    or since ``since`` (the lockstep loop's share: on a one-CPU host, e.g. the vcan-vm guest, their sum is
    the loop's wall time). Two /proc reads: taken at the loop's start and end only."""
    now = {"simulator": time.process_time(), "fsw": _process_cpu_s(getattr(fsw_proc, "pid", None)),
           "ground": _process_cpu_s(getattr(ground, "pid", None))}
    if since is None:
        return now
    return {k: (None if v is None or since.get(k) is None else v - since[k]) for k, v in now.items()}


def _start_fsw(run_dir: Path, tc_sock: socket.socket) -> subprocess.Popen:
    """``python -m fsw`` on the run's FSW_CONFIG_FILE in its own session (a terminal's Ctrl-C is the
    orchestrator's to handle), in the run folder, with absolute paths, taking telecommands on ``tc_sock``
    (inherited); it dies with this process (fsw.lifetime)."""
    fd = tc_sock.fileno()
    with open(run_dir / FSW_LOG, "w") as fsw_log:
        return subprocess.Popen(
            [sys.executable, "-m", "fsw", "--config", str(run_dir / FSW_CONFIG_FILE), "--tc-fd", str(fd)],
            pass_fds=(fd,), stdout=fsw_log, stderr=subprocess.STDOUT, cwd=str(run_dir), start_new_session=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1", PARENT_PID_ENV: str(os.getpid())})


def _check_alive(fsw_proc: subprocess.Popen, ground, t_s: float, run_dir: Path) -> None:
    """Raise ProcessCrashed when the flight software or the ground monitor ended mid-run."""
    if fsw_proc.poll() is not None:
        raise ProcessCrashed(f"crashed: fsw at t = {t_s:.1f} s (exit code {fsw_proc.returncode}; see "
                             f"{run_dir / FSW_LOG})")
    if not ground.is_alive():
        why = ": it could not write its telemetry archive" if ground.exitcode == GROUND_EXIT_CANNOT_WRITE else ""
        raise ProcessCrashed(f"crashed: ground at t = {t_s:.1f} s (exit code {ground.exitcode}){why}")


def _stop_children(fsw_proc: subprocess.Popen | None, ground, stop_event) -> None:
    """The flight software first (its last telemetry still reaches the ground), then the ground."""
    _stop_fsw(fsw_proc)
    stop_event.set()
    if ground.is_alive() or (ground.pid is not None and ground.exitcode is None):
        ground.join(timeout=15.0)
        if ground.is_alive():
            ground.terminate()
            ground.join(timeout=5.0)


# what the shutdown steps of this process's run could not do (a full disk): said once, in the final status
_shutdown_errors: list[Exception] = []


def _quietly(step) -> None:
    """One shutdown step; a failure (a full disk) must not keep the next ones or the summary from running."""
    if step is None:
        return
    try:
        step()
    except (OSError, ValueError) as exc:
        _shutdown_errors.append(exc)


def _disk_full(exc: BaseException | None = None) -> str | None:
    """'No space left on device' (or the first write error) when the run folder's disk failed the run."""
    errors = [e for e in (*_shutdown_errors, exc) if isinstance(e, OSError)]
    full = [e for e in errors if e.errno == errno.ENOSPC] or errors
    return (full[0].strerror or str(full[0])) if full else None


SUMMARY_FILE = "summary.json"
SUMMARY_RESERVE_BYTES = 256 * 1024


def _reserve_summary(run_dir: Path) -> None:
    """Write summary.json at the start, status 'running', padded: the final summary overwrites these
    blocks, so it can be written even when the disk has filled up during the run."""
    head = json.dumps({"status": "running", "pass": False, "run_dir": str(run_dir),
                       "orchestrator": {"pid": os.getpid(), "started_s": _own_start_time()}})
    (run_dir / SUMMARY_FILE).write_text(head + " " * (SUMMARY_RESERVE_BYTES - len(head)) + "\n")


def _write_reserved_summary(run_dir: Path, summary: dict[str, Any]) -> None:
    """Overwrite the reserved summary.json in place; on a full disk, a short summary that fits."""
    from hil_sim.sil.judge import summary_json

    path = run_dir / SUMMARY_FILE
    text = summary_json(summary).encode()
    try:
        with open(path, "r+b") as f:
            f.write(text)
            f.truncate()
        return
    except OSError as exc:
        short = {k: summary.get(k) for k in ("mission", "run_dir", "status", "pass", "simulated_s")}
        short["status"] = f"{summary.get('status')}; the full summary could not be written: {exc.strerror}"
        summary["status"] = short["status"]
    with open(path, "r+b") as f:
        f.write(json.dumps(short, indent=1).encode()[:SUMMARY_RESERVE_BYTES])
        f.truncate()


def _judge(run_dir: Path, mission, status: str, code: int | None,
           planned_duration_s: float | None = None) -> RunResult:
    """Judge what was recorded, write summary.json and the plots; the exit code follows the status."""
    from hil_sim.sil.plots import write_plots
    from hil_sim.sil.judge import evaluate

    summary, series = evaluate(run_dir, mission, status=status, planned_duration_s=planned_duration_s)
    status = summary["status"]  # 'completed' becomes 'incomplete telemetry' when the ground lost some
    if code is None:
        code = (EXIT_INCOMPLETE_TELEMETRY if status == STATUS_INCOMPLETE
                else EXIT_PASS if summary["pass"] else EXIT_FAIL)
    try:
        _write_reserved_summary(run_dir, summary)
    except OSError as exc:
        print(f"keepout: {run_dir / SUMMARY_FILE}: cannot write: {exc.strerror}", file=sys.stderr)
        code = code if code != EXIT_PASS else EXIT_CRASHED
    try:
        write_plots(run_dir, mission, series)
    except Exception as exc:  # plots are a view: a failure must not hide the summary
        _quietly(lambda: (run_dir / "plots_error.txt").write_text(f"{type(exc).__name__}: {exc}\n"))
    return RunResult(run_dir, code, summary)


def _endpoints(mission, run_id: str, bus_spec: str, realtime: bool):
    """The run's link before its ports are known: a per-run loopback multicast group (any number of ground
    clients attach), or with ``telemetry_link: unicast`` the SIL's own ground at the mission's address."""
    from ground.link import LOOPBACK, Endpoints, random_group

    tmtc = mission.flight_software.tmtc
    tc_host = tmtc.telecommand_bind_host if tmtc.telecommand_bind_host != "0.0.0.0" else LOOPBACK
    if mission.telemetry_link == "unicast":
        transport, tm_host, interface = "udp", tmtc.telemetry_host, tmtc.telemetry_host
    else:
        # fixed ports keep a group the mission names, so an outside ground can be set up in advance
        fixed_group = mission.tmtc_ports == "fixed" and ipaddress.ip_address(tmtc.telemetry_host).is_multicast
        transport, interface = "udp-multicast", tmtc.telemetry_multicast_interface
        tm_host = tmtc.telemetry_host if fixed_group else random_group()
    return Endpoints(run_id=run_id, tm_transport=transport, tm_host=tm_host, tm_port=0, tm_interface=interface,
                     tc_host=tc_host, tc_port=0, bus=bus_spec, clock="realtime" if realtime else "lockstep",
                     pids={"sil": os.getpid()}, started_unix_s=time.time(),
                     orchestrator_started_s=_own_start_time())


def _own_start_time() -> float:
    """This process's start time as psutil reports it: with the pid, tells a later reader of the run folder
    whether the orchestrator still runs (ground.link.settle_orphaned_run)."""
    import psutil

    return psutil.Process().create_time()


def _truth_error_function(mission, boresight_B: np.ndarray):
    """Truth pointing/attitude error [deg] against the current target, for the progress bar."""
    from gnc.attitude import attitude_error_angle, quat_rotate
    from hil_sim.mission.physics_checks import schedule

    segments = schedule(mission)

    def error(truth, t_s: float) -> float:
        seg = segments[-1]
        for s in segments:
            if s.t_start_s <= t_s < s.t_end_s:
                seg = s
                break
        if seg.mode == "QUATERNION":
            return math.degrees(attitude_error_angle(truth.q_NB, seg.target))
        if seg.mode == "POINTING":
            y = quat_rotate(truth.q_NB, boresight_B)
            return math.degrees(math.acos(max(-1.0, min(1.0, float(y @ seg.target)))))
        return float("nan")

    return error


def _pace_this_thread(priority: int) -> str:
    """Real time: ask SCHED_FIFO ``priority`` for the calling (tick loop) thread, so the host's other work
    cannot delay a tick; says what it got. The judge and the plots run after the loop, back on the normal
    scheduler (``_unpace_this_thread``)."""
    if priority <= 0:
        return "normal scheduler (--rt-priority 0)"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"SCHED_FIFO {priority} refused: {exc}"
    return f"SCHED_FIFO priority {priority}"


def _unpace_this_thread() -> None:
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass


def _no_wakeup_preemption(pid: int) -> bool:
    """Lockstep: let the flight software process ``pid`` wake up without preempting the simulator
    (SCHED_BATCH: time-sharing as before, minus wake-up preemption). Returns whether it was set.

    Each tick's SYNC, sensor and wheel frames leave in one sendmmsg. Where the SIL has one CPU (the vcan-vm
    guest), a flight software already waiting was woken by the first frame and preempted the simulator
    inside that call, then read the burst one frame per wake-up: in about one tick in five, 17 wake-ups
    and 50 system calls instead of one of each (counted in the guest). Under SCHED_BATCH it runs when the
    simulator waits for CYCLE_DONE, with the whole burst queued. Lockstep results do not depend on
    scheduling; real-time runs keep the normal policy (or their own SCHED_FIFO)."""
    try:
        os.sched_setscheduler(pid, os.SCHED_BATCH, os.sched_param(0))
    except (OSError, AttributeError):  # no such policy here, or the process is gone: run as before
        return False
    return True


def _stop_fsw(proc: subprocess.Popen | None) -> None:
    """Ask the flight software to stop (SIGINT: it sends FSW_STOPPED), then insist."""
    if proc is None or proc.poll() is not None:
        return
    for sig, wait in ((signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            proc.send_signal(sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue


def _tail(path: Path, lines: int = 20) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return ""


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if hasattr(value, "__dict__") and not isinstance(value, type):
        return _plain(vars(value))
    return value
