"""Transport specs, the vcan hint, udp_multicast isolation, and SocketCAN (in the vcan VM)."""
from __future__ import annotations

import time

import can
import pytest

from comms.bus import transport
from comms.bus.transport import BusSpecError, BusUnavailableError, open_bus, resolve_spec


def test_resolve_explicit_specs() -> None:
    assert resolve_spec("socketcan:vcan1").channel == "vcan1"
    assert resolve_spec("socketcan").channel == "vcan0"
    info = resolve_spec("udp_multicast:239.74.1.2:45000")
    assert (info.interface, info.channel, info.port) == ("udp_multicast", "239.74.1.2", 45000)
    assert resolve_spec("virtual:abc").spec == "virtual:abc"


@pytest.mark.parametrize("bad", ["can:0", "udp_multicast:239.1.1.1", "udp_multicast:239.1.1.1:x",
                                 "udp_multicast:239.1.1.1:80", "auto:vcan0", "socketcan:a:b",
                                 "udp_multicast:10.0.0.1:45000", "udp_multicast:ff02::1:45000"])
def test_bad_specs_name_the_accepted_forms(bad: str) -> None:
    with pytest.raises(BusSpecError, match="accepted|GROUP|PORT|auto"):
        resolve_spec(bad)


@pytest.mark.parametrize("spec, interface, channel, options", [
    ("pcan:PCAN_USBBUS1", "pcan", "PCAN_USBBUS1", {}),
    ("kvaser:0", "kvaser", "0", {}),
    ("vector:0,app_name=keepout", "vector", "0", {"app_name": "keepout"}),
    ("slcan:/dev/ttyACM0", "slcan", "/dev/ttyACM0", {}),
    ("socketcand:can0,host=10.0.0.2,port=29536", "socketcand", "can0", {"host": "10.0.0.2", "port": 29536}),
])
def test_any_python_can_interface_is_a_bus_spec(spec: str, interface: str, channel: str, options: dict) -> None:
    info = resolve_spec(spec)
    assert (info.spec, info.interface, info.channel, dict(info.options)) == (spec, interface, channel, options)


@pytest.mark.parametrize("bad", ["pcan:", "kvaser:0,bitrate", "vector:0,9x=1", "warpdrive:0"])
def test_bad_hardware_specs_say_what_is_allowed(bad: str) -> None:
    with pytest.raises(BusSpecError, match="accepted"):
        resolve_spec(bad)


def test_hardware_interface_opens_with_the_mission_bitrate(monkeypatch: pytest.MonkeyPatch) -> None:
    opened: list[dict] = []
    real_bus = can.Bus

    def fake_bus(**kwargs):
        opened.append(kwargs)
        return real_bus(interface="virtual", channel="hw-stand-in")

    monkeypatch.setattr(transport.can, "Bus", fake_bus)
    open_bus("kvaser:1,data_bitrate=2000000", bitrate=250000).shutdown()
    open_bus("pcan:PCAN_USBBUS1,bitrate=125000", bitrate=250000).shutdown()  # the spec's own option wins
    assert opened == [{"interface": "kvaser", "channel": "1", "bitrate": 250000, "data_bitrate": 2000000},
                      {"interface": "pcan", "channel": "PCAN_USBBUS1", "bitrate": 125000}]


def test_missing_hardware_driver_is_a_clear_bus_unavailable_error() -> None:
    # no PCAN driver on a test machine: python-can's own message, wrapped with the interface and channel
    with pytest.raises(BusUnavailableError, match="python-can interface 'pcan' channel 'PCAN_USBBUS1'"):
        open_bus("pcan:PCAN_USBBUS1", bitrate=500000)


def test_udp_endpoint_is_random_per_run_not_derived_from_the_run_name() -> None:
    # Two runs with the same folder name (started in the same second) must not share a bus.
    specs = {resolve_spec("udp_multicast", run_id="demo-20261125-120000").spec for _ in range(20)}
    assert len(specs) == 20
    ports = {int(s.rsplit(":", 1)[1]) for s in specs}
    assert len(ports) > 10


def test_auto_says_which_transport(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(transport, "interface_present", lambda iface: False)
    info = resolve_spec("auto", run_id="x")
    assert info.interface == "udp_multicast" and "vcan0 not present" in info.note
    monkeypatch.setattr(transport, "interface_present", lambda iface: iface == "vcan0")
    info = resolve_spec("auto", run_id="x")
    assert info.spec == "socketcan:vcan0" and "socketcan" in info.note


def test_missing_vcan_error_prints_the_commands(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(transport, "interface_present", lambda iface: False)
    with pytest.raises(BusUnavailableError) as exc:
        open_bus("socketcan:vcan7")
    text = str(exc.value)
    assert "sudo modprobe vcan" in text
    assert "sudo ip link add dev vcan7 type vcan" in text
    assert "sudo ip link set up vcan7" in text


def _ping(a: can.BusABC, b: can.BusABC, frame_id: int) -> can.Message | None:
    a.send(can.Message(arbitration_id=frame_id, data=b"\x01\x02\x03", is_extended_id=False))
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        msg = b.recv(timeout=0.2)
        if msg is not None and msg.arbitration_id == frame_id:
            return msg
    return None


def test_udp_multicast_runs_do_not_hear_each_other() -> None:
    spec_a, spec_b = resolve_spec("udp_multicast").spec, resolve_spec("udp_multicast").spec
    a1, a2 = open_bus(spec_a), open_bus(spec_a)
    b1 = open_bus(spec_b)
    try:
        assert _ping(a1, a2, 0x123) is not None
        a1.send(can.Message(arbitration_id=0x124, data=b"\x00", is_extended_id=False))
        time.sleep(0.2)
        heard = [m for m in iter(lambda: b1.recv(timeout=0.05), None)]
        assert heard == []
    finally:
        for bus in (a1, a2, b1):
            bus.shutdown()


def test_udp_multicast_bus_stays_on_loopback() -> None:
    """The bus socket sends on lo with TTL 0, joins on lo only and binds the group, not 0.0.0.0."""
    import socket

    info = resolve_spec("udp_multicast")
    bus = open_bus(info.spec)
    try:
        sock = bus._multicast._socket
        assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
        assert socket.inet_ntoa(sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, 4)) == "127.0.0.1"
        assert sock.getsockname() == (info.channel, info.port)
        # a unicast datagram to the port from this host is not received (only the group's traffic is)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as intruder:
            intruder.sendto(b"\x00" * 16, ("127.0.0.1", info.port))
        assert bus.recv(timeout=0.2) is None
    finally:
        bus.shutdown()


def test_loopback_bus_talks_to_python_can_udp_multicast_on_the_same_group() -> None:
    # same wire format as python-can's interface (cantools monitor -i udp_multicast still works here)
    info = resolve_spec("udp_multicast")
    ours = open_bus(info.spec)
    theirs = can.Bus(interface="udp_multicast", channel=info.channel, port=info.port, fd=False)
    try:
        assert _ping(ours, theirs, 0x42) is not None
    finally:
        ours.shutdown()
        theirs.shutdown()


def _frames(seed: int, n: int = 40) -> list[can.Message]:
    """Plain classic data frames of every length (and some ids at the ends of the range)."""
    import random

    rng = random.Random(seed)
    return [can.Message(arbitration_id=rng.choice([0, 0x7FF, rng.randrange(0x800)]), is_extended_id=False,
                        data=bytes(rng.randrange(256) for _ in range(rng.randrange(9)))) for _ in range(n)]


def _state(msg: can.Message) -> tuple:
    return (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame, msg.channel, msg.dlc,
            type(msg.data), bytes(msg.data), msg.is_fd, msg.is_rx, msg.bitrate_switch, msg.error_state_indicator)


def test_udp_multicast_bus_does_not_hear_itself_and_keeps_order() -> None:
    """A burst sent with send_batch (one sendmmsg) arrives whole and in order at another bus on the group;
    the sender does not read its own frames back (python-can's socket did, through the loopback)."""
    info = resolve_spec("udp_multicast")
    a, b = open_bus(info.spec), open_bus(info.spec)
    try:
        frames = _frames(1)
        assert transport.send_batch(a, frames) == len(frames)
        got: list[can.Message] = []
        deadline = time.monotonic() + 5.0
        while len(got) < len(frames) and time.monotonic() < deadline:
            burst = transport.recv_burst(b, 0.5)
            got += burst.messages() if burst is not None else []
        assert [_state(m)[:1] + _state(m)[5:8] for m in got] == [_state(m)[:1] + _state(m)[5:8] for m in frames]
        assert all(m.is_rx and m.timestamp > 0.0 for m in got)
        assert a.recv(timeout=0.2) is None  # no echo of its own frames
        b.send(can.Message(arbitration_id=0x55, data=b"\x07", is_extended_id=False))
        echo = a.recv(timeout=2.0)
        assert echo is not None and echo.arbitration_id == 0x55  # but it hears the others
    finally:
        a.shutdown()
        b.shutdown()


def test_udp_multicast_bus_reads_what_python_can_reads() -> None:
    """Frames (plain or not) sent by the loopback bus reach python-can's own udp_multicast reader and
    another loopback bus as the same can.Message (python-can's unpack_message with check=True)."""
    info = resolve_spec("udp_multicast")
    ours, other = open_bus(info.spec), open_bus(info.spec)
    listener = can.Bus(interface="udp_multicast", channel=info.channel, port=info.port, fd=False)
    try:
        frames = _frames(2, 20) + [
            can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, data=b"\x01"),
            can.Message(arbitration_id=0x123, is_extended_id=False, is_remote_frame=True, dlc=3),
            can.Message(arbitration_id=0x42, is_extended_id=False, data=b"\x00" * 8, channel="x")]
        assert transport.send_batch(ours, frames[:10]) == 10
        for msg in frames[10:]:
            ours.send(msg)
        got = [other.recv(timeout=2.0) for _ in frames]
        ref = [listener.recv(timeout=2.0) for _ in frames]
        assert None not in got and None not in ref
        assert [_state(m) for m in got] == [_state(m) for m in ref]
        assert [m.timestamp for m in got] == [m.timestamp for m in ref]  # the kernel's receive time stamps
    finally:
        for bus in (ours, other, listener):
            bus.shutdown()


@pytest.mark.parametrize("seed", range(20))
def test_burst_of_messages_is_from_messages(seed: int) -> None:
    from comms.bus.burst import FrameBurst

    frames = _frames(seed, 1 + seed)
    if seed % 3 == 0:  # a frame the table cannot judge: the general path, same result
        frames.insert(seed % len(frames), can.Message(arbitration_id=0x10, is_extended_id=True, data=b"\x01"))
    if seed % 5 == 0:
        frames.append(can.Message(arbitration_id=0x11, is_extended_id=False, is_remote_frame=True, dlc=2))
    if seed % 7 == 0:
        frames.append(can.Message(arbitration_id=0x12, is_extended_id=False, data=bytearray(b"\x01\x02")))
    fast, ref = transport.burst_of_messages(frames), FrameBurst.from_messages(frames)
    for name in ("ids", "data", "lengths"):
        a, b = getattr(fast, name), getattr(ref, name)
        assert a.dtype == b.dtype and a.shape == b.shape and (a == b).all()
    assert fast.data.flags.writeable and fast.msgs == ref.msgs and fast.msgs is not frames


def test_virtual_channels_are_isolated() -> None:
    a, b, c = open_bus("virtual:iso1"), open_bus("virtual:iso1"), open_bus("virtual:iso2")
    try:
        a.send(can.Message(arbitration_id=0x10, data=b"\x01", is_extended_id=False))
        assert b.recv(timeout=0.5) is not None
        assert c.recv(timeout=0.05) is None
    finally:
        for bus in (a, b, c):
            bus.shutdown()


@pytest.mark.socketcan
@pytest.mark.parametrize("iface", ["vcan0", "vcan1"])
def test_socketcan_round_trip(iface: str) -> None:
    a, b = open_bus(f"socketcan:{iface}"), open_bus(f"socketcan:{iface}")
    try:
        msg = _ping(a, b, 0x321)
        assert msg is not None and bytes(msg.data) == b"\x01\x02\x03"
        assert not msg.is_fd
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.socketcan
def test_socketcan_auto_prefers_vcan0() -> None:
    info: list = []
    bus = open_bus("auto", info_out=info)
    try:
        assert info[0].spec == "socketcan:vcan0"
    finally:
        bus.shutdown()


@pytest.mark.socketcan
def test_vcan0_and_vcan1_are_separate_buses() -> None:
    a0, b0, b1 = open_bus("socketcan:vcan0"), open_bus("socketcan:vcan0"), open_bus("socketcan:vcan1")
    try:
        assert _ping(a0, b0, 0x55) is not None
        assert b1.recv(timeout=0.1) is None
    finally:
        for bus in (a0, b0, b1):
            bus.shutdown()


def _frame(i: int) -> can.Message:
    return can.Message(arbitration_id=0x40 + i, data=bytes([i, 2, 3, 4, 5, 6, 7, 8]), is_extended_id=False)


def test_light_virtual_bus_delivers_like_the_virtual_bus() -> None:
    """LightVirtualBus (campaign fast mode) is a VirtualBus: it shares the channel with plain virtual buses
    and delivers what they would (a copy per receiver, stamped, is_rx set, in order)."""
    from can.interfaces.virtual import VirtualBus, channels

    light = open_bus("virtual:light-test", light=True)
    plain = open_bus("virtual:light-test")
    other = transport.LightVirtualBus(channel="light-test")
    assert isinstance(light, VirtualBus) and type(plain) is VirtualBus
    try:
        sent = [_frame(i) for i in range(5)]
        before = time.time()
        for m in sent:
            light.send(m)
        sent[0].data[0] = 99  # a copy was delivered: later changes by the sender do not show
        for rx in (plain, other):
            got = [rx.recv(timeout=0.0) for _ in range(5)]
            assert rx.recv(timeout=0.0) is None
            for m, g in zip(sent, got):
                assert g is not m and g.arbitration_id == m.arbitration_id and not g.is_extended_id
                assert g.is_rx and g.channel == "light-test" and before <= g.timestamp <= time.time()
            assert [bytes(g.data) for g in got] == [bytes([i, 2, 3, 4, 5, 6, 7, 8]) for i in range(5)]
        assert light.recv(timeout=0.0) is None  # no own echo
        plain.send(_frame(7))
        assert light.recv(timeout=0.5).arbitration_id == 0x47 and other.recv(timeout=0.0).arbitration_id == 0x47
        t0 = time.monotonic()
        assert light.recv(timeout=0.05) is None and time.monotonic() - t0 >= 0.04
        light.set_filters([{"can_id": 0x41, "can_mask": 0x7FF}])
        for i in range(3):
            plain.send(_frame(i))
        # (as BusABC.recv does: a non-matching frame costs a call when timeout=0, so allow some time)
        assert light.recv(timeout=0.5).arbitration_id == 0x41 and light.recv(timeout=0.05) is None
    finally:
        for bus in (light, plain, other):
            bus.shutdown()
    assert "light-test" not in channels


# ---------------------------------------------------------------------------------------------------
# BatchSocketcanBus: what open_bus gives for socketcan (batched reads and writes, doorbell wake-ups)
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("msg", [
    can.Message(arbitration_id=0x7FF, data=b"\x01\x02\x03", is_extended_id=False),
    can.Message(arbitration_id=0x123, data=b"", is_extended_id=False),
    can.Message(arbitration_id=0x1ABCDE, data=bytes(range(8)), is_extended_id=True),
    can.Message(arbitration_id=0x10, is_remote_frame=True, dlc=4, is_extended_id=False),
    can.Message(arbitration_id=0x20, is_error_frame=True, data=b"\x00\x04", is_extended_id=False),
])
def test_classic_frame_bytes_are_python_cans(msg: can.Message) -> None:
    from can.interfaces.socketcan.socketcan import build_can_frame

    from comms.bus.socketcan_batch import classic_frame

    assert classic_frame(msg) == build_can_frame(msg)


def _burst(n: int, base: int = 0x100) -> list[can.Message]:
    return [can.Message(arbitration_id=base + i % 0x80, data=bytes([i & 0xFF, i >> 8, 3, 4, 5, 6, 7, 8][:1 + i % 8]),
                        is_extended_id=False) for i in range(n)]


def _read(bus: can.BusABC, n: int, timeout: float = 2.0) -> list[can.Message]:
    out = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        msg = bus.recv(timeout=0.2)
        if msg is not None:
            out.append(msg)
    return out


@pytest.mark.socketcan
def test_socketcan_recv_burst_takes_everything_queued_up_to_the_limit() -> None:
    """recv_burst on the batch bus (recv_queued: one call for the whole queue) gives the frames recv
    would give one by one, stops at ``limit`` and leaves the rest queued, in order."""
    a, b = open_bus("socketcan:vcan0"), open_bus("socketcan:vcan0")
    try:
        sent = _burst(30)
        assert transport.send_batch(a, sent) == len(sent)
        first = transport.recv_burst(b, 2.0, limit=4)
        assert first is not None and len(first) == 4
        rest = transport.recv_burst(b, 2.0)
        got = first.messages() + (rest.messages() if rest is not None else [])
        while len(got) < len(sent):
            more = transport.recv_burst(b, 2.0)
            assert more is not None
            got += more.messages()
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == [(m.arbitration_id, bytes(m.data)) for m in sent]
        assert transport.recv_burst(b, 0.0) is None
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.socketcan
def test_socketcan_batch_send_delivers_every_frame_in_order_to_both_bus_kinds() -> None:
    """A burst larger than one sendmmsg (BATCH) reaches a batch bus and python-can's own bus alike."""
    from comms.bus.socketcan_batch import BATCH, BatchSocketcanBus

    a, b = open_bus("socketcan:vcan0"), open_bus("socketcan:vcan0")
    plain = can.Bus(interface="socketcan", channel="vcan0")
    try:
        assert isinstance(a, BatchSocketcanBus)
        sent = _burst(BATCH + 36)
        assert transport.send_batch(a, sent) == len(sent)
        got = {}
        for bus in (b, plain):
            got[bus] = _read(bus, len(sent))
            assert [(m.arbitration_id, bytes(m.data), m.dlc) for m in got[bus]] == \
                   [(m.arbitration_id, bytes(m.data), m.dlc) for m in sent]
            stamps = [m.timestamp for m in got[bus]]
            assert stamps == sorted(stamps) and abs(stamps[0] - time.time()) < 60.0  # kernel times, in order

        def flags(m: can.Message) -> tuple:
            return m.is_rx, m.is_fd, m.is_extended_id, m.is_remote_frame, m.is_error_frame, m.channel

        assert [flags(m) for m in got[b]] == [flags(m) for m in got[plain]]  # as python-can reads them
        assert [round(m.timestamp, 6) for m in got[b]] == [round(m.timestamp, 6) for m in got[plain]]
        assert b.recv(timeout=0.0) is None
    finally:
        for bus in (a, b, plain):
            bus.shutdown()


@pytest.mark.socketcan
def test_socketcan_batch_bus_reads_what_python_can_sends() -> None:
    plain = can.Bus(interface="socketcan", channel="vcan0")
    b = open_bus("socketcan:vcan0")
    try:
        sent = [can.Message(arbitration_id=0x1ABCDE, data=b"\x09\x08", is_extended_id=True),
                can.Message(arbitration_id=0x42, is_remote_frame=True, dlc=3, is_extended_id=False)]
        for msg in sent:
            plain.send(msg)
        got = _read(b, 2)
        assert [(m.arbitration_id, m.is_extended_id, m.is_remote_frame, m.dlc) for m in got] == \
               [(0x1ABCDE, True, False, 2), (0x42, False, True, 3)]
        assert bytes(got[0].data) == b"\x09\x08"
    finally:
        plain.shutdown()
        b.shutdown()


@pytest.mark.socketcan
def test_socketcan_recv_waits_the_whole_timeout() -> None:
    bus = open_bus("socketcan:vcan0")
    try:
        start = time.monotonic()
        assert bus.recv(timeout=0.15) is None
        assert time.monotonic() - start >= 0.14
        assert bus.recv(timeout=0.0) is None
    finally:
        bus.shutdown()


@pytest.mark.socketcan
def test_socketcan_doorbell_wakes_only_for_watched_ids_and_loses_nothing() -> None:
    """wait_for ends on a watched id only; the frames before it stay queued, in order, for recv."""
    sim, fsw = open_bus("socketcan:vcan0"), open_bus("socketcan:vcan0")
    try:
        sim.watch([0x70])
        transport.send_batch(fsw, _burst(4, base=0x40))
        start = time.monotonic()
        assert sim.wait_for(0.1) is False  # unwatched frames do not ring
        assert time.monotonic() - start >= 0.09
        fsw.send(can.Message(arbitration_id=0x70, data=b"\x01", is_extended_id=False))
        assert sim.wait_for(2.0) is True
        assert [m.arbitration_id for m in _read(sim, 5)] == [0x40, 0x41, 0x42, 0x43, 0x70]
        assert sim.wait_for(0.0) is False  # the ring was consumed
        # a watched frame that rang while nobody waited is still reported (then consumed)
        fsw.send(can.Message(arbitration_id=0x70, data=b"\x02", is_extended_id=False))
        time.sleep(0.05)
        assert sim.wait_for(0.0) is True and sim.wait_for(0.0) is False
        assert sim.recv(timeout=1.0).arbitration_id == 0x70
    finally:
        sim.shutdown()
        fsw.shutdown()


def test_one_can_bitrate_range_for_every_check() -> None:
    """comms.bus.transport.CAN_BITRATE_RANGE_BPS: is_can_bitrate's bounds, keepout fsw --bitrate's, and the
    bounds the mission schema and the flight run's configuration give their bit rate."""
    import argparse

    from annotated_types import Ge, Le

    from cli.fsw import _bitrate
    from comms.bus.transport import CAN_BITRATE_RANGE_BPS, is_can_bitrate
    from fsw.config import BusConfig
    from hil_sim.mission.model import Mission

    lo, hi = CAN_BITRATE_RANGE_BPS
    assert is_can_bitrate(lo) and is_can_bitrate(hi) and is_can_bitrate(500_000)
    assert not any(is_can_bitrate(v) for v in (lo - 1, hi + 1, True, 500_000.0, "500000", None))
    assert _bitrate(str(lo)) == lo and _bitrate(str(hi)) == hi
    for text in (str(lo - 1), str(hi + 1), "fast"):
        with pytest.raises(argparse.ArgumentTypeError, match=f"allowed: {lo}..{hi}"):
            _bitrate(text)
    for field in (Mission.model_fields["bus_bitrate_bps"], BusConfig.model_fields["bitrate_bps"]):
        bounds = {type(m): m for m in field.metadata}
        assert (bounds[Ge].ge, bounds[Le].le) == CAN_BITRATE_RANGE_BPS
