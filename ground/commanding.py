"""Ground commanding: encode telecommands with the flight dictionary and send them over UDP."""
from __future__ import annotations

import errno
import socket
from pathlib import Path
from typing import Any

from comms.dictionary import DEFAULT_HOST, DEFAULT_TC_PORT, DICTIONARY, TelemetryDictionary
from comms.link_security import SPI_TC, SecurityAssociation, SequenceFile, load_key_file
from comms.telemetry import SEQ_MODULO


def signing_sender_args(key_file: str | Path) -> dict[str, Any]:
    """``CommandSender`` keyword arguments that sign with the key in ``key_file``, drawing security SNs
    from the sequence file beside it (raises KeyFileError naming the file)."""
    return {"security": SecurityAssociation(load_key_file(key_file), SPI_TC),
            "sequence": SequenceFile.beside(key_file)}


class CommandSender:
    """Sends telecommands to the flight software, with its own TC sequence count.

    ``security``: the uplink association (``comms.link_security``) that signs every command; its security
    sequence numbers come from ``sequence`` (a ``SequenceFile`` shared by every sender of the key), else
    from the association itself. Without ``security`` commands go out plain (the flight software refuses
    them: unit tests of the flight side only).
    """

    def __init__(self, dictionary: TelemetryDictionary = DICTIONARY, host: str = DEFAULT_HOST,
                 port: int = DEFAULT_TC_PORT, seq_count: int = 0, *,
                 security: SecurityAssociation | None = None, sequence: SequenceFile | None = None) -> None:
        self.dictionary = dictionary
        self.security = security
        self.sequence = sequence
        self.destination = (host, port)
        self.seq_count = seq_count
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        # Connected, so that an ICMP "port unreachable" (nobody serves telecommands there) comes back to us
        # (``refused``) instead of vanishing: a UDP send itself succeeds whoever listens.
        try:
            self._sock.connect(self.destination)
        except OSError:
            self._sock.close()
            raise

    def send(self, command: str | int, *args: Any, check_range: bool = True, **kwargs: Any) -> bytes:
        """Encode and send; positional or keyword args (raises ``ArgError`` naming a bad arg)."""
        from comms.telecommand import encode_command

        if args and kwargs:
            raise TypeError("pass command args either positionally or by name, not both")
        packet = encode_command(self.dictionary, command, kwargs if kwargs else args, self.seq_count,
                                check_range=check_range)
        if self.security is not None:
            packet = self.security.protect(packet, self.sequence.advance() if self.sequence is not None else None)
        self._sock.send(packet)
        self.seq_count = (self.seq_count + 1) % SEQ_MODULO
        return packet

    def refused(self) -> bool:
        """True when the destination answered a telecommand with "port unreachable" (reading clears it)."""
        return self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) == errno.ECONNREFUSED

    def fileno(self) -> int:
        """The socket's descriptor: readable when an error (such as a refusal) is pending."""
        return self._sock.fileno()

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> "CommandSender":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
