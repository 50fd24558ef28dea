"""``keepout ground``: monitor (live table), ``send`` one telecommand, ``decode`` a raw archive."""
from __future__ import annotations

import argparse
import ipaddress
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fsw.dictionary import DEFAULT_HOST, DEFAULT_TC_PORT, DEFAULT_TM_PORT, DICTIONARY, TelemetryDictionary
from ground.archive import DECODED_ARCHIVE, RAW_ARCHIVE, read_raw_archive
from ground.commanding import CommandSender
from ground.link import LOOPBACK, Endpoints, LinkError, find_run, open_telemetry
from ground.monitor import GroundMonitor
from ground.web.cli import add_cli as add_web_cli


def add_cli(subparsers: Any) -> None:
    """Add ``keepout ground`` (monitor) and ``keepout ground send OPCODE ARGS...``."""
    parser = subparsers.add_parser(
        "ground", help="ground monitor: receive/archive/display telemetry; send telecommands",
        description="Receive, archive and display keepout telemetry; `ground send` sends a telecommand.",
    )
    parser.add_argument("--run", default=None, metavar="RUN_DIR",
                        help="attach to a SIL run (its endpoints.json; `latest`: the newest under ./runs); "
                             "archives into RUN_DIR/attached/ unless --archive is given")
    parser.add_argument("--config", default=None,
                        help="mission YAML: take telemetry/telecommand addresses from flight_software.tmtc")
    parser.add_argument("--host", default=None,
                        help=f"address to bind for telemetry (default {DEFAULT_HOST} or the mission's)")
    parser.add_argument("--port", type=int, default=None,
                        help=f"telemetry UDP port (default {DEFAULT_TM_PORT} or the mission's)")
    parser.add_argument("--archive", default=None,
                        help="archive directory (raw + decoded; default ground_archive, or with --run a new "
                             "folder under RUN_DIR/attached/)")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    parser.add_argument("--dictionary", default=None, help="telemetry dictionary JSON (default: built in)")
    parser.add_argument("--no-live", action="store_true", help="no live table; print events as lines")
    parser.set_defaults(func=_cmd_monitor)
    sub = parser.add_subparsers(dest="ground_command", metavar="{send,decode,web}")
    send = sub.add_parser("send", help="send one telecommand, e.g. `keepout ground send SET_MODE POINTING`",
                          epilog=_command_help(DICTIONARY), formatter_class=argparse.RawDescriptionHelpFormatter)
    send.add_argument("opcode", help="command name (or numeric opcode)")
    send.add_argument("args", nargs="*", help="command arguments in dictionary order")
    send.add_argument("--host", dest="tc_host", default=None,
                      help=f"flight software TC address (default {DEFAULT_HOST} or the mission's)")
    send.add_argument("--port", dest="tc_port", type=int, default=None,
                      help=f"telecommand UDP port (default {DEFAULT_TC_PORT} or the mission's)")
    send.add_argument("--seq", type=int, default=0, help="TC sequence count to use (without --seq-file)")
    send.add_argument("--seq-file", default=None,
                      help="file holding the next TC sequence count (incremented per send), so that the "
                           "flight software sees consecutive counts across invocations")
    send.add_argument("--no-check", action="store_true",
                      help="skip the dictionary range checks (test the flight-side validation)")
    send.set_defaults(func=_cmd_send)
    decode = sub.add_parser("decode", help="rebuild the decoded JSONL from a raw archive and report gaps")
    decode.add_argument("archive_dir", help="directory holding tm_raw.bin")
    decode.add_argument("--out", default=None, help="output JSONL (default: ARCHIVE_DIR/tm_decoded.jsonl)")
    decode.set_defaults(func=_cmd_decode)
    add_web_cli(sub)


def _command_help(dictionary: TelemetryDictionary) -> str:
    lines = ["commands (args in order; enums by name):"]
    for command in dictionary.commands:
        parts = []
        for arg in command.args:
            kind = "|".join(arg.enum) if arg.enum else arg.type
            bounds = f" [{arg.min}..{arg.max}]" if arg.min is not None or arg.max is not None else ""
            unit = f" {arg.unit}" if arg.unit else ""
            optional = f"={arg.default}" if arg.default is not None else ""
            parts.append(f"{arg.name}{optional}:{kind}{bounds}{unit}")
        lines.append(f"  {command.name:<15} " + " ".join(parts))
    lines.append("example: keepout ground send SET_TARGET DIRECTION 0 0.6 0.8")
    return "\n".join(lines)


def _load_dictionary(path: str | None) -> TelemetryDictionary:
    return TelemetryDictionary.load(path) if path else DICTIONARY


def _mission_addresses(config_path: str | None) -> dict[str, Any]:
    """Telemetry/telecommand addresses from a mission YAML (``fsw.config``), or the defaults."""
    addresses = {"tm_host": DEFAULT_HOST, "tm_port": DEFAULT_TM_PORT, "tc_host": DEFAULT_HOST,
                 "tc_port": DEFAULT_TC_PORT, "tm_interface": LOOPBACK}
    if config_path:
        from fsw.config import load_fsw_config

        tmtc = load_fsw_config(config_path).tmtc  # raises ConfigError naming the file and key
        addresses.update(tm_host=tmtc.telemetry_host, tm_port=tmtc.telemetry_port,
                         tc_host=tmtc.telecommand_bind_host, tc_port=tmtc.telecommand_port,
                         tm_interface=tmtc.telemetry_multicast_interface)
    return addresses


def _monitor_endpoints(args: argparse.Namespace) -> tuple[Endpoints, Path | None]:
    """The telemetry to receive: a run's (``--run``), or the mission's / command line's address."""
    if args.run is not None:
        if args.config or args.host or args.port is not None:
            raise LinkError("--run takes the addresses from the run's endpoints.json: drop --config/--host/--port")
        run_dir = find_run(args.run)
        return Endpoints.load(run_dir), run_dir
    addresses = _mission_addresses(args.config)
    host = args.host if args.host is not None else addresses["tm_host"]
    port = args.port if args.port is not None else addresses["tm_port"]
    multicast = ipaddress.ip_address(host).is_multicast if _is_ip(host) else False
    return Endpoints(run_id="-", tm_transport="udp-multicast" if multicast else "udp", tm_host=host, tm_port=port,
                     tc_host=addresses["tc_host"], tc_port=addresses["tc_port"], bus="-",
                     tm_interface=addresses["tm_interface"]), None


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


class _RunFinished:
    """``is_set()`` once the attached run's endpoints.json says it finished (read at most once a second)."""

    def __init__(self, run_dir: Path) -> None:
        self.run_dir = run_dir
        self._next_check = 0.0
        self._finished = False

    def is_set(self) -> bool:
        now = time.monotonic()
        if not self._finished and now >= self._next_check:
            self._next_check = now + 1.0
            try:
                self._finished = Endpoints.load(self.run_dir).state == "finished"
            except LinkError:
                pass
        return self._finished


def _cmd_monitor(args: argparse.Namespace) -> int:
    from fsw.dictionary import DictionaryError

    try:
        dictionary = _load_dictionary(args.dictionary)
        endpoints, run_dir = _monitor_endpoints(args)
        if run_dir is not None and endpoints.state == "finished":
            raise LinkError(f"run {run_dir} has finished: nothing to attach to; its archive is "
                            f"{run_dir / 'ground'} (browse it with `keepout ground web --run {run_dir}`)")
        sock = open_telemetry(endpoints)
    except (DictionaryError, LinkError, ValueError) as exc:
        print(f"keepout ground: {exc}", file=sys.stderr)
        return 2
    archive = args.archive
    if archive is None:
        archive = (run_dir / "attached" / f"ground-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
                   if run_dir is not None else "ground_archive")
    monitor = GroundMonitor(dictionary, port=None, archive_dir=archive, sock=sock)
    where = f"{endpoints.tm_host}:{endpoints.tm_port}" + (" (multicast)" if endpoints.multicast else "")
    attached = f"attached to run {endpoints.run_id}, " if run_dir is not None else ""
    print(f"keepout ground: {attached}telemetry on {where}, archive {archive}", flush=True)
    monitor.echo_events = args.no_live
    stop = _RunFinished(run_dir) if run_dir is not None else None
    stats = monitor.run(duration_s=args.duration, stop_event=stop, live=not args.no_live)
    if stop is not None and stop.is_set():
        print(f"run {endpoints.run_id} finished")
    summary = stats.to_json_dict()
    print(f"received {summary['datagrams']} packets, {summary['decode_errors']} decode errors, "
          f"{summary['missing_packets']} missing in {len(stats.gaps)} gaps")
    return 0


def _cmd_send(args: argparse.Namespace) -> int:
    from fsw.dictionary import ArgError, DictionaryError

    try:
        dictionary = _load_dictionary(args.dictionary)
        addresses = _mission_addresses(args.config)
        tc_host = args.tc_host if args.tc_host is not None else addresses["tc_host"]
        tc_port = args.tc_port if args.tc_port is not None else addresses["tc_port"]
        command: str | int = int(args.opcode, 0) if args.opcode[:1].isdigit() else args.opcode.upper()
        dictionary.command(command)  # unknown command: fail before touching the sequence file
        seq = args.seq
        if args.seq_file:
            from spacepackets.seqcount import CcsdsFileSeqCountProvider

            seq = CcsdsFileSeqCountProvider(Path(args.seq_file)).get_and_increment()
        with CommandSender(dictionary, tc_host, tc_port, seq) as sender:
            packet = sender.send(command, *args.args, check_range=not args.no_check)
    except (ArgError, DictionaryError, ValueError) as exc:
        print(f"keepout ground send: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"keepout ground send: cannot send to {tc_host}:{tc_port}: {exc}", file=sys.stderr)
        return 1
    print(f"sent {dictionary.command(command).name} ({len(packet)} bytes) to {tc_host}:{tc_port}: {packet.hex()}")
    return 0


def _cmd_decode(args: argparse.Namespace) -> int:
    from fsw.dictionary import DictionaryError

    archive = Path(args.archive_dir)
    if not (archive / RAW_ARCHIVE).exists():
        print(f"keepout ground decode: {archive / RAW_ARCHIVE} does not exist", file=sys.stderr)
        return 2
    try:
        dictionary = _load_dictionary(args.dictionary)
    except DictionaryError as exc:
        print(f"keepout ground decode: {exc}", file=sys.stderr)
        return 2
    out_path = Path(args.out) if args.out else archive / DECODED_ARCHIVE
    replay = GroundMonitor(dictionary, port=None)  # no socket, no archive: decode into one stream
    with open(out_path, "w", encoding="utf-8") as out:
        replay.decoded_stream = out
        for rx_time_s, raw in read_raw_archive(archive / RAW_ARCHIVE):
            replay.process(raw, rx_time_s)
    summary = replay.summary()
    print(f"decoded {summary['decoded']} of {summary['datagrams']} packets into {out_path}; "
          f"{summary['decode_errors']} decode errors, {summary['missing_packets']} missing")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="keepout")
    add_cli(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
