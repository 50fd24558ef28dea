"""The flight software as a process: ``python -m fsw --config FSW_FILE`` and ``keepout fsw MISSION``.

``python -m fsw`` (the flight process the SIL launches; `fsw.__main__` calls `main`) reads ``--config``, the
flight software's own configuration file (`fsw.config.FswRunConfig`: its bus and its ``flight_software``
section, resolved; the SIL writes it into the run folder). ``keepout fsw MISSION`` (a HIL bench: the flight
software alone against a simulator) resolves a mission with the simulator's mission reader
(`hil_sim.mission.flight`) and hands the flight software the same configuration, never the mission.
``--bus`` is a bus spec (``auto``, ``socketcan:vcan0``, ``udp_multicast[:group:port]``, ``virtual[:ch]``, or any
python-can interface as ``INTERFACE:CHANNEL``, e.g. ``pcan:PCAN_USBBUS1``); without it, the configured bus,
opened at the configured bit rate.
The tick source comes from ``rates.tick_source`` unless ``--lockstep`` / ``--realtime`` overrides it.
A lockstep run ends when no SYNC arrives for ``rates.lockstep_timeout_s`` (the simulator finished);
a real-time run ends after ``--duration-s`` or on SIGINT/SIGTERM. ``--first-sync-timeout-s`` lets a lockstep run
wait longer for the first SYNC (a bench where the simulator is started by hand, on another computer).
Once the bus is open and the software initialised it prints one ``fsw: ready`` line.

Exit codes: 0 normal end, 2 bad configuration or arguments, 3 bus unavailable, 1 unexpected failure.
"""
from __future__ import annotations

import argparse
import signal
import socket
import sys
from pathlib import Path
from typing import Any

from cli import udp_port, udp_port_or_zero

BENCH_FIRST_SYNC_TIMEOUT_S = 600.0  # `keepout fsw`: the simulator is started by hand, maybe on another computer


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m fsw", description="keepout flight software")
    p.add_argument("--config", required=True, metavar="FSW_FILE",
                   help="the flight software's configuration file (keys bus and flight_software, resolved; a SIL "
                        "run writes it as fsw.yaml; for a mission file use `keepout fsw MISSION`)")
    add_arguments(p)
    p.set_defaults(configuration=_from_file)
    return p


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    """``keepout fsw MISSION [--bus SPEC]``: the flight software alone, for a processor-in-the-loop bench
    (the simulator runs as ``keepout sim`` on the same bus, maybe on another computer; docs/hil-bench.md)."""
    p = subparsers.add_parser(
        "fsw", help="run the flight software alone on a bus (HIL bench; pair with `keepout sim`)",
        description="Run the flight software alone on the mission's bus or --bus SPEC (any python-can interface "
                    "as INTERFACE:CHANNEL). Lockstep (default when the mission ticks on SYNC): start this first, "
                    "then `keepout sim MISSION --bus SPEC`; it waits up to --first-sync-timeout-s for the first "
                    "SYNC and ends when SYNC stops. Exit codes: 0 normal end, 2 bad configuration or arguments, 3 "
                    "bus unavailable, 1 unexpected failure. See docs/hil-bench.md.")
    p.add_argument("config", metavar="MISSION", help="mission YAML")
    add_arguments(p, first_sync_default=BENCH_FIRST_SYNC_TIMEOUT_S)
    p.set_defaults(func=run, configuration=_from_mission)


def add_arguments(p: argparse.ArgumentParser, first_sync_default: float | None = None) -> None:
    p.add_argument("--bus", default=None, help="bus spec: auto | socketcan:vcan0 | udp_multicast[:group:port] | "
                   "virtual[:channel] | INTERFACE:CHANNEL[,KEY=VALUE...] (any python-can interface); default: the "
                   "mission's bus")
    p.add_argument("--bitrate", type=_bitrate, default=None, help="CAN bit rate [bit/s] for a hardware interface "
                   "(default: the mission's bus_bitrate_bps)")
    p.add_argument("--first-sync-timeout-s", type=float, default=first_sync_default,
                   help="lockstep: wait this long for the simulator's first SYNC (default: "
                        f"{first_sync_default or 'rates.lockstep_timeout_s'})")
    p.add_argument("--bus-file", default=None, metavar="FILE",
                   help="write the bus spec actually opened (e.g. udp_multicast:GROUP:PORT, chosen at random for "
                        "udp_multicast without a group) to FILE, for `keepout sim --bus \"$(cat FILE)\"`")
    p.add_argument("--run-id", default=None, help="run id for per-run UDP multicast endpoints (bus 'auto')")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", action="store_true", help="tick on simulator SYNC frames")
    mode.add_argument("--realtime", action="store_true", help="tick on the monotonic clock")
    p.add_argument("--duration-s", type=float, default=None, help="real time: stop after this many seconds")
    p.add_argument("--max-ticks", type=int, default=None, help="lockstep: stop after this many ticks")
    p.add_argument("--tm-port", type=udp_port, default=None, help="override tmtc.telemetry_port")
    p.add_argument("--tc-port", type=udp_port_or_zero, default=None,
                   help="override tmtc.telecommand_port (0: ephemeral)")
    p.add_argument("--tc-fd", type=int, default=None, metavar="FD",
                   help="take telecommands on the bound UDP socket inherited as file descriptor FD (a parent "
                        "that reserved the port, as `keepout sil run` does); overrides --tc-port")
    p.add_argument("--dbc", default=None, help="ICD DBC file (default config/icd/keepout.dbc)")
    p.add_argument("--key-file", default=None,
                   help="link key file (overrides tmtc.security.key_file; relative paths from the current folder)")


def _bitrate(text: str) -> int:
    from comms.bus.transport import CAN_BITRATE_RANGE_BPS, is_can_bitrate

    try:
        value = int(text)
    except ValueError:
        value = 0
    if not is_can_bitrate(value):
        lo, hi = CAN_BITRATE_RANGE_BPS
        raise argparse.ArgumentTypeError(f"{text!r} is not a CAN bit rate; allowed: {lo}..{hi} [bit/s]")
    return value


def main(argv: list[str] | None = None) -> int:
    return run(build_parser().parse_args(argv))


def _from_file(path: str) -> Any:
    """The flight software's configuration file (`fsw.config.FswRunConfig`), read once."""
    from fsw.config import FswConfigError, load_fsw_run_config

    try:
        return load_fsw_run_config(path)
    except FswConfigError as exc:
        raise _StartFailed(str(exc)) from None


def _from_mission(path: str) -> Any:
    """The flight software's configuration resolved from the mission ``path`` by the one mission reader."""
    from hil_sim.mission.flight import load_flight_config
    from hil_sim.mission.loader import ConfigError

    try:
        return load_flight_config(path)
    except ConfigError as exc:
        raise _StartFailed(str(exc)) from None


class _StartFailed(Exception):
    """The flight software cannot start: ``fsw: MESSAGE`` on stderr and exit code ``code``."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code


def run(args: argparse.Namespace) -> int:
    """Run the flight software with parsed arguments (``python -m fsw`` and ``keepout fsw``)."""
    import os

    from fsw.lifetime import PARENT_PID_ENV, die_with_parent

    if os.environ.get(PARENT_PID_ENV):  # started by the SIL: end with it, whatever ends it
        die_with_parent()
    try:
        resolved = args.configuration(args.config)
        cfg, bus_authentication = resolved.flight_software, resolved.bus.authentication
        from comms.bus import Icd
        from fsw import assembly  # noqa: F401 - the flight software's modules (~0.3 s) load before the bus opens

        bus, bus_spec = _open_bus(args, resolved.bus.spec, resolved.bus.bitrate_bps)
        icd = Icd(args.dbc) if args.dbc else Icd()
        bus, uplink, downlink = _secure_link(args, cfg, bus, icd, bus_authentication)
        telemetry, dispatcher, tm_port = _open_tmtc(args, cfg, uplink, downlink)
        fsw = _build(args, cfg, bus, icd, telemetry, dispatcher)
    except _StartFailed as exc:
        print(f"fsw: {exc}", file=sys.stderr)
        return exc.code

    def _stop(signum, frame):  # noqa: ARG001
        fsw.stop()

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    realtime = args.realtime or (not args.lockstep and cfg.rates.tick_source == "clock")
    tm_cfg = cfg.tmtc
    print(f"fsw: ready: bus {bus_spec}{' (SecOC)' if bus_authentication else ''}, {'real time' if realtime else 'lockstep'}, telemetry to "
          f"{tm_cfg.telemetry_host}:{tm_port}, telecommands on {dispatcher.address[0]}:{dispatcher.address[1]}",
          flush=True)
    return _fly(fsw, args, realtime, telemetry, dispatcher, bus)


def _open_bus(args: argparse.Namespace, configured_bus: str, configured_bitrate: int | None) -> tuple[Any, str]:
    """(the bus of --bus or the configured one, opened; its concrete spec), the spec written to --bus-file if
    asked. Exit code 2 for a bad spec or an unwritable file, 3 for a bus that is not there."""
    from comms.bus import BusSpecError, BusUnavailableError, open_bus

    bus_spec = args.bus if args.bus is not None else configured_bus
    opened: list = []
    try:
        bus = open_bus(bus_spec, args.run_id, info_out=opened,
                       bitrate=args.bitrate if args.bitrate is not None else configured_bitrate)
    except BusSpecError as exc:
        raise _StartFailed(f"--bus {bus_spec!r}: {exc}") from None
    except BusUnavailableError as exc:
        raise _StartFailed(f"bus unavailable: {exc}", 3) from None
    bus_spec = opened[0].spec  # the concrete spec: the group and port a random udp_multicast picked
    if args.bus_file:
        try:
            Path(args.bus_file).write_text(bus_spec + "\n")
        except OSError as exc:
            bus.shutdown()
            raise _StartFailed(f"--bus-file {args.bus_file}: {exc.strerror or exc}") from None
    return bus, bus_spec


def _secure_link(args: argparse.Namespace, cfg, bus, icd, bus_authentication: bool) -> tuple[Any, Any, Any]:
    """(the bus, under SecOC when the mission authenticates it; uplink receiver; downlink sender) of the
    run's link key. No usable key (or an ICD without authenticator frames) shuts the bus: exit code 2."""
    from comms.link_security import KeyFileError

    try:
        key = link_key(cfg, args.config, args.key_file)
        uplink, downlink = link_associations(cfg, key)
        if bus_authentication:
            from comms.bus.secoc import secure

            bus = secure(bus, icd, key, "FSW")
    except (KeyFileError, ValueError) as exc:  # (SecOCError: an ICD without authenticator frames)
        bus.shutdown()
        raise _StartFailed(str(exc)) from None
    return bus, uplink, downlink


def _open_tmtc(args: argparse.Namespace, cfg, uplink, downlink) -> tuple[Any, Any, int]:
    """(telemetry sender, telecommand dispatcher, telemetry port) on the configured ports or the overrides,
    after the TM/TC configuration's warnings. A telecommand socket that cannot be bound: exit code 2."""
    from comms.dictionary import DICTIONARY
    from fsw.telecommand import CommandDispatcher
    from fsw.telemetry import TelemetrySender

    for warning in cfg.tmtc.warnings():
        print(f"fsw: warning: {warning}", file=sys.stderr)
    tm_cfg = cfg.tmtc
    tm_port = tm_cfg.telemetry_port if args.tm_port is None else args.tm_port
    tc_port = tm_cfg.telecommand_port if args.tc_port is None else args.tc_port
    telemetry = TelemetrySender(DICTIONARY, tm_cfg.telemetry_host, tm_port, security=downlink,
                                multicast_interface=tm_cfg.telemetry_multicast_interface,
                                multicast_ttl=tm_cfg.telemetry_multicast_ttl)
    try:
        sock = None if args.tc_fd is None else _inherited_udp_socket(args.tc_fd)
        dispatcher = CommandDispatcher(DICTIONARY, telemetry, host=tm_cfg.telecommand_bind_host, port=tc_port,
                                       security=uplink, budget_s=tm_cfg.uplink_budget_ms / 1000.0, sock=sock)
    except OSError as exc:
        where = f"--tc-fd {args.tc_fd}" if args.tc_fd is not None else f"{tm_cfg.telecommand_bind_host}:{tc_port}"
        raise _StartFailed(f"cannot bind the telecommand socket {where}: {exc}") from None
    return telemetry, dispatcher, tm_port


def _inherited_udp_socket(fd: int) -> socket.socket:
    """The bound UDP socket a parent handed over as ``fd``; OSError when ``fd`` is not one."""
    sock = socket.socket(fileno=fd)
    if sock.family != socket.AF_INET or sock.type != socket.SOCK_DGRAM or sock.getsockname()[1] == 0:
        sock.detach()
        raise OSError(f"file descriptor {fd} is not a bound UDP socket")
    return sock


def _build(args: argparse.Namespace, cfg, bus, icd, telemetry, dispatcher):
    """The flight software on this bus and TM/TC; a plug-in that cannot be loaded closes them: exit code 2."""
    from fsw.assembly import build_flight_software
    from fsw.plugins import PluginError

    try:
        return build_flight_software(cfg, bus, icd, telemetry=telemetry, dispatcher=dispatcher)
    except PluginError as exc:
        dispatcher.close()
        telemetry.close()
        bus.shutdown()
        raise _StartFailed(f"{args.config}: flight_software.plugins: {exc}") from None


def _fly(fsw, args: argparse.Namespace, realtime: bool, telemetry, dispatcher, bus) -> int:
    """The executive's loop until its end (0) or a failure (FATAL_ERROR, 1); then everything closed."""
    code = 0
    try:
        if realtime:
            fsw.run_realtime(args.duration_s)
        else:
            fsw.run_lockstep(args.max_ticks, first_sync_timeout_s=args.first_sync_timeout_s)
    except Exception as exc:  # noqa: BLE001 - report, then exit non-zero
        telemetry.event("FATAL_ERROR", reason=f"{type(exc).__name__}: {exc}"[:110])
        print(f"fsw: fatal: {type(exc).__name__}: {exc}", file=sys.stderr)
        code = 1
    finally:
        fsw.shutdown()
        dispatcher.close()
        telemetry.close()
        bus.shutdown()
    return code


def link_key(cfg, config_path: str, key_file: str | None = None) -> bytes:
    """The run's link key, from the mission's key file (``key_file`` overrides it). Raises KeyFileError
    when there is no usable key: the flight software never runs an unauthenticated uplink."""
    from comms.link_security import KeyFileError, load_key_file, mission_key_path

    path = key_file or mission_key_path(cfg.tmtc.security.key_file, config_path)
    if path is None:
        raise KeyFileError(f"{config_path}: flight_software.tmtc.security.key_file: no link key named; make "
                           "one with `keepout ground keygen FILE` and name it there (or pass --key-file)")
    return load_key_file(path)


def link_associations(cfg, key: bytes):
    """(uplink receiver, downlink sender) associations of the link key ``key``."""
    from comms.dictionary import DICTIONARY
    from comms.link_security import SPI_TM, SecurityAssociation, uplink_receiver

    uplink = uplink_receiver(key, cfg.tmtc.security.tc_window, resync_opcode=DICTIONARY.command("SEC_RESYNC").opcode)
    return uplink, SecurityAssociation(key, SPI_TM)


if __name__ == "__main__":
    sys.exit(main())
