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
"""
from __future__ import annotations

import socket
import struct
from typing import Any

import can
from can import CanProtocol
from can.interfaces.udp_multicast.bus import GeneralPurposeUdpMulticastBus, UdpMulticastBus
from can.interfaces.udp_multicast.utils import is_msgpack_installed

LOOPBACK = "127.0.0.1"
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)


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
