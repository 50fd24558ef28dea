"""Rigid hub + N reaction wheels: equations of motion, wheel electronics and a fixed-step RK4, in numba.

State of one run, 7 + N numbers: ``q_NB`` (4, scalar-first Hamilton, rotates body vectors into N),
``omega_BN_B`` (3, rad/s), ``Omega`` (N, wheel speed relative to the body about its axis g_i, rad/s).

Equations (the same as Basilisk's BalancedWheels, see tests/data/basilisk/rw_reference_inputs.json):
  I_s omega_dot = -omega x (I omega + sum_i Js_i Omega_i g_i) - sum_i g_i u_i + tau_ext
  Omega_dot_i   = u_i / Js_i - g_i . omega_dot
  q_dot         = 1/2 A(q) omega,  A = [-q_v^T; eta I + q_v^x]
with I the whole spacecraft with the wheels locked and I_s = I - sum_free Js_i g_i g_i^T. u_i is the net
internal torque on rotor i (motor torque minus viscous and Coulomb friction); the hub feels -u_i g_i.
A stuck wheel is locked to the hub (Omega_dot = 0, its Js g g^T stays in I_s).

Wheel electronics (evaluated at the start of each integration step, torque then held like a real driver's
current loop): command clipped to +-max_torque; cut to zero when |Omega| >= max_speed and the command would
speed the wheel up further; zero for a failed wheel.

Memory layout: everything is written for a batch of M runs with the RUN AXIS LAST (structure of arrays):
X (7+N, M), G (N, 3, M), W (W_FIELDS, N, M), B (B_FIELDS, M). Each pass of the derivative is then a plain
loop over runs with contiguous loads, which the compiler vectorises (AVX): ~2x faster per run than one run at
a time. A single World is a batch of one and runs the same code.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit

from hil_sim.world import environment as env
from hil_sim.world.orbit import orbit_position_row_N_km
from hil_sim.world.params import SpacecraftParams

# Rows of the per-wheel parameter array W[field, i, m].
W_JS, W_MAX_TQ, W_MAX_SPEED, W_VISC, W_COUL, W_SMOOTH, W_KT, W_RES, W_RTH, W_CTH, W_TAMB, W_MODE, W_INV_JS = range(13)
W_FREE = 13  # 1.0 for a wheel free to spin, 0.0 when stuck (a multiplier keeps the passes branch-free)
W_FIELDS = 14
MODE_HEALTHY, MODE_STUCK, MODE_NO_TORQUE = 0, 1, 2
_MODE_CODES = {"none": MODE_HEALTHY, "stuck": MODE_STUCK, "no_torque": MODE_NO_TORQUE}

# Rows of the per-run body array B[field, m]: inertia (9, row major), inverse of I_s (9), constant torque (3),
# Gauss-Markov std (1) and correlation time (1), gravity gradient on (1.0) or off (0.0). When a run of the batch
# has an environment effect on (solar radiation pressure, ...), hil_sim.world.environment's rows follow.
B_I, B_IS_INV, B_TAU_CONST, B_DIST_STD, B_DIST_TAU, B_GG = 0, 9, 18, 21, 22, 23
B_FIELDS = 24
assert env.ENV_FLAGS == B_FIELDS

# Wheel status fault bits (wheel_status().fault)
FAULT_STUCK = 1
FAULT_NO_TORQUE = 2
FAULT_SPEED_LIMIT = 4
FAULT_TORQUE_SATURATED = 8


def state_size(n_wheels: int) -> int:
    return 7 + n_wheels


def pack_spacecraft(params: Sequence[SpacecraftParams]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(G (N,3,M) wheel axes, W (W_FIELDS,N,M), B (B_FIELDS,M), X0 (7+N,M)) for a batch of spacecraft."""
    n_wheels = {len(p.wheels) for p in params}
    if len(n_wheels) != 1:
        raise ValueError(f"all runs of a batch need the same number of wheels, got {sorted(n_wheels)}")
    M, N = len(params), n_wheels.pop()
    G = np.zeros((N, 3, M))
    W = np.zeros((W_FIELDS, N, M))
    B = np.zeros((B_FIELDS, M))
    X0 = np.zeros((7 + N, M))
    for m, p in enumerate(params):
        for i, w in enumerate(p.wheels):
            G[i, :, m] = w.axis_B
            W[:W_MODE, i, m] = (w.Js_kgm2, w.max_torque_Nm, w.max_speed_rad_s, w.viscous_friction_Nm_per_rad_s,
                                w.coulomb_friction_Nm, w.coulomb_smoothing_rad_s, w.motor_constant_Nm_per_A,
                                w.winding_resistance_ohm, w.thermal_resistance_K_per_W, w.thermal_capacity_J_per_K,
                                w.ambient_temp_C)
            W[W_MODE, i, m] = _MODE_CODES[w.failure]
            W[W_INV_JS, i, m] = 1.0 / w.Js_kgm2  # the derivative multiplies: a division costs ~5x more
            X0[7 + i, m] = 0.0 if w.failure == "stuck" else w.initial_speed_rad_s
        B[B_I:B_I + 9, m] = np.asarray(p.inertia_B_kgm2).reshape(-1)
        B[B_TAU_CONST:B_TAU_CONST + 3, m] = p.disturbance.constant_B_Nm
        B[B_DIST_STD, m] = p.disturbance.random_std_Nm
        B[B_DIST_TAU, m] = p.disturbance.random_correlation_time_s
        B[B_GG, m] = 1.0 if p.disturbance.gravity_gradient else 0.0
        X0[0:4, m] = p.q_NB0
        X0[4:7, m] = p.omega_BN_B0_rad_s
        update_free_inertia(G, W, B, m)
    rows = env.environment_rows(params)
    if rows is not None:
        B = np.ascontiguousarray(np.vstack([B, rows]))
    return G, W, B, X0


def update_free_inertia(G: np.ndarray, W: np.ndarray, B: np.ndarray, m: int) -> None:
    """Recompute the free flags and inv(I_s) of run m after a change of wheel failure modes (stuck wheels join
    the hub)."""
    Is = B[B_I:B_I + 9, m].reshape(3, 3).copy()
    for i in range(G.shape[0]):
        free = int(W[W_MODE, i, m]) != MODE_STUCK
        W[W_FREE, i, m] = 1.0 if free else 0.0
        if free:
            Is -= W[W_JS, i, m] * np.outer(G[i, :, m], G[i, :, m])
    B[B_IS_INV:B_IS_INV + 9, m] = np.linalg.inv(Is).reshape(-1)


@njit(cache=True, error_model="numpy")
def _derivative(x, u_motor, tau, G, W, B, has_coulomb, dx, h, r, u_net):
    """dx = f(x) for all runs. x, dx (7+N, M); u_motor (N, M) held motor torques; tau (3, M) external torque;
    h, r (3, M) and u_net (N, M) scratch. Each loop over m is branch-free so it vectorises."""
    M = x.shape[1]
    N = G.shape[0]
    for m in range(M):
        wx, wy, wz = x[4, m], x[5, m], x[6, m]
        h[0, m] = B[0, m] * wx + B[1, m] * wy + B[2, m] * wz
        h[1, m] = B[3, m] * wx + B[4, m] * wy + B[5, m] * wz
        h[2, m] = B[6, m] * wx + B[7, m] * wy + B[8, m] * wz
        r[0, m] = tau[0, m]
        r[1, m] = tau[1, m]
        r[2, m] = tau[2, m]
    for i in range(N):
        for m in range(M):
            Om = x[7 + i, m]
            jo = W[W_JS, i, m] * Om
            gx, gy, gz = G[i, 0, m], G[i, 1, m], G[i, 2, m]
            h[0, m] += jo * gx
            h[1, m] += jo * gy
            h[2, m] += jo * gz
            # net internal torque on the rotor: motor minus viscous friction (zero for a rotor locked to the hub)
            v = W[W_FREE, i, m] * (u_motor[i, m] - W[W_VISC, i, m] * Om)
            u_net[i, m] = v
            r[0, m] -= gx * v
            r[1, m] -= gy * v
            r[2, m] -= gz * v
        if has_coulomb[i]:  # tanh does not vectorise here: a separate pass only where configured
            for m in range(M):
                v = W[W_FREE, i, m] * W[W_COUL, i, m] * math.tanh(x[7 + i, m] / W[W_SMOOTH, i, m])
                u_net[i, m] -= v
                r[0, m] += G[i, 0, m] * v
                r[1, m] += G[i, 1, m] * v
                r[2, m] += G[i, 2, m] * v
    for m in range(M):
        wx, wy, wz = x[4, m], x[5, m], x[6, m]
        hx, hy, hz = h[0, m], h[1, m], h[2, m]
        # - omega x h
        rx = r[0, m] - (wy * hz - wz * hy)
        ry = r[1, m] - (wz * hx - wx * hz)
        rz = r[2, m] - (wx * hy - wy * hx)
        q0, q1, q2, q3 = x[0, m], x[1, m], x[2, m], x[3, m]
        dx[0, m] = 0.5 * (-q1 * wx - q2 * wy - q3 * wz)
        dx[1, m] = 0.5 * (q0 * wx + q2 * wz - q3 * wy)
        dx[2, m] = 0.5 * (q0 * wy + q3 * wx - q1 * wz)
        dx[3, m] = 0.5 * (q0 * wz + q1 * wy - q2 * wx)
        dx[4, m] = B[9, m] * rx + B[10, m] * ry + B[11, m] * rz
        dx[5, m] = B[12, m] * rx + B[13, m] * ry + B[14, m] * rz
        dx[6, m] = B[15, m] * rx + B[16, m] * ry + B[17, m] * rz
    for i in range(N):
        for m in range(M):
            dx[7 + i, m] = W[W_FREE, i, m] * (u_net[i, m] * W[W_INV_JS, i, m]
                                              - (G[i, 0, m] * dx[4, m] + G[i, 1, m] * dx[5, m]
                                                 + G[i, 2, m] * dx[6, m]))


@njit(cache=True, error_model="numpy")
def _axpy(out, x, a, k):
    """out = x + a k over (rows, M)."""
    for j in range(x.shape[0]):
        for m in range(x.shape[1]):
            out[j, m] = x[j, m] + a * k[j, m]


@njit(cache=True, error_model="numpy")
def _wheel_electronics(X, u_cmd, W, u_motor, U_APPLIED, FLAGS):
    """Motor torque each driver applies for the coming step, from the held command u_cmd (N, M).
    Written with conditional expressions only, so the loop over runs vectorises."""
    N, M = u_motor.shape
    for i in range(N):
        for m in range(M):
            cmd = u_cmd[i, m]
            lim = W[W_MAX_TQ, i, m]
            u = min(max(cmd, -lim), lim)
            mode = W[W_MODE, i, m]
            Om = X[7 + i, m]
            over = (abs(Om) >= W[W_MAX_SPEED, i, m]) and (u * Om > 0.0)
            healthy = mode == MODE_HEALTHY
            u = u if (healthy and not over) else 0.0
            u_motor[i, m] = u
            U_APPLIED[i, m] = u
            FLAGS[i, m] = ((FAULT_TORQUE_SATURATED if abs(cmd) > lim else 0)
                           | (FAULT_STUCK if mode == MODE_STUCK else 0)
                           | (FAULT_NO_TORQUE if mode == MODE_NO_TORQUE else 0)
                           | (FAULT_SPEED_LIMIT if (healthy and over) else 0))


def work_shape(n_wheels: int, n_runs: int) -> tuple[int, int]:
    """Shape of the scratch array ``dynamics_step_batch`` needs."""
    return 5 * (7 + n_wheels) + 9 + 3 * n_wheels + 6, n_runs


def step_coefficients(W: np.ndarray, B: np.ndarray, dt_sub: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-sub-step constants for ``dynamics_step_batch`` (computed once per dt_sub, not per call):
    winding temperature decay exp(-dt / (R_th C_th)) (N, M) (0 where R_th = 0); Gauss-Markov coefficients
    (2, M): d <- a d + b n with a = exp(-dt / tau), b = sigma sqrt(1 - a^2); and which wheels have Coulomb
    friction in any run (N,)."""
    rth = W[W_RTH]
    with np.errstate(divide="ignore"):
        decay = np.where(rth > 0.0, np.exp(-dt_sub / np.where(rth > 0.0, rth * W[W_CTH], 1.0)), 0.0)
    std, corr = B[B_DIST_STD], B[B_DIST_TAU]
    a = np.where((std > 0.0) & (corr > 0.0), np.exp(-dt_sub / np.where(corr > 0.0, corr, 1.0)), 0.0)
    gm = np.stack([a, std * np.sqrt(1.0 - a * a)])
    has_coulomb = np.any(W[W_COUL] != 0.0, axis=1)
    return np.ascontiguousarray(decay), gm, has_coulomb


@njit(cache=True, error_model="numpy", inline="always")
def _add_gravity_gradient(X, B, ORB, m, t_s, r, tau):
    """tau[:, m] += the gravity-gradient torque on run m at t_s: 3 mu / |r|^3 (u x I u), u the unit vector
    from the Earth's centre to the spacecraft in body axes (orbit row m of ORB, attitude X[0:4, m])."""
    orbit_position_row_N_km(ORB, m, t_s, r)
    rn2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    rn = math.sqrt(rn2)
    coef = 3.0 * ORB[m, 13] / (rn2 * rn)  # mu [km^3/s^2] / r^3 [km^3]: 1/s^2, the units cancel
    nx, ny, nz = r[0] / rn, r[1] / rn, r[2] / rn
    q0, q1, q2, q3 = X[0, m], X[1, m], X[2, m], X[3, m]
    # u_B = R(q)^T u_N, R(q) the rotation of body vectors into N (columns: the body axes in N)
    ux = (1.0 - 2.0 * (q2 * q2 + q3 * q3)) * nx + 2.0 * (q1 * q2 + q0 * q3) * ny + 2.0 * (q1 * q3 - q0 * q2) * nz
    uy = 2.0 * (q1 * q2 - q0 * q3) * nx + (1.0 - 2.0 * (q1 * q1 + q3 * q3)) * ny + 2.0 * (q2 * q3 + q0 * q1) * nz
    uz = 2.0 * (q1 * q3 + q0 * q2) * nx + 2.0 * (q2 * q3 - q0 * q1) * ny + (1.0 - 2.0 * (q1 * q1 + q2 * q2)) * nz
    jx = B[0, m] * ux + B[1, m] * uy + B[2, m] * uz
    jy = B[3, m] * ux + B[4, m] * uy + B[5, m] * uz
    jz = B[6, m] * ux + B[7, m] * uy + B[8, m] * uz
    tau[0, m] += coef * (uy * jz - uz * jy)
    tau[1, m] += coef * (uz * jx - ux * jz)
    tau[2, m] += coef * (ux * jy - uy * jx)


@njit(cache=True, error_model="numpy", inline="always")
def _with_gravity_gradient(tau, tau_gg, x, B, ORB, t_s, rpos, has_env):
    """tau_gg = ``tau`` (constant and random, held over the sub-step) plus, for the runs that have them on, the
    gravity gradient and (``has_env``: B has hil_sim.world.environment's rows) the environment torques of state ``x``
    at ``t_s``: the external torque at one RK4 stage."""
    for m in range(tau.shape[1]):
        tau_gg[0, m] = tau[0, m]
        tau_gg[1, m] = tau[1, m]
        tau_gg[2, m] = tau[2, m]
        if B[B_GG, m] > 0.0:
            _add_gravity_gradient(x, B, ORB, m, t_s, rpos, tau_gg)
        if has_env and B[env.ENV_FLAGS, m] != 0.0:
            env.add_environment_torque(x, B, ORB, m, t_s, rpos, tau_gg)


@njit(cache=True, error_model="numpy")
def _hold_command(U_CMD, u_cmd):
    """u_cmd (N, M) = U_CMD (M, N) transposed, once a step rather than every sub-step. False when a command is
    NaN or infinite."""
    nan_if_bad = 0.0  # x * 0 is 0 for finite x and NaN for NaN or inf: one branch-free pass checks them all
    for i in range(u_cmd.shape[0]):
        for m in range(u_cmd.shape[1]):
            u_cmd[i, m] = U_CMD[m, i]
            nan_if_bad += U_CMD[m, i] * 0.0
    return not (nan_if_bad != 0.0 or not math.isfinite(nan_if_bad))


@njit(cache=True, error_model="numpy")
def _torque_kinds(GM, B):
    """(any run with a random disturbance, any with a torque of its attitude and position: gravity gradient or
    an environment effect, B has hil_sim.world.environment's rows): one choice a call, none a stage."""
    any_random = False
    any_gg = False
    has_env = B.shape[0] > B_FIELDS  # only then does B have the environment's rows
    for m in range(B.shape[1]):
        if GM[1, m] > 0.0:
            any_random = True
        if B[B_GG, m] > 0.0 or (has_env and B[env.ENV_FLAGS, m] != 0.0):
            any_gg = True
    return any_random, any_gg, has_env


@njit(cache=True, error_model="numpy")
def _rk4_combine(X, k1, k2, k3, k4, c):
    """X += c (k1 + 2 k2 + 2 k3 + k4), c = dt / 6; then each run's quaternion back to unit norm."""
    K, M = X.shape
    for j in range(K):
        for m in range(M):
            X[j, m] += c * (k1[j, m] + 2.0 * k2[j, m] + 2.0 * k3[j, m] + k4[j, m])
    for m in range(M):
        inv = 1.0 / math.sqrt(X[0, m] ** 2 + X[1, m] ** 2 + X[2, m] ** 2 + X[3, m] ** 2)
        X[0, m] *= inv
        X[1, m] *= inv
        X[2, m] *= inv
        X[3, m] *= inv


@njit(cache=True, error_model="numpy")
def _winding_temperature(TEMP, u_motor, W, DECAY):
    """First-order winding temperature, copper loss i^2 R held over the step: T -> T_ss + (T - T_ss) e^-x,
    x = dt / (R_th C_th) (decay = 0 when R_th = 0: T = T_ss at once)."""
    for i in range(TEMP.shape[0]):
        for m in range(TEMP.shape[1]):
            cur = u_motor[i, m] / W[W_KT, i, m]
            t_ss = W[W_TAMB, i, m] + cur * cur * W[W_RES, i, m] * W[W_RTH, i, m]
            TEMP[i, m] = t_ss + (TEMP[i, m] - t_ss) * DECAY[i, m]


@njit(cache=True, error_model="numpy")
def dynamics_step_batch(X, D, TEMP, G, W, B, U_CMD, NORMALS, dt_sub, n_sub, U_APPLIED, FLAGS,
                        DECAY, GM, HAS_COULOMB, WORK, ORB, t0_s):
    """Advance every run by n_sub RK4 steps of dt_sub seconds, the torque command U_CMD[m] (M, N) held.

    X (7+N, M) state, updated in place; D (3, M) Gauss-Markov disturbance state (N m), updated;
    TEMP (N, M) wheel temperatures (deg C), updated; NORMALS flat (n_sub*M*3,) standard normals for the random
    disturbance (ignored where its std is 0); U_APPLIED (N, M) out: motor torque actually applied on the last
    sub-step; FLAGS (N, M) out: fault bits (stuck, no torque, speed limit, saturated); DECAY, GM, HAS_COULOMB
    from ``step_coefficients(W, B, dt_sub)``; WORK scratch of ``work_shape(N, M)`` (kept by the caller so a
    100 Hz step does not allocate). ORB: the runs' packed orbits (hil_sim.world.orbit) and t0_s the time at the
    start of the step, for the gravity-gradient torque of the runs that have it on (B[B_GG]): evaluated at
    every RK4 stage from the stage's attitude and orbit position (the constant and random torques are held
    over the sub-step). The environment torques (hil_sim.world.environment) likewise, for the runs that have them
    on, with the Sun held in B over the step. Returns False,
    having changed nothing, if a command is NaN or infinite.
    """
    K, M = X.shape
    N = G.shape[0]
    k1 = WORK[0:K]
    k2 = WORK[K:2 * K]
    k3 = WORK[2 * K:3 * K]
    k4 = WORK[3 * K:4 * K]
    xt = WORK[4 * K:5 * K]
    o = 5 * K
    h = WORK[o:o + 3]
    r = WORK[o + 3:o + 6]
    tau = WORK[o + 6:o + 9]
    o += 9
    u_net = WORK[o:o + N]
    u_motor = WORK[o + N:o + 2 * N]
    u_cmd = WORK[o + 2 * N:o + 3 * N]  # the command is held: transpose it once, not every sub-step
    tau_gg = WORK[o + 3 * N:o + 3 * N + 3]  # a stage's external torque with the gravity gradient
    rpos = WORK[o + 3 * N + 3:o + 3 * N + 6, 0]  # the orbit position of one run (scratch; no allocation per call)
    if not _hold_command(U_CMD, u_cmd):
        return False
    any_random, any_gg, has_env = _torque_kinds(GM, B)
    ext = tau_gg if any_gg else tau  # the stages' external torque (one choice a call, none a stage)
    for s in range(n_sub):
        _wheel_electronics(X, u_cmd, W, u_motor, U_APPLIED, FLAGS)
        if any_random:
            for m in range(M):
                for j in range(3):
                    D[j, m] = GM[0, m] * D[j, m] + GM[1, m] * NORMALS[(s * M + m) * 3 + j]
        for j in range(3):
            for m in range(M):
                tau[j, m] = B[B_TAU_CONST + j, m] + D[j, m]
        t_s = t0_s + s * dt_sub
        if any_gg:
            _with_gravity_gradient(tau, ext, X, B, ORB, t_s, rpos, has_env)
        _derivative(X, u_motor, ext, G, W, B, HAS_COULOMB, k1, h, r, u_net)
        _axpy(xt, X, 0.5 * dt_sub, k1)
        if any_gg:
            _with_gravity_gradient(tau, ext, xt, B, ORB, t_s + 0.5 * dt_sub, rpos, has_env)
        _derivative(xt, u_motor, ext, G, W, B, HAS_COULOMB, k2, h, r, u_net)
        _axpy(xt, X, 0.5 * dt_sub, k2)
        if any_gg:
            _with_gravity_gradient(tau, ext, xt, B, ORB, t_s + 0.5 * dt_sub, rpos, has_env)
        _derivative(xt, u_motor, ext, G, W, B, HAS_COULOMB, k3, h, r, u_net)
        _axpy(xt, X, dt_sub, k3)
        if any_gg:
            _with_gravity_gradient(tau, ext, xt, B, ORB, t_s + dt_sub, rpos, has_env)
        _derivative(xt, u_motor, ext, G, W, B, HAS_COULOMB, k4, h, r, u_net)
        _rk4_combine(X, k1, k2, k3, k4, dt_sub / 6.0)
        _winding_temperature(TEMP, u_motor, W, DECAY)
    return True


def angular_momentum_B(X: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Total angular momentum in body axes, N m s: I omega + sum Js Omega g. X (7+N, M) -> (M, 3)."""
    inertia = B[B_I:B_I + 9].T.reshape(-1, 3, 3)
    h = np.einsum("mij,mj->mi", inertia, X[4:7].T)
    h += np.einsum("im,im,icm->mc", W[W_JS], X[7:], G)
    return h


def angular_momentum_N(X: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Total angular momentum in N (conserved without external torque), N m s, (M, 3)."""
    from gnc.attitude import quat_rotate

    h_B = angular_momentum_B(X, G, W, B)
    return np.stack([quat_rotate(X[0:4, m], h_B[m]) for m in range(X.shape[1])])


def rotational_energy(X: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """T = 1/2 w^T I w + sum (1/2 Js Omega^2 + Js Omega g.w), J, (M,)."""
    inertia = B[B_I:B_I + 9].T.reshape(-1, 3, 3)
    w = X[4:7].T
    Om = X[7:]
    Js = W[W_JS]
    gw = np.einsum("icm,mc->im", G, w)
    return 0.5 * np.einsum("mi,mij,mj->m", w, inertia, w) + np.sum(0.5 * Js * Om**2 + Js * Om * gw, axis=0)


def seize_wheel(X: np.ndarray, G: np.ndarray, W: np.ndarray, B: np.ndarray, m: int, i: int) -> None:
    """Wheel i of run m seizes: its relative speed drops to zero and its momentum goes to the hub, with
    the total angular momentum conserved (I omega' = I omega + Js Omega g)."""
    inertia = B[B_I:B_I + 9, m].reshape(3, 3)
    X[4:7, m] += np.linalg.solve(inertia, W[W_JS, i, m] * X[7 + i, m] * G[i, :, m])
    X[7 + i, m] = 0.0
    W[W_MODE, i, m] = MODE_STUCK
    update_free_inertia(G, W, B, m)
