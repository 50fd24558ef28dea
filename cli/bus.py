"""``keepout bus monitor`` and ``keepout bus log``: look at the bus through the ICD; ``keepout bus respond``:
answer the simulator's SYNC frames as a stand-in flight software (benches and tests).

  keepout bus monitor [--bus SPEC] [--duration S] [--lines]
      live decoded view: one row per ICD message with its last values, rate and E2E classification
      counts (a table when stdout is a terminal, one line per frame with --lines or when piped).
  keepout bus log --out FILE [--bus SPEC] [--duration S] [--count N]
      candump-compatible log (``candump -L`` format, as python-can's CanutilsLogWriter writes it), which
      ``cantools decode config/icd/keepout.dbc < FILE`` decodes.
  keepout bus respond --bus SPEC [--wheels N] [--ticks N] [--idle-timeout S]
      a minimal flight-software stand-in, NOT the flight software: answers each SYNC with rate-damping
      wheel torques and CYCLE_DONE (hil_sim.sil.lockstep.RateDampingResponder on the flight bus driver);
      prints READY once listening, and at the end ``cycles N cpu_s S`` (the CPU its cycles took).

The same DBC works with cantools' own monitor on a real interface:
  cantools monitor config/icd/keepout.dbc -i socketcan -c vcan0
  cantools monitor config/icd/keepout.dbc -i udp_multicast -c GROUP --bus-kwargs port=PORT fd=False
(a SIL run prints its bus spec; with ``auto`` it says which transport it chose).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from typing import Any, TextIO

DEFAULT_SPEC = "auto"


def add_cli(subparsers: Any) -> None:
    bus = subparsers.add_parser("bus", help="monitor or log the CAN bus through the ICD (config/icd/keepout.dbc)",
                                description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = bus.add_subparsers(dest="bus_command", metavar="SUBCOMMAND")
    for name, helptext in (("monitor", "live decoded view of the bus"),
                           ("log", "write a candump-compatible log that `cantools decode` reads")):
        p = sub.add_parser(name, help=helptext)
        p.add_argument("--bus", default=DEFAULT_SPEC,
                       help="auto | socketcan[:IFACE] | udp_multicast[:GROUP:PORT] | virtual[:CHANNEL] "
                            "(default: auto)")
        p.add_argument("--run-id", default=None, help="derive the udp_multicast group/port from this SIL run id")
        p.add_argument("--dbc", default=None, help="ICD file (default: config/icd/keepout.dbc)")
        p.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: until Ctrl-C)")
        p.add_argument("--count", type=int, default=0, help="stop after this many frames (0: no limit)")
        if name == "monitor":
            p.add_argument("--lines", action="store_true", help="one line per frame instead of a live table")
            p.set_defaults(func=_monitor_command)
        else:
            p.add_argument("--out", default="-", help="log file (default: stdout)")
            p.add_argument("--channel-name", default=None,
                           help="interface name written in the log (default: the bus channel, or 'can0')")
            p.set_defaults(func=_log_command)
    respond = sub.add_parser("respond", help="answer SYNC frames as a minimal flight-software stand-in (benches)")
    respond.add_argument("--bus", required=True, help="bus spec, e.g. socketcan:vcan0")
    respond.add_argument("--wheels", type=int, default=4, help="number of reaction wheels (default: 4)")
    respond.add_argument("--ticks", type=int, default=0, help="stop after this many cycles (0: until idle)")
    respond.add_argument("--idle-timeout", type=float, default=5.0, help="stop after this long without SYNC [s]")
    respond.set_defaults(func=_respond_command)
    bus.set_defaults(func=lambda args: (bus.print_help(), 2)[1])


def _open(args: argparse.Namespace):
    from comms.bus.icd import Icd
    from comms.bus.transport import BusSpecError, BusUnavailableError, open_bus

    info: list = []
    try:
        icd = Icd(args.dbc) if args.dbc else Icd()
        bus = open_bus(args.bus, args.run_id, info_out=info)
    except (BusSpecError, BusUnavailableError, ValueError) as exc:
        print(f"keepout bus: {exc}", file=sys.stderr)
        return None
    print(f"keepout bus: {info[0].note}", file=sys.stderr)
    return icd, bus, info[0]


def _on_bus(args: argparse.Namespace, work: Callable[[Any, Any, Any], None]) -> int:
    """Open the ICD and the bus, run ``work(icd, bus, info)`` until it returns or Ctrl-C (a normal way to
    stop monitor and log), and always shut the bus down; 2 when the bus cannot be opened."""
    opened = _open(args)
    if opened is None:
        return 2
    icd, bus, info = opened
    try:
        work(icd, bus, info)
    except KeyboardInterrupt:
        pass
    finally:
        bus.shutdown()
    return 0


def _until(args: argparse.Namespace):
    deadline = time.monotonic() + args.duration if args.duration > 0 else None

    def more(n: int) -> bool:
        if args.count and n >= args.count:
            return False
        return deadline is None or time.monotonic() < deadline

    def wait_s() -> float:
        return 0.2 if deadline is None else max(0.0, min(0.2, deadline - time.monotonic()))

    return more, wait_s


# ------------------------------------------------------------------------------------------------ log
def log_frames(bus: Any, out: TextIO, channel: str, more, wait_s) -> int:
    """Copy frames from ``bus`` to ``out`` in candump -L format until ``more(n)`` is False."""
    import can

    writer = can.CanutilsLogWriter(out, channel=channel)
    n = 0
    try:
        while more(n):
            msg = bus.recv(timeout=wait_s())
            if msg is None:
                continue
            # candump names the interface; python-can channels may be addresses or None
            msg.channel = channel
            writer.on_message_received(msg)
            n += 1
    finally:
        out.flush()
    return n


def _log_command(args: argparse.Namespace) -> int:
    def log(_icd: Any, bus: Any, info: Any) -> None:
        channel = args.channel_name or (info.channel if info.interface == "socketcan" else "can0")
        more, wait_s = _until(args)
        out = sys.stdout if args.out == "-" else open(args.out, "w", encoding="ascii")
        try:
            n = log_frames(bus, out, channel, more, wait_s)
        finally:
            if out is not sys.stdout:
                out.close()
        # not reached on Ctrl-C: an interrupted log does not claim a count
        print(f"keepout bus: logged {n} frames", file=sys.stderr)

    return _on_bus(args, log)


# -------------------------------------------------------------------------------------------- monitor
class MonitorState:
    """Per-message view: count, rate, last decoded values, E2E classification counts."""

    def __init__(self, icd: Any) -> None:
        from comms.bus.e2e import E2EReceiver

        self.icd = icd
        self.receiver = E2EReceiver(icd)  # passive: judges every node's frames
        self.last: dict[str, dict] = {}
        self.first_t: dict[str, float] = {}
        self.seen: dict[str, int] = {}
        # SecOC authenticators (missions with bus_authentication): named, not "unknown"; E2E does not judge them
        self.authenticators = {fid: f"SECOC_{node}" for node, fid in icd.authenticators.items()}
        self.authenticators_seen = 0

    def _name(self, frame: Any) -> str:
        return frame.name or self.authenticators.get(frame.frame_id) or f"0x{frame.frame_id:03X}"

    def feed(self, msg: Any, now: float):
        frame = self.receiver.classify(msg, now)
        self.authenticators_seen += frame.name is None and frame.frame_id in self.authenticators
        name = self._name(frame)
        self.seen[name] = self.seen.get(name, 0) + 1
        self.first_t.setdefault(name, now)
        if frame.delivered:
            self.last[name] = {k: v for k, v in frame.signals.items() if not k.startswith("E2E_")}
        return frame

    def line(self, frame: Any) -> str:
        name = self._name(frame)
        values = self.last.get(name, {}) if frame.delivered else {}
        text = " ".join(f"{k}={_fmt(v)}" for k, v in values.items())
        return f"{frame.t:12.3f} {name:<14} {frame.status:<14} {text}"

    def table(self, now: float):
        from rich.table import Table

        table = Table(title="keepout bus (E2E-checked, config/icd/keepout.dbc)")
        for col in ("message", "frames", "rate Hz", "last values", "E2E not ok"):
            table.add_column(col)
        for name in sorted(self.seen, key=lambda n: self.icd.messages[n].frame_id if n in self.icd.messages else 2048):
            span = now - self.first_t[name]
            rate = f"{(self.seen[name] - 1) / span:.1f}" if span > 0 and self.seen[name] > 1 else "-"
            values = " ".join(f"{k}={_fmt(v)}" for k, v in self.last.get(name, {}).items())
            counts = self.receiver.counters.get(name, {})
            bad = " ".join(f"{k}:{v}" for k, v in counts.items() if v and k != "ok")
            table.add_row(name, str(self.seen[name]), rate, values, bad)
        unknown = self.receiver.counters["_bus"]["unknown_id"] - self.authenticators_seen
        if unknown:
            table.caption = f"unknown ids: {unknown}"
        return table


def _fmt(value: float) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def monitor(bus: Any, icd: Any, out: TextIO, more, wait_s, live: bool) -> MonitorState:
    state = MonitorState(icd)
    n = 0
    if not live:
        while more(n):
            msg = bus.recv(timeout=wait_s())
            if msg is None:
                continue
            frame = state.feed(msg, time.monotonic())
            out.write(state.line(frame) + "\n")
            n += 1
        out.flush()
        return state
    from rich.live import Live

    with Live(state.table(time.monotonic()), refresh_per_second=4) as view:
        while more(n):
            msg = bus.recv(timeout=wait_s())
            if msg is not None:
                state.feed(msg, time.monotonic())
                n += 1
            view.update(state.table(time.monotonic()))
    return state


def _monitor_command(args: argparse.Namespace) -> int:
    def watch(icd: Any, bus: Any, _info: Any) -> None:
        more, wait_s = _until(args)
        monitor(bus, icd, sys.stdout, more, wait_s, live=sys.stdout.isatty() and not args.lines)

    return _on_bus(args, watch)


# -------------------------------------------------------------------------------------------- respond
def _respond_command(args: argparse.Namespace) -> int:
    import numpy as np

    from comms.bus import Icd, open_bus
    from fsw.bus import FswBusDriver
    from hil_sim.sil.lockstep import RateDampingResponder

    bus = open_bus(args.bus)
    try:
        driver = FswBusDriver(bus, Icd(), args.wheels)
        axes = np.eye(3)[:, :args.wheels].T if args.wheels <= 3 else np.vstack(
            [np.eye(3), np.ones((args.wheels - 3, 3)) / math.sqrt(3)])
        responder = RateDampingResponder(driver, axes)
        print("READY", flush=True)
        cpu0 = time.process_time()
        while responder.cycle(args.idle_timeout):
            if args.ticks and responder.cycles >= args.ticks:
                break
        # CPU seconds used for all cycles (benchmarks derive the loop's capacity from it)
        print(f"cycles {responder.cycles} cpu_s {time.process_time() - cpu0:.6f}", flush=True)
    finally:
        bus.shutdown()
    return 0
