"""python-can's udp_multicast interface confined to this host: the bus of one run, nobody else's.

python-can's ``UdpMulticastBus`` binds its socket to every interface (``("", port)``), joins the group
on the default interface (INADDR_ANY) and sends with TTL 1, so a process on the LAN can hear and inject
frames. :class:`LoopbackUdpMulticastBus` is the same bus (same wire format, same receive path, so
cantools and ``can.Bus(interface="udp_multicast")`` on the same group still interoperate on this host)
with its socket configured for loopback only:

* ``IP_MULTICAST_IF`` 127.0.0.1 and ``IP_MULTICAST_TTL`` 0: frames are sent on ``lo`` and never leave
  the host (TTL 0 keeps even a misrouted datagram on the host);
* ``IP_ADD_MEMBERSHIP`` on 127.0.0.1: the group is joined on ``lo`` only, so a datagram for the group
  arriving on another interface is not accepted;
* the socket binds the group address, not 0.0.0.0 (unicast datagrams to the port are not received),
  and ``IP_MULTICAST_ALL`` 0 (Linux) keeps other groups joined by other sockets out.

Only IPv4 groups are supported (``lo`` has no IPv6 multicast route by default).

Cost per frame (a lockstep SIL moves ~23 frames a tick between two processes; python-can's path costs
~15 us a frame on this host, of which ~6 us are the kernel's):

* frames are sent from a second socket bound to an ephemeral port of 127.0.0.1, and the bus socket drops
  datagrams from that port in the kernel (a socket filter): the bus no longer reads back every frame it
  sent (one socket sending and receiving on a looped-back group hears itself; python-can documents
  ``receive_own_messages`` as unsupported, and SocketCAN with it off does not echo either);
* ``recv`` reads everything queued in one go (non-blocking ``recvmsg`` until the socket is empty, a
  ``poll`` only to wait) instead of a ``select`` per frame, and decodes a plain classic data frame
  slot by slot: the same ``can.Message`` state as python-can's ``unpack_message(..., check=True)``,
  which every other datagram still goes through;
* ``send``/``send_batch`` pack with one reused ``msgpack.Packer`` (the bytes of python-can's
  ``pack_message``).
"""
from __future__ import annotations

import ctypes
import math
import select
import socket
import struct
import time
from collections import deque
from typing import Any, Sequence

import can
import msgpack
from can import CanProtocol
from can.interfaces.udp_multicast.bus import GeneralPurposeUdpMulticastBus, UdpMulticastBus
from can.interfaces.udp_multicast.utils import is_msgpack_installed, unpack_message

from comms.bus.mmsg import IoVec as _IoVec, MMsgHdr as _MMsgHdr, libc, take_queued

LOOPBACK = "127.0.0.1"
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)
SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
MAX_DATAGRAM = 4096  # python-can's max_buffer
READS_PER_FILL = 1024  # datagrams read in one go at most (see _read_all)
_TIMESPEC = struct.Struct("@ll")  # python-can's received_timestamp_struct
_ANCILLARY = socket.CMSG_SPACE(_TIMESPEC.size)
# the keys of python-can's pack_message, in its order
_KEYS = ("timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame", "channel", "dlc",
         "data", "is_fd", "bitrate_switch", "error_state_indicator")
_KEY_SET = frozenset(_KEYS)
_unpackb = msgpack.unpackb
_new_message = can.Message.__new__
_Message = can.Message


def _well_typed(msg: can.Message) -> bool:
    """The fields of a message python-can unpacked have the types a frame's have (its ``check`` only
    compares values, and NaN compares false: a NaN identifier passed it and crashed the simulator)."""
    return (type(msg.arbitration_id) is int and type(msg.dlc) is int and isinstance(msg.data, bytearray)
            and (msg.dlc == len(msg.data) or msg.is_remote_frame is True and not msg.data)
            and all(type(f) is bool for f in (msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame,
                                              msg.is_fd, msg.bitrate_switch, msg.error_state_indicator))
            and (msg.channel is None or type(msg.channel) in (str, int)))


def _stamp_of(ancillary: list) -> float | None:
    """The SO_TIMESTAMPNS stamp of one received datagram, or None when its control data is not the one
    stamp asked for (python-can raises there; a bus that any local process can send to drops it)."""
    if len(ancillary) != 1:
        return None
    level, kind, cmsg = ancillary[0]
    if level != socket.SOL_SOCKET or kind != SO_TIMESTAMPNS or len(cmsg) != _TIMESPEC.size:
        return None
    seconds, nanoseconds = _TIMESPEC.unpack(cmsg)
    if nanoseconds >= 1_000_000_000:
        return None
    return seconds + nanoseconds * 1.0e-9


class _SockFilter(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint16), ("jt", ctypes.c_uint8), ("jf", ctypes.c_uint8), ("k", ctypes.c_uint32)]


class _SockFprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.POINTER(_SockFilter))]


def _drop_source_port(sock: socket.socket, port: int) -> None:
    """Attach a classic BPF filter to UDP socket ``sock``: datagrams whose UDP source port is ``port`` are
    dropped in the kernel. (A UDP socket's filter sees the packet from the UDP header on: the source port
    is the half-word at offset 0.)"""
    program = (_SockFilter * 4)(
        _SockFilter(0x28, 0, 0, 0),            # ldh [0]           A = source port
        _SockFilter(0x15, 0, 1, port),          # jeq #port, 0, 1
        _SockFilter(0x06, 0, 0, 0),             # ret #0            drop
        _SockFilter(0x06, 0, 0, 0xFFFFFFFF),    # ret #-1           keep the whole datagram
    )
    fprog = _SockFprog(len(program), ctypes.cast(program, ctypes.POINTER(_SockFilter)))
    sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, bytes(fprog))  # the kernel copies the program now


BATCH = 64  # datagrams per sendmmsg (a lockstep tick has ~20)
_MSG_DONTWAIT = int(socket.MSG_DONTWAIT)
_libc = libc


class _TxSlots:
    """BATCH iovecs and mmsghdrs (no address: the sender socket is connected to the group)."""

    def __init__(self) -> None:
        self.iov = (_IoVec * BATCH)()
        self.hdr = (_MMsgHdr * BATCH)()
        for i in range(BATCH):
            h = self.hdr[i].msg_hdr
            h.msg_iov = ctypes.pointer(self.iov[i])
            h.msg_iovlen = 1


def _sendmmsg(fd: int, slots: _TxSlots | None, datagrams: list[bytes]) -> int:
    """Queue ``datagrams`` (at most BATCH) in one sendmmsg(); returns how many, from the first, were sent
    (0 when the socket has no room now, or without sendmmsg: the caller sends the rest one by one)."""
    if _libc is None or slots is None:
        return 0
    iov = slots.iov
    for i, data in enumerate(datagrams):  # the bytes objects stay alive (the list) during the call
        iov[i].iov_base = ctypes.cast(ctypes.c_char_p(data), ctypes.c_void_p).value
        iov[i].iov_len = len(data)
    return max(0, _libc.sendmmsg(fd, slots.hdr, len(datagrams), _MSG_DONTWAIT))


def _sender_socket(group_port: int) -> socket.socket:
    """The socket frames are sent from: multicast on lo only (as the bus socket), bound to an ephemeral
    port of 127.0.0.1 that is not the group's port (the bus socket drops datagrams from this port; a
    python-can bus on the group sends from the group's port, which must stay heard)."""
    for _ in range(8):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 0))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(LOOPBACK))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            sock.bind((LOOPBACK, 0))
        except OSError:
            sock.close()
            raise
        if sock.getsockname()[1] != group_port:
            return sock
        sock.close()
    raise OSError(f"no ephemeral port other than {group_port} for the sender socket")


class _LoopbackMulticastSocket(GeneralPurposeUdpMulticastBus):
    """python-can's socket handler with the socket made by ``_create_socket`` below (the only change)."""

    def _create_socket(self, address_family: socket.AddressFamily) -> socket.socket:
        if address_family != socket.AF_INET:
            raise OSError(f"group {self.group}: the loopback bus supports IPv4 multicast groups only")
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 0))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(LOOPBACK))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            try:
                sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
            except OSError:
                pass  # not Linux: binding the group address already filters other groups
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            try:
                sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
                self.timestamp_nanosecond = True
            except OSError:
                self.timestamp_nanosecond = False
            sock.bind((self.group, self.port))
            membership = socket.inet_aton(self.group) + socket.inet_aton(LOOPBACK)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
            return sock
        except OSError:
            sock.close()
            raise


class LoopbackUdpMulticastBus(UdpMulticastBus):
    """``UdpMulticastBus`` on the loopback interface only (see the module docstring). ``fd``: CAN FD
    frames allowed (False: classic frames only, as on the spacecraft bus)."""

    def __init__(self, channel: str, port: int, fd: bool = False, **kwargs: Any) -> None:
        is_msgpack_installed()
        # UdpMulticastBus.__init__ would open python-can's own socket (bound to every interface) first:
        # set up the same attributes around the loopback socket instead.
        can.BusABC.__init__(self, channel, **kwargs)
        # (python-can's handler turns a socket that cannot be set up into CanInitializationError)
        self._multicast = _LoopbackMulticastSocket(channel, port, hop_limit=0)
        self._can_protocol = CanProtocol.CAN_FD if fd else CanProtocol.CAN_20
        self._fd_frames = bool(fd)
        rx = self._multicast._socket
        try:
            self._tx = _sender_socket(port)
            _drop_source_port(rx, self._tx.getsockname()[1])
        except OSError as exc:
            self._multicast.shutdown()
            raise can.CanInitializationError(f"udp_multicast {channel}:{port}: cannot set up the sender: {exc}") \
                from exc
        self._tx.connect((channel, port))  # send() and sendmmsg() without an address per datagram
        self._tx.setblocking(False)
        self._tx_poller = select.poll()
        self._tx_poller.register(self._tx.fileno(), select.POLLOUT)
        self._tx_slots = _TxSlots() if _libc is not None else None
        self._packer = msgpack.Packer(use_bin_type=True)
        self._stamped = bool(self._multicast.timestamp_nanosecond)
        rx.setblocking(False)  # recv reads until the socket is empty; waiting is a poll
        self._rx_sock = rx
        self._poller = select.poll()
        self._poller.register(rx.fileno(), select.POLLIN)
        self._rx: deque[can.Message] = deque()
        self._was_empty = False  # the last read found the socket empty
        # datagrams on the bus's group and port that are not a frame this bus packs (any local process can
        # send to the group): dropped and counted here, never raised into the cycle that reads the bus
        self.decode_errors = 0

    # ------------------------------------------------------------------------------------- receive
    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self._filters is not None:
            return super().recv(timeout)  # software filters: BusABC's loop over _recv_internal
        if self._rx or self._fill(timeout):
            return self._rx.popleft()
        return None

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._rx or self._fill(timeout):
            return self._rx.popleft(), False
        return None, False

    def recv_queued(self, timeout: float | None = 0.0, limit: int | None = None) -> list[can.Message] | None:
        """Every frame queued now (waiting up to ``timeout`` for the first), at most ``limit``; [] when
        nothing came: what ``recv`` would return call after call, in one call. None when software filters
        are set (then only ``recv`` reads)."""
        if self._filters is not None:
            return None
        return take_queued(self._rx, self._fill, timeout, limit)

    def _fill(self, timeout: float | None) -> bool:
        """Queue every datagram the socket holds; if none, wait up to ``timeout`` (None: for ever) for one."""
        waiting = timeout is None or timeout > 0.0
        # After an empty read (a recv(0) just before, typically) a waiting call polls first: poll() reports
        # what arrived since, and the read that would fail again is saved.
        if not (waiting and self._was_empty) and self._read_all():
            return True
        if not waiting:
            return False
        # the clock is read only when a wake-up brought nothing to read (rare): not once or twice a wait
        remaining, deadline = timeout, None
        while True:
            ms = -1 if remaining is None else max(0, math.ceil(remaining * 1000.0))
            if not self._poller.poll(ms):  # (interrupted: Python retries with the time left)
                return False
            if self._read_all():
                return True
            if remaining is not None:
                deadline = deadline if deadline is not None else time.monotonic() + remaining
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return False

    def _read_all(self) -> int:
        sock, rx, stamped = self._rx_sock, self._rx, self._stamped
        n = 0
        # at most READS_PER_FILL datagrams a call (more than the socket's buffer holds): a stream of junk
        # arriving as fast as it is read cannot keep the reader here for ever; the caller's timeout holds
        for _ in range(READS_PER_FILL):
            try:
                if stamped:
                    data, ancillary, _flags, _addr = sock.recvmsg(MAX_DATAGRAM, _ANCILLARY)
                else:
                    data = sock.recv(MAX_DATAGRAM)
                    ancillary = ()
            except (BlockingIOError, InterruptedError):
                self._was_empty = n == 0
                return n
            except OSError as exc:
                raise can.CanOperationError(f"Failed to receive via IP/UDP socket: {exc}") from exc
            if stamped:  # python-can's checks of the time stamp; a datagram that fails them is dropped
                stamp = _stamp_of(ancillary)
                if stamp is None:
                    self.decode_errors += 1
                    continue
            else:
                stamp = time.time()  # (python-can reads SIOCGSTAMP here; every Linux socket is stamped)
            msg = self._decode(data, stamp)
            if msg is not None:
                rx.append(msg)
                n += 1
        self._was_empty = False
        return n

    def _decode(self, data: bytes, stamp: float) -> can.Message | None:
        """``unpack_message(data, replace={"timestamp": stamp}, check=True)`` and python-can's CAN FD
        check; a plain classic data frame slot by slot (the same state as Message(**fields))."""
        try:
            fields = _unpackb(data, raw=False)
            payload = fields["data"]
            frame_id = fields["arbitration_id"]
            dlc = fields["dlc"]
            plain = (type(fields) is dict and fields.keys() == _KEY_SET and type(payload) is bytes
                     and type(frame_id) is int and 0 <= frame_id < 0x800 and type(dlc) is int
                     and dlc == len(payload) <= 8 and fields["is_extended_id"] is False
                     and fields["is_remote_frame"] is False and fields["is_error_frame"] is False
                     and fields["is_fd"] is False and fields["bitrate_switch"] is False
                     and fields["error_state_indicator"] is False and 0.0 <= stamp < math.inf)
        except Exception:  # noqa: BLE001 - not what pack_message makes: python-can's path says what
            plain = False
        if not plain:
            try:
                msg = unpack_message(data, replace={"timestamp": stamp}, check=True)
            except Exception:  # noqa: BLE001 - whatever a stranger's datagram makes msgpack or Message raise
                self.decode_errors += 1
                return None
            if not _well_typed(msg):
                self.decode_errors += 1
                return None
            if not self._fd_frames and msg.is_fd:  # a CAN FD frame on a classic bus: not one of ours
                self.decode_errors += 1
                return None
            return msg
        msg = _new_message(_Message)
        msg.timestamp = stamp
        msg.arbitration_id = frame_id
        msg.is_extended_id = False
        msg.is_remote_frame = False
        msg.is_error_frame = False
        msg.channel = fields["channel"]
        msg.is_fd = False
        msg.is_rx = True
        msg.bitrate_switch = False
        msg.error_state_indicator = False
        msg.data = bytearray(payload)
        msg.dlc = dlc
        return msg

    # ---------------------------------------------------------------------------------------- send
    def _pack(self, msg: can.Message) -> bytes:
        """python-can's ``pack_message(msg)`` (same dict, same order), with a reused packer."""
        if not self._fd_frames and msg.is_fd:
            raise can.CanOperationError("cannot send FD message over bus with CAN FD disabled")
        return self._packer.pack({
            "timestamp": msg.timestamp, "arbitration_id": msg.arbitration_id, "is_extended_id": msg.is_extended_id,
            "is_remote_frame": msg.is_remote_frame, "is_error_frame": msg.is_error_frame, "channel": msg.channel,
            "dlc": msg.dlc, "data": msg.data, "is_fd": msg.is_fd, "bitrate_switch": msg.bitrate_switch,
            "error_state_indicator": msg.error_state_indicator})

    def _send_one(self, data: bytes, timeout: float | None) -> None:
        """Send one datagram: at once when the socket has room (no wait for writability first: that is a
        poll per frame), else waiting up to ``timeout`` (None: for ever) for room."""
        tx = self._tx
        deadline = None
        while True:
            try:
                if tx.send(data) < len(data):
                    raise can.CanTimeoutError()
                return
            except (BlockingIOError, InterruptedError):
                pass
            except OSError as error:
                raise can.CanOperationError("failed to send via socket") from error
            if timeout is not None:
                deadline = deadline if deadline is not None else time.monotonic() + timeout
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    raise can.CanTimeoutError()
            ms = -1 if timeout is None else max(0, math.ceil(remaining * 1000.0))
            self._tx_poller.poll(ms)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._send_one(self._pack(msg), timeout)

    def send_batch(self, msgs: Sequence[can.Message], timeout: float | None = None) -> int:
        """Send ``msgs`` in order, one sendmmsg() per BATCH frames (the receiver wakes with the burst
        queued, not once per frame); returns how many, from the first, were sent (fewer when one was
        refused: queue still full after ``timeout``, or a frame that cannot be packed)."""
        sent = 0
        while sent < len(msgs):
            chunk = msgs[sent:sent + BATCH]
            try:
                datagrams = [self._pack(m) for m in chunk]
            except can.CanError:
                datagrams = []
            n = _sendmmsg(self._tx.fileno(), self._tx_slots, datagrams) if datagrams else 0
            sent += n
            if n < len(chunk):  # queue full (or a frame refused): one by one, waiting for room
                try:
                    self._send_one(self._pack(chunk[n]), timeout)
                except can.CanError:
                    return sent
                sent += 1
        return sent

    def shutdown(self) -> None:
        try:
            self._tx.close()
        finally:
            super().shutdown()
