"""Sensor models: rate gyro (IMU) and star tracker, for a batch of M runs (a single World is M = 1).

Random numbers come from numpy Generators owned by the caller (one per model, see hil_sim.world.world); the
kernels here are deterministic functions of the state, the parameters and the normals passed in.

Gyro (per axis, body axes), at each sample k with period T = 1 / rate_hz and elapsed time dt since the
previous sample:
  bias_k   = bias_{k-1} + K sqrt(dt) n1           (rate random walk / "bias instability" as a random walk)
  omega_m  = (1 + s) omega_true + bias_k + (N / sqrt(T)) n2   (N = angle random walk, rad/sqrt(s))
  omega_m  = clip(omega_m, -sat, sat); then quantised to multiples of q (round to nearest).
The angle random walk is sampled with the sensor's own period T, so the Allan deviation at tau = T is N/sqrt(T).

Star tracker: q_NS_meas = q_NB (x) q_BS (x) dq(e), e = (sx n1, sx n2, sz n3) a small rotation in the sensor frame
(z = boresight, sx cross-boresight, sz about-boresight std). Invalid (blind_source 1 Sun, 2 Moon, 3 rate) when
the angle between the boresight and the Sun (Moon) direction from the spacecraft is below the exclusion
half-angle, or |omega_BN_B| is above the tracking limit; checked in that order. When invalid the last valid
measurement is repeated (identity before any), with valid = False, like a tracker's held output.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np
from numba import njit

from hil_sim.world.params import ImuParams, StarTrackerParams

# Gyro parameter layout P[m, :]
G_SF, G_SAT, G_QUANT, G_ARW_STD, G_RRW, G_INV_QUANT = 0, 3, 4, 5, 6, 7
G_FIELDS = 8
# Star tracker parameter layout P[m, :]
S_Q_BS, S_BORESIGHT_B, S_CROSS, S_ABOUT, S_COS_SUN, S_COS_MOON, S_MAX_RATE = 0, 4, 7, 8, 9, 10, 11
S_FIELDS = 12

BLIND_NONE, BLIND_SUN, BLIND_MOON, BLIND_RATE = 0, 1, 2, 3
_ARCSEC = math.pi / (180.0 * 3600.0)


class ImuSample(NamedTuple):
    omega_BN_B: np.ndarray  # measured body rate, rad/s (3,)
    saturated: bool  # any axis clipped at the saturation limit
    t: float  # sample time, s since epoch


class StarTrackerSample(NamedTuple):
    q_NS: np.ndarray  # measured attitude of the sensor frame, scalar first (4,)
    valid: bool
    blind_source: int  # 0 none, 1 sun, 2 moon, 3 rate


def pack_gyro(params: Sequence[ImuParams]) -> np.ndarray:
    P = np.zeros((len(params), G_FIELDS))
    for m, p in enumerate(params):
        P[m, G_SF:G_SF + 3] = np.asarray(p.scale_factor_ppm) * 1e-6
        P[m, G_SAT] = p.saturation_rad_s
        P[m, G_QUANT] = p.quantisation_rad_s
        P[m, G_INV_QUANT] = 1.0 / p.quantisation_rad_s if p.quantisation_rad_s > 0.0 else 0.0
        P[m, G_ARW_STD] = p.angle_random_walk_rad_per_sqrt_s * math.sqrt(p.rate_hz)
        P[m, G_RRW] = p.bias_random_walk_rad_s_per_sqrt_s
    return P


def pack_star_tracker(params: Sequence[StarTrackerParams]) -> np.ndarray:
    from gnc.attitude import quat_rotate

    P = np.zeros((len(params), S_FIELDS))
    for m, p in enumerate(params):
        P[m, S_Q_BS:S_Q_BS + 4] = p.q_BS
        P[m, S_BORESIGHT_B:S_BORESIGHT_B + 3] = quat_rotate(np.asarray(p.q_BS), np.asarray(p.boresight_S))
        P[m, S_CROSS] = p.cross_boresight_std_arcsec * _ARCSEC
        P[m, S_ABOUT] = p.about_boresight_std_arcsec * _ARCSEC
        P[m, S_COS_SUN] = math.cos(math.radians(p.sun_exclusion_deg))
        P[m, S_COS_MOON] = math.cos(math.radians(p.moon_exclusion_deg))
        P[m, S_MAX_RATE] = math.radians(p.max_rate_deg_s)
    return P


def sensor_frame_basis_S(boresight_S: np.ndarray) -> np.ndarray:
    """Orthonormal basis (rows e1, e2, b) of the sensor frame with b the boresight: the star tracker's error
    axes (cross, cross, about). For the default boresight +z this is the identity."""
    b = np.asarray(boresight_S, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(b[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(helper, b)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(b, e1)
    if np.allclose(b, [0.0, 0.0, 1.0]):
        return np.eye(3)
    return np.stack([e1, e2, b])


@njit(cache=True, error_model="numpy")
def gyro_sample_batch(X, BIAS, P, NORMALS, dt_since_s, OUT, SAT):
    """Gyro samples for all runs. X (7+N, M) dynamics state (run axis last, see hil_sim.world.dynamics); OUT (M,3). BIAS (M,3) updated in place; NORMALS flat (M*6,): per run 3 bias-walk then 3 ARW normals."""
    M = X.shape[1]
    sq = math.sqrt(max(dt_since_s, 0.0))
    for m in range(M):
        sat_lim = P[m, G_SAT]
        q = P[m, G_QUANT]
        any_sat = False
        for j in range(3):
            BIAS[m, j] += P[m, G_RRW] * sq * NORMALS[6 * m + j]
            w = (1.0 + P[m, G_SF + j]) * X[4 + j, m] + BIAS[m, j] + P[m, G_ARW_STD] * NORMALS[6 * m + 3 + j]
            if w > sat_lim:
                w = sat_lim
                any_sat = True
            elif w < -sat_lim:
                w = -sat_lim
                any_sat = True
            if q > 0.0:
                w = q * math.floor(w * P[m, G_INV_QUANT] + 0.5)
            OUT[m, j] = w
        SAT[m] = any_sat


@njit(cache=True, inline="always", error_model="numpy")
def _qmul(p0, p1, p2, p3, q0, q1, q2, q3):
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


@njit(cache=True, error_model="numpy")
def star_tracker_sample_batch(X, P, BASIS_S, DIRS, sun_col, moon_col, NORMALS, Q_OUT, VALID, BLIND):
    """Star-tracker samples for all runs. X (7+N, M) dynamics state; BASIS_S (M,3,3) rows = error axes in S; DIRS[m, sun_col:sun_col+3]
    and DIRS[m, moon_col:moon_col+3] the unit Sun and Moon directions from the spacecraft in N;
    NORMALS flat (M*3,). Q_OUT holds the previous output and is overwritten only
    when valid."""
    M = X.shape[1]
    for m in range(M):
        q0, q1, q2, q3 = X[0, m], X[1, m], X[2, m], X[3, m]
        # boresight in N = R_NB b_B
        bx, by, bz = P[m, S_BORESIGHT_B], P[m, S_BORESIGHT_B + 1], P[m, S_BORESIGHT_B + 2]
        # v_N = v + 2 q0 (qv x v) + 2 qv x (qv x v)
        tx = 2.0 * (q2 * bz - q3 * by)
        ty = 2.0 * (q3 * bx - q1 * bz)
        tz = 2.0 * (q1 * by - q2 * bx)
        nx = bx + q0 * tx + (q2 * tz - q3 * ty)
        ny = by + q0 * ty + (q3 * tx - q1 * tz)
        nz = bz + q0 * tz + (q1 * ty - q2 * tx)
        blind = BLIND_NONE
        if nx * DIRS[m, sun_col] + ny * DIRS[m, sun_col + 1] + nz * DIRS[m, sun_col + 2] > P[m, S_COS_SUN]:
            blind = BLIND_SUN
        elif nx * DIRS[m, moon_col] + ny * DIRS[m, moon_col + 1] + nz * DIRS[m, moon_col + 2] > P[m, S_COS_MOON]:
            blind = BLIND_MOON
        else:
            rate = math.sqrt(X[4, m] ** 2 + X[5, m] ** 2 + X[6, m] ** 2)
            if rate > P[m, S_MAX_RATE]:
                blind = BLIND_RATE
        BLIND[m] = blind
        VALID[m] = blind == BLIND_NONE
        if blind != BLIND_NONE:
            continue
        # error rotation vector in S: cross-boresight axes e1, e2 and about-boresight axis b
        c1 = P[m, S_CROSS] * NORMALS[3 * m + 0]
        c2 = P[m, S_CROSS] * NORMALS[3 * m + 1]
        c3 = P[m, S_ABOUT] * NORMALS[3 * m + 2]
        ex = c1 * BASIS_S[m, 0, 0] + c2 * BASIS_S[m, 1, 0] + c3 * BASIS_S[m, 2, 0]
        ey = c1 * BASIS_S[m, 0, 1] + c2 * BASIS_S[m, 1, 1] + c3 * BASIS_S[m, 2, 1]
        ez = c1 * BASIS_S[m, 0, 2] + c2 * BASIS_S[m, 1, 2] + c3 * BASIS_S[m, 2, 2]
        ang = math.sqrt(ex * ex + ey * ey + ez * ez)
        if ang > 0.0:
            s = math.sin(0.5 * ang) / ang
            d0, d1, d2, d3 = math.cos(0.5 * ang), s * ex, s * ey, s * ez
        else:
            d0, d1, d2, d3 = 1.0, 0.0, 0.0, 0.0
        a0, a1, a2, a3 = _qmul(q0, q1, q2, q3, P[m, S_Q_BS], P[m, S_Q_BS + 1], P[m, S_Q_BS + 2], P[m, S_Q_BS + 3])
        r0, r1, r2, r3 = _qmul(a0, a1, a2, a3, d0, d1, d2, d3)
        norm = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
        if r0 < 0.0:  # canonical sign: scalar part >= 0 (what a tracker's interface usually emits)
            norm = -norm
        Q_OUT[m, 0] = r0 / norm
        Q_OUT[m, 1] = r1 / norm
        Q_OUT[m, 2] = r2 / norm
        Q_OUT[m, 3] = r3 / norm
