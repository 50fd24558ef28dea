"""Verified commanding: send one telecommand and wait for its acknowledgements (PUS service 1 style).

The flight software answers every telecommand with ``TC_ACK`` packets (``comms.dictionary``: acceptance
success or failure with a reason code, then for an accepted command completion success or failure), each
quoting the command's request id (its first four octets). ``send_verified`` sends the command, reads the
telemetry until the reports for that request id settle it, and returns the outcome; ``keepout ground
send`` prints it and exits with its code:

====  ==========================================================================================
code  outcome
====  ==========================================================================================
0     COMPLETED: accepted and executed (COMPLETION_SUCCESS)
1     NOT_SENT: the command could not be sent, or nothing listens at the telecommand address
2     bad input: unknown command, bad argument or option (nothing was sent)
3     REJECTED: ACCEPTANCE_FAILURE, with the reason code; nothing changed on board
4     FAILED: accepted, then COMPLETION_FAILURE, with the reason code
5     NO_ACK: no acknowledgement within the timeout (or accepted, but no completion report in time)
====  ==========================================================================================
"""
from __future__ import annotations

import select
import socket
import time
from dataclasses import dataclass, field
from typing import Any

from comms.dictionary import TC_REASON_DOCS, TelemetryDictionary
from comms.link_security import SecurityAssociation
from comms.telemetry import decode_tm_packet
from ground.commanding import CommandSender

EXIT_COMPLETED, EXIT_NOT_SENT, EXIT_BAD_INPUT, EXIT_REJECTED, EXIT_FAILED, EXIT_NO_ACK = 0, 1, 2, 3, 4, 5
ACK_PACKET = "TC_ACK"


@dataclass(frozen=True)
class Ack:
    """One verification report, as decoded from a ``TC_ACK`` packet."""

    report: str
    request_id: int
    seq: int
    opcode: int
    code: str
    time_s: float

    def describe(self, dictionary: TelemetryDictionary) -> str:
        command = dictionary.command_by_opcode(self.opcode)
        name = command.name if command is not None else f"opcode {self.opcode:#06x}"
        text = f"t={self.time_s:.2f} s  {self.report:<18} {name} seq {self.seq}"
        if self.code != "NONE":
            text += f": {self.code} ({TC_REASON_DOCS.get(self.code, 'see the dictionary')})"
        return text


def parse_ack(dictionary: TelemetryDictionary, raw: bytes, downlink: SecurityAssociation | None = None
              ) -> Ack | None:
    """The report in ``raw`` if it is a decodable TC_ACK packet, else None (other telemetry, or garbage).
    With ``downlink`` the packet must verify against the link key first: a forged acknowledgement is
    never taken for the flight software's."""
    try:
        if downlink is not None:
            raw, _ = downlink.unprotect(raw)
        packet = decode_tm_packet(dictionary, raw)
    except Exception:  # noqa: BLE001 - not ours to judge here; the monitor counts bad packets
        return None
    if packet.packet != ACK_PACKET:
        return None
    v = packet.values
    return Ack(v["ack_report"], int(v["ack_request_id"]), int(v["ack_tc_seq"]), int(v["ack_opcode"]),
               v["ack_code"], packet.time_s)


@dataclass
class Verification:
    """What came back for one telecommand."""

    exit_code: int
    outcome: str  # COMPLETED / REJECTED / FAILED / NO_ACK / NOT_SENT
    acks: list[Ack] = field(default_factory=list)
    detail: str = ""


def request_id(packet: bytes) -> int:
    """PUS request id of a telecommand: its first four octets."""
    return int.from_bytes(packet[:4], "big")


def send_verified(sender: CommandSender, telemetry: socket.socket, command: str | int, args: Any = (),
                  *, timeout_s: float = 5.0, check_range: bool = True,
                  downlink: SecurityAssociation | None = None) -> tuple[bytes, Verification]:
    """Send ``command`` and wait up to ``timeout_s`` for its acknowledgements on ``telemetry`` (a bound UDP
    socket receiving the flight software's telemetry). Returns (packet sent, verification).

    Raises what ``sender.send`` raises for a bad command or argument (``ArgError``, ``DictionaryError``)."""
    packet = sender.send(command, *args, check_range=check_range)
    wanted = request_id(packet)
    acks: list[Ack] = []
    deadline = time.monotonic() + timeout_s
    while True:
        if sender.refused():
            host, port = sender.destination
            return packet, Verification(EXIT_NOT_SENT, "NOT_SENT", acks,
                                        f"nothing listens for telecommands at {host}:{port} (connection refused)")
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            break
        ready, _, _ = select.select([telemetry, sender.fileno()], [], [], min(remaining, 0.2))
        if telemetry not in ready:
            continue
        while True:
            try:
                raw = telemetry.recv(65536)
            except (BlockingIOError, InterruptedError):
                break
            ack = parse_ack(sender.dictionary, raw, downlink)
            if ack is None or ack.request_id != wanted:
                continue
            acks.append(ack)
            if ack.report == "ACCEPTANCE_FAILURE":
                return packet, Verification(EXIT_REJECTED, "REJECTED", acks, ack.code)
            if ack.report == "COMPLETION_FAILURE":
                return packet, Verification(EXIT_FAILED, "FAILED", acks, ack.code)
            if ack.report == "COMPLETION_SUCCESS":
                return packet, Verification(EXIT_COMPLETED, "COMPLETED", acks)
    accepted = any(a.report == "ACCEPTANCE_SUCCESS" for a in acks)
    detail = (f"accepted, but no completion report within {timeout_s:g} s" if accepted
              else f"no acknowledgement within {timeout_s:g} s")
    return packet, Verification(EXIT_NO_ACK, "NO_ACK", acks, detail)

