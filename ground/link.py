"""The ground's link to a running spacecraft: a run's endpoints, and the one way to open its telemetry.

A SIL run writes ``RUN_DIR/endpoints.json`` as soon as it starts (``Endpoints.write``). Every ground
client (the SIL's own archiving ground, ``keepout ground --run``, ``keepout ground web``, ``keepout
ground send --run`` waiting for acknowledgements) reads it and calls ``open_telemetry``, so they all
receive the same packets without disturbing each other or the run.

Fan-out: the flight software sends telemetry to a per-run multicast group (random in 239.0.0.0/8, a
random port) on the loopback interface with TTL 0, so it never leaves the computer. Each client binds
the group's port with SO_REUSEADDR/SO_REUSEPORT and joins the group on 127.0.0.1; the kernel hands every
datagram to every member. A client that attaches late or detaches early changes nothing for the others
and costs the flight software nothing (one send per packet, whoever listens). A real link (a ground
station at a unicast address) is a mission setting (``telemetry_link: unicast``): then the telemetry
goes to one socket only, and ``open_telemetry`` binds that address like a plain receiver.
"""
from __future__ import annotations

import ipaddress
import json
import os
import random
import socket
from dataclasses import MISSING, asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

ENDPOINTS_FILE = "endpoints.json"
ENDPOINTS_VERSION = 1
LOOPBACK = "127.0.0.1"
RUNS_ROOT = Path("runs")  # where `keepout sil run` puts run folders by default (`--run latest` looks here)


class LinkError(Exception):
    """A run's endpoints cannot be found or read, or its telemetry cannot be opened (message says why)."""


@dataclass(frozen=True)
class Endpoints:
    """Where a run's telemetry and telecommands are, as written in ``RUN_DIR/endpoints.json``.

    ``tm_host`` is a multicast group (``tm_transport == "udp-multicast"``, joined on ``tm_interface``) or
    the unicast address the telemetry is sent to (``"udp"``). ``tc_host``/``tc_port`` is where the flight
    software receives telecommands. ``state`` is ``running`` until the run ends (then ``finished``).
    """

    run_id: str
    tm_transport: str
    tm_host: str
    tm_port: int
    tc_host: str
    tc_port: int
    bus: str
    tm_interface: str = LOOPBACK
    clock: str = "lockstep"
    pids: dict[str, int] = field(default_factory=dict)
    started_unix_s: float = 0.0
    state: str = "running"
    # the orchestrator's process start time (psutil's create_time): a reused pid is not taken for it
    orchestrator_started_s: float = 0.0
    version: int = ENDPOINTS_VERSION

    @property
    def multicast(self) -> bool:
        return self.tm_transport == "udp-multicast"

    def to_json_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json_dict(cls, data: dict[str, Any], source: str = ENDPOINTS_FILE) -> Endpoints:
        known = set(cls.__dataclass_fields__)
        required = [n for n, f in cls.__dataclass_fields__.items()
                    if f.default is MISSING and f.default_factory is MISSING]
        missing = [n for n in required if n not in data]
        if missing:
            raise LinkError(f"{source}: missing key(s) {', '.join(missing)}; expected the keys "
                            f"{', '.join(sorted(known))}")
        try:
            endpoints = cls(**{k: v for k, v in data.items() if k in known})
            int(endpoints.tm_port), int(endpoints.tc_port)
            ipaddress.ip_address(endpoints.tm_host)
        except (TypeError, ValueError) as exc:
            raise LinkError(f"{source}: bad value: {exc}") from None
        if endpoints.tm_transport not in ("udp-multicast", "udp"):
            raise LinkError(f"{source}: key tm_transport is {endpoints.tm_transport!r}; allowed: udp-multicast, udp")
        return endpoints

    @classmethod
    def load(cls, run_dir: str | Path) -> Endpoints:
        """Read ``RUN_DIR/endpoints.json`` (``run_dir`` may also name the file itself)."""
        path = Path(run_dir)
        if path.is_dir():
            path = path / ENDPOINTS_FILE
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise LinkError(f"{path} does not exist: is this a run folder of `keepout sil run`?") from None
        except (OSError, json.JSONDecodeError) as exc:
            raise LinkError(f"{path}: cannot read: {exc}") from None
        if not isinstance(data, dict):
            raise LinkError(f"{path}: expected a JSON object")
        return cls.from_json_dict(data, str(path))

    def write(self, run_dir: str | Path) -> Path:
        """Write ``RUN_DIR/endpoints.json`` atomically (a reader never sees half a file)."""
        path = Path(run_dir) / ENDPOINTS_FILE
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(self.to_json_dict(), indent=1) + "\n", encoding="utf-8")
        os.replace(tmp, path)
        return path


def random_group(rng: random.Random | None = None) -> str:
    """A multicast group in the administratively scoped 239.0.0.0/8 (never 239.0.0.x or .255 ends)."""
    rng = rng or random.SystemRandom()
    return f"239.{rng.randint(1, 254)}.{rng.randint(1, 254)}.{rng.randint(1, 254)}"


def open_telemetry(endpoints: Endpoints, *, port: int | None = None,
                   recv_buffer_bytes: int = 8 * 1024 * 1024) -> socket.socket:
    """Open a non-blocking UDP socket that receives the run's telemetry datagrams (CCSDS TM packets).

    Multicast (``endpoints.multicast``): binds ``(group, port)`` with SO_REUSEADDR and SO_REUSEPORT and
    joins the group on ``endpoints.tm_interface``, so any number of clients (in any process) receive every
    packet sent after they joined; closing the socket leaves the group. Unicast: binds
    ``(tm_host, port)`` (the only receiver; a second one fails with "address already in use").

    ``port`` overrides ``endpoints.tm_port``; 0 lets the kernel choose a free one (read it back with
    ``getsockname()``): the SIL's own ground opens the run's socket this way before the port is known.
    Raises ``LinkError`` naming the address when the socket cannot be opened. The caller reads with
    ``recv`` / ``select`` and decodes with ``comms.telemetry.decode_tm_packet`` (as ``GroundMonitor`` does).
    """
    port = endpoints.tm_port if port is None else port
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        try:  # a big buffer absorbs bursts when lockstep runs faster than real time
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, recv_buffer_bytes)
        except OSError:
            pass
        if endpoints.multicast:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            # Bound to the group address (not 0.0.0.0): this socket receives this group's datagrams only.
            sock.bind((endpoints.tm_host, port))
            membership = socket.inet_aton(endpoints.tm_host) + socket.inet_aton(endpoints.tm_interface)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        else:
            sock.bind((endpoints.tm_host, port))
        sock.setblocking(False)
    except OSError as exc:
        sock.close()
        where = f"group {endpoints.tm_host}:{port} on {endpoints.tm_interface}" if endpoints.multicast \
            else f"{endpoints.tm_host}:{port}"
        raise LinkError(f"cannot open the telemetry of run {endpoints.run_id} ({where}): {exc}") from None
    return sock


ORCHESTRATOR_KILLED = "crashed: orchestrator killed"


def orchestrator_alive(endpoints: Endpoints) -> bool:
    """Whether the process that wrote ``endpoints`` (``pids['sil']``) still runs: the same pid with the same
    start time (an old folder without the start time: the pid alone)."""
    import psutil

    pid = endpoints.pids.get("sil")
    if not pid:
        return True  # not written by an orchestrator we can check: leave it alone
    try:
        proc = psutil.Process(int(pid))
        if proc.status() == psutil.STATUS_ZOMBIE:
            return False
        started = proc.create_time()
    except (psutil.NoSuchProcess, psutil.AccessDenied, ValueError):
        return False
    return not endpoints.orchestrator_started_s or abs(started - endpoints.orchestrator_started_s) < 0.05


def settle_orphaned_run(run_dir: str | Path) -> bool:
    """Give a run whose orchestrator is gone (SIGKILL, a host crash) its final status: ``endpoints.json``
    ``state`` and ``summary.json`` ``status`` said "running" for ever; they now say it crashed. Returns
    whether the folder was changed. Any `keepout` command that reads run folders calls this."""
    run_dir = Path(run_dir)
    summary_path = run_dir / "summary.json"
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        summary = {"run_dir": str(run_dir)}
    try:
        endpoints = Endpoints.load(run_dir)
    except LinkError:  # killed before the endpoints were written: the reserved summary names the orchestrator
        who = summary.get("orchestrator") if isinstance(summary.get("orchestrator"), dict) else None
        if summary.get("status") != "running" or not who:
            return False
        endpoints = Endpoints(run_id="", tm_transport="udp", tm_host=LOOPBACK, tm_port=0, tc_host=LOOPBACK,
                              tc_port=0, bus="", pids={"sil": who.get("pid", 0)},
                              orchestrator_started_s=float(who.get("started_s") or 0.0), state="(none)")
        if orchestrator_alive(endpoints):
            return False
    else:
        if endpoints.state != "running" or orchestrator_alive(endpoints):
            return False
    if summary.get("status", "running") == "running":
        summary.update(status=ORCHESTRATOR_KILLED, **{"pass": False})
        tmp = summary_path.with_suffix(".json.tmp")
        try:
            tmp.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
            os.replace(tmp, summary_path)
        except OSError:
            return False
    if endpoints.state == "running":
        try:
            replace(endpoints, state="crashed").write(run_dir)
        except OSError:
            return False
    return True


def settle_orphaned_runs(runs_root: str | Path = RUNS_ROOT) -> list[Path]:
    """`settle_orphaned_run` on every run folder under ``runs_root``; the folders it changed."""
    root = Path(runs_root)
    return [p.parent for p in (root.glob("*/summary.json") if root.is_dir() else ())
            if _says_running(p) and settle_orphaned_run(p.parent)]


def _says_running(summary_path: Path) -> bool:
    """A cheap look at a summary's head (a finished one is never read whole here)."""
    try:
        with open(summary_path, "rb") as f:
            head = f.read(512)
    except OSError:
        return False
    return b'"status": "running"' in head or b'"status":"running"' in head


def find_run(spec: str | Path, runs_root: str | Path = RUNS_ROOT) -> Path:
    """The run folder ``spec`` names: a folder holding ``endpoints.json``, or ``latest`` (the run under
    ``runs_root`` that started last). Raises ``LinkError`` saying what was looked for."""
    if str(spec) != "latest":
        path = Path(spec)
        if not (path / ENDPOINTS_FILE).is_file():
            raise LinkError(f"--run {spec}: no {ENDPOINTS_FILE} there; give a run folder written by "
                            f"`keepout sil run` or `latest`")
        settle_orphaned_run(path)
        return path
    root = Path(runs_root)
    settle_orphaned_runs(root)
    candidates = []
    for path in root.glob(f"*/{ENDPOINTS_FILE}") if root.is_dir() else ():
        try:
            started = float(json.loads(path.read_text(encoding="utf-8")).get("started_unix_s", 0.0))
        except (OSError, ValueError, AttributeError):
            continue  # being written or not ours: skip it
        candidates.append((started, path.stat().st_mtime, path.parent))
    if not candidates:
        raise LinkError(f"--run latest: no run folder with {ENDPOINTS_FILE} under {root.resolve()}")
    return max(candidates)[2]

