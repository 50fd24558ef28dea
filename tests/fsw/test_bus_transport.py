"""Transport specs, the vcan hint, udp_multicast isolation, and SocketCAN (in the vcan VM)."""
from __future__ import annotations

import time

import can
import pytest

from fsw.bus import transport
from fsw.bus.transport import (BusSpecError, BusUnavailableError, open_bus, resolve_spec, udp_endpoint_for_run)


def test_resolve_explicit_specs() -> None:
    assert resolve_spec("socketcan:vcan1").channel == "vcan1"
    assert resolve_spec("socketcan").channel == "vcan0"
    info = resolve_spec("udp_multicast:239.74.1.2:45000")
    assert (info.interface, info.channel, info.port) == ("udp_multicast", "239.74.1.2", 45000)
    assert resolve_spec("virtual:abc").spec == "virtual:abc"


@pytest.mark.parametrize("bad", ["can:0", "udp_multicast:239.1.1.1", "udp_multicast:239.1.1.1:x",
                                 "udp_multicast:239.1.1.1:80", "auto:vcan0", "socketcan:a:b"])
def test_bad_specs_name_the_accepted_forms(bad: str) -> None:
    with pytest.raises(BusSpecError, match="accepted|GROUP|PORT|auto"):
        resolve_spec(bad)


def test_udp_endpoint_depends_on_run_id_only() -> None:
    a, b = udp_endpoint_for_run("run-a"), udp_endpoint_for_run("run-b")
    assert a == udp_endpoint_for_run("run-a")
    assert a[0] != b[0] and a[1] != b[1]
    assert resolve_spec("udp_multicast", run_id="run-a").spec == f"udp_multicast:{a[0]}:{a[1]}"


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
    a1, a2 = open_bus("udp_multicast", run_id="iso-a"), open_bus("udp_multicast", run_id="iso-a")
    b1 = open_bus("udp_multicast", run_id="iso-b")
    try:
        assert _ping(a1, a2, 0x123) is not None
        a1.send(can.Message(arbitration_id=0x124, data=b"\x00", is_extended_id=False))
        time.sleep(0.2)
        heard = [m for m in iter(lambda: b1.recv(timeout=0.05), None)]
        assert heard == []
    finally:
        for bus in (a1, a2, b1):
            bus.shutdown()


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
