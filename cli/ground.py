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

from cli import udp_port, udp_port_or_zero
from comms.dictionary import DEFAULT_HOST, DEFAULT_TC_PORT, DEFAULT_TM_PORT, DICTIONARY, TelemetryDictionary
from comms.link_security import LINK_KEY_FILE, downlink_receiver, load_key_file
from ground.archive import DECODED_ARCHIVE, RAW_ARCHIVE, read_raw_archive
from ground.commanding import CommandSender, signing_sender_args
from ground.link import LOOPBACK, Endpoints, LinkError, find_run, open_telemetry
from ground.monitor import GroundMonitor
from cli.ground_web import add_cli as add_web_cli


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
    parser.add_argument("--port", type=udp_port_or_zero, default=None,
                        help=f"telemetry UDP port (default {DEFAULT_TM_PORT} or the mission's; 0: any free port)")
    parser.add_argument("--archive", default=None,
                        help="archive directory (raw + decoded; default ground_archive, or with --run a new "
                             "folder under RUN_DIR/attached/)")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    parser.add_argument("--dictionary", default=None, help="telemetry dictionary JSON (default: built in)")
    parser.add_argument("--no-live", action="store_true", help="no live table; print events as lines")
    parser.add_argument("--key-file", default=None, help=_KEY_HELP)
    parser.set_defaults(func=_cmd_monitor)
    sub = parser.add_subparsers(dest="ground_command", metavar="{send,decode,xtce,keygen,web}")
    send = sub.add_parser(
        "send", help="send one telecommand and wait for its acknowledgement, e.g. `keepout ground send SET_MODE "
        "POINTING`", description="Send one telecommand, wait for its acknowledgements in telemetry (acceptance, "
        "completion) and print them. Exit codes: 0 completed; 1 not sent, or nothing listens at the telecommand "
        "address; 2 bad command, argument or option; 3 rejected (reason code printed); 4 failed in execution; "
        "5 no acknowledgement within --timeout.",
        epilog=_command_help(DICTIONARY), formatter_class=argparse.RawDescriptionHelpFormatter)
    send.add_argument("opcode", help="command name (or numeric opcode)")
    send.add_argument("args", nargs="*", help="command arguments in dictionary order")
    send.add_argument("--run", dest="send_run", default=None, metavar="RUN_DIR",
                      help="send to a SIL run (its endpoints.json; `latest`: the newest under ./runs) and hear the "
                           "acknowledgement on its telemetry")
    send.add_argument("--host", dest="tc_host", default=None,
                      help=f"flight software TC address (default {DEFAULT_HOST} or the mission's)")
    send.add_argument("--port", dest="tc_port", type=udp_port, default=None,
                      help=f"telecommand UDP port (default {DEFAULT_TC_PORT} or the mission's)")
    send.add_argument("--tm-host", default=None,
                      help=f"where the acknowledgements arrive: telemetry address to listen on (default "
                           f"{DEFAULT_HOST} or the mission's)")
    send.add_argument("--tm-port", type=udp_port, default=None,
                      help=f"telemetry UDP port to listen on (default {DEFAULT_TM_PORT} or the mission's)")
    send.add_argument("--timeout", type=_positive_seconds, default=5.0,
                      help="how long to wait for the acknowledgements [s] (default 5)")
    send.add_argument("--no-wait", action="store_true", help="send only; do not wait for acknowledgements")
    send.add_argument("--seq", type=_seq_count, default=None,
                      help="TC sequence count to use (default 0; with --run the next of RUN_DIR/ground_tc_seq.txt)")
    send.add_argument("--seq-file", default=None,
                      help="file holding the next TC sequence count (incremented per send), so that the "
                           "flight software sees consecutive counts across invocations")
    send.add_argument("--no-check", action="store_true",
                      help="skip the dictionary range checks (test the flight-side validation)")
    send.add_argument("--key-file", dest="send_key_file", default=None, help=_KEY_HELP)
    send.add_argument("--latitude-deg", type=float, default=None,
                      help="SET_TARGET GROUND: the point's geodetic latitude (WGS-84) [deg], -90..90, north positive")
    send.add_argument("--longitude-deg", type=float, default=None,
                      help="SET_TARGET GROUND: its longitude [deg], -180..360, east positive")
    send.add_argument("--altitude-m", type=float, default=None,
                      help="SET_TARGET GROUND: its height above the ellipsoid [m], -500..9000 (default 0)")
    send.set_defaults(func=_cmd_send)
    keygen = sub.add_parser("keygen", help="write a new link key file (32 random bytes as hex, mode 0600)")
    keygen.add_argument("key_path", help="where to write it (never overwrites); name it in the mission as "
                                         "flight_software.tmtc.security.key_file")
    keygen.set_defaults(func=_cmd_keygen)
    decode = sub.add_parser("decode", help="rebuild the decoded JSONL from a raw archive and report gaps")
    decode.add_argument("archive_dir", help="directory holding tm_raw.bin")
    decode.add_argument("--out", default=None, help="output JSONL (default: ARCHIVE_DIR/tm_decoded.jsonl)")
    decode.set_defaults(func=_cmd_decode)
    xtce = sub.add_parser("xtce", help="export the telemetry and telecommand dictionary as XTCE 1.2 (for Yamcs)",
                          description="Write the dictionary (parameters, containers by APID, events, meta-commands "
                                      "with arguments) as an XTCE 1.2 SpaceSystem, so an XTCE ground system such "
                                      "as Yamcs decodes keepout's packets and builds its telecommands.")
    xtce.add_argument("--out", default=None, help="output file (default: standard output)")
    xtce.set_defaults(func=_cmd_xtce)
    add_web_cli(sub)


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of seconds")
    return value


def _seq_count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 16383:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TC sequence count; allowed: 0..16383")
    return value


_KEY_HELP = ("link key file (default: the mission's flight_software.tmtc.security.key_file); telecommands "
             "are signed and telemetry verified with it")


def _key_file(explicit: str | None, config_path: str | None, run_dir: Path | None = None) -> str:
    """The link key file to use: ``--key-file``, a SIL run's own ``RUN_DIR/link.key``, or the mission's;
    raises ValueError (one line) when there is none."""
    if explicit:
        return explicit
    if run_dir is not None:
        return str(run_dir / LINK_KEY_FILE)
    if config_path:
        from comms.link_security import mission_key_path

        path = mission_key_path(_flight_software(config_path).tmtc.security.key_file, config_path)
        if path is not None:
            return str(path)
    raise ValueError("no link key: pass --key-file FILE, or --config MISSION naming "
                     "flight_software.tmtc.security.key_file (`keepout ground keygen FILE` makes one)")


def _cmd_keygen(args: argparse.Namespace) -> int:
    from comms.link_security import write_key_file

    try:
        write_key_file(args.key_path)
    except FileExistsError:
        print(f"keepout ground keygen: {args.key_path} exists; a key is never overwritten", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"keepout ground keygen: {args.key_path}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.key_path} (mode 0600)")
    return 0


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


def _flight_software(config_path: str) -> Any:
    """The flight software's configuration of a mission YAML, read by the mission reader; its problems (each
    at file:line:col) raised as one ValueError."""
    from hil_sim.mission.flight import load_flight_config
    from hil_sim.mission.loader import ConfigError

    try:
        return load_flight_config(config_path).flight_software
    except ConfigError as exc:
        raise ValueError(str(exc)) from None


def _mission_addresses(config_path: str | None) -> dict[str, Any]:
    """Telemetry/telecommand addresses from a mission YAML (its ``flight_software.tmtc``), or the defaults."""
    addresses = {"tm_host": DEFAULT_HOST, "tm_port": DEFAULT_TM_PORT, "tc_host": DEFAULT_HOST,
                 "tc_port": DEFAULT_TC_PORT, "tm_interface": LOOPBACK}
    if config_path:
        tmtc = _flight_software(config_path).tmtc  # raises ValueError naming the file, line and key
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
    return _address_endpoints(args.config, args.host, args.port), None


def _address_endpoints(config: str | None, tm_host: str | None, tm_port: int | None,
                       tc_host: str | None = None, tc_port: int | None = None) -> Endpoints:
    """Endpoints from the mission (``--config``) or the defaults, with the command line's overrides."""
    addresses = _mission_addresses(config)
    host = tm_host if tm_host is not None else addresses["tm_host"]
    port = tm_port if tm_port is not None else addresses["tm_port"]
    multicast = ipaddress.ip_address(host).is_multicast if _is_ip(host) else False
    return Endpoints(run_id="-", tm_transport="udp-multicast" if multicast else "udp", tm_host=host, tm_port=port,
                     tc_host=tc_host if tc_host is not None else addresses["tc_host"],
                     tc_port=tc_port if tc_port is not None else addresses["tc_port"], bus="-",
                     tm_interface=addresses["tm_interface"])


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
    from comms.dictionary import DictionaryError

    try:
        dictionary = _load_dictionary(args.dictionary)
        endpoints, run_dir = _monitor_endpoints(args)
        if run_dir is not None and endpoints.state == "finished":
            raise LinkError(f"run {run_dir} has finished: nothing to attach to; its archive is "
                            f"{run_dir / 'ground'} (browse it with `keepout ground web --run {run_dir}`)")
        key_file = _key_file(args.key_file, args.config, run_dir)
        security = downlink_receiver(load_key_file(key_file))
        sock = open_telemetry(endpoints)
    except (DictionaryError, LinkError, ValueError) as exc:
        print(f"keepout ground: {exc}", file=sys.stderr)
        return 2
    archive = args.archive
    if archive is None:
        archive = (run_dir / "attached" / f"ground-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
                   if run_dir is not None else "ground_archive")
    monitor = GroundMonitor(dictionary, port=None, archive_dir=archive, sock=sock, security=security)
    where = f"{endpoints.tm_host}:{endpoints.tm_port}" + (" (multicast)" if endpoints.multicast else "")
    attached = f"attached to run {endpoints.run_id}, " if run_dir is not None else ""
    print(f"keepout ground: {attached}telemetry on {where}, archive {archive}", flush=True)
    monitor.echo_events = args.no_live
    stop = _RunFinished(run_dir) if run_dir is not None else None
    stats = monitor.run(duration_s=args.duration, stop_event=stop, live=not args.no_live)
    if stop is not None and stop.is_set():
        print(f"run {endpoints.run_id} finished")
    summary = stats.to_json_dict()
    kinds = ", ".join(f"{k} {n}" for k, n in sorted(summary["decode_errors_by_kind"].items()))
    print(f"received {summary['datagrams']} packets, {summary['decode_errors']} decode errors"
          f"{f' ({kinds})' if kinds else ''}, "
          f"{summary['missing_packets']} missing in {len(stats.gaps)} gaps, "
          f"{summary['rejected_by_link_security']} refused by the link security (forged/unauthenticated/replayed)")
    return 0


def _cmd_send(args: argparse.Namespace) -> int:
    from comms.dictionary import ArgError, DictionaryError
    from ground import verify

    run = args.send_run if args.send_run is not None else args.run
    try:
        dictionary = _load_dictionary(args.dictionary)
        command: str | int = int(args.opcode, 0) if args.opcode[:1].isdigit() else args.opcode.upper()
        definition = dictionary.command(command)  # unknown command: fail before touching the sequence file
        values = _command_values(definition.name, args)
        endpoints, run_dir = _send_endpoints(args, run)
        key_file = _key_file(args.send_key_file, args.config, run_dir)
        signing = signing_sender_args(key_file)
        downlink = downlink_receiver(load_key_file(key_file))
    except (ArgError, DictionaryError, ValueError, LinkError) as exc:  # ValueError: a bad mission config or key
        print(f"keepout ground send: {exc}", file=sys.stderr)
        return verify.EXIT_BAD_INPUT
    tc_host, tc_port = endpoints.tc_host, endpoints.tc_port
    telemetry = None
    try:
        if not args.no_wait:  # listen before sending: an answer can come back within a millisecond
            telemetry = open_telemetry(endpoints)
        seq = args.seq if args.seq is not None else 0
        seq_file = args.seq_file or (run_dir / SEND_SEQ_FILE if run_dir is not None and args.seq is None else None)
        if seq_file:
            from spacepackets.seqcount import CcsdsFileSeqCountProvider

            seq = CcsdsFileSeqCountProvider(Path(seq_file)).get_and_increment()
        with CommandSender(dictionary, tc_host, tc_port, seq, **signing) as sender:
            if telemetry is None:
                packet = sender.send(command, *values, check_range=not args.no_check)
                print(f"sent {definition.name} ({len(packet)} bytes) to {tc_host}:{tc_port}: {packet.hex()} "
                      "(not waiting for the acknowledgement)")
                return verify.EXIT_COMPLETED
            packet, result = verify.send_verified(sender, telemetry, command, values, timeout_s=args.timeout,
                                                  check_range=not args.no_check, downlink=downlink)
    except (ArgError, DictionaryError) as exc:
        print(f"keepout ground send: {exc}", file=sys.stderr)
        return verify.EXIT_BAD_INPUT
    except LinkError as exc:
        print(f"keepout ground send: cannot listen for the acknowledgement: {exc}; use --run RUN_DIR for a SIL "
              "run, --tm-port for another telemetry port, or --no-wait", file=sys.stderr)
        return verify.EXIT_NOT_SENT
    except (OSError, ValueError) as exc:
        print(f"keepout ground send: cannot send to {tc_host}:{tc_port}: {exc}", file=sys.stderr)
        return verify.EXIT_NOT_SENT
    finally:
        if telemetry is not None:
            telemetry.close()
    print(f"sent {definition.name} seq {int.from_bytes(packet[2:4], 'big') & 0x3FFF} ({len(packet)} bytes) to "
          f"{tc_host}:{tc_port}")
    for ack in result.acks:
        print(f"  {ack.describe(dictionary)}")
    if result.exit_code == verify.EXIT_COMPLETED:
        print(f"{definition.name}: completed")
    else:
        print(f"keepout ground send: {definition.name} {result.outcome}: {result.detail}", file=sys.stderr)
    return result.exit_code


# SET_TARGET GROUND's point as the flight software accepts it (fsw.config.GroundTargetConfig, whose
# height range the onboard handler applies to a telecommand too)
_GROUND_RANGES = (("--latitude-deg", -90.0, 90.0), ("--longitude-deg", -180.0, 360.0), ("--altitude-m", -500.0, 9000.0))


def _command_values(name: str, args: argparse.Namespace) -> list[Any]:
    """The command's arguments in dictionary order: as typed, or for ``SET_TARGET GROUND --latitude-deg L
    --longitude-deg L [--altitude-m H]`` the point's vertical and height (`ground_target_args`), for
    ``SET_TARGET NADIR`` alone its unused components. Raises ``ArgError`` for a point out of range or the
    point's options anywhere else."""
    from comms.dictionary import ArgError
    from comms.telecommand import ground_target_args

    point = (args.latitude_deg, args.longitude_deg, args.altitude_m)
    kind = args.args[0].upper() if name == "SET_TARGET" and len(args.args) == 1 else None
    if any(v is not None for v in point) and kind != "GROUND":
        raise ArgError("--latitude-deg, --longitude-deg and --altitude-m go with SET_TARGET GROUND and no other "
                       "argument (e.g. SET_TARGET GROUND --latitude-deg 12.97 --longitude-deg 77.59)")
    if kind == "NADIR":
        return ["NADIR", 0.0, 0.0, 0.0]
    if kind != "GROUND":
        return list(args.args)
    if point[0] is None or point[1] is None:
        raise ArgError("SET_TARGET GROUND needs --latitude-deg and --longitude-deg (and optionally --altitude-m), "
                       "or its four components c0 c1 c2 c3")
    point = (point[0], point[1], 0.0 if point[2] is None else point[2])
    for value, (option, low, high) in zip(point, _GROUND_RANGES):
        if not low <= value <= high:  # also refuses nan
            raise ArgError(f"{option} {value:g} outside {low:g}..{high:g}")
    target = ground_target_args(*point)
    return [target[k] for k in ("kind", "c0", "c1", "c2", "c3")]


SEND_SEQ_FILE = "ground_tc_seq.txt"  # in a run folder: consecutive sequence counts across `send --run` calls


def _send_endpoints(args: argparse.Namespace, run: str | None) -> tuple[Endpoints, Path | None]:
    """Where to send (telecommand address) and hear the acknowledgements (telemetry), from ``--run`` or
    the addresses; raises LinkError or ValueError with the reason."""
    if run is None:
        return _address_endpoints(args.config, args.tm_host, args.tm_port, args.tc_host, args.tc_port), None
    if args.config or args.tc_host or args.tc_port or args.tm_host or args.tm_port:
        raise LinkError("--run takes the addresses from the run's endpoints.json: drop --config/--host/--port/"
                        "--tm-host/--tm-port")
    run_dir = find_run(run)
    endpoints = Endpoints.load(run_dir)
    if endpoints.state == "finished":
        raise LinkError(f"run {run_dir} has finished: its flight software no longer takes telecommands")
    return endpoints, run_dir


def _cmd_decode(args: argparse.Namespace) -> int:
    from comms.dictionary import DictionaryError

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


def _cmd_xtce(args: argparse.Namespace) -> int:
    from comms.dictionary import DictionaryError
    from ground.xtce import to_xtce, write_xtce

    try:
        dictionary = _load_dictionary(args.dictionary)
        if args.out is None:
            sys.stdout.write(to_xtce(dictionary))
            return 0
        write_xtce(args.out, dictionary)
    except DictionaryError as exc:
        print(f"keepout ground xtce: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"keepout ground xtce: cannot write {args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out} (XTCE 1.2)")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="keepout")
    add_cli(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
