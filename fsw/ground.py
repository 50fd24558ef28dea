"""Ground monitor: receive, archive and display telemetry; send telecommands.

``keepout ground`` listens for telemetry (loopback by default), archives every datagram raw
(``tm_raw.bin``: records of ``rx_time_s`` float64 + ``length`` u32 + bytes, big-endian) before decoding
it, then writes the decoded packet to ``tm_decoded.jsonl`` (events also to ``events.jsonl``), checks the
per-APID sequence count for gaps, limit-checks every channel that has dictionary limits (each
GREEN/YELLOW/RED transition goes to ``limits.jsonl``), and shows a live table of key channels (coloured
by their limits) and the latest events. On exit ``ground_summary.json`` holds per-APID counts, gaps,
decode errors and per-channel limit statistics.

``keepout ground send SET_MODE POINTING`` sends one telecommand.

``GroundMonitor`` is the programmatic form the SIL orchestrator runs in its own process
(``run_ground_monitor`` is a picklable entry point with an archive directory and a duration/stop event).
"""
from __future__ import annotations

import argparse
import collections
import json
import math
import select
import socket
import struct
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Iterator

from fsw.dictionary import (
    DEFAULT_HOST,
    DEFAULT_TC_PORT,
    DEFAULT_TM_PORT,
    DICTIONARY,
    Limits,
    LimitState,
    TelemetryDictionary,
)

if TYPE_CHECKING:
    import threading

    from fsw.telemetry import DecodedTm

RAW_RECORD = struct.Struct("!dI")  # rx time (s, UNIX), packet length (bytes)
RAW_ARCHIVE = "tm_raw.bin"
DECODED_ARCHIVE = "tm_decoded.jsonl"
EVENTS_ARCHIVE = "events.jsonl"
LIMITS_ARCHIVE = "limits.jsonl"  # every yellow/red limit transition seen by the ground
SUMMARY_FILE = "ground_summary.json"
SEQ_MODULO = 16384
# A backwards jump larger than this is read as a flight-software restart, not as 16000 lost packets.
MAX_PLAUSIBLE_GAP = SEQ_MODULO // 2

KEY_CHANNELS = (
    "mode", "safe_phase", "cycle", "pointing_error_deg", "att_error_deg", "margin_min_deg",
    "active_zone", "eps", "rate_norm_deg_s", "cov_trace", "st_valid", "st_blind_source",
    "wheel_speed_rad_s_0", "wheel_speed_rad_s_1", "wheel_speed_rad_s_2", "wheel_speed_rad_s_3",
    "torque_scale", "exec_time_ms", "slips_gnc", "exec_max_ms_gnc", "bus_crc_errors",
    "bus_alive_errors", "tc_accepted", "tc_rejected", "tm_send_errors", "fdir_trips",
)


@dataclass
class Gap:
    apid: int
    expected: int
    received: int
    missing: int
    rx_time_s: float

    def to_json_dict(self) -> dict[str, Any]:
        return {"apid": self.apid, "expected": self.expected, "received": self.received,
                "missing": self.missing, "rx_time_s": self.rx_time_s}


@dataclass
class ApidStats:
    received: int = 0
    missing: int = 0
    gaps: int = 0
    duplicates_or_restarts: int = 0
    last_seq: int | None = None


@dataclass
class LimitStats:
    """Ground-side limit monitoring of one channel: current state, transitions, extreme values."""

    state: str = "GREEN"
    to_yellow: int = 0
    to_red: int = 0
    min_value: float = math.inf
    max_value: float = -math.inf
    first_red_time_s: float | None = None

    def to_json_dict(self) -> dict[str, Any]:
        return {"state": self.state, "to_yellow": self.to_yellow, "to_red": self.to_red,
                "min": self.min_value if math.isfinite(self.min_value) else None,
                "max": self.max_value if math.isfinite(self.max_value) else None,
                "first_red_time_s": self.first_red_time_s}


@dataclass
class GroundStats:
    datagrams: int = 0
    bytes: int = 0
    decoded: int = 0
    decode_errors: int = 0
    per_apid: dict[int, ApidStats] = field(default_factory=dict)
    gaps: list[Gap] = field(default_factory=list)
    limits: dict[str, LimitStats] = field(default_factory=dict)

    @property
    def missing(self) -> int:
        return sum(s.missing for s in self.per_apid.values())

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "datagrams": self.datagrams, "bytes": self.bytes, "decoded": self.decoded,
            "decode_errors": self.decode_errors, "missing_packets": self.missing,
            "per_apid": {f"{apid:#05x}": {"received": s.received, "missing": s.missing, "gaps": s.gaps,
                                          "duplicates_or_restarts": s.duplicates_or_restarts,
                                          "last_seq": s.last_seq}
                         for apid, s in sorted(self.per_apid.items())},
            "gaps": [g.to_json_dict() for g in self.gaps[:1000]],
            "limits": {name: stats.to_json_dict() for name, stats in self.limits.items()},
        }


class GroundMonitor:
    """Receives telemetry on ``host:port``, archives raw + decoded, tracks gaps, keeps latest values.

    ``archive_dir=None`` keeps everything in memory only (tests, quick looks). ``port=0`` binds an
    ephemeral port (read ``address``); ``port=None`` opens no socket (feed ``process`` directly). ``write_decoded=False`` archives raw packets and events only
    (the decoded JSONL of a 24 h soak is gigabytes; ``decode_archive`` rebuilds it from the raw file). Use as a context manager or call ``close()`` to flush the archive
    and write the summary.
    """

    def __init__(self, dictionary: TelemetryDictionary = DICTIONARY, host: str = DEFAULT_HOST,
                 port: int | None = DEFAULT_TM_PORT, archive_dir: str | Path | None = None,
                 recv_buffer_bytes: int = 8 * 1024 * 1024, event_history: int = 20,
                 write_decoded: bool = True) -> None:
        self.dictionary = dictionary
        self.stats = GroundStats()
        self.latest: dict[str, Any] = {}
        self.latest_time_s: float | None = None
        self.events: collections.deque[DecodedTm] = collections.deque(maxlen=event_history)
        self.echo_events = False  # print each event as a line (the CLI without the live table)
        self.max_packets_per_poll = 5000
        self.archive_dir = Path(archive_dir) if archive_dir is not None else None
        self._raw: IO[bytes] | None = None
        self._decoded: IO[str] | None = None
        self._events: IO[str] | None = None
        self._limits: IO[str] | None = None
        self._limited: dict[str, list[tuple[str, Any, float, float]]] = {}
        if self.archive_dir is not None:
            self.archive_dir.mkdir(parents=True, exist_ok=True)
            self._raw = open(self.archive_dir / RAW_ARCHIVE, "ab")
            if write_decoded:  # long soaks may keep raw + events only and decode later (`ground decode`)
                self._decoded = open(self.archive_dir / DECODED_ARCHIVE, "a", encoding="utf-8")
            self._events = open(self.archive_dir / EVENTS_ARCHIVE, "a", encoding="utf-8")
            self._limits = open(self.archive_dir / LIMITS_ARCHIVE, "a", encoding="utf-8")
        self._sock: socket.socket | None = None
        if port is not None:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            # A big receive buffer absorbs bursts when lockstep runs faster than real time.
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, recv_buffer_bytes)
            except OSError:
                pass
            self._sock.bind((host, port))
            self._sock.setblocking(False)

    @property
    def address(self) -> tuple[str, int]:
        if self._sock is None:
            raise RuntimeError("this GroundMonitor has no socket (created with port=None)")
        return self._sock.getsockname()

    @property
    def decoded_stream(self) -> IO[str] | None:
        """Where decoded records go (the archive's JSONL by default)."""
        return self._decoded

    @decoded_stream.setter
    def decoded_stream(self, stream: IO[str] | None) -> None:
        self._decoded = stream

    # ---- receive ----
    def poll(self, timeout_s: float = 0.1) -> int:
        """Wait up to ``timeout_s`` for telemetry and process everything waiting; returns the count."""
        if self._sock is None:
            return 0
        ready, _, _ = select.select([self._sock], [], [], max(timeout_s, 0.0))
        if not ready:
            return 0
        count = 0
        # One receive time for the batch: everything read here was queued when the read began (a clock
        # read is a system call in the vcan-vm guest, ~10 us, and the ground takes ~10 packets a wake-up).
        rx_time_s = time.time()
        while count < self.max_packets_per_poll:  # bounded, so a flood cannot starve stop/display
            try:
                data = self._sock.recv(65536)
            except OSError:  # includes BlockingIOError: nothing left
                break
            self.process(data, rx_time_s)
            count += 1
        return count

    def process(self, raw: bytes, rx_time_s: float | None = None) -> DecodedTm | None:
        """Archive ``raw`` first (nothing is lost even if it cannot be decoded), then decode it."""
        from fsw.telemetry import TelemetryDecodeError, decode_tm_packet

        rx_time_s = time.time() if rx_time_s is None else rx_time_s
        self.stats.datagrams += 1
        self.stats.bytes += len(raw)
        if self._raw is not None:
            self._raw.write(RAW_RECORD.pack(rx_time_s, len(raw)) + raw)
        try:
            packet = decode_tm_packet(self.dictionary, raw)
        except (TelemetryDecodeError, ValueError) as exc:
            self.stats.decode_errors += 1
            self._write(self._decoded, {"rx_time_s": rx_time_s, "error": str(exc), "length": len(raw),
                                        "hex": raw[:64].hex()})
            return None
        self.stats.decoded += 1
        record = packet.to_json_dict()
        record["rx_time_s"] = rx_time_s
        gap = self._check_sequence(packet.apid, packet.seq_count, rx_time_s)
        if gap is not None:
            record["gap_missing"] = gap.missing
        self._write(self._decoded, record)
        if packet.kind == "event":
            self.events.append(packet)
            self._write(self._events, record)
            if self.echo_events:
                print(f"{packet.time_s:12.3f} {packet.severity:<11} {packet.event}: {packet.message}", flush=True)
        else:
            self.latest.update(packet.values)
            self.latest_time_s = packet.time_s
            self._check_limits(packet)
        return packet

    def _check_limits(self, packet: DecodedTm) -> None:
        """Track each limited channel's state; every YELLOW/RED transition goes to ``limits.jsonl``."""
        limit_stats = self.stats.limits
        values = packet.values
        for name, limits, green_low, green_high in self._limited_channels(packet.packet):
            value = values[name]
            if value != value:  # NaN: no value this packet
                continue
            stats = limit_stats.get(name)
            if stats is None:
                stats = limit_stats[name] = LimitStats()
            if value < stats.min_value:
                stats.min_value = value
            if value > stats.max_value:
                stats.max_value = value
            if stats.state == "GREEN" and green_low <= value <= green_high:
                continue  # the usual case: green and staying green (what limits.check would say)
            state = limits.check(value).value
            if state == stats.state:
                continue
            if state == "RED":
                stats.to_red += 1
                if stats.first_red_time_s is None:
                    stats.first_red_time_s = packet.time_s
            elif state == "YELLOW":
                stats.to_yellow += 1
            self._write(self._limits, {"time_s": packet.time_s, "channel": name, "from": stats.state,
                                       "to": state, "value": value})
            stats.state = state

    def _limited_channels(self, packet_name: str) -> list[tuple[str, Any, float, float]]:
        """(name, limits, green low, green high) of the packet's limit-checked channels; a value in
        [green low, green high] is inside every yellow and red bound, i.e. GREEN."""
        cached = self._limited.get(packet_name)
        if cached is None:
            packet = self.dictionary.packet(packet_name)
            cached = [(c.name, c.limits, *_green_band(c.limits)) for c in packet.channels
                      if c.limits is not None and c.type not in ("BOOL", "ENUM")]
            self._limited[packet_name] = cached
        return cached

    def _check_sequence(self, apid: int, seq: int, rx_time_s: float) -> Gap | None:
        stats = self.stats.per_apid.setdefault(apid, ApidStats())
        stats.received += 1
        previous, stats.last_seq = stats.last_seq, seq
        if previous is None:
            return None
        expected = (previous + 1) % SEQ_MODULO
        if seq == expected:
            return None
        jump = (seq - expected) % SEQ_MODULO
        if jump >= MAX_PLAUSIBLE_GAP:
            stats.duplicates_or_restarts += 1
            return None
        stats.gaps += 1
        stats.missing += jump
        gap = Gap(apid, expected, seq, jump, rx_time_s)
        self.stats.gaps.append(gap)
        return gap

    @staticmethod
    def _write(stream: IO[str] | None, record: dict[str, Any]) -> None:
        if stream is not None:
            stream.write(json.dumps(record) + "\n")

    # ---- loops ----
    def run(self, duration_s: float | None = None, stop_event: threading.Event | Any | None = None,
            live: bool = False, refresh_s: float = 0.5) -> GroundStats:
        """Receive until ``duration_s`` elapsed or ``stop_event`` is set (or Ctrl-C); then close."""
        deadline = None if duration_s is None else time.monotonic() + duration_s
        display = _LiveDisplay(self) if live else None
        try:
            if display is not None:
                display.start()
            last_flush = last_draw = time.monotonic()
            while True:
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    break
                if stop_event is not None and stop_event.is_set():
                    self.poll(0.0)  # drain what already arrived
                    break
                self.poll(0.05)
                now = time.monotonic()
                if now - last_flush > 1.0:
                    self.flush()
                    last_flush = now
                if display is not None and now - last_draw > refresh_s:
                    display.update()
                    last_draw = now
        except KeyboardInterrupt:
            pass
        finally:
            if display is not None:
                display.stop()
            self.close()
        return self.stats

    def flush(self) -> None:
        for stream in (self._raw, self._decoded, self._events, self._limits):
            if stream is not None:
                stream.flush()

    def summary(self) -> dict[str, Any]:
        return self.stats.to_json_dict()

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        for name in ("_raw", "_decoded", "_events", "_limits"):
            stream = getattr(self, name)
            if stream is not None:
                stream.close()
                setattr(self, name, None)
        if self.archive_dir is not None:
            (self.archive_dir / SUMMARY_FILE).write_text(json.dumps(self.summary(), indent=1) + "\n")

    def __enter__(self) -> "GroundMonitor":
        return self

    def __exit__(self, *exc: object) -> None:
        if self._sock is not None or self._raw is not None:
            self.close()


def _green_band(limits: Limits) -> tuple[float, float]:
    lows = [b for b in (limits.yellow[0], limits.red[0]) if b is not None]
    highs = [b for b in (limits.yellow[1], limits.red[1]) if b is not None]
    return max(lows, default=-math.inf), min(highs, default=math.inf)


def read_raw_archive(path: str | Path) -> Iterator[tuple[float, bytes]]:
    """Yield (rx_time_s, packet bytes) from a ``tm_raw.bin`` archive; stops at a torn final record."""
    with open(path, "rb") as stream:
        while True:
            head = stream.read(RAW_RECORD.size)
            if len(head) < RAW_RECORD.size:
                return
            rx_time_s, length = RAW_RECORD.unpack(head)
            data = stream.read(length)
            if len(data) < length:
                return
            yield rx_time_s, data


def decode_archive(archive_dir: str | Path, dictionary: TelemetryDictionary = DICTIONARY
                   ) -> Iterator[tuple[float, DecodedTm | None, bytes]]:
    """Yield (rx_time_s, decoded packet or None if undecodable, raw bytes) from a raw archive."""
    from fsw.telemetry import TelemetryDecodeError, decode_tm_packet

    for rx_time_s, raw in read_raw_archive(Path(archive_dir) / RAW_ARCHIVE):
        try:
            yield rx_time_s, decode_tm_packet(dictionary, raw), raw
        except (TelemetryDecodeError, ValueError):
            yield rx_time_s, None, raw


def read_channels(archive_dir: str | Path, packet_name: str = "GNC",
                  dictionary: TelemetryDictionary = DICTIONARY) -> dict[str, Any]:
    """Time series of one packet's channels from the raw archive, as numpy arrays keyed by channel.

    Also holds ``time_s`` (onboard), ``rx_time_s`` (ground) and ``seq``. Enum channels are arrays of
    names. For plots and summaries in the SIL run folder.
    """
    import numpy as np

    packet = dictionary.packet(packet_name)
    columns: dict[str, list[Any]] = {name: [] for name in ("time_s", "rx_time_s", "seq")}
    columns.update({c.name: [] for c in packet.channels})
    for rx_time_s, decoded, _ in decode_archive(archive_dir, dictionary):
        if decoded is None or decoded.packet != packet_name:
            continue
        columns["time_s"].append(decoded.time_s)
        columns["rx_time_s"].append(rx_time_s)
        columns["seq"].append(decoded.seq_count)
        for name, value in decoded.values.items():
            columns[name].append(value)
    return {name: np.asarray(values) for name, values in columns.items()}


def read_events(archive_dir: str | Path, dictionary: TelemetryDictionary = DICTIONARY) -> list[dict[str, Any]]:
    """Every event in the raw archive, decoded (dicts as in ``events.jsonl``)."""
    events = []
    for rx_time_s, decoded, _ in decode_archive(archive_dir, dictionary):
        if decoded is not None and decoded.kind == "event":
            record = decoded.to_json_dict()
            record["rx_time_s"] = rx_time_s
            events.append(record)
    return events


def run_ground_monitor(archive_dir: str, host: str = DEFAULT_HOST, port: int = DEFAULT_TM_PORT,
                       duration_s: float | None = None, stop_event: Any | None = None,
                       dictionary_path: str | None = None, ready: Any | None = None,
                       port_queue: Any | None = None, write_decoded: bool = True) -> dict[str, Any]:
    """Process entry point for the SIL orchestrator (``multiprocessing.Process(target=...)``).

    ``ready`` (optional multiprocessing Event) is set once the socket is bound, so the orchestrator
    can start the flight software without losing the first packets. With ``port=0`` the bound port
    is put on ``port_queue`` (a multiprocessing Queue) before ``ready`` is set.
    """
    dictionary = TelemetryDictionary.load(dictionary_path) if dictionary_path else DICTIONARY
    monitor = GroundMonitor(dictionary, host, port, archive_dir, write_decoded=write_decoded)
    if port_queue is not None:
        port_queue.put(monitor.address[1])
    if ready is not None:
        ready.set()
    return monitor.run(duration_s=duration_s, stop_event=stop_event).to_json_dict()


# ------------------------------------------------------------------------------------- commanding
class CommandSender:
    """Sends telecommands to the flight software, with its own TC sequence count."""

    def __init__(self, dictionary: TelemetryDictionary = DICTIONARY, host: str = DEFAULT_HOST,
                 port: int = DEFAULT_TC_PORT, seq_count: int = 0) -> None:
        self.dictionary = dictionary
        self.destination = (host, port)
        self.seq_count = seq_count
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(self, command: str | int, *args: Any, check_range: bool = True, **kwargs: Any) -> bytes:
        """Encode and send; positional or keyword args (raises ``ArgError`` naming a bad arg)."""
        from fsw.telecommand import encode_command

        if args and kwargs:
            raise TypeError("pass command args either positionally or by name, not both")
        packet = encode_command(self.dictionary, command, kwargs if kwargs else args, self.seq_count,
                                check_range=check_range)
        self._sock.sendto(packet, self.destination)
        self.seq_count = (self.seq_count + 1) % SEQ_MODULO
        return packet

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> "CommandSender":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ------------------------------------------------------------------------------------- display
_LIMIT_STYLE = {LimitState.GREEN: "green", LimitState.YELLOW: "bold yellow", LimitState.RED: "bold red"}
_SEVERITY_STYLE = {"FATAL": "bold white on red", "WARNING_HI": "bold red", "WARNING_LO": "yellow",
                   "COMMAND": "cyan", "ACTIVITY_HI": "bold", "ACTIVITY_LO": "", "DIAGNOSTIC": "dim"}


def limit_state(dictionary: TelemetryDictionary, name: str, value: Any) -> LimitState | None:
    """Dictionary limit state of a channel value (None when the channel has no limits or no number)."""
    channel = dictionary.channel(name)
    if channel.limits is None or isinstance(value, (str, bool)) or value != value:  # NaN: no value
        return None
    return channel.limits.check(value)


class _LiveDisplay:
    def __init__(self, monitor: GroundMonitor) -> None:
        from rich.console import Console
        from rich.live import Live

        self.monitor = monitor
        self.live = Live(console=Console(), auto_refresh=False)

    def start(self) -> None:
        self.live.start()

    def stop(self) -> None:
        self.update()
        self.live.stop()
        if not self.live.console.is_terminal:
            self.live.console.line()

    def update(self) -> None:
        self.live.update(render_tables(self.monitor), refresh=True)


def render_tables(monitor: GroundMonitor) -> Any:
    """A rich renderable: key channels with limit colours, link statistics and the latest events."""
    from rich.console import Group
    from rich.table import Table

    dictionary = monitor.dictionary
    channels = Table(title=f"keepout telemetry  t={monitor.latest_time_s}", expand=False)
    for column in ("channel", "value", "unit", "limit"):
        channels.add_column(column)
    for name in KEY_CHANNELS:
        if name not in monitor.latest:
            continue
        value = monitor.latest[name]
        state = limit_state(dictionary, name, value)
        text = f"{value:.5g}" if isinstance(value, float) else str(value)
        style = _LIMIT_STYLE[state] if state is not None else ""
        channels.add_row(name, text, dictionary.channel(name).unit, state.value if state else "", style=style)
    stats = monitor.stats
    link = Table(title="link", expand=False)
    for column in ("datagrams", "decoded", "decode errors", "gaps", "missing"):
        link.add_column(column)
    link.add_row(str(stats.datagrams), str(stats.decoded), str(stats.decode_errors), str(len(stats.gaps)),
                 str(stats.missing), style="bold red" if stats.missing or stats.decode_errors else "")
    events = Table(title="latest events", expand=False)
    for column in ("time_s", "severity", "event", "message"):
        events.add_column(column)
    for event in reversed(monitor.events):
        events.add_row(f"{event.time_s:.2f}", event.severity or "", event.event or "", event.message or "",
                       style=_SEVERITY_STYLE.get(event.severity or "", ""))
    return Group(channels, link, events)


# ------------------------------------------------------------------------------------- CLI
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
    parser.set_defaults(func=_cmd_monitor)
    sub = parser.add_subparsers(dest="ground_command", metavar="{send,decode}")
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

    try:
        dictionary = _load_dictionary(args.dictionary)
        addresses = _mission_addresses(args.config)
    except (DictionaryError, ValueError) as exc:
        print(f"keepout ground: {exc}", file=sys.stderr)
        return 2
    host = args.host if args.host is not None else addresses["tm_host"]
    port = args.port if args.port is not None else addresses["tm_port"]
    try:
        monitor = GroundMonitor(dictionary, host, port, args.archive)
    except OSError as exc:
        print(f"keepout ground: cannot bind {host}:{port}: {exc}", file=sys.stderr)
        return 2
    print(f"keepout ground: telemetry on {monitor.address[0]}:{monitor.address[1]}, archive {args.archive}")
    monitor.echo_events = args.no_live
    stats = monitor.run(duration_s=args.duration, live=not args.no_live)
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
