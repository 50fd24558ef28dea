"""The contract between the flight software, the ground and the simulator: what crosses the bus and
the space link, defined once and used by every end.

- ``comms.bus``: the CAN ICD (the DBC through cantools, compiled into one codec table), CRC and E2E
  protection, the frame burst, the transports (SocketCAN, python-can's udp_multicast, batched I/O) and
  SecOC-style authentication.
- ``comms.dictionary``: the telemetry and telecommand dictionary (channels, packets, events, commands,
  their argument codec); ``comms.telemetry`` / ``comms.telecommand``: the CCSDS packet codecs;
  ``comms.link_security``: the space link's authentication and anti-replay.

It imports only ``gnc`` and libraries; ``fsw``, ``ground`` and ``hil_sim`` depend on it.
"""

import gnc  # noqa: F401,E402  first: arms the kernel cache locator (gnc/_after_numba.py)
