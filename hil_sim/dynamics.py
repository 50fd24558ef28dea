"""Rigid hub + N reaction wheels: equations of motion, wheel electronics and a fixed-step RK4, in numba.

State of one run, float64[7 + N]: ``q_NB`` (4, scalar-first Hamilton, rotates body vectors into N),
``omega_BN_B`` (3, rad/s), ``Omega`` (N, wheel speed relative to the body about its axis g_i, rad/s).

Equations (the same as Basilisk's BalancedWheels, see ../shared/reference/basilisk/rw_reference_inputs.json):
  I_s omega_dot = -omega x (I omega + sum_i Js_i Omega_i g_i) - sum_i g_i u_i + tau_ext
  Omega_dot_i   = u_i / Js_i - g_i . omega_dot
  q_dot         = 1/2 A(q) omega,  A = [-q_v^T; eta I + q_v^x]
with I the whole spacecraft with the wheels locked and I_s = I - sum_free Js_i g_i g_i^T. u_i is the net
internal torque on rotor i (motor torque minus viscous and Coulomb friction); the hub feels -u_i g_i.
A stuck wheel is locked to the hub (Omega_dot = 0, its Js g g^T stays in I_s).

Wheel electronics (evaluated at the start of each integration step, torque then held like a real driver's
current loop): command clipped to +-max_torque; cut to zero when |Omega| >= max_speed and the command would
speed the wheel up further; zero for a failed wheel.

Everything is written for a batch of M runs (arrays with a leading run axis) so campaigns step many runs in
one compiled call; a single World is a batch of one.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit

from hil_sim.params import SpacecraftParams

# Layout of the per-wheel parameter array W[m, i, :].
W_JS, W_MAX_TQ, W_MAX_SPEED, W_VISC, W_COUL, W_SMOOTH, W_KT, W_RES, W_RTH, W_CTH, W_TAMB, W_MODE, W_INV_JS = range(13)
W_FIELDS = 13
MODE_HEALTHY, MODE_STUCK, MODE_NO_TORQUE = 0, 1, 2
_MODE_CODES = {"none": MODE_HEALTHY, "stuck": MODE_STUCK, "no_torque": MODE_NO_TORQUE}

# Layout of the per-run body array B[m, :]: inertia (9), inverse of I_s (9), constant torque (3),
# Gauss-Markov std (1) and correlation time (1).
B_I, B_IS_INV, B_TAU_CONST, B_DIST_STD, B_DIST_TAU = 0, 9, 18, 21, 22
B_FIELDS = 23

# Wheel status fault bits (wheel_status().fault)
FAULT_STUCK = 1
FAULT_NO_TORQUE = 2
FAULT_SPEED_LIMIT = 4
FAULT_TORQUE_SATURATED = 8


def state_size(n_wheels: int) -> int:
    return 7 + n_wheels


def pack_spacecraft(params: Sequence[SpacecraftParams]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(G (M,N,3) wheel axes, W (M,N,W_FIELDS), B (M,B_FIELDS), X0 (M,7+N)) for a batch of spacecraft."""
    n_wheels = {len(p.wheels) for p in params}
    if len(n_wheels) != 1:
        raise ValueError(f"all runs of a batch need the same number of wheels, got {sorted(n_wheels)}")
    M, N = len(params), n_wheels.pop()
    G = np.zeros((M, N, 3))
    W = np.zeros((M, N, W_FIELDS))
    B = np.zeros((M, B_FIELDS))
    X0 = np.zeros((M, 7 + N))
    for m, p in enumerate(params):
        for i, w in enumerate(p.wheels):
            G[m, i] = w.axis_B
            W[m, i, :W_MODE] = (w.Js_kgm2, w.max_torque_Nm, w.max_speed_rad_s, w.viscous_friction_Nm_per_rad_s,
                                w.coulomb_friction_Nm, w.coulomb_smoothing_rad_s, w.motor_constant_Nm_per_A,
                                w.winding_resistance_ohm, w.thermal_resistance_K_per_W, w.thermal_capacity_J_per_K,
                                w.ambient_temp_C)
            W[m, i, W_MODE] = _MODE_CODES[w.failure]
            W[m, i, W_INV_JS] = 1.0 / w.Js_kgm2  # the derivative multiplies: a division costs ~5x more
            X0[m, 7 + i] = 0.0 if w.failure == "stuck" else w.initial_speed_rad_s
        B[m, B_I:B_I + 9] = np.asarray(p.inertia_B_kgm2).reshape(-1)
        B[m, B_TAU_CONST:B_TAU_CONST + 3] = p.disturbance.constant_B_Nm
        B[m, B_DIST_STD] = p.disturbance.random_std_Nm
        B[m, B_DIST_TAU] = p.disturbance.random_correlation_time_s
        X0[m, 0:4] = p.q_NB0
        X0[m, 4:7] = p.omega_BN_B0_rad_s
        update_free_inertia(G, W, B, m)
    return G, W, B, X0


def update_free_inertia(G: np.ndarray, W: np.ndarray, B: np.ndarray, m: int) -> None:
    """Recompute inv(I_s) of run m after a change of wheel failure modes (stuck wheels join the hub)."""
    inertia = B[m, B_I:B_I + 9].reshape(3, 3)
    Is = inertia.copy()
    for i in range(G.shape[1]):
        if int(W[m, i, W_MODE]) != MODE_STUCK:
            Is -= W[m, i, W_JS] * np.outer(G[m, i], G[m, i])
    B[m, B_IS_INV:B_IS_INV + 9] = np.linalg.inv(Is).reshape(-1)


@njit(cache=True, inline="always", error_model="numpy")
def _derivative(x, u_motor, tau_B, G, W, B, m, dx, u_net):
    N = G.shape[1]
    q0, q1, q2, q3 = x[0], x[1], x[2], x[3]
    wx, wy, wz = x[4], x[5], x[6]
    # Total angular momentum about the centre of mass, body axes.
    hx = B[m, 0] * wx + B[m, 1] * wy + B[m, 2] * wz
    hy = B[m, 3] * wx + B[m, 4] * wy + B[m, 5] * wz
    hz = B[m, 6] * wx + B[m, 7] * wy + B[m, 8] * wz
    rx = tau_B[0]
    ry = tau_B[1]
    rz = tau_B[2]
    for i in range(N):
        Om = x[7 + i]
        jo = W[m, i, W_JS] * Om
        gx, gy, gz = G[m, i, 0], G[m, i, 1], G[m, i, 2]
        hx += jo * gx
        hy += jo * gy
        hz += jo * gz
        if W[m, i, W_MODE] != MODE_STUCK:
            u = u_motor[i] - W[m, i, W_VISC] * Om
            if W[m, i, W_COUL] != 0.0:
                u -= W[m, i, W_COUL] * math.tanh(Om / W[m, i, W_SMOOTH])
            u_net[i] = u
            rx -= gx * u
            ry -= gy * u
            rz -= gz * u
        else:
            u_net[i] = 0.0
    # - omega x h
    rx -= wy * hz - wz * hy
    ry -= wz * hx - wx * hz
    rz -= wx * hy - wy * hx
    ax = B[m, 9] * rx + B[m, 10] * ry + B[m, 11] * rz
    ay = B[m, 12] * rx + B[m, 13] * ry + B[m, 14] * rz
    az = B[m, 15] * rx + B[m, 16] * ry + B[m, 17] * rz
    dx[0] = 0.5 * (-q1 * wx - q2 * wy - q3 * wz)
    dx[1] = 0.5 * (q0 * wx + q2 * wz - q3 * wy)
    dx[2] = 0.5 * (q0 * wy + q3 * wx - q1 * wz)
    dx[3] = 0.5 * (q0 * wz + q1 * wy - q2 * wx)
    dx[4] = ax
    dx[5] = ay
    dx[6] = az
    for i in range(N):
        if W[m, i, W_MODE] != MODE_STUCK:
            dx[7 + i] = u_net[i] * W[m, i, W_INV_JS] - (G[m, i, 0] * ax + G[m, i, 1] * ay + G[m, i, 2] * az)
        else:
            dx[7 + i] = 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _rk4_run(x, dt, u_motor, tau_B, G, W, B, m, k1, k2, k3, k4, xt, u_net):
    n = x.shape[0]
    _derivative(x, u_motor, tau_B, G, W, B, m, k1, u_net)
    for j in range(n):
        xt[j] = x[j] + 0.5 * dt * k1[j]
    _derivative(xt, u_motor, tau_B, G, W, B, m, k2, u_net)
    for j in range(n):
        xt[j] = x[j] + 0.5 * dt * k2[j]
    _derivative(xt, u_motor, tau_B, G, W, B, m, k3, u_net)
    for j in range(n):
        xt[j] = x[j] + dt * k3[j]
    _derivative(xt, u_motor, tau_B, G, W, B, m, k4, u_net)
    for j in range(n):
        x[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
    norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
    for j in range(4):
        x[j] /= norm


@njit(cache=True, error_model="numpy")
def dynamics_step_batch(X, D, TEMP, G, W, B, U_CMD, NORMALS, dt_sub, n_sub, U_APPLIED, FLAGS):
    """Advance every run m by n_sub RK4 steps of dt_sub seconds, the torque command U_CMD[m] held.
    See ``dynamics_step_runs`` for the arrays."""
    dynamics_step_runs(X, D, TEMP, G, W, B, U_CMD, NORMALS, dt_sub, n_sub, U_APPLIED, FLAGS, 0, X.shape[0])


@njit(cache=True, error_model="numpy")
def dynamics_step_runs(X, D, TEMP, G, W, B, U_CMD, NORMALS, dt_sub, n_sub, U_APPLIED, FLAGS, m_begin, m_end):
    """Advance runs m_begin <= m < m_end by n_sub RK4 steps of dt_sub seconds, U_CMD[m] held.

    X (M,7+N) state, updated in place; D (M,3) Gauss-Markov disturbance state (N m), updated;
    TEMP (M,N) wheel temperatures (deg C), updated; NORMALS flat (n_sub*M*3,) standard normals for the random
    disturbance (ignored where its std is 0); U_APPLIED (M,N) out: motor torque actually applied on the last
    sub-step; FLAGS (M,N) out: fault bits (stuck, no torque, speed limit, saturated).
    """
    N = G.shape[1]
    n = X.shape[1]
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    xt = np.empty(n)
    u_net = np.empty(N)
    u_motor = np.empty(N)
    tau = np.empty(3)
    x = np.empty(n)  # work copy of one run's state (a per-run view X[m] would cost reference counting)
    for m in range(m_begin, m_end):
        for j in range(n):
            x[j] = X[m, j]
        std = B[m, B_DIST_STD]
        a = 0.0
        b = 0.0
        if std > 0.0:
            corr = B[m, B_DIST_TAU]
            a = math.exp(-dt_sub / corr) if corr > 0.0 else 0.0
            b = std * math.sqrt(1.0 - a * a)
        for s in range(n_sub):
            for i in range(N):
                mode = W[m, i, W_MODE]
                flags = 0
                u = U_CMD[m, i]
                lim = W[m, i, W_MAX_TQ]
                if u > lim:
                    u = lim
                    flags |= FAULT_TORQUE_SATURATED
                elif u < -lim:
                    u = -lim
                    flags |= FAULT_TORQUE_SATURATED
                Om = x[7 + i]
                if mode == MODE_STUCK:
                    u = 0.0
                    flags |= FAULT_STUCK
                elif mode == MODE_NO_TORQUE:
                    u = 0.0
                    flags |= FAULT_NO_TORQUE
                elif abs(Om) >= W[m, i, W_MAX_SPEED] and u * Om > 0.0:
                    u = 0.0
                    flags |= FAULT_SPEED_LIMIT
                u_motor[i] = u
                U_APPLIED[m, i] = u
                FLAGS[m, i] = flags
            if std > 0.0:
                for j in range(3):
                    D[m, j] = a * D[m, j] + b * NORMALS[(s * X.shape[0] + m) * 3 + j]
            for j in range(3):
                tau[j] = B[m, B_TAU_CONST + j] + D[m, j]
            _rk4_run(x, dt_sub, u_motor, tau, G, W, B, m, k1, k2, k3, k4, xt, u_net)
            # First-order winding temperature, copper loss i^2 R held over the step: T -> T_ss + (T - T_ss) e^-x,
            # x = dt / (R_th C_th). x is ~1e-5 at 100 Hz, so a 3-term series (error x^3/6) replaces exp.
            for i in range(N):
                cur = u_motor[i] / W[m, i, W_KT]
                rth = W[m, i, W_RTH]
                t_ss = W[m, i, W_TAMB] + cur * cur * W[m, i, W_RES] * rth
                if rth > 0.0:
                    xr = dt_sub / (rth * W[m, i, W_CTH])
                    decay = 1.0 - xr + 0.5 * xr * xr if xr < 1e-3 else math.exp(-xr)
                    TEMP[m, i] = t_ss + (TEMP[m, i] - t_ss) * decay
                else:
                    TEMP[m, i] = t_ss
        for j in range(n):
            X[m, j] = x[j]


def angular_momentum_B(x: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Total angular momentum in body axes, N m s: I omega + sum Js Omega g. x (M,7+N) -> (M,3)."""
    inertia = B[:, B_I:B_I + 9].reshape(-1, 3, 3)
    h = np.einsum("mij,mj->mi", inertia, x[:, 4:7])
    h += np.einsum("mi,mi,mij->mj", W[:, :, W_JS], x[:, 7:], G)
    return h


def angular_momentum_N(x: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Total angular momentum in N (conserved without external torque), N m s, (M,3)."""
    from gnc.attitude import quat_rotate

    h_B = angular_momentum_B(x, G, W, B)
    return np.stack([quat_rotate(x[m, 0:4], h_B[m]) for m in range(x.shape[0])])


def rotational_energy(x: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """T = 1/2 w^T I w + sum (1/2 Js Omega^2 + Js Omega g.w), J, (M,)."""
    inertia = B[:, B_I:B_I + 9].reshape(-1, 3, 3)
    w = x[:, 4:7]
    Om = x[:, 7:]
    Js = W[:, :, W_JS]
    gw = np.einsum("mij,mj->mi", G, w)
    return 0.5 * np.einsum("mi,mij,mj->m", w, inertia, w) + np.sum(0.5 * Js * Om**2 + Js * Om * gw, axis=1)


def seize_wheel(X: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray, m: int, i: int) -> None:
    """Wheel i of run m seizes: its relative speed drops to zero and its momentum goes to the hub, with
    the total angular momentum conserved (I omega' = I omega + Js Omega g)."""
    inertia = B[m, B_I:B_I + 9].reshape(3, 3)
    X[m, 4:7] += np.linalg.solve(inertia, W[m, i, W_JS] * X[m, 7 + i] * G[m, i])
    X[m, 7 + i] = 0.0
    W[m, i, W_MODE] = MODE_STUCK
    update_free_inertia(G, W, B, m)
