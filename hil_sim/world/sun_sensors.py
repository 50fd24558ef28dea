"""Truth model of the coarse sun sensors: cosine-law cells (as Basilisk's coarseSunSensor, without albedo).

Cell i with unit normal n_i (body axes) in a Sun of unit direction s (body axes, from the spacecraft) gives

    I_i = full_scale * f * cos(theta_i) + noise,  cos(theta_i) = n_i . s,  if theta_i <= field of view
    I_i = noise                                   otherwise,

clipped at 0 (a cell's current does not go negative) and f the sunlit fraction of the Sun's disc
(gnc.eclipse: 0 in umbra, between in penumbra), so every cell is dark in eclipse. The cells are computed by a
compiled kernel (hil_sim.world._magnetic_devices_nb), sampled every GNC tick.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil_sim.world._magnetic_devices_nb import sun_cells_nb

CUBE_FACES_B = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0),
                (0.0, 0.0, -1.0))


@dataclass(frozen=True)
class SunSensorParams:
    normals_B: tuple[tuple[float, float, float], ...] = CUBE_FACES_B  # one cell on each face of a cube
    field_of_view_half_angle_deg: float = 90.0
    full_scale: float = 1.0  # output at normal incidence in full Sun (the unit the bus carries, e.g. mA)
    noise_std: float = 0.0  # in full_scale's unit

    def __post_init__(self) -> None:
        normals = np.asarray(self.normals_B, dtype=float)
        if normals.ndim != 2 or normals.shape[1] != 3 or normals.shape[0] == 0:
            raise ValueError("sun sensors: one normal (3 numbers) per cell, at least one cell")
        if not np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-9):
            raise ValueError("sun sensors: every cell normal must be a unit vector")
        if not 0.0 < self.field_of_view_half_angle_deg <= 90.0:
            raise ValueError("sun sensors: the field of view's half-angle must be in (0, 90] deg")
        if not self.full_scale > 0.0:
            raise ValueError("sun sensors: full_scale must be > 0")


def sun_sensor_outputs(params: SunSensorParams, sun_B: np.ndarray, sunlit_fraction: float,
                       rng: np.random.Generator) -> np.ndarray:
    """Every cell's output for the unit Sun direction ``sun_B`` (body axes) at ``sunlit_fraction``."""
    return SunSensorModel(params).outputs(sun_B, sunlit_fraction, rng)


_EMPTY = np.zeros(0)  # no noise


class SunSensorModel:
    """`sun_sensor_outputs` with its parameters as arrays, made once: what a node samples every tick."""

    def __init__(self, params: SunSensorParams) -> None:
        self.params = params
        self.normals_B = np.asarray(params.normals_B, dtype=float)
        self.cos_fov = math.cos(math.radians(params.field_of_view_half_angle_deg))

    def outputs(self, sun_B: np.ndarray, sunlit_fraction: float, rng: np.random.Generator) -> np.ndarray:
        """Every cell's output (as `sun_sensor_outputs`)."""
        p = self.params
        n = self.normals_B.shape[0]
        noise = rng.normal(0.0, p.noise_std, (n,)) if p.noise_std > 0.0 else _EMPTY
        return sun_cells_nb(self.normals_B, np.asarray(sun_B, dtype=float), self.cos_fov,
                            p.full_scale * float(sunlit_fraction), noise, np.empty(n))
