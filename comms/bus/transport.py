"""Transports: one spec string picks the python-can interface underneath.

Specs:
  ``socketcan:IFACE``               SocketCAN (``socketcan`` alone means vcan0). The real thing, opened
                                    as :class:`comms.bus.socketcan_batch.BatchSocketcanBus` (python-can's
                                    bus with batched reads/writes: few system calls per frame).
  ``udp_multicast[:GROUP:PORT]``     python-can's multi-process interface, for kernels without CAN,
                                    confined to the loopback interface
                                    (:class:`comms.bus.udp_loopback.LoopbackUdpMulticastBus`). Without
                                    GROUP/PORT both are drawn at random (``secrets``): every run gets
                                    its own bus, which no other run shares or can predict; the
                                    resolved spec is what the other processes of the run are given.
  ``virtual[:CHANNEL]``              python-can's in-process bus (unit tests, campaigns' fast mode;
                                    ``open_bus(..., light=True)`` gives :class:`LightVirtualBus`).
  ``auto``                          socketcan on vcan0 when /sys/class/net/vcan0 exists, else
                                    udp_multicast; the choice is reported through ``BusInfo``.
  ``INTERFACE:CHANNEL[,KEY=VALUE...]`` any other python-can interface, for real CAN hardware on a
                                    processor-in-the-loop bench: ``pcan:PCAN_USBBUS1``, ``kvaser:0``,
                                    ``vector:0,app_name=keepout``, ``slcan:/dev/ttyACM0``,
                                    ``socketcand:can0,host=10.0.0.2,port=29536``, ``gs_usb:0``... The
                                    KEY=VALUE options go to ``can.Bus`` as keyword arguments (numbers as
                                    numbers). ``open_bus(..., bitrate=)`` passes the mission's bitrate to
                                    these; SocketCAN's bitrate is the kernel's (``ip link set can0 type can
                                    bitrate 500000``), and the loopback transports have none.
"""
from __future__ import annotations

import ipaddress
import queue
import secrets
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import can
import numpy as np
from can.interfaces.virtual import VirtualBus, channels_lock

from comms.bus.burst import FrameBurst
from comms.bus.kernels import MAX_DLC

# The classic CAN bit rates [bit/s] a hardware interface may be opened at (``keepout fsw --bitrate`` checks
# against it; the mission's bus_bitrate_bps and the flight run's bitrate_bps bound theirs the same, a test
# keeps them equal).
CAN_BITRATE_RANGE_BPS = (10_000, 1_000_000)


def is_can_bitrate(value: object) -> bool:
    """Whether ``value`` is an integer (a bool is not) in CAN_BITRATE_RANGE_BPS."""
    lo, hi = CAN_BITRATE_RANGE_BPS
    return isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi


VCAN_CREATE_COMMANDS = (
    "sudo modprobe vcan",
    "sudo ip link add dev {iface} type vcan",
    "sudo ip link set up {iface}",
)
UDP_GROUP_PREFIX = "239.74"   # administratively scoped IPv4 multicast (RFC 2365), like python-can's default
UDP_PORT_BASE = 43200
UDP_PORT_SPAN = 16000


class BusUnavailableError(RuntimeError):
    """The requested transport cannot be opened here (message says how to fix it)."""


class BusSpecError(ValueError):
    """A malformed --bus spec (message lists the accepted forms)."""


SPEC_HELP = ("accepted: auto | socketcan[:IFACE] | udp_multicast[:GROUP:PORT] | virtual[:CHANNEL] | "
             "INTERFACE:CHANNEL[,KEY=VALUE...] for any python-can interface (pcan, kvaser, vector, slcan, "
             "socketcand, gs_usb, ...)")
# The python-can interfaces the generic INTERFACE:CHANNEL form opens (the loopback ones have their own forms).
_OWN_FORMS = ("socketcan", "udp_multicast", "virtual")


@dataclass(frozen=True)
class BusInfo:
    """What ``resolve_spec`` chose: the concrete spec and why."""

    spec: str          # concrete spec, e.g. "udp_multicast:239.74.12.34:51234"
    interface: str     # python-can interface name
    channel: str
    port: int | None
    note: str          # human-readable explanation ("auto: vcan0 not present, using udp_multicast ...")
    options: tuple[tuple[str, Any], ...] = ()  # generic interfaces: extra can.Bus keyword arguments


def interface_present(iface: str) -> bool:
    return Path("/sys/class/net", iface).exists()


def vcan_hint(iface: str = "vcan0") -> str:
    commands = "\n  ".join(c.format(iface=iface) for c in VCAN_CREATE_COMMANDS)
    return (
        f"SocketCAN interface {iface} does not exist on this machine. Create it with:\n  {commands}\n"
        "(a kernel built without CAN has no vcan module: run in a virtual machine whose kernel has it), "
        "or use --bus udp_multicast."
    )


def random_udp_endpoint() -> tuple[str, int]:
    """A multicast group and port for one run, drawn at random (65k groups x 16k ports): not derived
    from anything another process could know (the run folder's name was, and runs started in the
    same second shared it)."""
    group = f"{UDP_GROUP_PREFIX}.{secrets.randbelow(256)}.{1 + secrets.randbelow(254)}"
    return group, UDP_PORT_BASE + secrets.randbelow(UDP_PORT_SPAN)


def resolve_spec(spec: str, run_id: str | int | None = None) -> BusInfo:
    """Turn a --bus spec into a concrete one. Raises BusSpecError for malformed specs.
    (``run_id`` is kept for callers' signatures; udp_multicast endpoints are random, see the module.)"""
    spec = (spec or "auto").strip()
    kind, _, rest = spec.partition(":")
    kind = kind.lower()
    if kind == "auto":
        if rest:
            raise BusSpecError(f"bus spec {spec!r}: 'auto' takes no arguments; {SPEC_HELP}")
        if interface_present("vcan0"):
            info = resolve_spec("socketcan:vcan0")
            return BusInfo(info.spec, info.interface, info.channel, None, "auto: using socketcan on vcan0")
        info = resolve_spec("udp_multicast", run_id)
        return BusInfo(info.spec, info.interface, info.channel, info.port,
                       f"auto: vcan0 not present, using udp_multicast group {info.channel} port {info.port}")
    if kind == "socketcan":
        iface = rest or "vcan0"
        if ":" in iface or not iface:
            raise BusSpecError(f"bus spec {spec!r}: bad interface name; {SPEC_HELP}")
        return BusInfo(f"socketcan:{iface}", "socketcan", iface, None, f"socketcan on {iface}")
    if kind == "udp_multicast":
        if rest:
            group, sep, port_text = rest.rpartition(":")
            if not sep or not group:
                raise BusSpecError(f"bus spec {spec!r}: give both GROUP and PORT, e.g. "
                                   f"udp_multicast:239.74.1.2:43210; {SPEC_HELP}")
            try:
                port = int(port_text)
            except ValueError:
                raise BusSpecError(f"bus spec {spec!r}: PORT {port_text!r} is not an integer") from None
            if not 1024 <= port <= 65535:
                raise BusSpecError(f"bus spec {spec!r}: PORT must be 1024..65535")
            try:
                multicast = ipaddress.IPv4Address(group).is_multicast
            except ValueError:
                multicast = False
            if not multicast:
                raise BusSpecError(f"bus spec {spec!r}: GROUP {group!r} is not an IPv4 multicast address "
                                   f"(224.0.0.0-239.255.255.255, e.g. 239.74.1.2); {SPEC_HELP}")
        else:
            group, port = random_udp_endpoint()
        return BusInfo(f"udp_multicast:{group}:{port}", "udp_multicast", group, port,
                       f"udp_multicast group {group} port {port}")
    if kind == "virtual":
        channel = rest or "keepout"
        return BusInfo(f"virtual:{channel}", "virtual", channel, None, f"virtual channel {channel}")
    if kind in can.interfaces.VALID_INTERFACES:
        channel, *pairs = rest.split(",")
        if not channel:
            raise BusSpecError(f"bus spec {spec!r}: give the channel, e.g. {kind}:0 or {kind}:PCAN_USBBUS1; "
                               f"{SPEC_HELP}")
        options = []
        for pair in pairs:
            key, sep, value = pair.partition("=")
            if not sep or not key.isidentifier():
                raise BusSpecError(f"bus spec {spec!r}: option {pair!r} is not KEY=VALUE; {SPEC_HELP}")
            options.append((key, _option_value(value)))
        return BusInfo(f"{kind}:{rest}", kind, channel, None, f"python-can interface {kind} channel {channel}",
                       tuple(options))
    raise BusSpecError(f"unknown bus spec {spec!r}; {SPEC_HELP}")


def _option_value(text: str) -> Any:
    """A KEY=VALUE option's value: an int or float when it reads as one, else the string."""
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def open_bus(spec: str = "auto", run_id: str | int | None = None, *, info_out: list | None = None,
             light: bool = False, bitrate: int | None = None) -> can.BusABC:
    """Open the bus named by ``spec`` (see module docstring). The BusInfo is appended to ``info_out``.
    ``light``: a ``virtual`` spec opens a :class:`LightVirtualBus` (ignored for other transports).
    ``bitrate`` [bit/s]: for hardware interfaces (the generic form); the others have no bitrate to set.

    Raises BusUnavailableError (with the commands that create vcan0) when socketcan is asked for and the
    interface is missing, or when a hardware interface cannot be opened (driver, device or channel
    missing: python-can's message says which).
    """
    info = resolve_spec(spec, run_id)
    if info_out is not None:
        info_out.append(info)
    if (spec or "auto").strip().lower() == "auto":
        print(f"bus: {info.note}", file=sys.stderr)  # the contract: auto says which transport it chose
    if info.interface == "socketcan":
        if not interface_present(info.channel):
            raise BusUnavailableError(vcan_hint(info.channel))
        from comms.bus.socketcan_batch import BatchSocketcanBus

        return BatchSocketcanBus(channel=info.channel, receive_own_messages=False, fd=False)
    if info.interface not in _OWN_FORMS:
        kwargs = dict(info.options)
        if bitrate is not None:
            kwargs.setdefault("bitrate", int(bitrate))
        try:
            return can.Bus(interface=info.interface, channel=info.channel, **kwargs)
        except (can.CanError, ImportError, OSError, ValueError, TypeError) as exc:
            raise BusUnavailableError(f"cannot open python-can interface {info.interface!r} channel "
                                      f"{info.channel!r}: {type(exc).__name__}: {exc}") from None
    if info.interface == "udp_multicast":
        from comms.bus.udp_loopback import LoopbackUdpMulticastBus

        # fd=False: classic CAN frames only, as on the spacecraft bus.
        return LoopbackUdpMulticastBus(channel=info.channel, port=info.port, fd=False)
    if light:
        return LightVirtualBus(channel=info.channel, receive_own_messages=False)
    return can.Bus(interface="virtual", channel=info.channel, receive_own_messages=False)


def drain(bus: can.BusABC) -> int:
    """Discard everything already queued on ``bus``; returns how many frames were dropped."""
    count = 0
    while bus.recv(timeout=0.0) is not None:
        count += 1
    return count


def send_batch(bus: can.BusABC, msgs: list[can.Message], timeout: float | None = None) -> int:
    """Send ``msgs`` in order, in one system call where the bus can (socketcan), else one by one. Returns
    how many, from the first, were sent: fewer when frame [n] was refused (CanError); the rest is unsent."""
    batch = getattr(bus, "send_batch", None)
    if batch is not None:
        return int(batch(msgs, timeout))
    for i, msg in enumerate(msgs):
        try:
            bus.send(msg, timeout)
        except can.CanError:
            return i
    return len(msgs)


def send_burst(bus: can.BusABC, burst: FrameBurst, timeout: float | None = None) -> int:
    """Send a burst's frames in order: as the burst itself on a bus that carries bursts
    (:class:`LightVirtualBus`), else as ``can.Message`` frames through :func:`send_batch`. Returns how
    many, from the first, were sent (as ``send_batch``)."""
    carry = getattr(bus, "send_burst", None)
    if carry is not None:
        return int(carry(burst, timeout))
    return send_batch(bus, burst.messages(), timeout)


def recv_burst(bus: can.BusABC, timeout: float | None = 0.0, limit: int | None = None) -> FrameBurst | None:
    """Every frame queued on ``bus`` now, in order, as one burst (waiting up to ``timeout`` for the
    first); None when nothing came. ``limit``: on a python-can bus, stop reading after this many frames
    (the caller expects no more: reading until the queue is empty costs one more system call each time);
    a bus that carries bursts returns its queued bursts whole."""
    carry = getattr(bus, "recv_burst", None)
    if carry is not None:
        return carry(timeout)
    queued = getattr(bus, "recv_queued", None)
    if queued is not None:  # a bus that reads everything queued in one call (no filters set): one call here
        msgs = queued(timeout, limit)
        if msgs is not None:  # None: the bus cannot (software filters set): frame by frame below
            return burst_of_messages(msgs) if msgs else None
    msg = bus.recv(timeout=timeout)
    if msg is None:
        return None
    msgs = [msg]
    while (limit is None or len(msgs) < limit) and (msg := bus.recv(timeout=0.0)) is not None:
        msgs.append(msg)
    return FrameBurst.from_messages(msgs)


_ZERO_ROW = bytes(MAX_DLC)


def burst_of_messages(msgs: Sequence[can.Message]) -> FrameBurst:
    """``FrameBurst.from_messages(msgs)`` (the same arrays and list), built with one array call per column
    instead of a numpy row assignment per frame (a lockstep SIL reads ~22 frames a tick); a burst with any
    frame that is not a plain classic data frame takes ``from_messages`` itself."""
    ids: list[int] = []
    lengths: list[int] = []
    rows = bytearray()
    for msg in msgs:
        data = msg.data
        kind = type(data)
        if (msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame or (kind is not bytearray and kind is not bytes)
                or len(data) > MAX_DLC or type(msg.arbitration_id) is not int):
            return FrameBurst.from_messages(msgs)
        ids.append(msg.arbitration_id)
        lengths.append(len(data))
        rows += data
        rows += _ZERO_ROW[len(data):]
    n = len(ids)
    return FrameBurst(np.array(ids, dtype=np.int64), np.frombuffer(rows, dtype=np.uint8).reshape(n, MAX_DLC),
                      np.array(lengths, dtype=np.int64), list(msgs))


def _copy_message(msg: can.Message) -> can.Message:
    # What VirtualBus.send's deepcopy produces (every slot, data in a new bytearray), ~20x cheaper:
    # deepcopy walks the slots through copyreg for each frame.
    out = can.Message.__new__(can.Message)
    out.timestamp = msg.timestamp
    out.arbitration_id = msg.arbitration_id
    out.is_extended_id = msg.is_extended_id
    out.is_remote_frame = msg.is_remote_frame
    out.is_error_frame = msg.is_error_frame
    out.channel = msg.channel
    out.dlc = msg.dlc
    data = msg.data
    out.data = bytearray(data) if type(data) is bytearray else data  # bytes / None need no copy
    out.is_fd = msg.is_fd
    out.is_rx = msg.is_rx
    out.bitrate_switch = msg.bitrate_switch
    out.error_state_indicator = msg.error_state_indicator
    return out


class LightVirtualBus(VirtualBus):
    """python-can's ``virtual`` bus with the per-frame overhead taken out, for the campaigns' fast mode.

    Same channel registry as ``VirtualBus`` (a light and a plain bus on one channel hear each other),
    same delivery: a copy of each frame per receiver, stamped with the send time, ``channel`` and
    ``is_rx`` set, reliable and in order. Differences are in cost only: frames are copied slot by slot
    instead of ``copy.deepcopy``; the receive queue is a ``queue.SimpleQueue`` (no unbounded-size
    bookkeeping; ``rx_queue_size`` is not supported); ``recv`` without filters skips BusABC's filter
    loop and logging call. bench/campaign.py measures the difference per GNC tick.

    Bursts (:mod:`comms.bus.burst`): ``send_burst`` queues a whole burst as one entry for each receiver
    (receivers share it: nothing edits a burst once sent, see comms.bus.burst); ``recv_burst`` returns everything queued as
    one burst; ``recv`` hands out a queued burst's frames one ``can.Message`` at a time, so a plain
    python-can reader on the channel sees the same frames as if they had been sent one by one.
    """

    def __init__(self, channel: Any = "channel-0", receive_own_messages: bool = False, **kwargs: Any) -> None:
        if kwargs.get("rx_queue_size"):
            raise ValueError("LightVirtualBus has no bounded receive queue; use VirtualBus for rx_queue_size")
        super().__init__(channel=channel, receive_own_messages=receive_own_messages, **kwargs)
        with channels_lock:  # swap the Queue VirtualBus registered for a SimpleQueue, in place
            fast: queue.SimpleQueue = queue.SimpleQueue()
            position = next(i for i, q in enumerate(self.channel) if q is self.queue)
            self.channel[position] = fast
            self.queue = fast  # type: ignore[assignment]
        self._spill: list[can.Message] = []  # frames of a burst ``recv`` has begun handing out, reversed

    def send_burst(self, burst: FrameBurst, timeout: float | None = None) -> int:
        if not self._open:
            self._check_if_open()  # raises
        own, skip_own = self.queue, not self.receive_own_messages
        for bus_queue in self.channel:
            if bus_queue is own and skip_own:
                continue
            if not isinstance(bus_queue, queue.SimpleQueue):  # a plain VirtualBus: frame by frame
                for msg in burst.messages():
                    msg.channel, msg.is_rx, msg.timestamp = self.channel_id, True, time.time()
                    try:
                        bus_queue.put(msg, block=True, timeout=timeout)
                    except queue.Full:
                        raise can.CanOperationError("Could not send message to one or more recipients")
                continue
            bus_queue.put(burst)
        return len(burst.ids)

    def recv_burst(self, timeout: float | None = 0.0) -> FrameBurst | None:
        if self._filters is not None or not self._open:
            return recv_burst(_PlainReader(self), timeout)
        q = self.queue
        parts: list[FrameBurst] = []
        if self._spill:
            parts.append(FrameBurst.from_messages(self._spill[::-1]))
            self._spill = []
        elif q.empty():  # (an empty queue asked first: no queue.Empty raised and caught)
            if timeout is not None and timeout <= 0.0:
                return None
            try:
                item = q.get(True, timeout)
            except queue.Empty:
                return None
            if q.empty() and type(item) is FrameBurst:
                return item
            parts.append(item if type(item) is FrameBurst else FrameBurst.from_messages([item]))
        else:
            item = q.get_nowait()  # (this bus is the queue's one reader: not empty means an item is there)
            if q.empty() and type(item) is FrameBurst:
                return item  # the usual lockstep read: one burst queued
            parts.append(item if type(item) is FrameBurst else FrameBurst.from_messages([item]))
        get = q.get_nowait
        while not q.empty():
            item = get()
            parts.append(item if type(item) is FrameBurst else FrameBurst.from_messages([item]))
        return FrameBurst.join(parts)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._check_if_open()
        timestamp = msg.timestamp if self.preserve_timestamps else time.time()
        all_sent = True
        for bus_queue in self.channel:
            if bus_queue is self.queue and not self.receive_own_messages:
                continue
            copy = _copy_message(msg)
            copy.timestamp = timestamp
            copy.channel = self.channel_id
            copy.is_rx = bus_queue is not self.queue
            try:
                bus_queue.put(copy, block=True, timeout=timeout)
            except queue.Full:  # a plain VirtualBus receiver with a bounded queue
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self._filters is not None or not self._open:
            return super().recv(timeout)
        if self._spill:
            return self._spill.pop()
        try:
            if timeout is not None and timeout <= 0.0:
                msg = self.queue.get_nowait()
            else:
                msg = self.queue.get(block=True, timeout=timeout)
        except queue.Empty:
            return None
        if type(msg) is FrameBurst:
            return self._hand_out(msg)
        return msg

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._spill:
            return self._spill.pop(), False
        msg, filtered = super()._recv_internal(timeout)
        if type(msg) is FrameBurst:  # BusABC.recv's path (filters set): the burst's frames one by one
            msg = self._hand_out(msg)
        return msg, filtered

    def _hand_out(self, burst: FrameBurst) -> can.Message:
        """A burst's frames as messages, stamped as ``send`` stamps them; the first now, the rest queued."""
        msgs = burst.messages()
        now = time.time()
        for msg in msgs:
            msg.channel, msg.is_rx, msg.timestamp = self.channel_id, True, now
        self._spill = msgs[:0:-1]
        return msgs[0]


class _PlainReader:
    """``recv`` of a bus, for ``recv_burst`` on a LightVirtualBus whose filters are set."""

    def __init__(self, bus: can.BusABC) -> None:
        self.recv = bus.recv
