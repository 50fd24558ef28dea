"""Truth model of the coarse sun sensors: cosine-law cells (as Basilisk's coarseSunSensor, without albedo).

Cell i with unit normal n_i (body axes) in a Sun of unit direction s (body axes, from the spacecraft) gives

    I_i = full_scale * f * cos(theta_i) + noise,  cos(theta_i) = n_i . s,  if theta_i <= field of view
    I_i = noise                                   otherwise,

clipped at 0 (a cell's current does not go negative) and f the sunlit fraction of the Sun's disc
(gnc.eclipse: 0 in umbra, between in penumbra), so every cell is dark in eclipse.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

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
    cos_theta = np.asarray(params.normals_B, dtype=float) @ np.asarray(sun_B, dtype=float)
    seen = cos_theta >= math.cos(math.radians(params.field_of_view_half_angle_deg))
    out = params.full_scale * float(sunlit_fraction) * np.where(seen, cos_theta, 0.0)
    if params.noise_std > 0.0:
        out = out + rng.normal(0.0, params.noise_std, out.shape)
    return np.maximum(out, 0.0)
