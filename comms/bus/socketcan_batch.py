"""SocketCAN with few system calls per frame: python-can's ``SocketcanBus`` with batched reads and writes.

Why: in the vcan-vm guest (User-Mode Linux on ptrace) a system call costs ~15 us against <1 us natively,
and python-can spends 4-5 of them per frame (send: time() + select() with its clock read + send; recv:
time() + select() with its clock read + recvmsg + ioctl(SIOCGIFNAME), as CPython resolves the interface
name of every AF_CAN address). A lockstep tick moves ~23 frames between two processes, and each frame sent
singly can wake the receiver (a context switch each way on the guest's one CPU).

``BatchSocketcanBus`` keeps python-can's socket set-up (loopback, own messages, error frames, kernel
filters, nanosecond timestamps) and changes only how frames cross the socket:

* ``send``: one non-blocking send(); python-can's wait for room is used only when the queue is full;
* ``send_batch(msgs)``: one sendmmsg() for a burst (a lockstep tick's frames): the receiver wakes once
  with all of them queued;
* ``recv``: frames come from a local queue that one recvmmsg() fills with everything the socket holds;
  waiting is one poll(). Timestamps are the kernel's (SO_TIMESTAMPNS), as with python-can;
* ``watch(ids)`` + ``wait_for(timeout)``: block until a frame whose id is in ``ids`` has arrived; other
  frames queue without waking the process (a second socket with a kernel filter on ``ids`` is the
  doorbell; it consumes nothing from the bus's own queue). The doorbell is waited on edge-triggered
  (epoll): a wait is one system call, and its queue is emptied only every ``DRAIN_EVERY`` rings;
* a waiting read reads first (the frames are usually there: the simulator's read after the doorbell rang,
  the flight software's wait for the next SYNC when the simulator ran in between); after a waiting read
  found the socket empty, the next ``POLL_FIRST_WAITS`` waiting reads poll first (the wait that finds
  nothing queued, tick after tick, costs two system calls instead of three).

Frames, their order and content are exactly what python-can delivers.
"""
from __future__ import annotations

import ctypes
import errno
import math
import select
import socket
import struct
import time
from collections import deque
from typing import Iterable, Sequence

import can
from can.interfaces.socketcan import constants
from can.interfaces.socketcan.socketcan import SocketcanBus, build_can_frame, pack_filters

from comms.bus.mmsg import IoVec as _IoVec, MMsgHdr as _MMsgHdr, PollFd as _PollFd, libc, take_queued

BATCH = 64  # frames per recvmmsg/sendmmsg call (a lockstep tick has ~20)
# The doorbell's queue is emptied every this many rings (a ring is one frame queued there): edge-triggered
# waiting needs no read per ring, but a full queue would drop frames without a wake-up. DOORBELL_RCVBUF
# holds far more (a classic CAN frame takes well under 2 KiB of it).
DRAIN_EVERY = 32
POLL_FIRST_WAITS = 16
DOORBELL_RCVBUF = 1 << 20
_FRAME = struct.Struct("=IB3x8s")  # struct can_frame (classic CAN, CAN_MTU = 16 bytes)
_CMSG_SPACE = 32  # CMSG_SPACE(sizeof(struct timespec)) on 64-bit Linux
_TIMESPEC = struct.Struct("=qq")
_POLLIN = 0x001
_EFF, _RTR, _ERR = constants.CAN_EFF_FLAG, constants.CAN_RTR_FLAG, constants.CAN_ERR_FLAG
_SFF_MASK, _EFF_MASK = 0x7FF, 0x1FFFFFFF

_MSG_DONTWAIT, _MSG_DONTROUTE = int(socket.MSG_DONTWAIT), int(socket.MSG_DONTROUTE)  # plain ints: IntFlag & is slow
_HEADER = struct.Struct("=IBB1xB")  # python-can's CAN_FRAME_HEADER_STRUCT
_Message = can.Message
_new_message = can.Message.__new__


_libc = libc


def classic_frame(msg: can.Message) -> bytes:
    """``build_can_frame(msg)`` for a classic frame, without its per-frame debug logging and DLC search
    (a test checks both give the same bytes); other frames go to python-can's builder."""
    data = bytes(msg.data)
    length = msg.dlc if msg.is_remote_frame else len(data)
    if msg.is_fd or msg.bitrate_switch or msg.error_state_indicator or length > 8:
        return build_can_frame(msg)
    can_id = msg.arbitration_id
    if msg.is_extended_id:
        can_id |= _EFF
    if msg.is_remote_frame:
        can_id |= _RTR
    if msg.is_error_frame:
        can_id |= _ERR
    return _HEADER.pack(can_id, length, 0, msg.dlc) + data.ljust(8, b"\x00")


class _Slots:
    """BATCH frame buffers (16 bytes each) with their iovecs and mmsghdrs, plus control buffers for the
    receive timestamps."""

    def __init__(self, with_control: bool) -> None:
        self.data = ctypes.create_string_buffer(16 * BATCH)
        self.view = memoryview(self.data).cast("B")
        self.control = ctypes.create_string_buffer(_CMSG_SPACE * BATCH) if with_control else None
        self.iov = (_IoVec * BATCH)()
        self.hdr = (_MMsgHdr * BATCH)()
        base = ctypes.addressof(self.data)
        for i in range(BATCH):
            self.iov[i].iov_base = base + 16 * i
            self.iov[i].iov_len = 16
            h = self.hdr[i].msg_hdr
            h.msg_iov = ctypes.pointer(self.iov[i])
            h.msg_iovlen = 1
            if self.control is not None:
                h.msg_control = ctypes.addressof(self.control) + _CMSG_SPACE * i
        self.used = BATCH  # headers whose msg_controllen the kernel may have changed

    def reset_control(self) -> None:
        if self.control is not None:
            for i in range(self.used):
                self.hdr[i].msg_hdr.msg_controllen = _CMSG_SPACE


def _poll(fd: int, timeout: float | None) -> bool:
    """poll() one fd for input; True when readable. EINTR is retried with the time left (PEP 475 style:
    Python signal handlers run between the attempts)."""
    pfd = _PollFd(fd, _POLLIN, 0)
    return _wait(lambda ms: _libc.poll(ctypes.byref(pfd), 1, ms), timeout, "poll")


def _wait(call, timeout: float | None, name: str) -> bool:
    """``call(ms)`` (poll/epoll_wait: a count, or -1 with errno) until it is not interrupted; True when it
    reported something. EINTR is retried with the time left (PEP 475 style: Python signal handlers run
    between the attempts)."""
    deadline = None  # the clock is read only after an interruption (a clock read is a system call too)
    remaining = timeout
    while True:
        ms = -1 if remaining is None else min(max(0, math.ceil(remaining * 1000.0)), 2**31 - 1)
        n = call(ms)
        if n >= 0:
            return n > 0
        err = ctypes.get_errno()
        if err != errno.EINTR:
            raise can.CanOperationError(f"{name} failed: {errno.errorcode.get(err, err)}", err)
        if remaining is not None:
            if deadline is None:
                deadline = time.monotonic() + remaining  # first interruption: start the clock here
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return False


class BatchSocketcanBus(SocketcanBus):
    """python-can's SocketcanBus with batched, low-syscall send and receive (see the module docstring)."""

    def __init__(self, channel: str = "vcan0", **kwargs) -> None:
        super().__init__(channel=channel, **kwargs)
        self.socket.setblocking(False)
        self._fd = self.socket.fileno()
        self._rx: deque[can.Message] = deque()
        self._was_empty = False  # the last read found the socket empty
        self.decode_errors = 0  # received buffers that are not a classic can_frame, dropped
        self._poll_first = 0  # waiting reads left that poll before reading (see the module docstring)
        self._rx_slots = _Slots(with_control=True)
        self._tx_slots = _Slots(with_control=False)
        self._doorbell: socket.socket | None = None
        self._bell_epoll: select.epoll | None = None
        self._bell_events = ctypes.create_string_buffer(64)  # epoll_wait's output (only its count is used)
        self._rings = 0  # rings since the doorbell's queue was last emptied
        self._scratch = _Slots(with_control=False)

    # ------------------------------------------------------------------------------------- receive
    def recv(self, timeout: float | None = None) -> can.Message | None:
        if not self._is_filtered:
            return super().recv(timeout)  # software filters: BusABC's loop over _recv_internal
        if self._rx or self._fill(timeout):
            return self._rx.popleft()
        return None

    def recv_queued(self, timeout: float | None = 0.0, limit: int | None = None) -> list[can.Message] | None:
        """Every frame queued now (waiting up to ``timeout`` for the first), at most ``limit``; [] when
        nothing came: what ``recv`` would return call after call, in one call. None when software filters
        are set (then only ``recv`` reads)."""
        if not self._is_filtered:
            return None
        return take_queued(self._rx, self._fill, timeout, limit)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._rx or self._fill(timeout):
            return self._rx.popleft(), self._is_filtered
        return None, self._is_filtered

    def _fill(self, timeout: float | None) -> bool:
        """Queue what the socket holds; if nothing, wait up to ``timeout`` (None: for ever) and read."""
        waiting = timeout is None or timeout > 0.0
        # After an empty read (a recv(0) just before, typically) a waiting call polls first: poll() reports
        # what arrived since, and the read that would fail again is saved. So do the waiting calls after
        # one that found the socket empty, for a while (see the module docstring).
        if not waiting:
            return self._read_batch() > 0
        if self._poll_first:
            self._poll_first -= 1
        elif not self._was_empty:
            if self._read_batch():
                return True
            self._poll_first = POLL_FIRST_WAITS
        remaining, deadline = timeout, None
        while _poll(self._fd, remaining):
            if self._read_batch():
                return True
            # readable yet empty (another reader of the socket was first): wait for what is left
            if remaining is not None:
                deadline = deadline if deadline is not None else time.monotonic() + remaining
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return False
        return False

    def _read_batch(self) -> int:
        slots = self._rx_slots
        slots.reset_control()
        n = _libc.recvmmsg(self._fd, slots.hdr, BATCH, _MSG_DONTWAIT, None)
        if n < 0:
            err = ctypes.get_errno()
            if err in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EINTR):
                slots.used = 0
                self._was_empty = True
                return 0
            raise can.CanOperationError(f"Error receiving: {errno.errorcode.get(err, err)}", err)
        slots.used = n
        self._was_empty = False
        view, control, channel, rx = slots.view, slots.control, self.channel, self._rx
        for i in range(n):
            h = slots.hdr[i].msg_hdr
            can_id, dlc, payload = _FRAME.unpack_from(view, 16 * i)
            if slots.hdr[i].msg_len != 16 or dlc > 8:  # not a classic can_frame: dropped and counted
                self.decode_errors += 1
                continue
            if h.msg_controllen >= _CMSG_SPACE:
                sec, nsec = _TIMESPEC.unpack_from(control, _CMSG_SPACE * i + 16)
                stamp = sec + nsec * 1e-9
            else:
                stamp = 0.0
            # can.Message(timestamp=..., ..., data=...) slot by slot: the same object state, a third of
            # the keyword constructor's cost (two processes build ~22 a GNC tick on the guest's one CPU)
            msg = _new_message(_Message)
            msg.timestamp = stamp
            extended = bool(can_id & _EFF)
            msg.arbitration_id = can_id & (_EFF_MASK if extended else _SFF_MASK)
            msg.is_extended_id = extended
            remote = bool(can_id & _RTR)
            msg.is_remote_frame = remote
            msg.is_error_frame = bool(can_id & _ERR)
            msg.channel = channel
            msg.is_fd = False
            msg.is_rx = not h.msg_flags & _MSG_DONTROUTE
            msg.bitrate_switch = False
            msg.error_state_indicator = False
            msg.data = bytearray() if remote else bytearray(payload[:min(dlc, 8)])
            msg.dlc = dlc
            rx.append(msg)
        return n

    # ---------------------------------------------------------------------------------------- send
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        data = classic_frame(msg)
        try:
            if self.socket.send(data) == len(data):
                return
        except (BlockingIOError, InterruptedError):
            pass
        except OSError as error:
            if error.errno != errno.ENOBUFS:
                raise can.CanOperationError(f"Failed to transmit: {error.strerror}", error.errno) from error
        super().send(msg, timeout)  # queue full: python-can's wait for room (select) and retry

    def send_batch(self, msgs: Sequence[can.Message], timeout: float | None = None) -> int:
        """Send ``msgs`` in order, one sendmmsg() per BATCH frames. Returns how many, from the first, were
        sent: fewer than ``len(msgs)`` when frame [n] was refused (queue still full after ``timeout``, bus
        error); the caller decides about the rest."""
        slots = self._tx_slots
        sent = 0
        while sent < len(msgs):
            chunk = msgs[sent:sent + BATCH]
            frames = [classic_frame(m) for m in chunk]
            n = 0
            if all(len(f) == 16 for f in frames):  # classic frames (a CAN FD one goes through send)
                for i, f in enumerate(frames):
                    slots.view[16 * i:16 * i + 16] = f
                n = max(0, _libc.sendmmsg(self._fd, slots.hdr, len(frames), 0))
            sent += n
            if n < len(frames):  # full queue or error: python-can's send waits for room / raises
                try:
                    self.send(chunk[n], timeout)
                except can.CanError:
                    return sent
                sent += 1
        return sent

    # ------------------------------------------------------------------------------------ doorbell
    def watch(self, frame_ids: Iterable[int]) -> None:
        """Frames with these (standard) ids end a ``wait_for``; replaces an earlier watch list."""
        if self._doorbell is not None:
            self._doorbell.close()
        bell = socket.socket(constants.PF_CAN, socket.SOCK_RAW, constants.CAN_RAW)
        bell.setsockopt(constants.SOL_CAN_RAW, constants.CAN_RAW_FILTER,
                        pack_filters([{"can_id": i, "can_mask": _SFF_MASK, "extended": False} for i in frame_ids]))
        try:
            bell.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, DOORBELL_RCVBUF)
        except OSError:
            pass
        bell.bind((self.channel,))
        bell.setblocking(False)
        self._doorbell = bell
        if self._bell_epoll is not None:
            self._bell_epoll.close()
        # edge-triggered: a wait returns once for every burst of rings since the last one, without a read
        self._bell_epoll = select.epoll()
        self._bell_epoll.register(bell.fileno(), select.EPOLLIN | select.EPOLLET)
        self._rings = 0

    def wait_for(self, timeout: float | None) -> bool:
        """Block until a watched frame has arrived since the last call (True) or ``timeout`` (False; 0
        only looks). The frame itself is read with ``recv``; without ``watch`` this returns True at once."""
        if self._doorbell is None:
            return True
        epfd, events = self._bell_epoll.fileno(), self._bell_events
        # (select.epoll.poll would read the clock for its timeout: a system call in the vcan-vm guest)
        if _wait(lambda ms: _libc.epoll_wait(epfd, events, 1, ms), timeout, "epoll_wait"):
            # a ring from before this call counts: its edge is kept until a wait takes it
            self._rings += 1
            self._poll_first = 0  # the frames before the ring are queued: read them first
            if self._rings >= DRAIN_EVERY:
                self._drain_doorbell()
            return True
        self._drain_doorbell()  # nothing came: start again from an empty queue (a lost edge costs one wait)
        return False

    def _drain_doorbell(self) -> int:
        self._rings = 0
        total = 0
        while True:
            n = _libc.recvmmsg(self._doorbell.fileno(), self._scratch.hdr, BATCH, _MSG_DONTWAIT, None)
            if n <= 0:
                return total
            total += n
            if n < BATCH:
                return total

    def shutdown(self) -> None:
        if self._doorbell is not None:
            self._bell_epoll.close()
            self._bell_epoll = None
            self._doorbell.close()
            self._doorbell = None
        super().shutdown()
