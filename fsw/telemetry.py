"""Telemetry: CCSDS space packets (built with ``spacepackets``) over UDP, from the dictionary.

``TelemetrySender`` keeps the latest value of every channel, packs a packet definition from the
dictionary when asked (``send_channels``), and sends events (``event``) with per-event throttling.
Each APID has its own 14-bit sequence count, so the ground sees any lost packet as a gap.

The packet codec it uses (``encode_tm_packet``, ``encode_event_packet``, ``decode_tm_packet``) is
``comms.telemetry``, shared with the ground.
"""
from __future__ import annotations

import collections
import ipaddress
import math
import socket
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from comms.dictionary import (
    DEFAULT_HOST,
    DEFAULT_TM_PORT,
    DICTIONARY,
    Channel,
    DictionaryError,
    EventDef,
    PacketDef,
    Severity,
    TelemetryDictionary,
    coerce_arg,
    packet_struct,
    vector_groups,
)
from comms.link_security import SecurityAssociation
from comms.telemetry import SEQ_MODULO, encode_event_packet, format_event_message, frame_tm_packet


def _wire_value(channel: Channel, value: Any) -> Any:
    """Convert a channel value to its wire type; integers saturate (telemetry never raises on range)."""
    t = channel.type
    if t in ("F32", "F64"):
        return float(value)
    if t == "BOOL":
        return bool(value)
    if t == "ENUM":
        assert channel.enum is not None
        if isinstance(value, str):
            try:
                return channel.enum.index(value.upper())
            except ValueError:
                raise DictionaryError(f"channel {channel.name}: {value!r} not one of {list(channel.enum)}") from None
        if hasattr(value, "name") and isinstance(getattr(value, "name"), str) and value.name in channel.enum:
            return channel.enum.index(value.name)  # an enum.Enum member with a matching name
        low, high = 0, len(channel.enum) - 1
    else:
        low, high = _INT_LIMITS[t]
    return _saturate(value, low, high)


_F32_MAX = 3.4028234663852886e38


def _f32(value: float) -> float:
    """``value`` as float32 can hold it: beyond the largest float32, +-inf (what IEEE conversion gives),
    instead of struct's OverflowError."""
    return math.copysign(math.inf, value) if math.isfinite(value) and abs(value) > _F32_MAX else value


def _saturate(value: Any, low: int, high: int) -> int:
    number = float(value)
    if math.isnan(number):
        return 0
    return int(min(max(number, low), high))


def _convert(channel: Channel, value: Any) -> Any:
    """Wire value of ``value`` for ``channel``; None is "no value"; a non-number names the channel."""
    if value is None:
        return _default_value(channel)
    try:
        return _wire_value(channel, value)
    except (TypeError, ValueError) as exc:
        raise DictionaryError(f"channel {channel.name} ({channel.type}): cannot use {value!r}: {exc}") from None


_INT_LIMITS = {"U8": (0, 255), "I8": (-128, 127), "U16": (0, 65535), "I16": (-32768, 32767),
               "U32": (0, 2**32 - 1), "I32": (-(2**31), 2**31 - 1)}


def _default_value(channel: Channel) -> Any:
    if channel.no_value is not None:
        return channel.no_value
    if channel.type in ("F32", "F64"):
        return math.nan  # "no value yet" is visible on the ground, never a plausible 0
    if channel.type == "BOOL":
        return False
    return 0


def _saturating(low: int, high: int) -> Callable[[Any], int]:
    return lambda value: _saturate(value, low, high)


def _update_plans(packet: PacketDef, index: dict[str, int],
                  groups: dict[str, list[str]]) -> dict[str, tuple[int, int, Callable[[Any], Any] | None]]:
    """Name -> (first slot, end slot, conversion) for the float, bool and integer channels (the conversion
    ``_wire_value`` makes for that type) and, with conversion None, for the vectors of float channels in
    consecutive slots: ``TelemetrySender.update`` stores those without a call chain per channel."""
    convert: dict[str, Callable[[Any], Any]] = {}
    for c in packet.channels:
        if c.type in ("F32", "F64"):
            convert[c.name] = float
        elif c.type == "BOOL":
            convert[c.name] = bool
        elif c.type in _INT_LIMITS:
            convert[c.name] = _saturating(*_INT_LIMITS[c.type])
    plans: dict[str, tuple[int, int, Callable[[Any], Any] | None]] = {
        name: (slot, slot + 1, convert[name]) for name, slot in index.items() if name in convert}
    for base, members in groups.items():
        slots = [index[m] for m in members]
        if base not in index and all(convert.get(m) is float for m in members) \
                and slots == list(range(slots[0], slots[0] + len(slots))):
            plans[base] = (slots[0], slots[0] + len(slots), None)
    return plans


@dataclass
class RecordedEvent:
    time_s: float
    name: str
    severity: Severity
    args: dict[str, Any]
    message: str


class TelemetrySender:
    """Sends telemetry packets and events as CCSDS space packets over UDP.

    ``host``/``port`` is the ground destination; ``port=None`` records without sending (unit tests,
    replay). The socket binds to ``bind_host`` (loopback when the destination is on loopback, so a
    default flight build never listens on an external interface). A multicast ``host`` (224.0.0.0/4) is
    sent on the interface of ``multicast_interface`` with TTL ``multicast_ttl`` and loopback on, so every
    ground client that joined the group there receives each packet. ``clock`` gives the onboard time in
    seconds stamped into packets when the caller passes no ``time_s`` (lockstep flight code passes
    the simulated time). ``security``: the downlink association (``comms.link_security``) that signs
    every packet before it is sent (None: plain packets).
    """

    def __init__(self, dictionary: TelemetryDictionary = DICTIONARY, host: str = DEFAULT_HOST,
                 port: int | None = DEFAULT_TM_PORT, *, bind_host: str | None = None,
                 clock: Callable[[], float] = time.monotonic, event_history: int = 512,
                 multicast_interface: str = DEFAULT_HOST, multicast_ttl: int = 0,
                 security: SecurityAssociation | None = None) -> None:
        self.dictionary = dictionary
        self.security = security
        self.destination = (host, port) if port is not None else None
        self.clock = clock
        self._latest: dict[str, list[Any]] = {
            p.name: [_default_value(c) for c in p.channels] for p in dictionary.packets
        }
        self._index: dict[str, dict[str, int]] = {
            p.name: {c.name: i for i, c in enumerate(p.channels)} for p in dictionary.packets
        }
        self._groups = {p.name: vector_groups(p) for p in dictionary.packets}
        self._plans = {p.name: _update_plans(p, self._index[p.name], self._groups[p.name]) for p in dictionary.packets}
        self._structs = {p.name: packet_struct(p) for p in dictionary.packets}
        self._seq: dict[int, int] = collections.defaultdict(int)
        self._throttle_times: dict[str, collections.deque[float]] = {}
        self._throttled_since: dict[str, int] = collections.defaultdict(int)
        self.recent_events: collections.deque[RecordedEvent] = collections.deque(maxlen=event_history)
        self.counters: dict[str, int] = {
            "packets_sent": 0, "bytes_sent": 0, "send_errors": 0, "events_sent": 0, "events_throttled": 0,
        }
        self.events_by_severity: dict[str, int] = {s.value: 0 for s in Severity}
        self._sock: socket.socket | None = None
        if self.destination is not None:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if _is_multicast(host):
                # Fan-out to any number of ground clients: they join the group on ``multicast_interface``.
                # Loop on, so clients on this host receive it; TTL 0 keeps it on this host by default.
                self._sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                      socket.inet_aton(multicast_interface))
                self._sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, multicast_ttl)
                self._sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
                if bind_host is None:
                    bind_host = multicast_interface
            if bind_host is None:
                bind_host = DEFAULT_HOST if _is_loopback(host) else "0.0.0.0"
            self._sock.bind((bind_host, 0))
            self._sock.setblocking(False)

    # ---- channels ----
    def update(self, packet_name: str, values: Mapping[str, Any]) -> None:
        """Store channel values without sending. Vector base names take a sequence (``q_est_NB``);
        ``None`` means "no value" (NaN for floats, 0/False otherwise)."""
        latest = self._packet_values(packet_name)
        plans = self._plans[packet_name]
        for name, value in values.items():
            plan = plans.get(name)
            if plan is not None and value is not None:
                # Fast path for float, bool and integer channels and for float vectors (most of the GNC
                # packet): the conversion _wire_value makes for that type, without the per-channel calls;
                # anything it refuses takes the general path below, which names the channel.
                start, stop, convert = plan
                try:
                    if convert is not None:
                        latest[start] = convert(value)
                        continue
                    tolist = getattr(value, "tolist", None)  # numpy: one call instead of a scalar per element
                    components = [float(c) for c in (tolist() if tolist is not None else value)]
                    if len(components) == stop - start:
                        latest[start:stop] = components
                        continue
                except (TypeError, ValueError):
                    pass
            self._update_one(packet_name, latest, name, value)

    def _update_one(self, packet_name: str, latest: list[Any], name: str, value: Any) -> None:
        index = self._index[packet_name]
        channels = self.dictionary.packet(packet_name).channels
        slot = index.get(name)
        if slot is not None:
            latest[slot] = _convert(channels[slot], value)
            return
        members = self._groups[packet_name].get(name)
        if members is None:
            raise DictionaryError(f"packet {packet_name} has no channel or vector {name!r}")
        if value is None:  # "no value" (e.g. no target attitude outside QUATERNION mode)
            for member in members:
                latest[index[member]] = _default_value(channels[index[member]])
            return
        components = list(value)
        if len(components) > len(members):
            raise DictionaryError(f"{packet_name}.{name}: {len(components)} values for {len(members)} channels")
        for member, component in zip(members, components):
            slot = index[member]
            latest[slot] = _convert(channels[slot], component)

    def send_channels(self, packet_name: str, values: Mapping[str, Any] | None = None,
                      time_s: float | None = None) -> bytes:
        """Update ``values`` and send the whole packet; channels not given keep their last value.

        Unknown names raise ``DictionaryError`` (a programming error); numeric values never raise:
        integers saturate at their type's range, F32 values beyond float32 become +-inf. Returns the
        packet bytes.
        """
        if values:
            self.update(packet_name, values)
        packet = self.dictionary.packet(packet_name)
        latest = self._latest[packet_name]
        try:
            payload = self._structs[packet_name].pack(*latest)
        except OverflowError:  # an F32 channel beyond float32 (found by bench/fuzz.py): saturate, then pack
            for i, channel in enumerate(packet.channels):
                if channel.type == "F32":
                    latest[i] = _f32(latest[i])
            payload = self._structs[packet_name].pack(*latest)
        raw = frame_tm_packet(packet.apid, self._next_seq(packet.apid), self._time(time_s), payload)
        return self._transmit(raw)

    def latest(self, packet_name: str) -> dict[str, Any]:
        """The values the next packet would carry (wire types: enums as indices)."""
        packet = self.dictionary.packet(packet_name)
        return {c.name: v for c, v in zip(packet.channels, self._latest[packet_name])}

    # ---- events ----
    def event(self, name: str, /, time_s: float | None = None, **args: Any) -> bool:
        """Send event ``name`` with typed ``args``; returns False if throttled.

        An unknown event name or a missing/mistyped arg raises (programming errors caught by tests).
        """
        event = self.dictionary.event(name)
        coerced = self._coerce_event_args(event, args)
        now = self._time(time_s)
        if not self._throttle_allows(event, now):
            self.counters["events_throttled"] += 1
            self._throttled_since[event.name] += 1
            return False
        suppressed = self._throttled_since.pop(event.name, 0)
        if suppressed:
            summary = self.dictionary.event("EVENTS_THROTTLED")
            self._emit(summary, {"event": event.name, "count": suppressed}, now)
        self._emit(event, coerced, now)
        return True

    def _coerce_event_args(self, event: EventDef, args: Mapping[str, Any]) -> dict[str, Any]:
        unknown = set(args) - {a.name for a in event.args}
        if unknown:
            raise DictionaryError(f"event {event.name}: unknown args {sorted(unknown)}; "
                                  f"declared {[a.name for a in event.args]}")
        coerced = {}
        for arg in event.args:
            if arg.name not in args:
                raise DictionaryError(f"event {event.name}: missing arg {arg.name!r}")
            value = coerce_arg(arg, args[arg.name], check_range=False)
            if arg.type == "F32":
                value = _f32(value)
            if arg.type in _INT_LIMITS:
                low, high = _INT_LIMITS[arg.type]
                value = min(max(value, low), high)
            coerced[arg.name] = value
        return coerced

    def _throttle_allows(self, event: EventDef, now: float) -> bool:
        if event.throttle is None:
            return True
        times = self._throttle_times.setdefault(event.name, collections.deque())
        while times and now - times[0] >= event.throttle_window_s:
            times.popleft()
        if len(times) >= event.throttle:
            return False
        times.append(now)
        return True

    def _emit(self, event: EventDef, args: dict[str, Any], now: float) -> None:
        raw = encode_event_packet(self.dictionary, event, self._next_seq(self.dictionary.event_apid), now, args)
        self.recent_events.append(RecordedEvent(now, event.name, event.severity, args,
                                                format_event_message(event, args)))
        self.counters["events_sent"] += 1
        self.events_by_severity[event.severity.value] += 1
        self._transmit(raw)

    # ---- plumbing ----
    def _packet_values(self, packet_name: str) -> list[Any]:
        try:
            return self._latest[packet_name]
        except KeyError:
            self.dictionary.packet(packet_name)  # raises with the known names
            raise

    def _time(self, time_s: float | None) -> float:
        return float(self.clock() if time_s is None else time_s)

    def _next_seq(self, apid: int) -> int:
        seq = self._seq[apid]
        self._seq[apid] = (seq + 1) % SEQ_MODULO
        return seq

    def sequence_count(self, apid: int) -> int:
        """The sequence count the next packet on ``apid`` will carry."""
        return self._seq[apid]

    def _transmit(self, raw: bytes) -> bytes:
        """Sign (with a security association) and send one packet; returns the bytes sent."""
        if self.security is not None:
            raw = self.security.protect(raw)
        if self._sock is None or self.destination is None:
            self.counters["packets_sent"] += 1
            self.counters["bytes_sent"] += len(raw)
            return raw
        try:
            self._sock.sendto(raw, self.destination)
        except OSError:
            # A full socket buffer or an unreachable ground must not stop the flight software; the
            # ground sees the gap in the sequence count, and the count shows in housekeeping.
            self.counters["send_errors"] += 1
            return raw
        self.counters["packets_sent"] += 1
        self.counters["bytes_sent"] += len(raw)
        return raw

    def reset_counters(self) -> None:
        for key in self.counters:
            self.counters[key] = 0

    @property
    def local_address(self) -> tuple[str, int] | None:
        return self._sock.getsockname() if self._sock is not None else None

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> "TelemetrySender":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _is_loopback(host: str) -> bool:
    return host.startswith("127.") or host in ("localhost", "::1")


def _is_multicast(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_multicast
    except ValueError:  # a host name: never a group
        return False
