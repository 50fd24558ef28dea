"""The magnetic devices' truth models and the unloading law's cycle written with numpy arrays, test oracles:
hil_sim.world._magnetic_devices_nb and fsw._momentum_nb write the same sums out on scalars and must agree.
"""
from __future__ import annotations

import math

import numpy as np

from gnc.attitude import quat_to_dcm
from gnc.magnetic import saturate_dipole, unloading_dipole


def rod_dipoles(command_Am2: np.ndarray, limit_Am2: np.ndarray) -> np.ndarray:
    """Each rod's dipole: the command clipped to its saturation, NaN as 0."""
    cmd = np.nan_to_num(np.asarray(command_Am2, dtype=float), nan=0.0)
    limit = np.asarray(limit_Am2, dtype=float)
    return np.clip(cmd, -limit, limit)


def magnetometer_reading(b_B_T, coupling, rods_Am2, R_BS, bias_S_T, noise_S_T, resolution_T, full_scale_T):
    """The magnetometer's reading in sensor axes (``rods_Am2``/``noise_S_T`` None: left out)."""
    b = np.asarray(b_B_T, dtype=float)
    if rods_Am2 is not None:
        b = b + np.asarray(coupling, dtype=float) @ rods_Am2
    reading = R_BS.T @ b + np.asarray(bias_S_T, dtype=float)
    if noise_S_T is not None:
        reading = reading + noise_S_T
    if resolution_T > 0.0:
        reading = np.round(reading / resolution_T) * resolution_T
    return np.clip(reading, -full_scale_T, full_scale_T)


def sun_cells(normals_B, sun_B, half_angle_deg, full_scale, sunlit_fraction, noise):
    """Every cosine-law cell's output (``noise`` None: none)."""
    cos_theta = np.asarray(normals_B, dtype=float) @ np.asarray(sun_B, dtype=float)
    seen = cos_theta >= math.cos(math.radians(half_angle_deg))
    out = full_scale * float(sunlit_fraction) * np.where(seen, cos_theta, 0.0)
    if noise is not None:
        out = out + noise
    return np.maximum(out, 0.0)


def to_body(q_NB, v_N) -> np.ndarray:
    """``R_NB^T v``."""
    return quat_to_dcm(q_NB).T @ np.asarray(v_N, dtype=float)


def unloading_step(G, Js, wheel_speed, bias, R_BS, b_S, gain, rods_pinv, max_Am2):
    """(|h_excess|, finite, rods' dipoles or None) of one unloading cycle."""
    h_excess = G @ (Js * np.asarray(wheel_speed, dtype=float)) - bias
    norm = float(np.linalg.norm(h_excess))
    b_S = np.asarray(b_S, dtype=float)
    if not (np.all(np.isfinite(b_S)) and np.all(np.isfinite(h_excess))):
        return norm, False, None
    m_B = unloading_dipole(h_excess, R_BS @ b_S, gain, np.full(3, np.inf))
    return norm, True, saturate_dipole(rods_pinv @ m_B, max_Am2)
