"""``keepout ground web``: Open MCT over a run's telemetry (live over a WebSocket, history from the archive).

The server (aiohttp) serves:

- ``/``: the page (``static/index.html``): Open MCT with the keepout plugin (``static/keepout-plugin.js``);
- ``/openmct/``: Open MCT itself, from the npm package ``make setup`` installs (``ground/web/node_modules``,
  or ``--openmct DIR`` / ``KEEPOUT_OPENMCT_DIR``); nothing is fetched from the network at run time;
- ``/api/objects``: the dictionary as Open MCT objects (``ground.web.catalog``); ``/api/run``: what is
  served (run id, live or replay, the archive's time span);
- ``/api/history/KEY?start=MS&end=MS[&strategy=latest]``: points from the run's archive
  (``RUN_DIR/ground/tm_raw.bin``, read incrementally, so a live run's history grows as it is browsed);
- ``/api/realtime``: a WebSocket. The client sends ``{"op": "subscribe" | "unsubscribe", "key": KEY}``;
  the server sends JSON arrays of points of the subscribed keys as packets arrive on the run's telemetry
  (joined like every other ground client, ``ground.link.open_telemetry``). Anything else from a client
  (not JSON, another shape, an unknown key, binary, over 4 KiB) closes that client's connection with
  code 1003 and a reason; the server and the other clients carry on.

It binds 127.0.0.1 unless told otherwise: it has no authentication.
"""
from __future__ import annotations

import asyncio
import json
import os
import signal
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aiohttp import WSCloseCode, WSMsgType, web

from comms.dictionary import TelemetryDictionary
from ground.link import Endpoints, open_telemetry
from ground.web.alarms import ACKS_FILE, AlarmBook
from ground.web.catalog import build_objects, display_names
from ground.web.points import TIME_DOMAINS, ArchiveReader, PointMaker

if TYPE_CHECKING:
    from fsw.config import FswConfig
    from comms.link_security import SecurityAssociation

STATIC_DIR = Path(__file__).resolve().parent / "static"
OPENMCT_ENV = "KEEPOUT_OPENMCT_DIR"
DEFAULT_OPENMCT_DIR = Path(__file__).resolve().parent / "node_modules" / "openmct" / "dist"
MAX_CLIENT_MESSAGE_BYTES = 4096
CLIENT_QUEUE_BATCHES = 2000  # a client this far behind loses batches (counted) instead of growing memory
MAX_PACKETS_PER_WAKEUP = 2000


class WebSetupError(Exception):
    """The web ground cannot start (message says what is missing and how to get it)."""


class ProtocolError(ValueError):
    """A WebSocket client sent something the protocol does not allow."""


def find_openmct(explicit: str | Path | None = None) -> Path:
    """The folder holding Open MCT's ``openmct.js`` (explicit, ``$KEEPOUT_OPENMCT_DIR`` or the npm install)."""
    for candidate, origin in ((explicit, "--openmct"), (os.environ.get(OPENMCT_ENV), OPENMCT_ENV),
                              (DEFAULT_OPENMCT_DIR, "make setup")):
        if candidate is None:
            continue
        path = Path(candidate)
        if (path / "openmct.js").is_file():
            return path
        if origin != "make setup":
            raise WebSetupError(f"{origin} {path}: no openmct.js there; give the dist folder of the npm package openmct")
    raise WebSetupError(f"Open MCT is not installed ({DEFAULT_OPENMCT_DIR} is missing): run `make setup` (it runs "
                        f"`npm ci --prefix ground/web`), or set {OPENMCT_ENV} to the dist folder of the npm package openmct")


def parse_client_message(text: str, known_keys: set[str] | dict[str, Any]) -> tuple[str, str]:
    """(op, key) of a client message, or ProtocolError saying what is wrong with it."""
    try:
        message = json.loads(text)
    except (ValueError, RecursionError):
        raise ProtocolError("not JSON") from None
    if not isinstance(message, dict) or set(message) != {"op", "key"}:
        raise ProtocolError('expected {"op": "subscribe"|"unsubscribe", "key": KEY}')
    op, key = message["op"], message["key"]
    if op not in ("subscribe", "unsubscribe"):
        raise ProtocolError("op must be subscribe or unsubscribe")
    if not isinstance(key, str) or key not in known_keys:
        raise ProtocolError("unknown telemetry key")
    return op, key


@dataclass(eq=False)  # one per connection, kept in a set by identity
class _Client:
    ws: web.WebSocketResponse
    keys: set[str] = field(default_factory=set)
    queue: asyncio.Queue = field(default_factory=lambda: asyncio.Queue(CLIENT_QUEUE_BATCHES))
    dropped: int = 0

    async def pump(self) -> None:
        while True:
            batch = await self.queue.get()
            await self.ws.send_str(json.dumps(batch))


class WebGround:
    """The state behind the web server: the catalog, the archive reader and the live telemetry feed."""

    def __init__(self, dictionary: TelemetryDictionary, archive_dir: Path, openmct_dir: Path, *,
                 cfg: FswConfig | None = None, endpoints: Endpoints | None = None, title: str = "keepout",
                 security: SecurityAssociation | None = None) -> None:
        self.dictionary = dictionary
        self.objects = build_objects(dictionary, title, cfg)
        self.telemetry_keys = {k for k, o in self.objects.items() if "telemetry" in o}
        acks = Path(archive_dir) / ACKS_FILE if os.access(archive_dir, os.W_OK) else None
        self.reader = ArchiveReader(archive_dir, PointMaker(dictionary, cfg),
                                    AlarmBook(dictionary, display_names(dictionary, cfg), acks))
        self.live_maker = PointMaker(dictionary, cfg)
        self.endpoints = endpoints
        self.security = security  # the downlink association: live packets must verify against the link key
        self.openmct_dir = openmct_dir
        self.title = title
        self.clients: set[_Client] = set()
        self.counters = {"tm_packets": 0, "tm_decode_errors": 0, "tm_refused_by_link_security": 0,
                         "ws_connections": 0, "ws_protocol_errors": 0, "ws_batches_dropped": 0}
        self._sock: socket.socket | None = None

    # ---- the application ----
    def app(self) -> web.Application:
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/api/objects", self._objects)
        app.router.add_get("/api/run", self._run)
        app.router.add_get("/api/history/{key}", self._history)
        app.router.add_get("/api/alarms", self._alarms)
        app.router.add_post("/api/alarms/ack", self._acknowledge)
        app.router.add_get("/api/realtime", self._realtime)
        app.router.add_static("/keepout/", STATIC_DIR)
        app.router.add_static("/openmct/", self.openmct_dir)
        app.on_startup.append(self._start_live)
        app.on_cleanup.append(self._stop_live)
        return app

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC_DIR / "index.html")

    async def _objects(self, request: web.Request) -> web.Response:
        return web.json_response(self.objects)

    async def _run(self, request: web.Request) -> web.Response:
        self.reader.refresh()
        span, onboard = self.reader.span("utc"), self.reader.span("onboard_s")
        return web.json_response({
            "title": self.title, "run_id": self.endpoints.run_id if self.endpoints else None,
            "live": self._sock is not None, "span_ms": list(span) if span else None,
            "onboard_span_s": list(onboard) if onboard else None,
            "archive_decode_errors": self.reader.decode_errors, **self.counters})

    async def _history(self, request: web.Request) -> web.Response:
        key = request.match_info["key"]
        if key not in self.telemetry_keys:
            raise web.HTTPNotFound(text=f"unknown telemetry key {key!r}")
        domain = request.query.get("domain", "utc")
        if domain not in TIME_DOMAINS:
            raise web.HTTPBadRequest(text=f"domain must be one of {', '.join(TIME_DOMAINS)}")
        try:
            start, end = float(request.query.get("start", "-inf")), float(request.query.get("end", "inf"))
        except ValueError:
            raise web.HTTPBadRequest(text="start and end must be numbers (ms since 1970, or onboard s with "
                                          "domain=onboard_s)") from None
        self.reader.refresh()
        points = self.reader.history.query(key, self.reader.maker.columns, start, end,
                                           latest=request.query.get("strategy") == "latest",
                                           outline=request.query.get("outline", "all"), domain=domain)
        return web.json_response(points)

    async def _alarms(self, request: web.Request) -> web.Response:
        self.reader.refresh()
        return web.json_response(self.reader.alarms.to_json())

    async def _acknowledge(self, request: web.Request) -> web.Response:
        """``{"ids": [n, ...]}`` or ``{"all": true}``: the operator acknowledges alarms."""
        try:
            body = await request.json()
        except ValueError:
            raise web.HTTPBadRequest(text='expected JSON: {"ids": [n, ...]} or {"all": true}') from None
        self.reader.refresh()
        book = self.reader.alarms
        if isinstance(body, dict) and body.get("all") is True and set(body) <= {"all", "operator"}:
            ids = [a.alarm_id for a in book.alarms]
        elif (isinstance(body, dict) and set(body) <= {"ids", "operator"} and isinstance(body.get("ids"), list)
              and all(isinstance(i, int) and not isinstance(i, bool) for i in body["ids"])):
            ids = body["ids"]
        else:
            raise web.HTTPBadRequest(text='expected JSON: {"ids": [n, ...]} or {"all": true}')
        try:
            newly = book.acknowledge(ids, str(body.get("operator", ""))[:40])
        except KeyError as exc:
            raise web.HTTPBadRequest(text=str(exc.args[0])) from None
        return web.json_response({"acknowledged": newly, **book.to_json()})

    async def _realtime(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=30.0, max_msg_size=MAX_CLIENT_MESSAGE_BYTES)
        await ws.prepare(request)
        client = _Client(ws)
        self.clients.add(client)
        self.counters["ws_connections"] += 1
        pump = asyncio.create_task(client.pump())
        try:
            async for message in ws:
                try:
                    if message.type != WSMsgType.TEXT:
                        raise ProtocolError("binary or malformed frame")
                    op, key = parse_client_message(message.data, self.telemetry_keys)
                except ProtocolError as exc:
                    self.counters["ws_protocol_errors"] += 1
                    await ws.close(code=WSCloseCode.UNSUPPORTED_DATA, message=str(exc).encode()[:120])
                    break
                (client.keys.add if op == "subscribe" else client.keys.discard)(key)
        finally:
            self.clients.discard(client)
            pump.cancel()
        return ws

    # ---- live telemetry ----
    async def _start_live(self, app: web.Application) -> None:
        if self.endpoints is None or self.endpoints.state != "running":
            return
        self._sock = open_telemetry(self.endpoints)
        asyncio.get_running_loop().add_reader(self._sock.fileno(), self._on_telemetry)

    async def _stop_live(self, app: web.Application) -> None:
        if self._sock is not None:
            asyncio.get_running_loop().remove_reader(self._sock.fileno())
            self._sock.close()
            self._sock = None

    def _on_telemetry(self) -> None:
        """Read what arrived, turn it into points, and queue each client the points it subscribed to."""
        from comms.link_security import SecurityError
        from comms.telemetry import TelemetryDecodeError, decode_tm_packet

        rx_time_s = time.time()
        wanted = set().union(*(c.keys for c in self.clients)) if self.clients else set()
        points: list[dict[str, Any]] = []
        for _ in range(MAX_PACKETS_PER_WAKEUP):
            try:
                raw = self._sock.recv(65536)  # type: ignore[union-attr]
            except OSError:  # BlockingIOError: nothing left
                break
            self.counters["tm_packets"] += 1
            if self.security is not None:
                try:
                    raw = self.security.unprotect(raw)[0]
                except SecurityError:
                    self.counters["tm_refused_by_link_security"] += 1
                    continue
            try:
                packet = decode_tm_packet(self.dictionary, raw)
            except (TelemetryDecodeError, ValueError):
                self.counters["tm_decode_errors"] += 1
                continue
            if not wanted:
                continue
            utc = rx_time_s * 1000.0
            if packet.kind == "channels":
                columns = self.live_maker.columns
                row = None
                for key in wanted:
                    where = columns.get(key)
                    if where is None or where[0] != packet.packet:
                        continue
                    row = row if row is not None else self.live_maker.row(packet)
                    if row[where[1]] is not None:
                        points.append({"id": key, "utc": utc, "onboard_s": packet.time_s, "value": row[where[1]]})
            points.extend(p for p in self.live_maker.stream_points(rx_time_s, packet) if p["id"] in wanted)
        if not points:
            return
        for client in self.clients:
            batch = [p for p in points if p["id"] in client.keys]
            if batch:
                try:
                    client.queue.put_nowait(batch)
                except asyncio.QueueFull:
                    client.dropped += 1
                    self.counters["ws_batches_dropped"] += 1


def bind(host: str, port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(64)
    sock.setblocking(False)
    return sock


async def serve(ground: WebGround, sock: socket.socket, announce: str = "") -> None:
    """Serve until SIGINT/SIGTERM."""
    runner = web.AppRunner(ground.app(), handle_signals=False, access_log=None)
    await runner.setup()
    await web.SockSite(runner, sock).start()
    host, port = sock.getsockname()[:2]
    print(f"keepout ground web: http://{host}:{port}/ {announce}".rstrip(), flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await stop.wait()
    finally:
        await runner.cleanup()
