"""A run's start does not depend on luck with the host's ports.

The simulator's udp_multicast bus port is drawn among the host's ephemeral ports: a client socket that sent
without binding holds such a port on every address and blocks the group's bind. A run draws again then.
(The flight software's telecommand socket is reserved by the orchestrator and handed over: tests/fsw.)
"""
from __future__ import annotations

import socket
from types import SimpleNamespace

import pytest

import can

import comms.bus.transport as transport
from ground.link import Endpoints
from hil_sim.sil import orchestrator as sil


def _parts(tmp_path, bus: str):
    info = transport.resolve_spec(bus)
    mission = SimpleNamespace(bus=bus, bus_bitrate_bps=None)
    endpoints = Endpoints(run_id="r", tm_transport="udp-multicast", tm_host="239.1.1.1", tm_port=0,
                          tc_host="127.0.0.1", tc_port=0, bus=info.spec)
    return sil._RunParts(SimpleNamespace(), mission, tmp_path, info, endpoints)


@pytest.fixture
def taken_port():
    """A port held on every address, as an unbound client socket's ephemeral port is."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("0.0.0.0", 0))
        yield holder.getsockname()[1]


def test_a_drawn_bus_port_that_another_socket_holds_is_drawn_again(tmp_path, monkeypatch, taken_port):
    draws = iter([("239.74.1.1", taken_port)])
    real = transport.random_udp_endpoint
    monkeypatch.setattr(transport, "random_udp_endpoint", lambda: next(draws, None) or real())
    run = _parts(tmp_path, "udp_multicast")
    assert run.bus_info.port == taken_port
    sil._open_simulator_bus(run)
    try:
        assert run.bus_info.port != taken_port
        assert run.endpoints.bus == run.bus_info.spec  # what the ground and the flight software will be told
        run.bus.send(can.Message(arbitration_id=0x10, data=b"\x01", is_extended_id=False))
    finally:
        run.bus.shutdown()


def test_a_bus_the_mission_names_is_not_replaced_by_another(tmp_path, taken_port):
    run = _parts(tmp_path, f"udp_multicast:239.74.1.2:{taken_port}")
    with pytest.raises(sil.RunNotStarted, match=f"udp_multicast:239.74.1.2:{taken_port} cannot be opened"):
        sil._open_simulator_bus(run)
    assert run.bus is None
