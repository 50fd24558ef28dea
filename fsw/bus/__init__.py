"""The spacecraft bus: ICD (DBC via cantools), end-to-end protection, transports, flight-side driver.

``open_bus(spec)``, ``Icd``, ``E2EReceiver`` and the driver's sample types are re-exported here; heavy
modules (cantools, python-can, numba for the burst codec in ``fsw.bus.kernels``) load on first use of this
package only.
"""
from fsw.bus.driver import FswBusDriver, ImuSample, LatestInputs, StarTrackerSample, TickInputs, WheelStatus
from fsw.bus.crc import crc8_sae_j1850, e2e_crc
from fsw.bus.e2e import E2EReceiver, ReceivedFrame
from fsw.bus.icd import DEFAULT_DBC_PATH, E2ESender, Icd, IcdError, MessageSpec
from fsw.bus.transport import (
    BusInfo,
    BusSpecError,
    BusUnavailableError,
    open_bus,
    resolve_spec,
    random_udp_endpoint,
    vcan_hint,
)

__all__ = [
    "BusInfo", "BusSpecError", "BusUnavailableError", "DEFAULT_DBC_PATH", "E2EReceiver", "E2ESender",
    "FswBusDriver", "Icd", "IcdError", "ImuSample", "LatestInputs", "MessageSpec", "ReceivedFrame",
    "StarTrackerSample", "TickInputs", "WheelStatus", "crc8_sae_j1850", "e2e_crc", "open_bus",
    "resolve_spec", "random_udp_endpoint", "vcan_hint",
]
