"""Optional frame authentication on the bus, in the manner of AUTOSAR SecOC (off by default).

E2E (CRC-8 and alive counter) detects corruption and loss; it stops nothing on purpose, since anyone on
the bus computes a valid CRC. With ``bus_authentication: true`` in the mission every frame a sender puts on
the bus is followed by an authenticator frame of its own (``SECOC_<node>`` in the DBC, attribute
``SecOCAuthenticator``), in the manner of a SecOC secured PDU whose authentic PDU and cryptographic PDU
travel in separate frames: the ICD's classic 8-byte frames keep their layout and no CAN FD is needed. The
authenticator holds (little endian, 8 bytes):

    frame_id 11 bits | freshness_lsb 21 bits | mac 32 bits

``mac`` is HMAC-SHA256, truncated to its first 4 bytes, keyed with the sender's direction key over

    authenticator id u16 | freshness u64 | frame id u16 | length u8 | data

where ``freshness`` counts the frames the sender has authenticated (1, 2, ...). The receiver holds the last
few unverified frames of each of the peer's identifiers; an authenticator is checked against those of its
``frame_id`` under the smallest freshness above the last accepted one with the transmitted low 21 bits, and
the frame whose MAC matches is released. So a frame is accepted at most once and never after a later one
(an old frame replayed fails the MAC under the new freshness), frames injected between a genuine frame and
its authenticator do not void it, and whatever is not released is counted and dropped. A 32-bit MAC is
forged by chance once in 2^32 tries (AUTOSAR SecOC profiles for classic CAN truncate to 24..28 bits).

Keys: each direction has its own key, HMAC-SHA256(link key, "keepout bus SecOC " + sender node), from the
run's link key (``comms.link_security``): the SIL writes a fresh one for every run, so a recording of an
earlier run fails the MAC. A hand-started pair of processes that reuses one key file across runs can be
fed the start of an earlier run's recording (its freshness values are the same): docs/security.md.

The layer wraps any python-can bus (:class:`SecOCBus`) and keeps the transport's fast paths
(``send_batch``, ``recv_queued``), so the flight software's driver and the simulator use it unchanged.
"""
from __future__ import annotations

import hmac
import struct
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from typing import Any, Iterable, Sequence

import can

MAC_BYTES = 4
ID_BITS = 11
FRESHNESS_LSB_BITS = 21
_FRESHNESS_LSB_MASK = (1 << FRESHNESS_LSB_BITS) - 1
_ID_MASK = (1 << ID_BITS) - 1
_WORD = struct.Struct("<I")  # frame id and freshness_lsb; the MAC follows
_MAC_INPUT = struct.Struct("<HQHB")  # authenticator id, freshness, frame id, length
CANDIDATES = 4  # unverified frames held per identifier while their authenticators are awaited
KEY_LABEL = b"keepout bus SecOC "


class SecOCError(ValueError):
    """Bus authentication cannot be set up (the ICD lacks the authenticator frames)."""


def direction_key(link_key: bytes, sender: str) -> bytes:
    """The key of the frames ``sender`` (a DBC node: SIM or FSW) authenticates, from the run's link key."""
    return hmac.digest(link_key, KEY_LABEL + sender.encode(), "sha256")


def mac(key: bytes, auth_id: int, freshness: int, msg: can.Message) -> bytes:
    """The truncated MAC of frame ``msg`` under ``freshness`` (see the module docstring)."""
    data = bytes(msg.data)
    return hmac.digest(key, _MAC_INPUT.pack(auth_id, freshness, msg.arbitration_id, len(data)) + data,
                       "sha256")[:MAC_BYTES]


def authenticator(key: bytes, auth_id: int, freshness: int, msg: can.Message) -> can.Message:
    """The authenticator frame of ``msg``, the ``freshness``-th frame its sender authenticates."""
    word = (msg.arbitration_id & _ID_MASK) | ((freshness & _FRESHNESS_LSB_MASK) << ID_BITS)
    return can.Message(arbitration_id=auth_id, data=_WORD.pack(word) + mac(key, auth_id, freshness, msg),
                       is_extended_id=False)


def next_freshness(last: int, lsb: int) -> int:
    """The smallest freshness value above ``last`` whose low 21 bits are ``lsb``."""
    candidate = (last & ~_FRESHNESS_LSB_MASK) | lsb
    return candidate if candidate > last else candidate + (1 << FRESHNESS_LSB_BITS)


@dataclass
class SecOCCounters:
    """What the receiving side accepted and refused, by reason (housekeeping ``bus_auth_failures`` is the
    sum of the refusals)."""

    frames_accepted: int = 0
    bad_mac: int = 0            # authenticators that matched no held frame (forged, replayed, frame lost)
    unauthenticated: int = 0    # frames of the peer's identifiers dropped without a matching authenticator
    foreign: int = 0            # frames whose identifier the peer does not send (and not an authenticator)

    @property
    def failures(self) -> int:
        return self.bad_mac + self.unauthenticated + self.foreign

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


@dataclass(frozen=True)
class Association:
    """One end of the bus: its authenticator id and key, the peer's, and the frame ids the peer sends."""

    tx_auth_id: int
    tx_key: bytes
    rx_auth_id: int
    rx_key: bytes
    rx_ids: frozenset[int] = field(default_factory=frozenset)


def association(icd: Any, link_key: bytes, node: str) -> Association:
    """The association of ``node`` ("SIM": the simulator and its devices; "FSW": the flight software) from
    the ICD's authenticator frames and the run's link key."""
    peer = "FSW" if node == "SIM" else "SIM"
    auth = icd.authenticators
    if node not in auth or peer not in auth:
        raise SecOCError(f"{icd.path}: bus authentication needs SECOC authenticator frames for SIM and FSW "
                         f"(DBC attribute SecOCAuthenticator); found {sorted(auth)}")
    fsw_ids = icd.ids_sent_by("FSW")
    peer_ids = fsw_ids if peer == "FSW" else frozenset(i for i in icd.by_id if i not in fsw_ids)
    return Association(tx_auth_id=auth[node], tx_key=direction_key(link_key, node), rx_auth_id=auth[peer],
                       rx_key=direction_key(link_key, peer), rx_ids=frozenset(peer_ids))


class SecOCBus(can.BusABC):
    """``inner`` with every sent batch authenticated and only authenticated frames of the peer received."""

    def __init__(self, inner: can.BusABC, assoc: Association, **kwargs: object) -> None:
        self.inner = inner
        self.assoc = assoc
        self.counters = SecOCCounters()
        self._tx_freshness = 0
        self._rx_freshness = 0
        self._held: dict[int, deque[can.Message]] = {i: deque() for i in assoc.rx_ids}
        self._released: deque[can.Message] = deque()
        super().__init__(channel=getattr(inner, "channel_info", "secoc"), **kwargs)
        self.channel_info = f"SecOC over {getattr(inner, 'channel_info', inner)}"

    # ------------------------------------------------------------------------------------------ send
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.send_batch([msg], timeout) != 1:
            raise can.CanOperationError("the frame or its authenticator was not sent")

    def send_batch(self, msgs: Sequence[can.Message], timeout: float | None = None) -> int:
        """Send each of ``msgs`` followed by its authenticator; returns how many of ``msgs``, from the first,
        went out with their authenticators (the rest is unsent, as with ``transport.send_batch``)."""
        from comms.bus.transport import send_batch

        out = []
        for msg in msgs:
            self._tx_freshness += 1
            out += (msg, authenticator(self.assoc.tx_key, self.assoc.tx_auth_id, self._tx_freshness, msg))
        return send_batch(self.inner, out, timeout) // 2

    # --------------------------------------------------------------------------------------- receive
    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self._released:
            self._fill(timeout)
        return (self._released.popleft(), False) if self._released else (None, False)

    def recv_queued(self, timeout: float | None = 0.0, limit: int | None = None) -> list[can.Message]:  # noqa: ARG002
        """Every authenticated frame available now (waiting up to ``timeout`` for the first)."""
        if not self._released:
            self._fill(timeout)
        out = list(self._released)
        self._released.clear()
        return out

    def _fill(self, timeout: float | None) -> None:
        """Read the inner bus until an authenticated frame is released or ``timeout`` passes."""
        from comms.bus.transport import recv_burst

        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            burst = recv_burst(self.inner, remaining)
            if burst is not None:
                self.take(burst.messages())
            if self._released or (deadline is not None and time.monotonic() >= deadline):
                return

    def take(self, msgs: Iterable[can.Message]) -> None:
        """Judge received frames in order (authenticated frames go to the released queue)."""
        assoc, held = self.assoc, self._held
        for msg in msgs:
            fid = getattr(msg, "arbitration_id", None)
            if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
                self.counters.foreign += 1
            elif fid == assoc.rx_auth_id:
                self._verify(msg)
            elif fid in held:
                queue = held[fid]
                if len(queue) >= CANDIDATES:
                    queue.popleft()
                    self.counters.unauthenticated += 1
                queue.append(msg)
            elif fid != assoc.tx_auth_id:  # our own authenticator echoed back is not news
                self.counters.foreign += 1

    def _verify(self, auth: can.Message) -> None:
        data = bytes(auth.data)
        word = _WORD.unpack_from(data)[0] if len(data) == 8 else None
        queue = self._held.get(word & _ID_MASK) if word is not None else None
        if not queue:
            self.counters.bad_mac += 1
            return
        freshness = next_freshness(self._rx_freshness, word >> ID_BITS)
        tag = data[_WORD.size:]
        for i in range(len(queue) - 1, -1, -1):  # newest first: the genuine frame came just before
            if hmac.compare_digest(mac(self.assoc.rx_key, self.assoc.rx_auth_id, freshness, queue[i]), tag):
                msg = queue[i]
                del queue[i]
                self._rx_freshness = freshness
                self.counters.frames_accepted += 1
                self._released.append(msg)
                return
        self.counters.bad_mac += 1

    # ------------------------------------------------------------------------------------ delegation
    @property
    def auth_failures(self) -> int:
        """Frames and authenticators refused (housekeeping ``bus_auth_failures``)."""
        return self.counters.failures

    @property
    def decode_errors(self) -> int:
        return int(getattr(self.inner, "decode_errors", 0))

    def shutdown(self) -> None:
        super().shutdown()
        self.inner.shutdown()


def secure(bus: can.BusABC, icd: Any, link_key: bytes, node: str) -> SecOCBus:
    """``bus`` with SecOC for ``node`` (see :func:`association`)."""
    return SecOCBus(bus, association(icd, link_key, node))
