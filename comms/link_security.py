"""Link security in the manner of CCSDS SDLS (355.0-B-2): authentication and anti-replay for TC and TM.

SDLS protects the data field of a transfer frame with a security header (Security Parameter Index and
sequence number) in front and a security trailer (the MAC) behind it, and leaves the frame's error
control outside, computed last. keepout has no transfer frames (one space packet per UDP datagram), so
the same layout is applied to each space packet:

    primary header | SPI u16 | SN u32 | data field of the plain packet | MAC (16 bytes) | CRC-16

The primary header's length field covers the whole secured packet. The MAC is HMAC-SHA256 truncated to
16 bytes (SDLS allows a truncated MAC; 128 bits is its baseline length for authentication) over
everything before it: primary header, security header and data field, so neither the APID, the packet
type, the sequence number nor a byte of the command can be changed. Each direction is its own security
association with its own key, derived from the mission key (HMAC(key, label)): a TM packet can never be
taken for a TC, and the two SN spaces are independent.

Receivers check, in this order (cheapest first, so a flood of junk costs little): length and CRC (a
corrupt or junk datagram: a format error, not a security event), security header present with the
expected SPI (else "unauthenticated"), MAC ("bad_mac"), then the sequence number: it must be greater
than the last accepted one ("replay") and at most ``window`` ahead of it ("outside_window"), unless the
packet is the resynchronisation telecommand, which may move the window forward by any amount (never
back: going back would reopen every SN in between to replay). Only then is the plain packet (header
length corrected, CRC recomputed) handed to the ordinary decoder.

The key lives in a file named by the mission (``flight_software.tmtc.security.key_file``), never in the
YAML: 32 random bytes written as hex, readable by its owner only (``write_key_file``; a key file readable
by group or others is refused, as ssh refuses such a private key). The ground keeps its TC sequence
number in ``<key file>.tcsn`` (``SequenceFile``), locked while it is read and advanced, so every sender
of a run (the SIL's timeline, ``keepout ground send``) draws from one increasing sequence.
"""
from __future__ import annotations

import fcntl
import hashlib
import hmac
import os
import secrets
import stat
import struct
from dataclasses import dataclass, field
from pathlib import Path

from fastcrc import crc16  # CRC-16/CCITT-FALSE, as fsw.telemetry.crc16_ccitt (no import cycle this way)

SPI_TC = 0x5C01  # security parameter index of the uplink association
SPI_TM = 0x5C02  # ... and of the downlink association
SECURITY_HEADER = struct.Struct("!HI")  # SPI, sequence number
MAC_LEN = 16
CRC_LEN = 2
PRIMARY_HEADER_LEN = 6
OVERHEAD = SECURITY_HEADER.size + MAC_LEN  # bytes a secured packet is longer than the plain one
MIN_SECURED_LEN = PRIMARY_HEADER_LEN + OVERHEAD + CRC_LEN
MAX_SN = 2**32 - 1  # an association must be rekeyed before its SN runs out (SDLS: the SN never wraps)
KEY_BYTES = 32
DEFAULT_TC_WINDOW = 1024
SN_FILE_SUFFIX = ".tcsn"
LINK_KEY_FILE = "link.key"  # the SIL's per-run key, in the run folder

# Reasons a receiver gives (and counts); the format class is not a security event.
FORMAT = "format"
UNAUTHENTICATED = "unauthenticated"
BAD_MAC = "bad_mac"
REPLAY = "replay"
OUTSIDE_WINDOW = "outside_window"
REASONS = (UNAUTHENTICATED, BAD_MAC, REPLAY, OUTSIDE_WINDOW)

_LABELS = {SPI_TC: b"keepout SDLS TC", SPI_TM: b"keepout SDLS TM"}


class KeyFileError(ValueError):
    """The key file is missing, unreadable, malformed or readable by others (one-line message)."""


class SecurityError(ValueError):
    """A secured packet was refused; ``reason`` is one of FORMAT or REASONS."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


# ------------------------------------------------------------------------------------------ keys
def write_key_file(path: str | Path) -> bytes:
    """Create ``path`` with a new random key (hex), mode 0600 from the start; refuses to overwrite."""
    key = secrets.token_bytes(KEY_BYTES)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(key.hex() + "\n")
    return key


def load_key_file(path: str | Path) -> bytes:
    """Read a key file written by ``write_key_file``; raises KeyFileError naming the file and the fault."""
    p = Path(path)
    try:
        info = p.stat()
    except OSError as exc:
        raise KeyFileError(f"{p}: cannot read the link key: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise KeyFileError(f"{p}: the link key must be a regular file")
    if info.st_mode & 0o077:
        raise KeyFileError(f"{p}: the link key is readable by others (mode {stat.S_IMODE(info.st_mode):04o}); "
                           f"chmod 600 it")
    if info.st_size > 1024:
        raise KeyFileError(f"{p}: {info.st_size} bytes is not a key file (expected {2 * KEY_BYTES} hex digits)")
    try:
        text = p.read_text().strip()
        key = bytes.fromhex(text)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise KeyFileError(f"{p}: not a key file (expected {2 * KEY_BYTES} hex digits): {exc}") from None
    if len(key) < 16:
        raise KeyFileError(f"{p}: key of {len(key)} bytes is too short (at least 16, {KEY_BYTES} written by keygen)")
    return key


def mission_key_path(named: str | None, config_path: str | Path) -> Path | None:
    """The key file a mission names (``flight_software.tmtc.security.key_file``), relative to the
    mission file's folder; None when it names none."""
    if named is None:
        return None
    return Path(config_path).resolve().parent / named


def _subkey(key: bytes, spi: int) -> bytes:
    return hmac.new(key, _LABELS[spi], hashlib.sha256).digest()


def _crc(data: bytes | bytearray) -> int:
    return crc16.ibm_3740(bytes(data))


# ------------------------------------------------------------------------------------- association
@dataclass
class SecurityAssociation:
    """One direction of the link: protects packets (sender) or verifies them (receiver).

    ``window``: how far ahead of the last accepted SN a packet may be (receiver). ``resync_opcode``: the
    opcode (u16 after the security header) of the telecommand allowed to move the window forward by any
    amount (uplink receiver only; None elsewhere). ``counters`` counts refusals by reason and ``accepted``;
    nothing resets them (RESET_COUNTERS must not erase the evidence of an attack).
    """

    key: bytes = field(repr=False)  # never printed (logs, tracebacks)
    spi: int
    window: int = DEFAULT_TC_WINDOW
    resync_opcode: int | None = None
    last_sn: int = 0
    next_sn: int = 1
    resyncs: int = 0
    counters: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REASONS + ("accepted",), 0))

    def __post_init__(self) -> None:
        self._mac_key = _subkey(self.key, self.spi)

    def _mac(self, data: bytes | bytearray) -> bytes:
        return hmac.new(self._mac_key, data, hashlib.sha256).digest()[:MAC_LEN]

    # ---- sending ----
    def protect(self, plain: bytes, sn: int | None = None) -> bytes:
        """The secured form of the plain space packet ``plain`` (header ... CRC-16), with ``sn`` (default:
        this association's next SN, then advanced)."""
        if sn is None:
            sn = self.next_sn
            self.next_sn += 1
        if not 0 < sn <= MAX_SN:
            raise ValueError(f"security sequence number {sn} outside 1..{MAX_SN}: the key must be renewed")
        header = bytearray(plain[:PRIMARY_HEADER_LEN])
        length = int.from_bytes(header[4:6], "big") + OVERHEAD
        header[4:6] = length.to_bytes(2, "big")
        body = header + SECURITY_HEADER.pack(self.spi, sn) + plain[PRIMARY_HEADER_LEN:-CRC_LEN]
        body += self._mac(body)
        return bytes(body) + _crc(body).to_bytes(2, "big")

    # ---- receiving ----
    def unprotect(self, raw: bytes) -> tuple[bytes, int]:
        """Verify a secured packet and return (plain packet, SN); raises SecurityError (see the module
        docstring for the order of the checks). An accepted SN becomes the new reference."""
        raw = bytes(raw)
        n = len(raw)
        if n < PRIMARY_HEADER_LEN + CRC_LEN:
            raise SecurityError(FORMAT, f"datagram of {n} bytes shorter than a space packet")
        if int.from_bytes(raw[4:6], "big") + PRIMARY_HEADER_LEN + 1 != n or _crc(raw) != 0:
            raise SecurityError(FORMAT, "length field or CRC wrong: corrupt or not a space packet")
        if n < MIN_SECURED_LEN:
            return self._refuse(UNAUTHENTICATED, f"packet of {n} bytes has no security header and MAC")
        spi, sn = SECURITY_HEADER.unpack_from(raw, PRIMARY_HEADER_LEN)
        if spi != self.spi:
            return self._refuse(UNAUTHENTICATED, f"security parameter index {spi:#06x}, expected {self.spi:#06x}")
        mac_at = n - CRC_LEN - MAC_LEN
        if not hmac.compare_digest(self._mac(raw[:mac_at]), raw[mac_at:n - CRC_LEN]):
            return self._refuse(BAD_MAC, "MAC does not verify: forged, or signed with another key")
        data = raw[PRIMARY_HEADER_LEN + SECURITY_HEADER.size:mac_at]
        if sn <= self.last_sn:
            return self._refuse(REPLAY, f"security SN {sn} not above the last accepted {self.last_sn}: replay")
        if sn > self.last_sn + self.window:
            if self.resync_opcode is None or data[:2] != self.resync_opcode.to_bytes(2, "big"):
                return self._refuse(OUTSIDE_WINDOW, f"security SN {sn} more than {self.window} above the last "
                                                    f"accepted {self.last_sn}: resynchronise (SEC_RESYNC)")
            self.resyncs += 1
        self.last_sn = sn
        self.counters["accepted"] += 1
        header = bytearray(raw[:PRIMARY_HEADER_LEN])
        header[4:6] = (int.from_bytes(header[4:6], "big") - OVERHEAD).to_bytes(2, "big")
        body = bytes(header) + data
        return body + _crc(body).to_bytes(2, "big"), sn

    def _refuse(self, reason: str, message: str):
        self.counters[reason] += 1
        raise SecurityError(reason, message)


def uplink_receiver(key: bytes, window: int = DEFAULT_TC_WINDOW, resync_opcode: int | None = None
                    ) -> SecurityAssociation:
    """The flight software's end of the uplink association."""
    return SecurityAssociation(key, SPI_TC, window=window, resync_opcode=resync_opcode)


def downlink_receiver(key: bytes) -> SecurityAssociation:
    """The ground's end of the downlink: every TM packet's SN must increase (any jump forward is a loss,
    which the per-APID counts report; only a repeat or a step back is refused)."""
    return SecurityAssociation(key, SPI_TM, window=MAX_SN)


# ------------------------------------------------------------------------------------- ground SN
class SequenceFile:
    """The ground's uplink SN, kept in a file and advanced under an exclusive lock, so that every
    process sending with one key (the SIL timeline, ``keepout ground send``) uses increasing SNs."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    @classmethod
    def beside(cls, key_file: str | Path) -> "SequenceFile":
        return cls(str(key_file) + SN_FILE_SUFFIX)

    def advance(self, at_least: int = 0) -> int:
        """Reserve and return the next SN (above ``at_least``, e.g. the flight's ``tc_sec_last_sn``)."""
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.lockf(fd, fcntl.LOCK_EX)
            text = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
            last = int(text) if text.isdigit() else 0
            sn = max(last, at_least) + 1
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{sn}\n".encode(), 0)
            return sn
        finally:
            os.close(fd)

    def peek(self) -> int:
        try:
            text = self.path.read_text().strip()
        except OSError:
            return 0
        return int(text) if text.isdigit() else 0
