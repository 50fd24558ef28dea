"""Compiled per-cycle arithmetic of the guidance (one call each instead of a dozen numpy calls on 3-vectors).

A GNC cycle's guidance is mostly small-vector arithmetic: at ~1 us per numpy call on a 3-vector the calls
cost more than the sums. These kernels do that arithmetic in one compiled call each, with the expressions
of the numpy code they replace (elementwise operations are bit-identical; sums of three products may differ
from numpy's dot in the last bit, since numpy's dot may use fused multiply-adds).

* `sky_directions_nb`: the onboard Sun, Moon and Earth directions (`SkyEphemeris.directions`);
* `boresight_nb`: ``y_N = R_NB(q) b_B``;
* `pointing_command_nb`: POINTING's body-rate command from the law's ``u``: ``b^x R^T k1 u``, the rate
  limit and the governor's rate, the pointing error, and the roll law about the boresight;
* `aim_index_nb`: `PathFollower.aim_index` (pure pursuit along the planned path).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gnc.attitude import pointing_rate_command_nb, quat_to_dcm_nb


@njit(cache=True)
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def sky_directions_nb(t_s, u0, n_rad_s, radius_km, p_hat, q_hat, f, s0, s1, m0, m1):
    """Rows: unit vectors spacecraft -> Sun, -> Moon, -> Earth centre (N), with the geocentric Sun and Moon
    positions interpolated between two nodes (``f`` in [0, 1)) and the circular orbit's position at t."""
    u = u0 + n_rad_s * t_s
    cu, su = math.cos(u), math.sin(u)
    out = np.empty((3, 3))
    r = np.empty(3)
    for i in range(3):
        r[i] = radius_km * (cu * p_hat[i] + su * q_hat[i])
        out[0, i] = s0[i] + f * (s1[i] - s0[i]) - r[i]
        out[1, i] = m0[i] + f * (m1[i] - m0[i]) - r[i]
        out[2, i] = -r[i]
    for k in range(2):
        n = math.sqrt(_dot3(out[k], out[k]))
        for i in range(3):
            out[k, i] = out[k, i] / n
    n = math.sqrt(_dot3(r, r))
    for i in range(3):
        out[2, i] = out[2, i] / n
    return out


@njit(cache=True)
def boresight_nb(q, b):
    """``R_NB(q) b``: the instrument boresight in N."""
    R = quat_to_dcm_nb(q)
    y = np.empty(3)
    for i in range(3):
        y[i] = R[i, 0] * b[0] + R[i, 1] * b[1] + R[i, 2] * b[2]
    return y


@njit(cache=True)
def _scale_into(w, limit):
    """``w`` scaled down to norm ``limit`` when longer (`common._saturate`), in place."""
    n = math.sqrt(_dot3(w, w))
    if n > limit:
        s = limit / n
        for i in range(3):
            w[i] = w[i] * s


@njit(cache=True)
def roll_error_nb(q, y, b, roll_axis_B, roll_ref_N):
    """Angle [rad] about the boresight ``b`` from ``roll_axis_B``'s projection to the roll reference's
    (``roll_ref_N``, or a coordinate axis when the reference is within ~18 deg of the boresight ``y``)."""
    ref = roll_ref_N.copy()
    if abs(_dot3(ref, y)) > 0.95:  # reference nearly along the boresight: use another axis
        ref[:] = 0.0
        if abs(y[0]) < 0.9:
            ref[0] = 1.0
        else:
            ref[1] = 1.0
    R = quat_to_dcm_nb(q)
    r_B = np.empty(3)
    for i in range(3):
        r_B[i] = R[0, i] * ref[0] + R[1, i] * ref[1] + R[2, i] * ref[2]
    ab = _dot3(roll_axis_B, b)
    rb = _dot3(r_B, b)
    a = roll_axis_B - ab * b
    r = r_B - rb * b
    ax0 = a[1] * r[2] - a[2] * r[1]
    ax1 = a[2] * r[0] - a[0] * r[2]
    ax2 = a[0] * r[1] - a[1] * r[0]
    return math.atan2(b[0] * ax0 + b[1] * ax1 + b[2] * ax2, _dot3(a, r))


@njit(cache=True)
def pointing_command_nb(q, y, b, u_law, k1, max_rate, governor_rate, target, roll_axis_B, roll_ref_N, roll_gain):
    """POINTING's command from the law's ``u_law`` (S^2, N frame) for attitude ``q`` and boresight ``y``.

    ``omega = b^x R^T (k1 u_law)`` scaled into ``max_rate`` and then into ``governor_rate`` (negative: no
    governor this cycle); the roll rate about the boresight gets what the rate limit leaves (at most half
    of it). Returns [omega_cmd_BN_B (3), |law rate after the limits|, pointing error deg, roll error rad].
    """
    w = pointing_rate_command_nb(q, b, k1 * u_law)
    _scale_into(w, max_rate)
    if governor_rate >= 0.0:
        _scale_into(w, governor_rate)
    out = np.empty(6)
    ww = _dot3(w, w)
    out[3] = math.sqrt(ww)
    out[4] = math.degrees(math.acos(max(-1.0, min(1.0, _dot3(y, target)))))
    roll = roll_error_nb(q, y, b, roll_axis_B, roll_ref_N)
    out[5] = roll
    omega_roll = roll_gain * roll * b
    room = math.sqrt(max(0.0, max_rate ** 2 - ww))
    _scale_into(omega_roll, min(room, 0.5 * max_rate))
    for i in range(3):
        out[i] = w[i] + omega_roll[i]
    return out


@njit(cache=True)
def _row_dot(path, k, y):
    c = 0.0
    for i in range(y.shape[0]):
        c += path[k, i] * y[i]
    return c


@njit(cache=True)
def aim_index_nb(path, start, y, cos_ahead):
    """(nearest index from ``start`` on, aim index): the first path point at or after ``start`` with the
    largest cosine to ``y``, then the first point from there whose cosine is below ``cos_ahead`` (the
    path's last index when none is). Any dimension: S^2 (boresight paths) and S^3 (attitude paths)."""
    best_k, best_c = start, -math.inf
    for k in range(start, path.shape[0]):
        c = _row_dot(path, k, y)
        if c > best_c:
            best_k, best_c = k, c
    for k in range(best_k, path.shape[0]):
        if _row_dot(path, k, y) < cos_ahead:
            return best_k, k
    return best_k, path.shape[0] - 1
