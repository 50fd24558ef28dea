"""The spacecraft bus contract: ICD (DBC via cantools), end-to-end protection, transports, authentication.

``open_bus(spec)``, ``Icd`` and ``E2EReceiver`` are re-exported here; heavy modules (cantools, python-can,
numba for the burst codec in ``comms.bus.kernels``) load on first use of this package only. The flight
software's driver is ``fsw.bus``, the simulator's devices ``hil_sim.devices.nodes``: both ends use this codec.
"""
from comms.bus.crc import crc8_sae_j1850, e2e_crc
from comms.bus.e2e import E2EReceiver, ReceivedFrame
from comms.bus.icd import DEFAULT_DBC_PATH, E2ESender, Icd, IcdError, MessageSpec
from comms.bus.transport import (
    BusInfo,
    BusSpecError,
    BusUnavailableError,
    open_bus,
    resolve_spec,
    random_udp_endpoint,
    vcan_hint,
)

__all__ = [
    "BusInfo", "BusSpecError", "BusUnavailableError", "DEFAULT_DBC_PATH", "E2EReceiver", "E2ESender", "Icd",
    "IcdError", "MessageSpec", "ReceivedFrame", "crc8_sae_j1850", "e2e_crc", "open_bus", "resolve_spec",
    "random_udp_endpoint", "vcan_hint",
]
