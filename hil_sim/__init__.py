"""keepout.hil_sim: the world the flight software lives in (truth dynamics, sensors, actuators,
ephemeris truth, virtual CAN devices, the SIL orchestrator, campaigns and reports)."""

import gnc  # noqa: F401,E402  first: arms the kernel cache locator (gnc/_after_numba.py)
