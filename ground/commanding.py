"""Ground commanding: encode telecommands with the flight dictionary and send them over UDP."""
from __future__ import annotations

import socket
from typing import Any

from fsw.dictionary import DEFAULT_HOST, DEFAULT_TC_PORT, DICTIONARY, TelemetryDictionary
from fsw.telemetry import SEQ_MODULO


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
