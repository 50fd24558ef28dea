"""The flight software's side of the bus: the driver that reads sensor frames into the GNC cycle's
inputs and writes wheel commands (the ICD, E2E and transports it uses are ``comms.bus``)."""
from fsw.bus.driver import FswBusDriver, ImuSample, LatestInputs, StarTrackerSample, TickInputs, WheelStatus

__all__ = ["FswBusDriver", "ImuSample", "LatestInputs", "StarTrackerSample", "TickInputs", "WheelStatus"]
