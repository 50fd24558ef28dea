"""The magnetic devices and the coarse sun sensors on the bus (missions with ``spacecraft.magnetometer``,
``.sun_sensors`` or ``.magnetorquers`` only): their parameters as built, and their node.

The truth models are hil_sim.world.magnetic_devices and hil_sim.world.sun_sensors; the Earth's field is the
run's centred dipole (hil_sim.world.environment.dipole_field_N, the kernel the dynamics' dipole torque uses).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from comms.bus.icd import Icd
from gnc.attitude import quat_to_dcm
from gnc.eclipse import sunlit_fraction
from hil_sim.devices.nodes import _row_maker
from hil_sim.world import environment as env
from hil_sim.world.ephemeris import spline_eval
from hil_sim.world.magnetic_devices import MagnetometerParams, MagnetorquerParams, magnetometer_sample, rod_dipoles
from hil_sim.world.sun_sensors import SunSensorParams, sun_sensor_outputs


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


class MagneticNodes:
    """Nodes MAG, CSS and MTQ of one spacecraft (each only when fitted): the frames they send every GNC tick,
    sampled at the tick's time, and the rods' command state.

    The rods hold the latest valid MTQ_COMMAND (each clipped to its saturation) until ``mtq_cmd_timeout_s``
    without one, then zero. Over a GNC period they hold what they held at its start; the simulator adds their
    body dipole to the run's dipole row, so the dynamics' dipole-torque kernel applies residual + rods
    (``rods_dipole_B``). Each device draws its noise from its own generator (seeded from ``seed``), so fitting
    one does not change another's numbers."""

    def __init__(self, icd: Icd, params: MagneticParams, seed: int = 0) -> None:
        self.params = params
        self.mag_rng, self.css_rng = (np.random.default_rng([seed, 0x4D41, k]) for k in (0, 1))
        self.command_Am2 = np.zeros(3)
        self.last_command_s = math.nan
        self.commands = 0
        # the Earth's dipole in the rows dipole_field_N reads (the kernel the dynamics' dipole torque uses)
        self._field_rows = np.zeros((env.ENV_ERA0 + 1, 1))
        g10, g11, h11 = params.geomagnetic_dipole_T
        self._field_rows[env.ENV_EARTH_DIPOLE:env.ENV_EARTH_DIPOLE + 3, 0] = (g11, h11, g10)
        self._field_rows[env.ENV_ERA0, 0] = params.earth_rotation_angle_rad
        self._field_rows[env.ENV_OMEGA_E, 0] = env.EARTH_ROTATION_RAD_S
        self.mag_m, self._mag_row = _row_maker(icd, "MAG_FIELD")
        self.css_m, self._css_row = _row_maker(icd, "CSS_CURRENTS")
        self.status_m, self._status_row = _row_maker(icd, "MTQ_STATUS")
        self.command_id = icd.spec("MTQ_COMMAND").frame_id
        self.command_cols = [icd.column("MTQ_COMMAND", f"dipole_{i}") for i in (1, 2, 3)]
        self._mag_hi = icd.signal_range("MAG_FIELD", "b_x")[1]
        self._css_hi = icd.signal_range("CSS_CURRENTS", "cell_1")[1]

    # --------------------------------------------------------------------------------------- rods
    def on_command(self, dipoles_Am2: Sequence[float], t_s: float) -> None:
        """A valid MTQ_COMMAND (already E2E-checked) arrived at simulation time ``t_s``."""
        self.command_Am2[:] = dipoles_Am2
        self.last_command_s = t_s
        self.commands += 1

    def held_Am2(self, t_s: float) -> np.ndarray:
        """Each rod's dipole [A m^2] at ``t_s``: the command clipped to its saturation, zero without a valid
        command within the timeout (or without rods)."""
        rods = self.params.magnetorquers
        if rods is None or not t_s - self.last_command_s <= self.params.mtq_cmd_timeout_s:
            return np.zeros(3)
        return rod_dipoles(rods, self.command_Am2)

    def rods_dipole_B(self, t_s: float) -> np.ndarray:
        """The rods' dipole in body axes [A m^2] held from ``t_s`` on."""
        rods = self.params.magnetorquers
        if rods is None:
            return np.zeros(3)
        return np.asarray(rods.axes_B, dtype=float).T @ self.held_Am2(t_s)

    # ------------------------------------------------------------------------------------ sensing
    def field_B_T(self, world: Any) -> np.ndarray:
        """The Earth's field [T] in body axes at the world's time, position and attitude."""
        b = world.batch
        r = b.r_sc_N_km[0]
        rows = env.field_model_rows(b.B)  # IGRF, where the mission asks for it: the dynamics' own rows
        kernel, rows = (env.dipole_field_N, self._field_rows) if rows is None else (env.earth_field_N, rows)
        n = kernel(rows, 0, float(r[0]), float(r[1]), float(r[2]), float(world.t))
        return quat_to_dcm(b.q_NB[0]).T @ np.array(n)

    def _sun_B(self, world: Any) -> tuple[np.ndarray, float]:
        """The Sun's unit direction in body axes and the sunlit fraction of its disc at the world's time."""
        b = world.batch
        eph_t0, sun_c, _ = b.ephemeris.table
        sun_km = np.empty(3)
        spline_eval(sun_c, eph_t0, b.ephemeris.node_spacing_s, float(world.t), sun_km)
        frac = float(sunlit_fraction(b.r_sc_N_km[0], sun_km))
        return quat_to_dcm(b.q_NB[0]).T @ b.sun_N[0], frac

    def rows(self, world: Any, t_s: float) -> list[tuple[int, list]]:
        """The tick's frames (message index, value row), in the order they go out: MAG_FIELD, CSS_CURRENTS,
        MTQ_STATUS (each only when its device is fitted)."""
        p = self.params
        out = []
        if p.magnetometer is not None:
            reading = magnetometer_sample(p.magnetometer, self.field_B_T(world), p.magnetorquers,
                                          self.held_Am2(t_s), self.mag_rng)
            bx, by, bz = np.clip(1e6 * reading, -self._mag_hi, self._mag_hi).tolist()
            out.append((self.mag_m, self._mag_row(b_x=bx, b_y=by, b_z=bz, valid=1.0)))
        if p.sun_sensors is not None:
            sun_B, frac = self._sun_B(world)
            cells = np.minimum(sun_sensor_outputs(p.sun_sensors, sun_B, frac, self.css_rng), self._css_hi).tolist()
            values = {f"cell_{i + 1}": v for i, v in enumerate(cells)}
            out.append((self.css_m, self._css_row(n_cells=float(len(cells)), **values)))
        if p.magnetorquers is not None:
            held = self.held_Am2(t_s)
            live = t_s - self.last_command_s <= p.mtq_cmd_timeout_s
            clipped = np.abs(self.command_Am2) > np.asarray(p.magnetorquers.max_dipole_Am2) if live else ()
            bits = sum(1 << i for i, c in enumerate(clipped) if c)
            d1, d2, d3 = held.tolist()
            out.append((self.status_m, self._status_row(dipole_1=d1, dipole_2=d2, dipole_3=d3, saturated=float(bits))))
        return out
