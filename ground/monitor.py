"""Ground monitor: receive telemetry, archive it raw then decoded, check sequence gaps and limits.

``GroundMonitor`` archives every datagram raw before decoding it, then writes the decoded packet to
``tm_decoded.jsonl`` (events also to ``events.jsonl``), checks the per-APID sequence count for gaps,
limit-checks every channel that has dictionary limits (each GREEN/YELLOW/RED transition goes to
``limits.jsonl``) and keeps the latest values and events for displays. On close
``ground_summary.json`` holds per-APID counts, gaps, decode errors and per-channel limit statistics.

With a downlink ``security`` association (``comms.link_security``; the SIL and the CLI always give one)
every datagram must carry a valid MAC and a security sequence number above the last one. Only those are
archived, as the plain packet they carry: a forged, unauthenticated or replayed packet is counted by
reason (``stats.rejected``, shown live and in the summary) and kept apart in ``tm_rejected.bin``, never
in ``tm_raw.bin`` or the event log, so it cannot change what the run is judged on.

``run_ground_monitor`` is the picklable entry point the SIL orchestrator runs in its own process.
"""
from __future__ import annotations

import collections
import ctypes
import json
import math
import select
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from comms.dictionary import DEFAULT_HOST, DEFAULT_TM_PORT, DICTIONARY, Limits, TelemetryDictionary
from comms.telemetry import SEQ_MODULO
from ground.archive import (
    DECODED_ARCHIVE,
    EVENTS_ARCHIVE,
    LIMITS_ARCHIVE,
    RAW_ARCHIVE,
    RAW_RECORD,
    REJECTED_ARCHIVE,
    SUMMARY_FILE,
)
from ground.display import LiveDisplay

if TYPE_CHECKING:
    import threading

    from comms.link_security import SecurityAssociation
    from comms.telemetry import DecodedTm

# A backwards jump larger than this is read as a flight-software restart, not as 16000 lost packets.
MAX_PLAUSIBLE_GAP = SEQ_MODULO // 2
# Archives reach the disk in pieces of this size (and at every flush): a lockstep SIL archives a packet
# every ~1 ms, and each write, like each lock a buffered file takes, is a system call in the vcan-vm guest
# (CPython 3.11 reads the monotonic clock at every lock acquire, even a non-blocking one).
ARCHIVE_CHUNK_BYTES = 1 << 16
DATAGRAM_BYTES = 65536  # what a receive reads: more than any UDP datagram, so none is cut
RECV_BATCH = 32  # datagrams per recvmmsg() (a SIL ground takes ~20 a wake-up)
_MSG_DONTWAIT = int(socket.MSG_DONTWAIT)


class _ChunkedWriter:
    """An append-only binary file written from a bytearray in ``ARCHIVE_CHUNK_BYTES`` pieces: what a
    ``BufferedWriter`` does (bytes reach the file on ``flush``/``close`` or when a piece is full), without
    its lock (see ``ARCHIVE_CHUNK_BYTES``)."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "ab", buffering=0)
        self._pending = bytearray()

    def write(self, data: bytes) -> int:
        self._pending += data
        if len(self._pending) >= ARCHIVE_CHUNK_BYTES:
            self.flush()
        return len(data)

    def flush(self) -> None:
        pending = self._pending
        while pending:  # FileIO writes at most what it can (a full disk raises, the rest stays pending)
            written = self._file.write(pending)
            del pending[:written]

    def close(self) -> None:
        try:
            self.flush()
        finally:
            self._file.close()


class _DatagramBatch:
    """recvmmsg() of up to ``RECV_BATCH`` datagrams into fixed buffers: one system call for what would
    be a ``recv`` each (Linux; ``libc`` None elsewhere, and then the monitor reads datagram by datagram)."""

    def __init__(self, sock: socket.socket) -> None:
        from comms.bus.mmsg import IoVec, MMsgHdr, libc

        self.libc = libc
        self.fd = sock.fileno()
        self.data = ctypes.create_string_buffer(DATAGRAM_BYTES * RECV_BATCH)
        self.view = memoryview(self.data).cast("B")
        self.iov = (IoVec * RECV_BATCH)()
        self.hdr = (MMsgHdr * RECV_BATCH)()
        base = ctypes.addressof(self.data)
        for i in range(RECV_BATCH):
            self.iov[i].iov_base = base + DATAGRAM_BYTES * i
            self.iov[i].iov_len = DATAGRAM_BYTES
            self.hdr[i].msg_hdr.msg_iov = ctypes.pointer(self.iov[i])
            self.hdr[i].msg_hdr.msg_iovlen = 1

    def read(self, limit: int) -> list[bytes]:
        """The datagrams queued now, in order, at most ``limit`` (<= RECV_BATCH); [] when none (or on a
        socket error: ``recv`` stopped there too)."""
        n = self.libc.recvmmsg(self.fd, self.hdr, limit, _MSG_DONTWAIT, None)
        if n <= 0:
            return []
        view, hdr = self.view, self.hdr
        return [bytes(view[DATAGRAM_BYTES * i:DATAGRAM_BYTES * i + hdr[i].msg_len]) for i in range(n)]


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
    decode_errors_by_kind: dict[str, int] = field(default_factory=dict)  # TRUNCATED, UNKNOWN_APID, ...
    last_decode_error: str = ""
    per_apid: dict[int, ApidStats] = field(default_factory=dict)
    gaps: list[Gap] = field(default_factory=list)
    limits: dict[str, LimitStats] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)  # link-security refusals by reason

    @property
    def missing(self) -> int:
        return sum(s.missing for s in self.per_apid.values())

    @property
    def forged(self) -> int:
        """Datagrams refused by the link security (forged, unauthenticated, replayed or corrupt)."""
        return sum(self.rejected.values())

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "datagrams": self.datagrams, "bytes": self.bytes, "decoded": self.decoded,
            "decode_errors": self.decode_errors, "decode_errors_by_kind": dict(self.decode_errors_by_kind),
            "last_decode_error": self.last_decode_error, "missing_packets": self.missing,
            "rejected_by_link_security": self.forged, "rejected_by_reason": dict(sorted(self.rejected.items())),
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
    ephemeral port (read ``address``); ``port=None`` opens no socket (feed ``process`` directly); ``sock``
    receives from a socket opened elsewhere (a run's multicast telemetry: ``ground.link.open_telemetry``). ``write_decoded=False`` archives raw packets and events only
    (the decoded JSONL of a 24 h soak is gigabytes; ``decode_archive`` rebuilds it from the raw file). Use as a context manager or call ``close()`` to flush the archive
    and write the summary.
    """

    def __init__(self, dictionary: TelemetryDictionary = DICTIONARY, host: str = DEFAULT_HOST,
                 port: int | None = DEFAULT_TM_PORT, archive_dir: str | Path | None = None,
                 recv_buffer_bytes: int = 8 * 1024 * 1024, event_history: int = 20,
                 write_decoded: bool = True, sock: socket.socket | None = None,
                 security: SecurityAssociation | None = None) -> None:
        self.dictionary = dictionary
        self.security = security
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
        self._rejected: IO[bytes] | None = None
        self._limited: dict[str, list[tuple[str, Any, float, float]]] = {}
        if self.archive_dir is not None:
            self.archive_dir.mkdir(parents=True, exist_ok=True)
            self._raw = _ChunkedWriter(self.archive_dir / RAW_ARCHIVE)
            if write_decoded:  # long soaks may keep raw + events only and decode later (`ground decode`)
                self._decoded = open(self.archive_dir / DECODED_ARCHIVE, "a", encoding="utf-8",
                                     buffering=ARCHIVE_CHUNK_BYTES)
                self._decoded._CHUNK_SIZE = ARCHIVE_CHUNK_BYTES  # text goes to the buffer in pieces this big
            self._events = open(self.archive_dir / EVENTS_ARCHIVE, "a", encoding="utf-8")
            self._limits = open(self.archive_dir / LIMITS_ARCHIVE, "a", encoding="utf-8")
            if security is not None:
                self._rejected = open(self.archive_dir / REJECTED_ARCHIVE, "ab")
        self._sock: socket.socket | None = sock  # e.g. ``ground.link.open_telemetry(endpoints)``
        if sock is None and port is not None:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            # A big receive buffer absorbs bursts when lockstep runs faster than real time.
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, recv_buffer_bytes)
            except OSError:
                pass
            self._sock.bind((host, port))
            self._sock.setblocking(False)
        self._batch: _DatagramBatch | None = None
        if self._sock is not None:
            from comms.bus.mmsg import libc

            if libc is not None:
                self._batch = _DatagramBatch(self._sock)

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
        batch = self._batch
        while count < self.max_packets_per_poll:  # bounded, so a flood cannot starve stop/display
            if batch is not None:  # everything queued (up to RECV_BATCH) in one system call
                wanted = min(RECV_BATCH, self.max_packets_per_poll - count)
                datagrams = batch.read(wanted)
                for data in datagrams:
                    self.process(data, rx_time_s)
                count += len(datagrams)
                if len(datagrams) < wanted:  # the queue was empty: as a recv would have found next
                    break
                continue
            try:
                data = self._sock.recv(DATAGRAM_BYTES)
            except OSError:  # includes BlockingIOError: nothing left
                break
            self.process(data, rx_time_s)
            count += 1
        return count

    def process(self, raw: bytes, rx_time_s: float | None = None) -> DecodedTm | None:
        """Archive ``raw`` first (nothing is lost even if it cannot be decoded), then decode it."""
        from comms.telemetry import TelemetryDecodeError, decode_tm_packet

        rx_time_s = time.time() if rx_time_s is None else rx_time_s
        self.stats.datagrams += 1
        self.stats.bytes += len(raw)
        if self.security is not None:
            raw = self._authenticate(raw, rx_time_s)
            if raw is None:
                return None
        if self._raw is not None:
            self._raw.write(RAW_RECORD.pack(rx_time_s, len(raw)) + raw)
        try:
            packet = decode_tm_packet(self.dictionary, raw)
        except Exception as exc:  # noqa: BLE001 - whatever arrives, the ground counts it and goes on
            kind = exc.kind if isinstance(exc, TelemetryDecodeError) else "MALFORMED"
            stats = self.stats
            stats.decode_errors += 1
            stats.decode_errors_by_kind[kind] = stats.decode_errors_by_kind.get(kind, 0) + 1
            stats.last_decode_error = f"{kind}: {exc}"
            self._write(self._decoded, {"rx_time_s": rx_time_s, "error": str(exc), "kind": kind,
                                        "length": len(raw), "hex": raw[:64].hex()})
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

    def _authenticate(self, raw: bytes, rx_time_s: float) -> bytes | None:
        """The plain packet inside an authentic, fresh secured one; None (counted, quarantined) otherwise."""
        from comms.link_security import SecurityError

        try:
            return self.security.unprotect(raw)[0]
        except SecurityError as exc:
            self.stats.rejected[exc.reason] = self.stats.rejected.get(exc.reason, 0) + 1
            if self._rejected is not None:
                self._rejected.write(RAW_RECORD.pack(rx_time_s, len(raw)) + raw)
            self._write(self._decoded, {"rx_time_s": rx_time_s, "rejected": exc.reason, "error": str(exc),
                                        "length": len(raw)})
            return None

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
        display = LiveDisplay(self) if live else None
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
        for stream in (self._raw, self._decoded, self._events, self._limits, self._rejected):
            if stream is not None:
                stream.flush()

    def summary(self) -> dict[str, Any]:
        return self.stats.to_json_dict()

    def close(self) -> None:
        if self._sock is not None:
            self._batch = None
            self._sock.close()
            self._sock = None
        for name in ("_raw", "_decoded", "_events", "_limits", "_rejected"):
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



def run_ground_monitor(archive_dir: str, host: str = DEFAULT_HOST, port: int = DEFAULT_TM_PORT,
                       duration_s: float | None = None, stop_event: Any | None = None,
                       dictionary_path: str | None = None, ready: Any | None = None,
                       port_queue: Any | None = None, write_decoded: bool = True,
                       key_file: str | None = None) -> dict[str, Any]:
    """Process entry point for the SIL orchestrator (``multiprocessing.Process(target=...)``).

    ``ready`` (optional multiprocessing Event) is set once the socket is bound, so the orchestrator
    can start the flight software without losing the first packets. With ``port=0`` the bound port
    is put on ``port_queue`` (a multiprocessing Queue) before ``ready`` is set. ``key_file``: the link
    key; telemetry is then verified (see the module docstring).
    """
    from comms.link_security import downlink_receiver, load_key_file

    dictionary = TelemetryDictionary.load(dictionary_path) if dictionary_path else DICTIONARY
    security = downlink_receiver(load_key_file(key_file)) if key_file else None
    monitor = GroundMonitor(dictionary, host, port, archive_dir, write_decoded=write_decoded, security=security)
    if port_queue is not None:
        port_queue.put(monitor.address[1])
    if ready is not None:
        ready.set()
    return monitor.run(duration_s=duration_s, stop_event=stop_event).to_json_dict()
