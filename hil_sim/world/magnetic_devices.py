"""Truth models of the magnetic devices: three magnetorquer rods and a three-axis magnetometer.

Magnetorquers (as Basilisk's MtbEffector): each rod i along the body unit axis g_i takes a dipole command,
clipped to its own saturation +-m_max_i; the body dipole is m_B = sum_i g_i m_i, and the torque on the
spacecraft m_B x B_B. A rod that is on also makes a field at the magnetometer: B_dist = C m_cmd (C, 3 x 3 in
T per A m^2, measured on the built spacecraft), which is why flight software samples the magnetometer in a
window with the rods off (duty cycling).

Magnetometer (as Basilisk's magnetometer module, plus the rods' field): the field in sensor axes
B_S = R_SB (B_B + C m_cmd) + bias + noise, quantised to the resolution and clipped at the full-scale range.

Random numbers come from numpy Generators owned by the caller, as for the other sensor models. The sums are
compiled kernels (hil_sim.world._magnetic_devices_nb): sampled every GNC tick, numpy's per-call overhead on
3-vectors cost more than the arithmetic.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnc.attitude import quat_to_dcm
from hil_sim.world._magnetic_devices_nb import clip_rods_nb, magnetometer_nb


@dataclass(frozen=True)
class MagnetorquerParams:
    axes_B: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    max_dipole_Am2: tuple[float, ...] = (0.2, 0.2, 0.2)
    # field at the magnetometer [T] per commanded A m^2 of each rod (columns: rods), in body axes
    magnetometer_coupling_T_per_Am2: tuple[tuple[float, float, float], ...] = ((0.0,) * 3,) * 3

    def __post_init__(self) -> None:
        axes = np.asarray(self.axes_B, dtype=float)
        if axes.ndim != 2 or axes.shape[1] != 3 or len(self.max_dipole_Am2) != axes.shape[0]:
            raise ValueError("magnetorquers: one axis (3 numbers) and one saturation per rod")
        if not np.allclose(np.linalg.norm(axes, axis=1), 1.0, atol=1e-9):
            raise ValueError("magnetorquers: every rod axis must be a unit vector")
        if not all(m > 0.0 and np.isfinite(m) for m in self.max_dipole_Am2):
            raise ValueError("magnetorquers: every rod's saturation must be a finite dipole > 0 A m^2")


@dataclass(frozen=True)
class MagnetometerParams:
    q_BS: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # sensor axes in body axes, scalar first
    noise_std_T: float = 0.0
    bias_S_T: tuple[float, float, float] = (0.0, 0.0, 0.0)
    resolution_T: float = 0.0  # 0: not quantised
    full_scale_T: float = 1e-4  # +-100 uT, a typical small-satellite magnetometer's range


def rod_dipoles(params: MagnetorquerParams, command_Am2: np.ndarray) -> np.ndarray:
    """Each rod's dipole [A m^2]: the command clipped to that rod's saturation (NaN commands give 0)."""
    cmd = np.asarray(command_Am2, dtype=float)
    return clip_rods_nb(cmd, np.asarray(params.max_dipole_Am2, dtype=float), np.empty(cmd.shape))


def body_dipole(params: MagnetorquerParams, command_Am2: np.ndarray) -> np.ndarray:
    """The rods' dipole in body axes [A m^2] for a per-rod command."""
    return np.asarray(params.axes_B, dtype=float).T @ rod_dipoles(params, command_Am2)


def magnetorquer_torque_B(params: MagnetorquerParams, command_Am2: np.ndarray, b_B_T: np.ndarray) -> np.ndarray:
    """Torque [N m] of the rods on the spacecraft in the body-frame field ``b_B_T``: m_B x B_B."""
    return np.cross(body_dipole(params, command_Am2), np.asarray(b_B_T, dtype=float))


def magnetometer_sample(params: MagnetometerParams, b_B_T: np.ndarray, rods: MagnetorquerParams | None,
                        command_Am2: np.ndarray | None, rng: np.random.Generator) -> np.ndarray:
    """The magnetometer's reading [T] in sensor axes, with the rods' own field while they are on."""
    held = rod_dipoles(rods, command_Am2) if rods is not None and command_Am2 is not None else _EMPTY
    return MagnetometerModel(params, rods).sample(b_B_T, held, rng)


_EMPTY = np.zeros(0)  # no rods' field, no noise


class MagnetometerModel:
    """`magnetometer_sample` with its parameters as arrays, made once: what a node samples every tick."""

    def __init__(self, params: MagnetometerParams, rods: MagnetorquerParams | None) -> None:
        self.params = params
        self.coupled = rods is not None
        self.coupling = (np.asarray(rods.magnetometer_coupling_T_per_Am2, dtype=float) if rods is not None
                         else np.zeros((3, 0)))
        self.R_BS = quat_to_dcm(np.asarray(params.q_BS, dtype=float))
        self.bias_S_T = np.asarray(params.bias_S_T, dtype=float)

    def sample(self, b_B_T: np.ndarray, rods_Am2: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The reading [T] in sensor axes for the body field ``b_B_T`` and the rods' held dipoles
        ``rods_Am2`` (length 0, or no rods fitted: their field left out); the noise drawn from ``rng`` when
        there is any."""
        p = self.params
        if not self.coupled:
            rods_Am2 = _EMPTY
        noise = rng.normal(0.0, p.noise_std_T, 3) if p.noise_std_T > 0.0 else _EMPTY
        return magnetometer_nb(np.asarray(b_B_T, dtype=float), self.coupling, rods_Am2, self.R_BS, self.bias_S_T,
                               noise, float(p.resolution_T), float(p.full_scale_T), np.empty(3))
