"""``keepout ground``: monitor (live table), ``send`` one telecommand, ``decode`` a raw archive."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fsw.dictionary import DEFAULT_HOST, DEFAULT_TC_PORT, DEFAULT_TM_PORT, DICTIONARY, TelemetryDictionary
from ground.archive import DECODED_ARCHIVE, RAW_ARCHIVE, read_raw_archive
from ground.commanding import CommandSender, signing_sender_args
from ground.monitor import GroundMonitor


def add_cli(subparsers: Any) -> None:
    """Add ``keepout ground`` (monitor) and ``keepout ground send OPCODE ARGS...``."""
    parser = subparsers.add_parser(
        "ground", help="ground monitor: receive/archive/display telemetry; send telecommands",
        description="Receive, archive and display keepout telemetry; `ground send` sends a telecommand.",
    )
    parser.add_argument("--config", default=None,
                        help="mission YAML: take telemetry/telecommand addresses from flight_software.tmtc")
    parser.add_argument("--host", default=None,
                        help=f"address to bind for telemetry (default {DEFAULT_HOST} or the mission's)")
    parser.add_argument("--port", type=int, default=None,
                        help=f"telemetry UDP port (default {DEFAULT_TM_PORT} or the mission's)")
    parser.add_argument("--archive", default="ground_archive", help="archive directory (raw + decoded)")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    parser.add_argument("--dictionary", default=None, help="telemetry dictionary JSON (default: built in)")
    parser.add_argument("--no-live", action="store_true", help="no live table; print events as lines")
    parser.add_argument("--key-file", default=None, help=_KEY_HELP)
    parser.set_defaults(func=_cmd_monitor)
    sub = parser.add_subparsers(dest="ground_command", metavar="{send,decode,keygen}")
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
    send.add_argument("--key-file", dest="send_key_file", default=None, help=_KEY_HELP)
    send.set_defaults(func=_cmd_send)
    keygen = sub.add_parser("keygen", help="write a new link key file (32 random bytes as hex, mode 0600)")
    keygen.add_argument("key_path", help="where to write it (never overwrites); name it in the mission as "
                                         "flight_software.tmtc.security.key_file")
    keygen.set_defaults(func=_cmd_keygen)
    decode = sub.add_parser("decode", help="rebuild the decoded JSONL from a raw archive and report gaps")
    decode.add_argument("archive_dir", help="directory holding tm_raw.bin")
    decode.add_argument("--out", default=None, help="output JSONL (default: ARCHIVE_DIR/tm_decoded.jsonl)")
    decode.set_defaults(func=_cmd_decode)


_KEY_HELP = ("link key file (default: the mission's flight_software.tmtc.security.key_file); telecommands "
             "are signed and telemetry verified with it")


def _key_file(explicit: str | None, config_path: str | None) -> str:
    """The link key file to use; raises ValueError (one line) when there is none."""
    if explicit:
        return explicit
    if config_path:
        from fsw.config import load_fsw_config
        from fsw.link_security import mission_key_path

        path = mission_key_path(load_fsw_config(config_path).tmtc.security.key_file, config_path)
        if path is not None:
            return str(path)
    raise ValueError("no link key: pass --key-file FILE, or --config MISSION naming "
                     "flight_software.tmtc.security.key_file (`keepout ground keygen FILE` makes one)")


def _cmd_keygen(args: argparse.Namespace) -> int:
    from fsw.link_security import write_key_file

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


def _mission_addresses(config_path: str | None) -> dict[str, Any]:
    """Telemetry/telecommand addresses from a mission YAML (``fsw.config``), or the defaults."""
    addresses = {"tm_host": DEFAULT_HOST, "tm_port": DEFAULT_TM_PORT, "tc_host": DEFAULT_HOST,
                 "tc_port": DEFAULT_TC_PORT}
    if config_path:
        from fsw.config import load_fsw_config

        tmtc = load_fsw_config(config_path).tmtc  # raises ConfigError naming the file and key
        addresses.update(tm_host=tmtc.telemetry_host, tm_port=tmtc.telemetry_port,
                         tc_host=tmtc.telecommand_bind_host, tc_port=tmtc.telecommand_port)
    return addresses


def _cmd_monitor(args: argparse.Namespace) -> int:
    from fsw.dictionary import DictionaryError

    from fsw.link_security import downlink_receiver, load_key_file

    try:
        dictionary = _load_dictionary(args.dictionary)
        addresses = _mission_addresses(args.config)
        security = downlink_receiver(load_key_file(_key_file(args.key_file, args.config)))
    except (DictionaryError, ValueError) as exc:
        print(f"keepout ground: {exc}", file=sys.stderr)
        return 2
    host = args.host if args.host is not None else addresses["tm_host"]
    port = args.port if args.port is not None else addresses["tm_port"]
    try:
        monitor = GroundMonitor(dictionary, host, port, args.archive, security=security)
    except OSError as exc:
        print(f"keepout ground: cannot bind {host}:{port}: {exc}", file=sys.stderr)
        return 2
    print(f"keepout ground: telemetry on {monitor.address[0]}:{monitor.address[1]}, archive {args.archive}")
    monitor.echo_events = args.no_live
    stats = monitor.run(duration_s=args.duration, live=not args.no_live)
    summary = stats.to_json_dict()
    print(f"received {summary['datagrams']} packets, {summary['decode_errors']} decode errors, "
          f"{summary['missing_packets']} missing in {len(stats.gaps)} gaps, "
          f"{summary['rejected_by_link_security']} refused by the link security (forged/unauthenticated/replayed)")
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
        signing = signing_sender_args(_key_file(args.send_key_file, args.config))
        seq = args.seq
        if args.seq_file:
            from spacepackets.seqcount import CcsdsFileSeqCountProvider

            seq = CcsdsFileSeqCountProvider(Path(args.seq_file)).get_and_increment()
        with CommandSender(dictionary, tc_host, tc_port, seq, **signing) as sender:
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
