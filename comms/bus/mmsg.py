"""recvmmsg/sendmmsg/poll through ctypes, shared by the batched SocketCAN and UDP buses: one system call for
a whole burst of frames (Python's socket module has no recvmmsg/sendmmsg). Linux only; elsewhere ``libc`` is
None and the buses fall back to python-can's own per-frame calls."""
from __future__ import annotations

import ctypes
import ctypes.util
import sys
from collections import deque
from typing import Callable


def _load_libc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    try:  # find_library("c") would run `ldconfig -p` in a subprocess at every start
        return ctypes.CDLL("libc.so.6", use_errno=True)
    except OSError:
        return ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)


class IoVec(ctypes.Structure):
    _fields_ = [("iov_base", ctypes.c_void_p), ("iov_len", ctypes.c_size_t)]


class MsgHdr(ctypes.Structure):
    _fields_ = [("msg_name", ctypes.c_void_p), ("msg_namelen", ctypes.c_uint32),
                ("msg_iov", ctypes.POINTER(IoVec)), ("msg_iovlen", ctypes.c_size_t),
                ("msg_control", ctypes.c_void_p), ("msg_controllen", ctypes.c_size_t),
                ("msg_flags", ctypes.c_int)]


class MMsgHdr(ctypes.Structure):
    _fields_ = [("msg_hdr", MsgHdr), ("msg_len", ctypes.c_uint)]


class PollFd(ctypes.Structure):
    _fields_ = [("fd", ctypes.c_int), ("events", ctypes.c_short), ("revents", ctypes.c_short)]


libc = _load_libc()
if libc is not None:
    libc.recvmmsg.argtypes = [ctypes.c_int, ctypes.POINTER(MMsgHdr), ctypes.c_uint, ctypes.c_int, ctypes.c_void_p]
    libc.sendmmsg.argtypes = [ctypes.c_int, ctypes.POINTER(MMsgHdr), ctypes.c_uint, ctypes.c_int]
    libc.poll.argtypes = [ctypes.POINTER(PollFd), ctypes.c_ulong, ctypes.c_int]
    libc.epoll_wait.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_int, ctypes.c_int]


def take_queued(rx: deque, fill: Callable[[float | None], bool], timeout: float | None,
                limit: int | None) -> list:
    """Every frame of the local queue ``rx`` (``fill(timeout)`` first when it is empty), at most ``limit``:
    what ``recv`` would return call after call, in one call; [] when nothing came."""
    if not rx and not fill(timeout):
        return []
    if limit is None or len(rx) <= limit:
        out = list(rx)
        rx.clear()
        return out
    return [rx.popleft() for _ in range(limit)]
