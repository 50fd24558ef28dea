"""The simulated world: hub + wheels + disturbance, IMU, star tracker, orbit and Sun/Moon truth.

``World(params, seed)`` is one run; ``WorldBatch(params_list, seed)`` steps M runs together as arrays in
one compiled call per step (campaigns, benchmarks). A World is a WorldBatch of one whose outputs are
unwrapped, so both share every line of model code.

Randomness: one ``numpy.random.Generator`` per model (disturbance, IMU, star tracker), each from
``SeedSequence(seed, spawn_key=(k,))`` - the k-th spawned child of the world seed - unless that model's
params carry their own ``seed``. So the same seed gives bit-identical outputs, and changing one model's seed
(or how often one sensor is sampled) never changes another model's numbers. In a batch each model's
generator draws for all runs at once (run m's noise depends on the batch seed and M, not on run m alone), and a
model's own ``seed`` override is taken from the first run's params.

Time: ``t`` is seconds since ``params.epoch_utc``; the ephemerides run on TDB = UTC + 69.184 s.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple, Sequence

import numpy as np
from numba import njit

from gnc.ephemeris import julian_date_tdb, parse_utc
from hil_sim.world import dynamics as dyn
from hil_sim.world import environment as env
from hil_sim.world import sensors as sen
from hil_sim.world.ephemeris import TruthEphemeris, spline_eval
from hil_sim.world.orbit import orbit_elements_array, orbit_position_row_N_km
from hil_sim.world.params import WHEEL_FAILURE_MODES, WorldParams

# spawn_key of each model's generator under the world seed (fixed: adding a model never shifts the others)
SEED_KEY_DISTURBANCE, SEED_KEY_IMU, SEED_KEY_STAR_TRACKER = 0, 1, 2

# AUX[m, :] layout: spacecraft position (km), then unit directions from the spacecraft in N.
AUX_R_SC, AUX_SUN, AUX_MOON, AUX_EARTH = 0, 3, 6, 9


class WheelStatus(NamedTuple):
    speed_rad_s: float  # relative to the body, about the wheel axis
    torque_Nm: float  # motor torque applied (after saturation, speed cut, failure)
    current_A: float
    temp_C: float
    fault: int  # bits: 1 stuck, 2 no torque, 4 speed limit, 8 torque saturated


class Truth(NamedTuple):
    t: float
    q_NB: np.ndarray
    omega_BN_B: np.ndarray
    wheel_speeds_rad_s: np.ndarray
    sun_N: np.ndarray  # unit, from the spacecraft
    moon_N: np.ndarray  # unit, from the spacecraft (with parallax)
    earth_N: np.ndarray  # unit, from the spacecraft to the Earth's centre
    r_sc_N_km: np.ndarray
    disturbance_B_Nm: np.ndarray


@lru_cache(maxsize=16)
def _shared_ephemeris(epoch_tdb_jd: float, spacing_s: float) -> TruthEphemeris:
    return TruthEphemeris(epoch_tdb_jd, spacing_s)


class NormalStream:
    """Standard normals from one model's Generator, drawn in blocks: numpy's per-call overhead (~2 us)
    would otherwise dominate a 1-run world. Deterministic: the block size is fixed, so the numbers a
    model sees depend only on its seed and its own call sequence."""

    BLOCK = 4096

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._buf = np.empty(0)
        self._pos = 0

    def take(self, n: int) -> np.ndarray:
        if self._pos + n > self._buf.size:
            self._buf = self.rng.standard_normal(max(self.BLOCK, n))
            self._pos = 0
        out = self._buf[self._pos:self._pos + n]
        self._pos += n
        return out

    def take_rows(self, n: int, k: int) -> np.ndarray:
        """(k, n): the numbers of k successive ``take(n)`` calls (one slice when no refill falls inside)."""
        if k and self._pos + n * k <= self._buf.size:
            out = self._buf[self._pos:self._pos + n * k].reshape(k, n)
            self._pos += n * k
            return out
        rows = np.empty((k, n))
        for i in range(k):
            rows[i] = self.take(n)
        return rows


def model_generator(seed: int | None, key: int, own_seed: int | None) -> np.random.Generator:
    """The generator of one model: its own seed if set, else child ``key`` of the world seed."""
    # SFC64: a statistically strong generator ~20 % faster than the default PCG64 at drawing normals,
    # which matters for 1,000-run batches sampling gyros at 100 Hz.
    if own_seed is not None:
        return np.random.Generator(np.random.SFC64(np.random.SeedSequence(own_seed)))
    return np.random.Generator(np.random.SFC64(np.random.SeedSequence(seed, spawn_key=(key,))))


# numba's on-disk cache of a kernel is keyed on its own module's source file only: after editing dynamics.py,
# orbit.py or ephemeris_truth.py in place, delete hil_sim/__pycache__/*.nbi/*.nbc so these kernels recompile.
@njit(cache=True, error_model="numpy")
def _world_step_kernel(X, D, TEMP, G, W, B, U_CMD, NORMALS, dt_sub, n_sub, U_APPLIED, FLAGS, DECAY, GM, HAS_COULOMB,
                       WORK, t_end_s, ORB, sun_c, moon_c, eph_t0, eph_h, AUX):
    """Step all runs (dynamics), then their orbit positions and Sun/Moon/Earth directions at t_end_s.
    Returns False (and changes nothing) if any torque command is NaN or infinite."""
    if B.shape[0] > dyn.B_FIELDS:
        _hold_sun(B, sun_c, eph_t0, eph_h, t_end_s - n_sub * dt_sub)
    if not dyn.dynamics_step_batch(X, D, TEMP, G, W, B, U_CMD, NORMALS, dt_sub, n_sub, U_APPLIED, FLAGS,
                                   DECAY, GM, HAS_COULOMB, WORK, ORB, t_end_s - n_sub * dt_sub):
        return False
    _aux_at(t_end_s, ORB, sun_c, moon_c, eph_t0, eph_h, AUX)
    return True


@njit(cache=True, error_model="numpy")
def _hold_sun(B, sun_c, eph_t0, eph_h, t_s):
    """The Sun's position at the start of a step into B, for the environment torques (held over the step)."""
    sun = np.empty(3)
    spline_eval(sun_c, eph_t0, eph_h, t_s, sun)
    env.hold_sun(B, sun)


@njit(cache=True, error_model="numpy")
def _aux_at(t_end_s, ORB, sun_c, moon_c, eph_t0, eph_h, AUX):
    """AUX rows at t_end_s: every run's orbit position and its Sun/Moon/Earth directions (nothing in the
    dynamics reads them: only the star tracker and the recorded truth)."""
    sun = np.empty(3)
    moon = np.empty(3)
    r = np.empty(3)
    spline_eval(sun_c, eph_t0, eph_h, t_end_s, sun)
    spline_eval(moon_c, eph_t0, eph_h, t_end_s, moon)
    for m in range(AUX.shape[0]):
        orbit_position_row_N_km(ORB, m, t_end_s, r)
        rn = 1.0 / math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
        s0, s1, s2 = sun[0] - r[0], sun[1] - r[1], sun[2] - r[2]
        sn = 1.0 / math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        m0, m1, m2 = moon[0] - r[0], moon[1] - r[1], moon[2] - r[2]
        mn = 1.0 / math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        for j in range(3):
            AUX[m, AUX_R_SC + j] = r[j]
            AUX[m, AUX_EARTH + j] = -r[j] * rn
        AUX[m, AUX_SUN], AUX[m, AUX_SUN + 1], AUX[m, AUX_SUN + 2] = s0 * sn, s1 * sn, s2 * sn
        AUX[m, AUX_MOON], AUX[m, AUX_MOON + 1], AUX[m, AUX_MOON + 2] = m0 * mn, m1 * mn, m2 * mn


@njit(cache=True, error_model="numpy")
def _world_period_kernel(X, D, TEMP, G, W, B, U_SEQ, NORMALS_SEQ, dt_sub, n_sub, U_APPLIED, FLAGS, DECAY, GM,
                         HAS_COULOMB, WORK, T_END, ORB, sun_c, moon_c, eph_t0, eph_h, AUX,
                         IMU_DUE, CLOCK, IMU_NORMALS, BIAS, GYRO_P, GYRO_SEQ, SAT_SEQ,
                         ST_DUE, ST_P, ST_BASIS, ST_NORMALS, ST_Q, ST_VALID, ST_BLIND, ST_Q_SEQ, ST_VALID_SEQ,
                         ST_BLIND_SEQ):
    """J steps of ``_world_step_kernel`` (U_SEQ[j], NORMALS_SEQ[j]), each followed by a gyro sample where
    IMU_DUE[j] and a star-tracker sample where ST_DUE[j]. One compiled call per GNC period instead of ~2 per
    dynamics step, with the per-period bookkeeping inside too (Python's per-call cost is the budget here).

    CLOCK: (t before the period, dt, IMU period, time of the last gyro sample or NaN); out: [3] = the time
    of the last gyro sample taken. T_END: out: each step's end time, accumulated as J one-step calls would. IMU_NORMALS / ST_NORMALS: one row per sample due (in
    order), as the one-call-per-step path draws them.
    Returns the number of steps done (< J: U_SEQ[j] not finite, nothing of step j applied)."""
    # AUX (orbit, Sun/Moon/Earth directions) only where it is read: at star-tracker samples and at the end
    # of the period (or of the last step done); the same values as evaluating it after every step.
    J = U_SEQ.shape[0]
    t, dt = CLOCK[0], CLOCK[1]
    for j in range(J):
        t = t + dt
        T_END[j] = t
    aux_step = -1
    i_imu = i_st = 0
    has_env = B.shape[0] > dyn.B_FIELDS
    for j in range(J):
        if has_env:
            _hold_sun(B, sun_c, eph_t0, eph_h, CLOCK[0] if j == 0 else T_END[j - 1])
        if not dyn.dynamics_step_batch(X, D, TEMP, G, W, B, U_SEQ[j], NORMALS_SEQ[j], dt_sub, n_sub, U_APPLIED,
                                       FLAGS, DECAY, GM, HAS_COULOMB, WORK, ORB, CLOCK[0] if j == 0 else T_END[j - 1]):
            if j > 0 and aux_step != j - 1:
                _aux_at(T_END[j - 1], ORB, sun_c, moon_c, eph_t0, eph_h, AUX)
            return j
        if ST_DUE[j] or j == J - 1:
            _aux_at(T_END[j], ORB, sun_c, moon_c, eph_t0, eph_h, AUX)
            aux_step = j
        if IMU_DUE[j]:
            imu_dt = CLOCK[2] if math.isnan(CLOCK[3]) else T_END[j] - CLOCK[3]
            CLOCK[3] = T_END[j]
            sen.gyro_sample_batch(X, BIAS, GYRO_P, IMU_NORMALS[i_imu], imu_dt, GYRO_SEQ[j], SAT_SEQ[j])
            i_imu += 1
        if ST_DUE[j]:
            sen.star_tracker_sample_batch(X, ST_P, ST_BASIS, AUX, AUX_SUN, AUX_MOON, ST_NORMALS[i_st], ST_Q,
                                          ST_VALID, ST_BLIND)
            i_st += 1
            ST_Q_SEQ[j] = ST_Q
            ST_VALID_SEQ[j] = ST_VALID
            ST_BLIND_SEQ[j] = ST_BLIND
    return J


_A_TABLE = 40  # slot of the ephemeris table in WorldBatch._period_kernel_args (after the kernel's 40 arguments)


# ------------------------------------------------------------------------------------------ packed state
# A compiled call pays numba's argument dispatch per argument (~0.1 us each): state a per-tick kernel reads
# lives in a few buffers (one per dtype), the named arrays being views of them, so such a call passes the
# buffers. The int buffer starts with the layout: one row (offset in its dtype's buffer, d0, d1, d2) per slot.
PACK_LAYOUT_COLS = 4


def pack_arrays(floats: Sequence[np.ndarray], ints: Sequence[np.ndarray],
                bools: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """(float64 buffer, int64 buffer with the layout first, bool buffer, views): copies of the arrays (up to
    3-d) in buffers, and the views that take their place, in the order given (floats, ints, bools = the
    slots 0..). The views are C-contiguous, as the arrays the kernels were typed with."""
    n_slots = len(floats) + len(ints) + len(bools)
    head = n_slots * PACK_LAYOUT_COLS
    bufs = []
    layout = np.zeros((n_slots, PACK_LAYOUT_COLS), dtype=np.int64)
    slot = 0
    for group, dtype, start in ((floats, np.float64, 0), (ints, np.int64, head), (bools, np.bool_, 0)):
        o = start
        for a in group:
            if a.ndim > 3:
                raise ValueError(f"pack_arrays: up to 3 dimensions, got shape {a.shape}")
            layout[slot, 0] = o
            layout[slot, 1:1 + a.ndim] = a.shape
            o += a.size
            slot += 1
        bufs.append(np.zeros(max(o, 1), dtype=dtype))
    fbuf, ibuf, bbuf = bufs
    ibuf[:head] = layout.reshape(-1)
    views = []
    for group, buf in ((floats, fbuf), (ints, ibuf), (bools, bbuf)):
        for a in group:
            o = int(layout[len(views), 0])
            v = buf[o:o + a.size].reshape(a.shape)
            v[...] = a
            views.append(v)
    return fbuf, ibuf, bbuf, views


@njit(cache=True, inline="always")
def view1(buf, layout, k):
    """Slot k of a packed buffer (1-d)."""
    o = layout[k * PACK_LAYOUT_COLS]
    return buf[o:o + layout[k * PACK_LAYOUT_COLS + 1]]


@njit(cache=True, inline="always")
def view2(buf, layout, k):
    """Slot k of a packed buffer (2-d)."""
    r = k * PACK_LAYOUT_COLS
    o, d0, d1 = layout[r], layout[r + 1], layout[r + 2]
    return buf[o:o + d0 * d1].reshape((d0, d1))


@njit(cache=True, inline="always")
def view3(buf, layout, k):
    """Slot k of a packed buffer (3-d)."""
    r = k * PACK_LAYOUT_COLS
    o, d0, d1, d2 = layout[r], layout[r + 1], layout[r + 2], layout[r + 3]
    return buf[o:o + d0 * d1 * d2].reshape((d0, d1, d2))


# WorldBatch's packed state (_pack_state): its slots, and the float / int scalars' places
(WP_X, WP_D, WP_TEMP, WP_G, WP_W, WP_B, WP_U_APPLIED, WP_DECAY, WP_GM, WP_WORK, WP_ORB, WP_AUX, WP_CLOCK, WP_BIAS,
 WP_GYRO_P, WP_ST_P, WP_ST_BASIS, WP_ST_Q, WP_GYRO_OUT, WP_SCALARS,
 WP_FLAGS, WP_ST_BLIND, WP_ISCALARS,
 WP_HAS_COULOMB, WP_ST_VALID, WP_GYRO_SAT) = range(26)
WPS_T_END, WPS_DT_SUB, WPS_EPH_T0, WPS_EPH_H = range(4)  # float scalars (WPS_T_END: out, the period's end)
WPS_N_SUB = 0  # int scalars


class WorldBatch:
    """M runs stepped together. All runs share the epoch and the number of wheels; any other parameter may
    differ per run (dispersions). Outputs and properties have a leading run axis (M, ...); the dynamics
    arrays X (7+N, M), G, W, B, D, TEMP, U_APPLIED, FLAGS keep the run axis last (see hil_sim.world.dynamics)."""

    def __init__(self, params: Sequence[WorldParams], seed: int | None = 0) -> None:
        params = list(params)
        if not params:
            raise ValueError("WorldBatch: need at least one WorldParams")
        if not all(isinstance(p, WorldParams) for p in params):
            raise ValueError("WorldBatch: every entry must be a hil_sim.world.params.WorldParams")
        epochs = {(parse_utc(p.epoch_utc), p.ephemeris_node_spacing_s) for p in params}
        if len(epochs) != 1:
            raise ValueError("WorldBatch: all runs must share epoch_utc and ephemeris_node_spacing_s")
        self.params = params
        self.seed = seed
        self.n_runs = M = len(params)
        p0 = params[0]
        self.epoch_tdb_jd = julian_date_tdb(parse_utc(p0.epoch_utc))
        self.ephemeris = _shared_ephemeris(self.epoch_tdb_jd, p0.ephemeris_node_spacing_s)
        self.max_step_s = np.array([p.max_integration_step_s for p in params]).min()

        self.G, self.W, self.B, self.X = dyn.pack_spacecraft([p.spacecraft for p in params])
        # Dynamics arrays have the run axis LAST (see hil_sim.world.dynamics): X (7+N, M), TEMP/U_APPLIED/FLAGS (N, M).
        self.n_wheels = N = self.G.shape[0]
        self.D = np.zeros((3, M))
        self.TEMP = self.W[dyn.W_TAMB].copy()
        self.U_APPLIED = np.zeros((N, M))
        self.FLAGS = np.zeros((N, M), dtype=np.int64)
        mode = self.W[dyn.W_MODE]
        self.FLAGS[mode == dyn.MODE_STUCK] = dyn.FAULT_STUCK
        self.FLAGS[mode == dyn.MODE_NO_TORQUE] = dyn.FAULT_NO_TORQUE
        self._coef_dt = -1.0
        self._coef: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._work = np.empty(dyn.work_shape(N, M))
        self.ORB = np.stack([orbit_elements_array(p.orbit) for p in params])
        self.AUX = np.zeros((M, 12))
        self._has_random_disturbance = bool(np.any(self.B[dyn.B_DIST_STD] > 0.0))
        self._no_normals = np.zeros(M * 3)

        self.rng_disturbance = model_generator(seed, SEED_KEY_DISTURBANCE, p0.spacecraft.disturbance.seed)
        self.rng_imu = model_generator(seed, SEED_KEY_IMU, p0.imu.seed)
        self.rng_star_tracker = model_generator(seed, SEED_KEY_STAR_TRACKER, p0.star_tracker.seed)

        self.normals_disturbance = NormalStream(self.rng_disturbance)
        self.normals_imu = NormalStream(self.rng_imu)
        self.normals_star_tracker = NormalStream(self.rng_star_tracker)

        self.GYRO_P = sen.pack_gyro([p.imu for p in params])
        turn_on = np.array([p.imu.bias_turn_on_std_rad_s for p in params])[:, None]
        self.BIAS = (np.array([p.imu.bias_B_rad_s for p in params])
                     + turn_on * self.normals_imu.take(M * 3).reshape(M, 3))
        self.imu_period_s = np.array([1.0 / p.imu.rate_hz for p in params])
        self._t_last_imu: float | None = None
        self.GYRO_OUT = np.zeros((M, 3))
        self.GYRO_SAT = np.zeros(M, dtype=np.bool_)

        self.ST_P = sen.pack_star_tracker([p.star_tracker for p in params])
        self.ST_BASIS = np.stack([sen.sensor_frame_basis_S(np.asarray(p.star_tracker.boresight_S)) for p in params])
        self.star_tracker_period_s = np.array([1.0 / p.star_tracker.rate_hz for p in params])
        self.ST_Q = np.zeros((M, 4))
        self.ST_Q[:, 0] = 1.0
        self.ST_VALID = np.zeros(M, dtype=np.bool_)
        self.ST_BLIND = np.zeros(M, dtype=np.int64)

        self._period_out: tuple[np.ndarray, ...] | None = None
        self._kernel_args: list | None = None  # see _period_kernel_args
        self._t_end = np.zeros(0)
        self._clock = np.array([0.0, 0.0, self.imu_period_s[0], math.nan])  # see _world_period_kernel
        self._no_normals_rows = np.zeros((0, M * 3))
        self._pack_state()
        self._t = 0.0
        self._advance(0.0, np.zeros((M, N)), 0)
        self._warm_period_kernel()

    def _pack_state(self) -> None:
        """The arrays of the per-period kernel (``period_packed`` in hil_sim.devices.kernels) as views of three
        buffers (``pack_arrays``): the same arrays, in place, for every other reader. The step coefficients
        get slots too (``_set_coef`` writes them in place)."""
        N, M = self.n_wheels, self.n_runs
        floats = [self.X, self.D, self.TEMP, self.G, self.W, self.B, self.U_APPLIED, np.zeros((N, M)),
                  np.zeros((2, M)), self._work, self.ORB, self.AUX, self._clock, self.BIAS, self.GYRO_P, self.ST_P,
                  self.ST_BASIS, self.ST_Q, self.GYRO_OUT, np.zeros(4)]
        ints = [self.FLAGS, self.ST_BLIND, np.zeros(1, dtype=np.int64)]
        bools = [np.zeros(N, dtype=np.bool_), self.ST_VALID, self.GYRO_SAT]
        self.packed_f, self.packed_i, self.packed_b, views = pack_arrays(floats, ints, bools)
        (self.X, self.D, self.TEMP, self.G, self.W, self.B, self.U_APPLIED, decay, gm, self._work, self.ORB, self.AUX,
         self._clock, self.BIAS, self.GYRO_P, self.ST_P, self.ST_BASIS, self.ST_Q, self.GYRO_OUT, self._scalars,
         self.FLAGS, self.ST_BLIND, self._iscalars, has_coulomb, self.ST_VALID, self.GYRO_SAT) = views
        self._coef = (decay, gm, has_coulomb)  # filled in place (_set_coef): the views stay the kernels' arrays
        self._coef_dt = -1.0
        self._packed_dt, self._packed_n_sub = math.nan, -1  # what dt_sub / n_sub were set for (prepare_packed)
        self._packed_table: tuple | None = None

    def _set_coef(self, dt_sub: float) -> None:
        """The step coefficients for sub-steps of dt_sub, into their slots."""
        decay, gm, has_coulomb = dyn.step_coefficients(self.W, self.B, dt_sub)
        self._coef[0][...] = decay
        self._coef[1][...] = gm
        self._coef[2][...] = has_coulomb
        self._coef_dt = dt_sub

    def _warm_period_kernel(self) -> None:
        """Call the period kernel once with no step (J = 0), with the types ``advance_sampled`` passes: on a
        machine without numba's cache it compiles here, at set-up, not inside the first lockstep tick
        (seconds, in which the flight software would wait for a SYNC)."""
        M, N = self.n_runs, self.n_wheels
        none = np.zeros(0, dtype=np.bool_)
        self._period_kernel(np.zeros((0, M, N)), np.zeros((0, M * 3)), 0.0, 0, np.zeros(0), none, np.zeros(4),
                            np.zeros((0, M * 6)), none, np.zeros((0, M * 3)),
                            (np.zeros((0, M, 3)), np.zeros((0, M), dtype=np.bool_), np.zeros((0, M, 4)),
                             np.zeros((0, M), dtype=np.bool_), np.zeros((0, M), dtype=np.int64)))

    def _period_kernel(self, u_seq, normals, dt_sub, n_sub, t_end, imu_due, clock, imu_normals, st_due, st_normals,
                       out) -> int:
        """``_world_period_kernel`` on this batch's state; ``out``: (gyro, sat, st_q, st_valid, st_blind)."""
        eph = self.ephemeris
        eph_t0, sun_c, moon_c = eph.table  # one read: consistent even if another thread extends the table
        decay, gm, has_coulomb = self._coef
        gyro, sat, st_q, st_valid, st_blind = out
        return _world_period_kernel(self.X, self.D, self.TEMP, self.G, self.W, self.B, u_seq, normals, dt_sub, n_sub,
                                    self.U_APPLIED, self.FLAGS, decay, gm, has_coulomb, self._work, t_end, self.ORB,
                                    sun_c, moon_c, eph_t0, eph.node_spacing_s, self.AUX,
                                    imu_due, clock, imu_normals, self.BIAS, self.GYRO_P, gyro, sat,
                                    st_due, self.ST_P, self.ST_BASIS, st_normals, self.ST_Q, self.ST_VALID,
                                    self.ST_BLIND, st_q, st_valid, st_blind)

    # ----------------------------------------------------------------------------------------- stepping
    @property
    def t(self) -> float:
        """Simulation time, s since the epoch."""
        return self._t

    def _advance(self, dt_s: float, u_cmd: np.ndarray, n_sub: int) -> None:
        t_end = self._t + dt_s
        eph = self.ephemeris
        if t_end >= eph.t_end_s or t_end < eph.t_start_s:
            eph.ensure(min(self._t, t_end), t_end)
        if self._has_random_disturbance and n_sub > 0:
            normals = self.normals_disturbance.take(n_sub * self.n_runs * 3)
        else:
            normals = self._no_normals
        dt_sub = dt_s / n_sub if n_sub else 0.0
        if dt_sub != self._coef_dt:
            self._set_coef(dt_sub)
        decay, gm, has_coulomb = self._coef
        eph_t0, sun_c, moon_c = eph.table  # one read: consistent even if another thread extends the table
        if not _world_step_kernel(self.X, self.D, self.TEMP, self.G, self.W, self.B, u_cmd, normals, dt_sub, n_sub,
                                  self.U_APPLIED, self.FLAGS, decay, gm, has_coulomb, self._work, t_end, self.ORB,
                                  sun_c, moon_c, eph_t0, eph.node_spacing_s, self.AUX):
            raise ValueError(f"step: wheel_torque_cmd_Nm must be finite, got {u_cmd.tolist()!r}")
        self._t = t_end

    def advance_sampled(self, dt_s: float, n_sub: int, u_seq: np.ndarray, imu_due: np.ndarray,
                        st_due: np.ndarray, n_imu: int | None = None,
                        n_st: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """J = len(u_seq) steps of dt_s (n_sub RK4 sub-steps each), commands u_seq[j] (M, N), each step
        followed by ``imu_sample_arrays()`` where imu_due[j] and ``star_tracker_sample_arrays()`` where
        st_due[j]: the same numbers, bit for bit, as those calls one by one, in one compiled call.
        Returns gyro (J, M, 3), saturated (J, M), star-tracker q (J, M, 4), valid (J, M), blind (J, M);
        rows where the sensor was not due are left unset. ``n_imu``/``n_st``: the number of True flags in
        imu_due/st_due when the caller has counted them."""
        J, M = len(u_seq), self.n_runs
        if self._has_random_disturbance and n_sub > 0:
            normals = self.normals_disturbance.take_rows(n_sub * M * 3, J)
        else:
            normals = self._no_normals_rows
            if normals.shape[0] != J:
                normals = self._no_normals_rows = np.zeros((J, self._no_normals.size))
        # one row per sample due, in order: the numbers J one-step calls would draw
        if n_imu is None:
            n_imu = int(np.count_nonzero(imu_due))
        if n_st is None:
            n_st = int(np.count_nonzero(st_due))
        imu_normals = self.normals_imu.take_rows(M * 6, n_imu)
        st_normals = self.normals_star_tracker.take_rows(M * 3, n_st)
        args = self.prepare_period(dt_s, n_sub, J)
        args[6], args[7] = u_seq, normals
        args[23], args[25], args[30], args[33] = imu_due, imu_normals, st_due, st_normals
        self.finish_period(_world_period_kernel(*args[:_A_TABLE]), u_seq, imu_due)
        return self._period_out

    def prepare_period(self, dt_s: float, n_sub: int, J: int) -> list:
        """What ``advance_sampled`` does before drawing the period's normals and calling the kernel (the
        ephemeris table's reach, the step coefficients, the outputs, the clock), with the kernel's arguments
        (``_period_kernel_args``, dt and sub-steps set) returned."""
        self._reach(dt_s, J)
        M = self.n_runs
        dt_sub = dt_s / n_sub if n_sub else 0.0
        if dt_sub != self._coef_dt:
            self._set_coef(dt_sub)
        if self._period_out is None or self._period_out[0].shape[0] != J:
            # outputs reused from period to period (callers copy what they keep, as with GYRO_OUT)
            self._period_out = (np.zeros((J, M, 3)), np.zeros((J, M), dtype=np.bool_), np.zeros((J, M, 4)),
                                np.zeros((J, M), dtype=np.bool_), np.zeros((J, M), np.int64))
            self._t_end = np.zeros(J)
        table = self.ephemeris.table  # one read: consistent even if another thread extends the table
        args = self._kernel_args
        if (args is None or args[_A_TABLE] is not table or args[_A_TABLE + 1] is not self._coef
                or args[16] is not self._t_end):
            args = self._kernel_args = self._period_kernel_args(table)
        args[8], args[9] = dt_sub, n_sub
        self._start_clock(dt_s)
        return args

    def _reach(self, dt_s: float, J: int) -> None:
        """The ephemeris table reaches past the period's J steps (a bound: the kernels accumulate exactly)."""
        eph = self.ephemeris
        t_last = self._t + J * dt_s
        if t_last + dt_s >= eph.t_end_s or self._t < eph.t_start_s:
            eph.ensure(self._t, t_last + dt_s)

    def _start_clock(self, dt_s: float) -> None:
        clock = self._clock
        clock[0], clock[1] = self._t, dt_s
        clock[3] = math.nan if self._t_last_imu is None else self._t_last_imu

    def prepare_packed(self, dt_s: float, n_sub: int, J: int) -> tuple:
        """``prepare_period`` for ``period_packed`` (the state in its slots, not an argument list): the
        ephemeris table's reach, the step coefficients, dt_sub / n_sub and the clock. Returns the table."""
        self._reach(dt_s, J)
        if dt_s != self._packed_dt or n_sub != self._packed_n_sub:
            self._dt_sub = dt_s / n_sub if n_sub else 0.0
            self._scalars[WPS_DT_SUB] = self._dt_sub
            self._iscalars[WPS_N_SUB] = n_sub
            self._packed_dt, self._packed_n_sub = dt_s, n_sub
        if self._dt_sub != self._coef_dt:
            self._set_coef(self._dt_sub)
        table = self.ephemeris.table  # one read: consistent even if another thread extends the table
        if table is not self._packed_table:
            self._scalars[WPS_EPH_T0] = table[0]
            self._scalars[WPS_EPH_H] = self.ephemeris.node_spacing_s
            self._packed_table = table
        self._start_clock(dt_s)
        return table

    def finish_packed(self, done: int, J: int, u_seq: np.ndarray) -> None:
        """``finish_period`` after ``period_packed`` (which copied the last gyro sample already)."""
        if done:
            self._t = self._scalars.item(WPS_T_END)
            t_imu = self._clock.item(3)
            if t_imu == t_imu:  # not NaN
                self._t_last_imu = t_imu
        if done < J:
            raise ValueError(f"step: wheel_torque_cmd_Nm must be finite, got {u_seq[done].tolist()!r}")

    def finish_period(self, done: int, u_seq: np.ndarray, imu_due: np.ndarray) -> None:
        """After the period kernel did ``done`` of len(u_seq) steps: the clock and the last gyro sample;
        ValueError if a step was refused (a command not finite)."""
        if done:
            clock = self._clock
            self._t = float(self._t_end[done - 1])
            if not math.isnan(clock[3]):
                self._t_last_imu = float(clock[3])
            if imu_due[done - 1]:
                gyro, sat = self._period_out[0], self._period_out[1]
                self.GYRO_OUT[:], self.GYRO_SAT[:] = gyro[done - 1], sat[done - 1]
        if done < len(u_seq):
            raise ValueError(f"step: wheel_torque_cmd_Nm must be finite, got {u_seq[done].tolist()!r}")

    def _period_kernel_args(self, table: tuple) -> list:
        """``_world_period_kernel``'s arguments on this batch's state, as ``_period_kernel`` passes them, with
        the per-period ones (commands, normals, dt, due flags: slots 6-9, 23, 25, 30, 33) to be filled in,
        then the ephemeris table and the step coefficients they were made from (slots _A_TABLE, _A_TABLE + 1).
        Rebuilt when the step coefficients, the period's length or the table change."""
        eph = self.ephemeris
        eph_t0, sun_c, moon_c = table
        decay, gm, has_coulomb = self._coef
        gyro, sat, st_q, st_valid, st_blind = self._period_out
        return [self.X, self.D, self.TEMP, self.G, self.W, self.B, None, None, 0.0, 0, self.U_APPLIED, self.FLAGS,
                decay, gm, has_coulomb, self._work, self._t_end, self.ORB, sun_c, moon_c, eph_t0, eph.node_spacing_s,
                self.AUX, None, self._clock, None, self.BIAS, self.GYRO_P, gyro, sat, None, self.ST_P, self.ST_BASIS,
                None, self.ST_Q, self.ST_VALID, self.ST_BLIND, st_q, st_valid, st_blind, table, self._coef]

    def step(self, dt_s: float, wheel_torque_cmd_Nm: np.ndarray) -> None:
        """Advance all runs by dt_s (split into equal RK4 sub-steps <= max_integration_step_s) with the motor
        torque commands (M, N) N m held. Non-finite commands raise ValueError."""
        if not dt_s > 0.0:
            raise ValueError(f"step: dt_s must be > 0, got {dt_s!r}")
        u = np.asarray(wheel_torque_cmd_Nm, dtype=np.float64)
        if u.shape != (self.n_runs, self.n_wheels):
            if u.size != self.n_runs * self.n_wheels:
                raise ValueError(f"step: wheel_torque_cmd_Nm must have shape ({self.n_runs}, {self.n_wheels}) "
                                 f"(runs, wheels), got {u.shape}")
            u = u.reshape(self.n_runs, self.n_wheels)
        n_sub = max(1, math.ceil(dt_s / self.max_step_s - 1e-9))
        self._advance(dt_s, u, n_sub)

    # ------------------------------------------------------------------------------------------ sensors
    def imu_sample_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Gyro outputs (M,3) rad/s and saturation flags (M,) at the current time."""
        dt_since = self.imu_period_s[0] if self._t_last_imu is None else self._t - self._t_last_imu
        self._t_last_imu = self._t
        normals = self.normals_imu.take(self.n_runs * 6)
        sen.gyro_sample_batch(self.X, self.BIAS, self.GYRO_P, normals, dt_since, self.GYRO_OUT, self.GYRO_SAT)
        return self.GYRO_OUT, self.GYRO_SAT

    def star_tracker_sample_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q_NS (M,4), valid (M,), blind_source (M,) at the current time."""
        normals = self.normals_star_tracker.take(self.n_runs * 3)
        sen.star_tracker_sample_batch(self.X, self.ST_P, self.ST_BASIS, self.AUX, AUX_SUN, AUX_MOON, normals,
                                      self.ST_Q, self.ST_VALID, self.ST_BLIND)
        return self.ST_Q, self.ST_VALID, self.ST_BLIND

    # ------------------------------------------------------------------------------------------- truth
    @property
    def q_NB(self) -> np.ndarray:
        return self.X[0:4].T

    @property
    def omega_BN_B(self) -> np.ndarray:
        return self.X[4:7].T

    @property
    def wheel_speeds_rad_s(self) -> np.ndarray:
        return self.X[7:].T

    @property
    def sun_N(self) -> np.ndarray:
        return self.AUX[:, AUX_SUN:AUX_SUN + 3]

    @property
    def moon_N(self) -> np.ndarray:
        return self.AUX[:, AUX_MOON:AUX_MOON + 3]

    @property
    def earth_N(self) -> np.ndarray:
        return self.AUX[:, AUX_EARTH:AUX_EARTH + 3]

    @property
    def r_sc_N_km(self) -> np.ndarray:
        return self.AUX[:, AUX_R_SC:AUX_R_SC + 3]

    def angular_momentum_N(self) -> np.ndarray:
        return dyn.angular_momentum_N(self.X, self.G, self.W, self.B)

    def environment_torques_B(self) -> np.ndarray:
        """Each environment effect's torque (hil_sim.world.environment.EFFECTS) on every run at the current state and
        time, (M, len(EFFECTS), 3) [N m] in body axes: the dynamics' own kernels; zero where an effect is off."""
        out = np.zeros((self.n_runs, len(env.EFFECTS), 3))
        if self.B.shape[0] > dyn.B_FIELDS:
            eph_t0, sun_c, _ = self.ephemeris.table
            # the next step holds its own Sun: overwriting the held one here changes nothing it computes
            _hold_sun(self.B, sun_c, eph_t0, self.ephemeris.node_spacing_s, self._t)
            env.environment_torques_B(self.X, self.B, self.ORB, self._t, out)
        return out

    def wheel_currents_A(self) -> np.ndarray:
        """Motor currents (M, N), A."""
        return (self.U_APPLIED / self.W[dyn.W_KT]).T

    def wheel_status_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(speed rad/s, applied motor torque N m, current A, temperature deg C, fault bits), each (M, N)."""
        return (self.X[7:].T.copy(), self.U_APPLIED.T.copy(), self.wheel_currents_A(), self.TEMP.T.copy(),
                self.FLAGS.T.copy())

    # ------------------------------------------------------------------------------------------ faults
    def set_wheel_failure(self, wheel: int, mode: str, run: int = 0) -> None:
        """Change wheel ``wheel`` of run ``run`` to ``none``, ``stuck`` (seizes: momentum goes to the hub,
        total angular momentum conserved) or ``no_torque``."""
        if mode not in WHEEL_FAILURE_MODES:
            raise ValueError(f"set_wheel_failure: mode {mode!r} not allowed; use one of {WHEEL_FAILURE_MODES}")
        if not 0 <= wheel < self.n_wheels:
            raise ValueError(f"set_wheel_failure: wheel index {wheel} out of range 0..{self.n_wheels - 1}")
        if mode == "stuck":
            dyn.seize_wheel(self.X, self.G, self.W, self.B, run, wheel)
        else:
            self.W[dyn.W_MODE, wheel, run] = dyn._MODE_CODES[mode]
            dyn.update_free_inertia(self.G, self.W, self.B, run)
        self._coef_dt = -1.0  # W changed: recompute the per-step coefficients (their slots, in place)


class World:
    """One simulated run (the contract in the team brief). See the module docstring."""

    def __init__(self, params: WorldParams | None = None, seed: int | None = 0) -> None:
        self.params = params if params is not None else WorldParams()
        self.seed = seed
        self.batch = WorldBatch([self.params], seed)
        self.n_wheels = self.batch.n_wheels
        self.imu_period_s = float(self.batch.imu_period_s[0])
        self.star_tracker_period_s = float(self.batch.star_tracker_period_s[0])
        self._u = np.zeros((1, self.n_wheels))  # (M, N) command layout, as WorldBatch.step takes it
        self._last_dt = -1.0
        self._last_n_sub = 1

    @property
    def t(self) -> float:
        return self.batch._t

    def step(self, dt_s: float, wheel_torque_cmd_Nm: np.ndarray | Sequence[float]) -> None:
        """Advance truth by dt_s seconds (RK4 sub-steps <= max_integration_step_s), motor torques (N,) N m held."""
        u = self._u
        try:
            u[0] = wheel_torque_cmd_Nm
        except ValueError as exc:
            raise ValueError(f"step: wheel_torque_cmd_Nm must have {self.n_wheels} values, "
                             f"got {wheel_torque_cmd_Nm!r}") from exc
        if not dt_s > 0.0:
            raise ValueError(f"step: dt_s must be > 0, got {dt_s!r}")
        if dt_s != self._last_dt:
            self._last_dt = dt_s
            self._last_n_sub = max(1, math.ceil(dt_s / self.batch.max_step_s - 1e-9))
        self.batch._advance(dt_s, u, self._last_n_sub)

    def advance_sampled(self, dt_s: float, wheel_torque_cmds_Nm: np.ndarray, imu_due: Sequence[bool],
                        st_due: Sequence[bool]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """J steps of ``step(dt_s, wheel_torque_cmds_Nm[j])`` (J, N), each followed by ``imu_sample()``
        where imu_due[j] and ``star_tracker_sample()`` where st_due[j], in one compiled call (the same
        numbers). Returns gyro (J, 3), saturated (J,), star-tracker q_NS (J, 4), valid (J,), blind (J,);
        rows where a sensor was not due are unset."""
        u = np.ascontiguousarray(wheel_torque_cmds_Nm, dtype=np.float64)
        if u.ndim != 2 or u.shape[1] != self.n_wheels or not u.shape[0]:
            raise ValueError(f"advance_sampled: commands must have shape (steps, {self.n_wheels}), got {u.shape}")
        if not dt_s > 0.0:
            raise ValueError(f"step: dt_s must be > 0, got {dt_s!r}")
        if dt_s != self._last_dt:
            self._last_dt = dt_s
            self._last_n_sub = max(1, math.ceil(dt_s / self.batch.max_step_s - 1e-9))
        gyro, sat, q, valid, blind = self.batch.advance_sampled(
            dt_s, self._last_n_sub, u.reshape(u.shape[0], 1, self.n_wheels), np.asarray(imu_due, dtype=np.bool_),
            np.asarray(st_due, dtype=np.bool_))
        return gyro[:, 0], sat[:, 0], q[:, 0], valid[:, 0], blind[:, 0]

    def sub_steps(self, dt_s: float) -> int:
        """RK4 sub-steps of a step of ``dt_s`` (each <= max_integration_step_s)."""
        if dt_s != self._last_dt:
            if not dt_s > 0.0:
                raise ValueError(f"step: dt_s must be > 0, got {dt_s!r}")
            self._last_dt = dt_s
            self._last_n_sub = max(1, math.ceil(dt_s / self.batch.max_step_s - 1e-9))
        return self._last_n_sub

    def advance_planned(self, dt_s: float, u_seq: np.ndarray, imu_due: np.ndarray, st_due: np.ndarray, n_imu: int,
                        n_st: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``advance_sampled`` with its inputs already as the batch takes them (the devices' tick kernels
        make them): u_seq (J, 1, N) float64, imu_due/st_due (J,) bool with n_imu/n_st True. Returns the
        batch's outputs (run axis kept: gyro (J, 1, 3), ...)."""
        if not dt_s > 0.0:
            raise ValueError(f"step: dt_s must be > 0, got {dt_s!r}")
        if dt_s != self._last_dt:
            self._last_dt = dt_s
            self._last_n_sub = max(1, math.ceil(dt_s / self.batch.max_step_s - 1e-9))
        return self.batch.advance_sampled(dt_s, self._last_n_sub, u_seq, imu_due, st_due, n_imu, n_st)

    def imu_sample(self) -> sen.ImuSample:
        omega, sat = self.batch.imu_sample_arrays()
        return sen.ImuSample(omega[0].copy(), bool(sat[0]), self.batch._t)

    def star_tracker_sample(self) -> sen.StarTrackerSample:
        q, valid, blind = self.batch.star_tracker_sample_arrays()
        return sen.StarTrackerSample(q[0].copy(), bool(valid[0]), int(blind[0]))

    def wheel_status(self) -> list[WheelStatus]:
        b = self.batch  # run 0's columns of WorldBatch.wheel_status_arrays, read directly (once per tick)
        applied = b.U_APPLIED[:, 0]
        return [WheelStatus(*row) for row in zip(b.X[7:, 0].tolist(), applied.tolist(),
                                                  (applied / b.W[dyn.W_KT, :, 0]).tolist(), b.TEMP[:, 0].tolist(),
                                                  b.FLAGS[:, 0].tolist())]

    @property
    def truth(self) -> Truth:
        b = self.batch
        return Truth(b._t, b.X[0:4, 0].copy(), b.X[4:7, 0].copy(), b.X[7:, 0].copy(), b.sun_N[0].copy(),
                     b.moon_N[0].copy(), b.earth_N[0].copy(), b.r_sc_N_km[0].copy(),
                     b.B[dyn.B_TAU_CONST:dyn.B_TAU_CONST + 3, 0] + b.D[:, 0])

    def angular_momentum_N(self) -> np.ndarray:
        """Total inertial angular momentum, N m s (3,)."""
        return self.batch.angular_momentum_N()[0]

    def set_wheel_failure(self, wheel: int, mode: str) -> None:
        self.batch.set_wheel_failure(wheel, mode, 0)
