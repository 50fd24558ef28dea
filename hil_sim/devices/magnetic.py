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
from gnc.eclipse import sunlit_fraction
from hil_sim.devices.nodes import _row_maker
from hil_sim.world import environment as env
from hil_sim.world.ephemeris import spline_eval
from hil_sim.world._magnetic_devices_nb import held_rods_nb, to_body_nb
from hil_sim.world.magnetic_devices import MagnetometerModel, MagnetometerParams, MagnetorquerParams
from hil_sim.world.sun_sensors import SunSensorModel, SunSensorParams


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
        # the truth models' parameters as arrays, made once (sampled every tick)
        self._magnetometer = (MagnetometerModel(params.magnetometer, params.magnetorquers)
                              if params.magnetometer is not None else None)
        self._sun_sensors = SunSensorModel(params.sun_sensors) if params.sun_sensors is not None else None
        rods = params.magnetorquers
        self._rod_limit = np.asarray(rods.max_dipole_Am2 if rods is not None else (0.0,) * 3, dtype=float)
        self._rod_limits = tuple(float(m) for m in self._rod_limit)
        self._rod_axes_T = np.ascontiguousarray(np.asarray(rods.axes_B if rods is not None else np.zeros((3, 3)),
                                                           dtype=float).T)

    # --------------------------------------------------------------------------------------- rods
    def on_command(self, dipoles_Am2: Sequence[float], t_s: float) -> None:
        """A valid MTQ_COMMAND (already E2E-checked) arrived at simulation time ``t_s``."""
        self.command_Am2[:] = dipoles_Am2
        self.last_command_s = t_s
        self.commands += 1

    def _live(self, t_s: float) -> bool:
        """A valid command within the timeout at ``t_s`` (and rods to take it)."""
        return self.params.magnetorquers is not None and t_s - self.last_command_s <= self.params.mtq_cmd_timeout_s

    def _held(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(each rod's dipole, the rods' dipole in body axes) [A m^2] at ``t_s``, new arrays."""
        held, body = np.empty(3), np.empty(3)
        held_rods_nb(self._live(t_s), self.command_Am2, self._rod_limit, self._rod_axes_T, held, body)
        return held, body

    def held_Am2(self, t_s: float) -> np.ndarray:
        """Each rod's dipole [A m^2] at ``t_s``: the command clipped to its saturation, zero without a valid
        command within the timeout (or without rods)."""
        return self._held(t_s)[0]

    def rods_dipole_B(self, t_s: float) -> np.ndarray:
        """The rods' dipole in body axes [A m^2] held from ``t_s`` on."""
        return self._held(t_s)[1]

    # ------------------------------------------------------------------------------------ sensing
    def field_B_T(self, world: Any) -> np.ndarray:
        """The Earth's field [T] in body axes at the world's time, position and attitude."""
        b = world.batch
        r = b.r_sc_N_km[0]
        rows = env.field_model_rows(b.B)  # IGRF, where the mission asks for it: the dynamics' own rows
        kernel, rows = (env.dipole_field_N, self._field_rows) if rows is None else (env.earth_field_N, rows)
        n = kernel(rows, 0, float(r[0]), float(r[1]), float(r[2]), float(world.t))
        return to_body_nb(b.q_NB[0], *n)

    def _sun_B(self, world: Any) -> tuple[np.ndarray, float]:
        """The Sun's unit direction in body axes and the sunlit fraction of its disc at the world's time."""
        b = world.batch
        eph_t0, sun_c, _ = b.ephemeris.table
        sun_km = np.empty(3)
        spline_eval(sun_c, eph_t0, b.ephemeris.node_spacing_s, float(world.t), sun_km)
        frac = float(sunlit_fraction(b.r_sc_N_km[0], sun_km))
        sun_N = b.sun_N[0]
        return to_body_nb(b.q_NB[0], sun_N[0], sun_N[1], sun_N[2]), frac

    def rows(self, world: Any, t_s: float) -> list[tuple[int, list]]:
        """The tick's frames (message index, value row), in the order they go out: MAG_FIELD, CSS_CURRENTS,
        MTQ_STATUS (each only when its device is fitted)."""
        p = self.params
        out = []
        held = self._held(t_s)[0]
        if self._magnetometer is not None:
            reading = self._magnetometer.sample(self.field_B_T(world), held, self.mag_rng)
            hi = self._mag_hi
            bx, by, bz = (min(max(1e6 * v, -hi), hi) for v in reading.tolist())
            out.append((self.mag_m, self._mag_row(b_x=bx, b_y=by, b_z=bz, valid=1.0)))
        if self._sun_sensors is not None:
            sun_B, frac = self._sun_B(world)
            cells = [min(v, self._css_hi) for v in self._sun_sensors.outputs(sun_B, frac, self.css_rng).tolist()]
            values = {f"cell_{i + 1}": v for i, v in enumerate(cells)}
            out.append((self.css_m, self._css_row(n_cells=float(len(cells)), **values)))
        if p.magnetorquers is not None:
            live = self._live(t_s)
            bits = sum(1 << i for i, (c, m) in enumerate(zip(self.command_Am2.tolist(), self._rod_limits))
                       if live and abs(c) > m)
            d1, d2, d3 = held.tolist()
            out.append((self.status_m, self._status_row(dipole_1=d1, dipole_2=d2, dipole_3=d3, saturated=float(bits))))
        return out
