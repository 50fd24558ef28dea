"""``keepout ground web [--run RUN_DIR | --archive DIR] [--port P]``: Open MCT over a run (see ground.web.server)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

DEFAULT_PORT = 8090


def add_cli(subparsers: Any) -> None:
    web = subparsers.add_parser(
        "web", help="Open MCT in the browser: live telemetry of a running SIL, or a finished run's archive",
        description="Serve Open MCT with the keepout plugin: every dictionary channel with units and limits, events, "
                    "FDIR trips, command acknowledgements, a sky view and margin plots. Live over a WebSocket "
                    "while the run flies, history (and replay of a finished run) from its archive.")
    source = web.add_mutually_exclusive_group()
    source.add_argument("--run", default=None, metavar="RUN_DIR",
                        help="a run folder of `keepout sil run` (live while it runs); `latest`: the newest under ./runs "
                             "(the default)")
    source.add_argument("--archive", default=None, metavar="DIR", help="a ground archive folder (holding tm_raw.bin)")
    web.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: no authentication)")
    web.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"HTTP port (default {DEFAULT_PORT}; 0: any free)")
    web.add_argument("--openmct", default=None, metavar="DIR",
                     help="Open MCT dist folder (default: the one `make setup` installs under ground/web)")
    web.add_argument("--key-file", dest="web_key_file", default=None,
                     help="link key that live telemetry must verify against (default: the run's own RUN_DIR/link.key)")
    web.set_defaults(func=_cmd_web)


def archive_title(archive: Path) -> str:
    """The name Open MCT's tree shows for an archive: its run's folder name (a SIL run keeps its ground
    archive in RUN/ground, whose own name says nothing), else the archive folder's."""
    archive = Path(archive).resolve()
    if archive.name == "ground" and any((archive.parent / f).exists() for f in ("summary.json", "mission.yaml")):
        return archive.parent.name
    return archive.name


def _source(args: argparse.Namespace) -> tuple[Path, Path | None, Any]:
    """(archive dir, mission config path or None, endpoints or None) of the command line."""
    from ground.link import Endpoints, find_run

    if args.archive is not None:
        archive = Path(args.archive)
        if not (archive / "tm_raw.bin").is_file():
            raise ValueError(f"--archive {archive}: no tm_raw.bin there; give a ground archive folder")
        config = next((p for p in (archive / "mission.yaml", archive.parent / "mission.yaml") if p.is_file()), None)
        return archive, config, None
    run_dir = find_run(args.run or "latest")
    config = run_dir / "mission.yaml"
    return run_dir / "ground", config if config.is_file() else None, Endpoints.load(run_dir)


def _cmd_web(args: argparse.Namespace) -> int:
    import asyncio

    from hil_sim.mission.flight import load_flight_config
    from hil_sim.mission.loader import ConfigError
    from comms.dictionary import DICTIONARY, DictionaryError, TelemetryDictionary
    from ground.link import LinkError
    from ground.web.server import WebGround, WebSetupError, bind, find_openmct, serve

    try:
        openmct_dir = find_openmct(args.openmct)
        archive, config, endpoints = _source(args)
        dictionary = TelemetryDictionary.load(args.dictionary) if args.dictionary else DICTIONARY
        cfg = load_flight_config(config).flight_software if config is not None else None
        security = None
        if endpoints is not None and endpoints.state == "running":
            from comms.link_security import LINK_KEY_FILE, downlink_receiver, load_key_file

            security = downlink_receiver(load_key_file(args.web_key_file or archive.parent / LINK_KEY_FILE))
        ground = WebGround(dictionary, archive, openmct_dir, cfg=cfg, endpoints=endpoints, security=security,
                           title=endpoints.run_id if endpoints else archive_title(archive))
        sock = bind(args.host, args.port)
    except (WebSetupError, LinkError, ConfigError, DictionaryError, ValueError) as exc:
        print(f"keepout ground web: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"keepout ground web: cannot listen on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 2
    live = endpoints is not None and endpoints.state == "running"
    note = f"(run {endpoints.run_id}, {'live' if live else 'finished: replay'})" if endpoints else f"(archive {archive})"
    try:
        asyncio.run(serve(ground, sock, note))
    except KeyboardInterrupt:
        pass
    return 0
