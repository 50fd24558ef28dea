"""The magnetic devices and the coarse sun sensors on the bus (missions with ``spacecraft.magnetometer``,
``.sun_sensors`` or ``.magnetorquers`` only): their parameters as built, and their node.

The truth models are hil_sim.world.magnetic_devices and hil_sim.world.sun_sensors; the Earth's field is the
run's centred dipole (hil_sim.world.environment.dipole_field_N, the kernel the dynamics' dipole torque uses).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from hil_sim.world.magnetic_devices import MagnetometerParams, MagnetorquerParams
from hil_sim.world.sun_sensors import SunSensorParams


@dataclass(frozen=True)
class MagneticParams:
    """What a spacecraft carries of the three devices (None: not fitted), the rods' command timeout [s], and
    the Earth's dipole at the epoch (Gauss coefficients (g10, g11, h11) [T], rotation angle at t = 0 [rad])."""

    magnetometer: MagnetometerParams | None = None
    sun_sensors: SunSensorParams | None = None
    magnetorquers: MagnetorquerParams | None = None
    mtq_cmd_timeout_s: float = 0.3
    geomagnetic_dipole_T: tuple[float, float, float] = (0.0, 0.0, 0.0)
    earth_rotation_angle_rad: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mtq_cmd_timeout_s) and self.mtq_cmd_timeout_s > 0):
            raise ValueError(f"MagneticParams.mtq_cmd_timeout_s: must be a finite number > 0 [s], "
                             f"got {self.mtq_cmd_timeout_s!r}")
        if self.sun_sensors is not None and len(self.sun_sensors.normals_B) > 6:
            raise ValueError("MagneticParams.sun_sensors: CSS_CURRENTS carries at most 6 cells")
        if self.magnetorquers is not None and len(self.magnetorquers.axes_B) != 3:
            raise ValueError("MagneticParams.magnetorquers: MTQ_COMMAND carries exactly 3 rods")

