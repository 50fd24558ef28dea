"""A burst: the frames one node puts on the bus at one time (a tick's SYNC and device frames, a cycle's
wheel commands and CYCLE_DONE), held as arrays so that the compiled codec (comms.bus.kernels) encodes and
checks all of them in one call.

On a python-can bus a burst travels as ordinary ``can.Message`` frames (``send_burst`` builds them and
sends them in one batch; ``recv_burst`` reads everything queued), so a SIL over socketcan or udp_multicast
carries exactly the frames it always did. The in-process bus of fast mode
(:class:`comms.bus.transport.LightVirtualBus`) carries the burst itself: one queue entry instead of a
``can.Message`` built, copied, queued and read per frame; its plain ``recv`` still hands out messages.
"""
from __future__ import annotations

from typing import Any, Sequence

import can
import numpy as np

from comms.bus.kernels import MAX_DLC


def data_frame(frame_id: int, data: bytearray) -> can.Message:
    """``can.Message(arbitration_id=frame_id, data=data, is_extended_id=False, is_fd=False)``, slot by slot
    (the same object state; the keyword constructor is a third of an encode's cost)."""
    msg = can.Message.__new__(can.Message)
    msg.timestamp = 0.0
    msg.arbitration_id = frame_id
    msg.is_extended_id = False
    msg.is_remote_frame = False
    msg.is_error_frame = False
    msg.channel = None
    msg.is_fd = False
    msg.is_rx = True
    msg.bitrate_switch = False
    msg.error_state_indicator = False
    msg.data = data
    msg.dlc = len(data)
    return msg


class FrameBurst:
    """Frames in bus order: ``ids`` (n,) int64, ``data`` (n, 8) uint8 (bytes past a frame's length are
    zero), ``lengths`` (n,) int64. ``msgs``: the ``can.Message`` of each frame when the burst was read off
    a python-can bus (frames that are not plain classic data frames have id -1 here and are judged from
    their message); None when the burst was built from arrays (all plain data frames). A burst is never
    edited once built (the in-process bus hands the same one to every receiver; ``tail`` makes a new one)."""

    __slots__ = ("ids", "data", "lengths", "msgs")

    def __init__(self, ids: np.ndarray, data: np.ndarray, lengths: np.ndarray,
                 msgs: list[can.Message] | None = None) -> None:
        self.ids, self.data, self.lengths, self.msgs = ids, data, lengths, msgs

    def __len__(self) -> int:
        return len(self.ids)

    def message(self, i: int) -> can.Message:
        """Frame ``i`` as a ``can.Message`` (a new one when the burst has none)."""
        if self.msgs is not None:
            return self.msgs[i]
        return data_frame(int(self.ids[i]), bytearray(self.data[i, :self.lengths[i]].tobytes()))

    def messages(self) -> list[can.Message]:
        if self.msgs is not None:
            return list(self.msgs)
        rows = self.data.tobytes()
        return [data_frame(fid, bytearray(rows[MAX_DLC * i:MAX_DLC * i + n]))
                for i, (fid, n) in enumerate(zip(self.ids.tolist(), self.lengths.tolist()))]

    def tail(self, start: int) -> "FrameBurst":
        """The frames from ``start`` on."""
        return FrameBurst(self.ids[start:], self.data[start:], self.lengths[start:],
                          None if self.msgs is None else self.msgs[start:])

    @classmethod
    def from_messages(cls, msgs: Sequence[Any]) -> "FrameBurst":
        """A burst of received messages (kept in ``msgs``); anything but a plain classic data frame of at
        most 8 bytes gets id -1, so the receiver judges it from its message."""
        n = len(msgs)
        ids = np.full(n, -1, dtype=np.int64)
        lengths = np.zeros(n, dtype=np.int64)
        data = np.zeros((n, MAX_DLC), dtype=np.uint8)
        for i, msg in enumerate(msgs):
            try:
                payload = msg.data if msg.data is not None else b""
                if msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame or len(payload) > MAX_DLC:
                    continue
                ids[i] = msg.arbitration_id
                lengths[i] = len(payload)
                data[i, :len(payload)] = np.frombuffer(bytes(payload), dtype=np.uint8)
            except (AttributeError, TypeError, ValueError):
                continue  # not a frame the table can judge: the receiver takes its message path
        return cls(ids, data, lengths, list(msgs))

    @classmethod
    def join(cls, parts: Sequence["FrameBurst"]) -> "FrameBurst":
        if len(parts) == 1:
            return parts[0]
        msgs = None
        if any(p.msgs is not None for p in parts):
            msgs = [m for p in parts for m in (p.msgs if p.msgs is not None else p.messages())]
        return cls(np.concatenate([p.ids for p in parts]), np.concatenate([p.data for p in parts]),
                   np.concatenate([p.lengths for p in parts]), msgs)
