"""Telecommands: CCSDS TC space packets over UDP, decoded and validated with the dictionary.

``CommandDispatcher`` owns the uplink socket (bound to loopback unless the mission config names another
address), checks every datagram (length, header, APID, CRC, opcode, argument types and ranges) before any
handler runs, and classifies every failure as one of the typed errors INVALID_OPCODE, VALIDATION, FORMAT
or EXECUTION. Every datagram changes the counters; none can raise out of ``handle_datagram``/``poll``.

With a ``security`` association (``comms.link_security``, what the flight process always uses) every
datagram must first pass the link's authentication and anti-replay checks; a refusal is the error class
SECURITY, counted by reason in the association (which RESET_COUNTERS never clears). The link, not the
handlers, does this: the handlers only ever see authenticated, fresh commands.

``poll`` reads the uplink until it is empty, within a time budget per call; what the kernel had to
discard because the socket buffer was full (SO_RXQ_OVFL) is counted, so no command is lost silently.

Handlers are registered per opcode and called with the decoded arguments as keywords (enums as their
names, e.g. ``handler(mode="POINTING")``). A handler signals a rejected request by raising
``CommandValidationError`` (e.g. target inside a keep-out zone) or ``CommandExecutionError``; any other
exception is also counted as an execution error, never propagated.

Every telecommand is acknowledged in telemetry as PUS service 1 does (``TC_ACK`` packets, see
``comms.dictionary.TC_VERIFICATION_DOC``): ACCEPTANCE_SUCCESS or ACCEPTANCE_FAILURE with a reason code,
then for an accepted command COMPLETION_SUCCESS or COMPLETION_FAILURE, each quoting the command's request
id and sequence count. Each failure carries a reason code from ``TC_REASON_CODES``; its error class follows
from the code. With link security only packets that authenticate are answered (see ``_unprotect``).
"""
from __future__ import annotations

import fcntl
import math
import os
import select
import signal
from _signal import getsignal as _handler_of
import socket
import struct
import threading
import time
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from spacepackets.ccsds.spacepacket import (
    CCSDS_HEADER_LEN,
    MAX_SEQ_COUNT,
)

from comms.dictionary import (
    DEFAULT_HOST,
    DEFAULT_TC_PORT,
    DICTIONARY,
    TelemetryDictionary,
)
from comms.link_security import FORMAT as LINK_FORMAT
from comms.link_security import OUTSIDE_WINDOW, REPLAY
from comms.link_security import REASONS as SECURITY_REASONS
from comms.link_security import SecurityAssociation, SecurityError
from comms.telecommand import (
    CommandError,
    CommandExecutionError,
    CommandFormatError,
    CommandResult,
    CommandSecurityError,
    EXECUTION,
    FORMAT,
    InvalidOpcodeError,
    OPCODE,
    decode_command,
)

if TYPE_CHECKING:
    from fsw.telemetry import TelemetrySender


JUNK_EVENT_PERIOD_S = 60.0  # UPLINK_JUNK events: at most one a minute of onboard time
# SO_RXQ_OVFL (Linux socket option 40, not exported by every Python): each datagram then carries the
# socket's cumulative count of datagrams the kernel dropped because the receive buffer was full.
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)
_OVFL = struct.Struct("=I")
_ANC_SPACE = socket.CMSG_SPACE(_OVFL.size)
_BUDGET_CHECK_EVERY = 16  # datagrams between two clock reads while draining
# SO_RXQ_OVFL reports drops only with the next datagram queued; drops after the last one are read with
# SO_MEMINFO (Linux >= 4.16: u32 sk_meminfo array, SK_MEMINFO_DROPS at index 8) when housekeeping asks.
SO_MEMINFO = getattr(socket, "SO_MEMINFO", 55)
_MEMINFO_DROPS = 8

Handler = Callable[..., Any]

# Arrival signal (O_ASYNC): the kernel raises SIGIO when a datagram is queued on an armed uplink socket, and
# the handler marks every armed dispatcher "maybe readable". A lockstep GNC cycle then reads the socket only
# after something arrived, instead of one failing recv() per cycle (a system call: ~15 us in the vcan-vm
# guest, at 10 cycles per simulated second). The signal is raised in the sender's system call, before the
# simulator's SYNC for that tick goes out, so it is always handled before the cycle polls.
_ARMED: "weakref.WeakSet[CommandDispatcher]" = weakref.WeakSet()
_SIGIO = getattr(signal, "SIGIO", None)
_previous_sigio: Any = None


def _on_sigio(signum: int, frame: Any) -> None:
    for dispatcher in list(_ARMED):
        dispatcher._maybe_readable = True
    if callable(_previous_sigio):
        _previous_sigio(signum, frame)


class CommandDispatcher:
    """Receives, checks and dispatches telecommands; counts every outcome.

    ``port=None`` creates no socket (``handle_datagram`` only); ``port=0`` binds an ephemeral port
    (read it from ``address``); ``sock``: a UDP socket already bound (one a parent process reserved and
    handed over), used in place of binding ``host``:``port``. ``telemetry`` (optional) receives the COMMAND
    and rejection events.
    ``security``: the uplink association every datagram must pass (None: plain packets, unit tests).
    ``budget_s``: host time one ``poll`` may spend draining the socket (the rest waits for the next).
    """

    # accepted + rejected = received; completed + failed = accepted; the five error classes add up to
    # rejected + failed.
    COUNTER_NAMES = ("received", "accepted", "rejected", "completed", "failed", "invalid_opcode", "validation",
                     "format", "execution", "security", "seq_gaps", "acks_sent")

    def __init__(self, dictionary: TelemetryDictionary = DICTIONARY, telemetry: TelemetrySender | None = None,
                 host: str = DEFAULT_HOST, port: int | None = DEFAULT_TC_PORT, *,
                 security: SecurityAssociation | None = None, budget_s: float = 0.005,
                 rcvbuf_bytes: int | None = None, sock: socket.socket | None = None) -> None:
        self.dictionary = dictionary
        self.telemetry = telemetry
        self.security = security
        self.budget_s = budget_s
        self.kernel_drops = 0  # datagrams the kernel discarded (socket buffer full), never reset
        # Junk: datagrams refused without an answer (they do not authenticate; without link security, the
        # malformed ones). Anyone on the host can send them, so they are housekeeping counters, not warning
        # events: one UPLINK_JUNK event at most every JUNK_EVENT_PERIOD_S says how many came and why.
        self.junk_total = 0  # never reset
        self._junk_window: dict[str, int] = {}
        self._junk_event_t = -math.inf
        self.budget_exhausted = 0  # polls that stopped at the budget with datagrams still queued
        self._handlers: dict[int, Handler] = {}
        self.counters: dict[str, int] = dict.fromkeys(self.COUNTER_NAMES, 0)
        self.last_opcode = 0
        self.last_result: CommandResult | None = None
        self._last_seq: int | None = None
        self._sock: socket.socket | None = None
        self._maybe_readable = True  # read at the first poll, whatever arrived before the socket was armed
        self._armed = False
        if sock is not None or port is not None:
            self._sock = sock if sock is not None else socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if rcvbuf_bytes is not None:
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf_bytes)
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            except OSError:
                pass  # not Linux: drops cannot be counted (hk shows 0)
            if sock is None:
                self._sock.bind((host, port))
            self._sock.setblocking(False)
            self._arm()
        if security is not None and security.resync_opcode is not None:
            self.register(security.resync_opcode, self._cmd_resync)

    def _arm(self) -> None:
        """Ask for SIGIO on arrivals (see ``_on_sigio``); where that is not possible (no SIGIO, not the main
        thread, which alone may install signal handlers) every poll reads the socket."""
        global _previous_sigio
        if _SIGIO is None or threading.current_thread() is not threading.main_thread():
            return
        try:
            current = signal.getsignal(_SIGIO)
            if current is not _on_sigio:
                _previous_sigio = current
                signal.signal(_SIGIO, _on_sigio)
            fd = self._sock.fileno()
            fcntl.fcntl(fd, fcntl.F_SETOWN, os.getpid())
            fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) | os.O_ASYNC)
        except (OSError, ValueError):
            return
        _ARMED.add(self)
        self._armed = True

    def _disarm(self) -> None:
        global _previous_sigio
        if not self._armed:
            return
        self._armed = False
        _ARMED.discard(self)
        if self._sock is not None:
            fd = self._sock.fileno()
            fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_ASYNC)
        if not _ARMED and signal.getsignal(_SIGIO) is _on_sigio \
                and threading.current_thread() is threading.main_thread():
            signal.signal(_SIGIO, _previous_sigio if _previous_sigio is not None else signal.SIG_DFL)
            _previous_sigio = None

    def _nothing_arrived(self) -> bool:
        """True only when the arrival signal guarantees the socket is empty: armed, the handler still
        installed, no SIGIO since the last read, and in the main thread (where the handler runs)."""
        # (signal.getsignal wraps the handler through an Enum lookup that fails for a function: ~2 us a
        # cycle; the C function returns the same handler object)
        return (self._armed and not self._maybe_readable and _handler_of(_SIGIO) is _on_sigio
                and threading.current_thread() is threading.main_thread())

    # ---- registration ----
    def register(self, opcode: int | str, handler: Handler) -> None:
        """Route ``opcode`` (number or command name) to ``handler(**args)``."""
        definition = self.dictionary.command(opcode)
        if definition.opcode in self._handlers:
            raise ValueError(f"a handler for {definition.name} is already registered")
        self._handlers[definition.opcode] = handler

    # ---- input ----
    def poll(self, timeout_s: float = 0.0) -> list[CommandResult]:
        """Handle every datagram waiting on the socket, until it is empty or ``budget_s`` is spent."""
        if self._sock is None:
            return []
        results: list[CommandResult] = []
        if timeout_s <= 0.0 and self._nothing_arrived():
            return results
        self._maybe_readable = False  # cleared before reading: a datagram arriving from here on sets it again
        if timeout_s > 0.0:
            ready, _, _ = select.select([self._sock], [], [], timeout_s)
            if not ready:
                return results
        start = time.perf_counter()
        while True:
            try:
                # Read more than the maximum so an oversized datagram is seen as oversized, not cut.
                data, ancillary, _, _ = self._sock.recvmsg(65536, _ANC_SPACE)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= _OVFL.size:
                    self.kernel_drops = max(self.kernel_drops, _OVFL.unpack_from(value)[0])
            results.append(self.handle_datagram(data))
            if len(results) % _BUDGET_CHECK_EVERY == 0 and time.perf_counter() - start > self.budget_s:
                # Out of time with datagrams still queued: they wait for the next cycle (the kernel counts
                # any that no longer fit), the GNC cycle keeps its deadline.
                self.budget_exhausted += 1
                self._maybe_readable = True
                break
        if self._junk_window:
            self._report_junk()
        return results

    def handle_datagram(self, data: bytes) -> CommandResult:
        """Check, decode and dispatch one datagram, and acknowledge it in telemetry (TC_ACK packets: an
        acceptance report, then for an accepted command a completion report). Never raises (except
        BaseException like Ctrl-C)."""
        self.counters["received"] += 1
        data = bytes(data)
        request_id = _request_id(data)
        opcode: int | None = None
        name: str | None = None
        seq: int | None = None
        try:
            if self.security is not None:
                data = self._unprotect(data)
            try:
                definition, args, seq = decode_command(self.dictionary, data)
            except CommandError:
                opcode = _peek_opcode(data)  # what the packet says, for the report (0 when too short)
                raise
            opcode, name = definition.opcode, definition.name
            self._track_sequence(seq)
            handler = self._handlers.get(opcode)
            if handler is None:
                raise InvalidOpcodeError(f"{name} has no handler in this flight software", "NO_HANDLER")
            self._event("CMD_DISPATCHED", opcode=opcode, command=name, seq=seq)
            try:
                handler(**args)
            except CommandError:
                raise
            except Exception as exc:  # noqa: BLE001 - a handler bug must not take down the task
                raise CommandExecutionError(f"{name}: {type(exc).__name__}: {exc}") from exc
        except CommandError as exc:
            return self._fail(exc, opcode, name, seq, request_id, _seq_of(data) if seq is None else seq)
        except Exception as exc:  # noqa: BLE001 - last line of defence: count, never crash
            failure = CommandFormatError(f"unexpected {type(exc).__name__}: {exc}")
            return self._fail(failure, opcode, name, seq, request_id, _seq_of(data) if seq is None else seq)
        # Handlers run to completion synchronously: acceptance (the checks and the handler's own
        # validation passed) and completion are reported together.
        self.counters["accepted"] += 1
        self.counters["completed"] += 1
        self.last_opcode = opcode
        self._acknowledge("ACCEPTANCE_SUCCESS", request_id, seq, opcode)
        self._event("CMD_COMPLETED", opcode=opcode, command=name)
        self._acknowledge("COMPLETION_SUCCESS", request_id, seq, opcode)
        result = CommandResult(True, None, opcode, name, seq, "completed", args, "NONE", request_id)
        self.last_result = result
        return result

    def _unprotect(self, data: bytes) -> bytes:
        """The plain packet inside a secured one, or CommandSecurityError. A packet that does not
        authenticate (junk, no security header, bad MAC) is refused with ``acknowledge = False``: the flight
        software answers only packets signed with the mission key, so a flood of junk draws no flood of
        reports, and a forger cannot fake a rejection of the ground's own command."""
        try:
            return self.security.unprotect(data)[0]
        except SecurityError as exc:
            code = {LINK_FORMAT: "CRC_MISMATCH"}.get(exc.reason, exc.reason.upper())
            raise CommandSecurityError(f"{exc.reason}: {exc}", code,
                                       acknowledge=exc.reason in (REPLAY, OUTSIDE_WINDOW)) from None

    def _cmd_resync(self) -> None:
        """SEC_RESYNC: the link already moved the window to this command's SN; say so."""
        self._event("SEC_RESYNCED", sn=self.security.last_sn)

    def _fail(self, exc: CommandError, opcode: int | None, name: str | None, seq: int | None,
              request_id: int, ack_seq: int) -> CommandResult:
        """A failure: an execution error fails an accepted command (completion failure); any other error
        rejects the command (acceptance failure: nothing changed on board)."""
        kind, code, reason = exc.kind, exc.code, str(exc)
        if not getattr(exc, "acknowledge", True):
            request_id = -1  # not answered (see _unprotect)
        self.counters[kind.lower()] += 1
        accepted = kind == EXECUTION
        if accepted:
            self.counters["accepted"] += 1
            self.counters["failed"] += 1
            self._acknowledge("ACCEPTANCE_SUCCESS", request_id, ack_seq, opcode)
        else:
            self.counters["rejected"] += 1
        if request_id < 0 or (self.security is None and kind == FORMAT):  # junk: counted, summarised
            self.junk_total += 1
            self._junk_window[code] = self._junk_window.get(code, 0) + 1
            self._report_junk()
        else:
            self._event("CMD_REJECTED", opcode=opcode or 0, error=kind, reason=reason)
        if request_id >= 0:
            self._acknowledge("COMPLETION_FAILURE" if accepted else "ACCEPTANCE_FAILURE", request_id, ack_seq,
                              opcode, code)
        result = CommandResult(accepted, kind, opcode, name, seq, reason, None, code, request_id)
        self.last_result = result
        return result

    def _report_junk(self) -> None:
        """One UPLINK_JUNK event for the junk since the last one, at most every JUNK_EVENT_PERIOD_S of
        onboard time (the first at once: the ground learns that junk started)."""
        now = self.telemetry.clock() if self.telemetry is not None else time.monotonic()
        if now - self._junk_event_t < JUNK_EVENT_PERIOD_S:
            return
        window = self._junk_window
        reasons = ", ".join(f"{n} {code}" for code, n in sorted(window.items(), key=lambda kv: -kv[1]))
        self._event("UPLINK_JUNK", count=sum(window.values()), reasons=reasons[:120],
                    window_s=min(now - self._junk_event_t, 1e9))
        self._junk_window = {}
        self._junk_event_t = now

    def _acknowledge(self, report: str, request_id: int, seq: int, opcode: int | None, code: str = "NONE") -> None:
        """Send one verification report (a TC_ACK packet: never throttled, unlike events)."""
        if self.telemetry is None:
            return
        values = {"ack_report": report, "ack_request_id": request_id, "ack_tc_seq": seq,
                  "ack_opcode": opcode or 0, "ack_code": code}
        try:
            self.telemetry.send_channels("TC_ACK", values)  # stamped by the telemetry clock: onboard time
            self.counters["acks_sent"] += 1
        except Exception:  # noqa: BLE001 - reporting must never turn a command into a crash
            pass

    def _track_sequence(self, seq: int) -> None:
        # The ground counts TCs per APID too; a jump means an uplinked command never arrived.
        if self._last_seq is not None and seq != (self._last_seq + 1) % (MAX_SEQ_COUNT + 1):
            self.counters["seq_gaps"] += 1
        self._last_seq = seq

    def _event(self, event_name: str, /, **args: Any) -> None:
        if self.telemetry is None:
            return
        try:
            self.telemetry.event(event_name, **args)
        except Exception:  # noqa: BLE001 - reporting must never turn a command into a crash
            pass

    # ---- housekeeping ----
    def hk_values(self) -> dict[str, int]:
        """The dispatcher's housekeeping channels, named as in the dictionary's HK packet."""
        c = self.counters
        return {"tc_accepted": c["accepted"], "tc_rejected": c["rejected"], "tc_completed": c["completed"],
                "tc_failed": c["failed"],
                "tc_invalid_opcode": c["invalid_opcode"], "tc_validation_errors": c["validation"],
                "tc_format_errors": c["format"], "tc_execution_errors": c["execution"],
                "tc_last_opcode": self.last_opcode, **self.security_hk_values()}

    def security_hk_values(self) -> dict[str, int]:
        """Link-security and uplink-loss channels: never reset by RESET_COUNTERS (the evidence stays)."""
        sa = self.security
        values = {f"tc_sec_{reason}": (sa.counters[reason] if sa is not None else 0) for reason in SECURITY_REASONS}
        values.update(tc_sec_resyncs=sa.resyncs if sa is not None else 0,
                      tc_sec_last_sn=sa.last_sn if sa is not None else 0,
                      tc_uplink_dropped=self._read_kernel_drops(), tc_uplink_deferred=self.budget_exhausted,
                      tc_uplink_junk=self.junk_total)
        return values

    def reset_counters(self) -> None:
        self.counters = dict.fromkeys(self.COUNTER_NAMES, 0)

    def _read_kernel_drops(self) -> int:
        """The kernel's drop count for the uplink socket, including drops no datagram has reported yet."""
        if self._sock is not None:
            try:
                info = self._sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, 4 * (_MEMINFO_DROPS + 1))
                if len(info) >= 4 * (_MEMINFO_DROPS + 1):
                    drops = _OVFL.unpack_from(info, 4 * _MEMINFO_DROPS)[0]
                    self.kernel_drops = max(self.kernel_drops, drops)
            except OSError:
                pass  # older kernel: the per-datagram SO_RXQ_OVFL count alone
        return self.kernel_drops

    @property
    def address(self) -> tuple[str, int] | None:
        return self._sock.getsockname() if self._sock is not None else None

    def fileno(self) -> int:
        """Socket file descriptor (for select in a real-time loop); -1 without a socket."""
        return self._sock.fileno() if self._sock is not None else -1

    def close(self) -> None:
        if self._sock is not None:
            self._disarm()
            self._sock.close()
            self._sock = None

    def __enter__(self) -> "CommandDispatcher":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _request_id(data: bytes) -> int:
    """PUS request id: the first four octets of the telecommand (zero-padded when shorter)."""
    return int.from_bytes(data[:4].ljust(4, b"\0"), "big")


def _seq_of(data: bytes) -> int:
    """The sequence count field of a packet that may not decode (0 when too short to hold one)."""
    return int.from_bytes(data[2:4], "big") & MAX_SEQ_COUNT if len(data) >= 4 else 0


def _peek_opcode(data: bytes) -> int | None:
    if len(data) >= CCSDS_HEADER_LEN + OPCODE.size:
        return OPCODE.unpack_from(data, CCSDS_HEADER_LEN)[0]
    return None
