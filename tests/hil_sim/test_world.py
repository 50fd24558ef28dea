"""World composition: determinism and seed independence, truth ephemeris, orbit, parameter read-back."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hil_sim.world.params import (DisturbanceParams, ImuParams, OrbitParams, SpacecraftParams, StarTrackerParams,
                            WorldParams)
from hil_sim.world.world import World, WorldBatch


def _noisy_params(imu_seed=None, st_seed=None) -> WorldParams:
    return WorldParams(
        spacecraft=SpacecraftParams(disturbance=DisturbanceParams(random_std_Nm=1e-4, random_correlation_time_s=5.0),
                                    omega_BN_B0_rad_s=(0.01, -0.005, 0.002)),
        imu=ImuParams(seed=imu_seed),
        star_tracker=StarTrackerParams(seed=st_seed),
    )


def _record(world: World, steps: int = 300, imu_every: int = 1) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(99)  # the same command sequence for every world
    out = {"q": [], "imu": [], "st": []}
    for k in range(steps):
        world.step(0.01, rng.uniform(-0.05, 0.05, world.n_wheels))
        if k % imu_every == 0:
            out["imu"].append(world.imu_sample().omega_BN_B)
        if k % 10 == 0:
            out["st"].append(world.star_tracker_sample().q_NS)
        out["q"].append(world.truth.q_NB)
    return {k: np.array(v) for k, v in out.items()}


def test_same_seed_is_bit_identical():
    a = _record(World(_noisy_params(), seed=1234))
    b = _record(World(_noisy_params(), seed=1234))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])


def test_different_seed_differs():
    a = _record(World(_noisy_params(), seed=1))
    b = _record(World(_noisy_params(), seed=2))
    for key in a:
        assert not np.array_equal(a[key], b[key]), key


def test_changing_one_models_seed_leaves_the_others_unchanged():
    base = _record(World(_noisy_params(), seed=5))
    imu_changed = _record(World(_noisy_params(imu_seed=777), seed=5))
    st_changed = _record(World(_noisy_params(st_seed=777), seed=5))
    assert not np.array_equal(base["imu"], imu_changed["imu"])
    np.testing.assert_array_equal(base["st"], imu_changed["st"])
    np.testing.assert_array_equal(base["q"], imu_changed["q"])  # disturbance stream untouched
    assert not np.array_equal(base["st"], st_changed["st"])
    np.testing.assert_array_equal(base["imu"], st_changed["imu"])
    np.testing.assert_array_equal(base["q"], st_changed["q"])
    # sampling the IMU less often consumes fewer IMU numbers but must not touch the star tracker's stream
    sparse_imu = _record(World(_noisy_params(), seed=5), imu_every=7)
    np.testing.assert_array_equal(base["st"], sparse_imu["st"])


def test_truth_ephemeris_interpolation_error_against_direct_astropy():
    from hil_sim.world.ephemeris import TruthEphemeris, astropy_sun_moon_N_km

    eph = TruthEphemeris(2462580.0, 3600.0)
    t = np.random.default_rng(2).uniform(0.0, 20 * 86400.0, 300)  # crosses several node blocks
    sun_i, moon_i = eph.positions_N_km(t)
    sun_d, moon_d = astropy_sun_moon_N_km(2462580.0 + t / 86400.0)

    def ang(a, b):
        return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))

    assert ang(moon_i, moon_d).max() < 1e-7  # rad (0.02 arcsec): stated in ephemeris_truth's docstring
    assert ang(sun_i, sun_d).max() < 1e-9
    assert np.abs(np.linalg.norm(moon_i, axis=1) / np.linalg.norm(moon_d, axis=1) - 1).max() < 1e-8


def test_world_sun_moon_earth_directions_are_from_the_spacecraft():
    from gnc.ephemeris import julian_date_tdb
    from hil_sim.world.ephemeris import astropy_sun_moon_N_km

    params = WorldParams(epoch_utc="2031-11-05T03:00:00Z")
    world = World(params, seed=0)
    world.step(600.0, np.zeros(4))
    truth = world.truth
    sun, moon = astropy_sun_moon_N_km(julian_date_tdb(params.epoch_utc) + 600.0 / 86400.0)
    r = truth.r_sc_N_km
    np.testing.assert_allclose(truth.moon_N, (moon[0] - r) / np.linalg.norm(moon[0] - r), atol=1e-7)
    np.testing.assert_allclose(truth.sun_N, (sun[0] - r) / np.linalg.norm(sun[0] - r), atol=1e-9)
    np.testing.assert_allclose(truth.earth_N, -r / np.linalg.norm(r), atol=1e-15)


def test_kepler_orbit_two_body_invariants():
    from hil_sim.world.orbit import KeplerOrbit

    p = OrbitParams(semi_major_axis_km=12000.0, eccentricity=0.3, inclination_deg=63.4, raan_deg=40.0,
                    arg_perigee_deg=270.0, mean_anomaly_deg=10.0)
    orbit = KeplerOrbit(p)
    t = np.linspace(0.0, orbit.period_s, 400)
    r = orbit.position_N_km(t)
    radius = np.linalg.norm(r, axis=1)
    assert radius.min() == pytest.approx(12000.0 * 0.7, rel=1e-4)
    assert radius.max() == pytest.approx(12000.0 * 1.3, rel=1e-4)
    np.testing.assert_allclose(r[0], r[-1], atol=1e-6)  # closed after one period
    # vis-viva and constant angular momentum (velocity from central differences, independent of the code)
    h = 1e-3
    for tk in t[::40]:
        v = (orbit.position_N_km(tk + h) - orbit.position_N_km(tk - h)) / (2 * h)
        np.testing.assert_allclose(orbit.velocity_N_km_s(tk), v, rtol=0, atol=1e-6)
        rk = orbit.position_N_km(tk)
        assert v @ v == pytest.approx(p.mu_km3_s2 * (2 / np.linalg.norm(rk) - 1 / 12000.0), rel=1e-7)
        hvec = np.cross(rk, v)
        assert math.degrees(math.acos(hvec[2] / np.linalg.norm(hvec))) == pytest.approx(63.4, abs=1e-6)


def test_params_round_trip_and_clear_errors():
    params = WorldParams(imu=ImuParams(rate_hz=200.0), orbit=OrbitParams(eccentricity=0.01))
    data = params.to_dict()
    assert data["imu"]["rate_hz"] == 200.0 and len(data["spacecraft"]["wheels"]) == 4
    assert WorldParams.from_dict(data) == params
    data["star_tracker"]["sun_exclusion"] = 30.0
    with pytest.raises(ValueError, match=r"world.star_tracker: unknown key\(s\) \['sun_exclusion'\]"):
        WorldParams.from_dict(data)
    with pytest.raises(ValueError, match="orbit.eccentricity"):
        OrbitParams(eccentricity=1.2)
    with pytest.raises(ValueError, match="epoch_utc"):
        WorldParams(epoch_utc="yesterday")
    dispersed = dataclasses.replace(params, star_tracker=dataclasses.replace(params.star_tracker,
                                                                              sun_exclusion_deg=35.0))
    assert World(dispersed, seed=0).params.star_tracker.sun_exclusion_deg == 35.0


def test_batch_rejects_mixed_epochs_and_wheel_counts():
    with pytest.raises(ValueError, match="epoch"):
        WorldBatch([WorldParams(), WorldParams(epoch_utc="2031-01-01T00:00:00Z")])
    with pytest.raises(ValueError, match="number of wheels"):
        WorldBatch([WorldParams(), WorldParams(spacecraft=SpacecraftParams(wheels=()))])


def test_batch_is_deterministic():
    params = [_noisy_params()] * 4
    outs = []
    for _ in range(2):
        b = WorldBatch(params, seed=3)
        for _ in range(50):
            b.step(0.1, np.full((4, 4), 0.01))
            b.imu_sample_arrays()
        outs.append((b.X.copy(), b.imu_sample_arrays()[0].copy(), b.star_tracker_sample_arrays()[0].copy()))
    for x, y in zip(*outs):
        np.testing.assert_array_equal(x, y)


def test_truth_ephemeris_works_offline(monkeypatch):
    """No IERS table, leap-second file or ephemeris may be downloaded: block every socket and build a fresh
    table (an epoch no other test uses, so nothing comes from the cache)."""
    import socket

    from hil_sim.world.ephemeris import TruthEphemeris

    def refuse(*args, **kwargs):
        raise OSError("network access attempted while computing the truth ephemeris")

    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)
    monkeypatch.setenv("KEEPOUT_EPHEMERIS_CACHE", "off")  # astropy itself, not the nodes kept on disk
    eph = TruthEphemeris(2463912.25, 3600.0)  # 2034-03
    sun, moon = eph.positions_N_km(np.array([0.0, 86400.0]))
    assert np.all(np.isfinite(sun)) and np.all(np.isfinite(moon))
    assert 1.45e8 < np.linalg.norm(sun[0]) < 1.53e8 and 3.5e5 < np.linalg.norm(moon[0]) < 4.1e5


def test_truth_ephemeris_values_do_not_depend_on_history():
    """Determinism across runs sharing the cached table: extending it must not change values already used."""
    from hil_sim.world.ephemeris import TruthEphemeris

    t = np.array([1.0, 2.5 * 86400.0, 3.99 * 86400.0])
    short = TruthEphemeris(2462001.5, 3600.0)
    before = short.positions_N_km(t)
    short.ensure(-5 * 86400.0, 30 * 86400.0)  # what a long run (or an earlier one) would do
    after = short.positions_N_km(t)
    np.testing.assert_array_equal(before[0], after[0])
    np.testing.assert_array_equal(before[1], after[1])


def test_truth_ephemeris_epochs_share_one_absolute_grid():
    """Campaigns disperse the epoch by hours: a second epoch in the same blocks must reuse the fitted
    blocks (no astropy call) and give the same positions at the same absolute instant."""
    from hil_sim.world.ephemeris import TruthEphemeris, _astropy_nodes

    a = TruthEphemeris(2462100.25, 3600.0)
    misses = _astropy_nodes.cache_info().misses
    shift_s = 5.5 * 3600.0 + 17.0
    b = TruthEphemeris(2462100.25 + shift_s / 86400.0, 3600.0)
    t_b = np.array([0.0, 123.4, 600.0])
    sun_b, moon_b = b.positions_N_km(t_b)
    assert _astropy_nodes.cache_info().misses == misses
    sun_a, moon_a = a.positions_N_km(t_b + shift_s)
    # same spline segments; only the epoch's float rounding (~40 us of time) differs
    np.testing.assert_allclose(sun_b, sun_a, rtol=1e-10)
    np.testing.assert_allclose(moon_b, moon_a, rtol=1e-9)


def test_advance_sampled_is_bit_identical_to_step_and_sample_calls():
    """The simulator's one-call GNC period (fast mode) must give exactly what step() + imu_sample() +
    star_tracker_sample() one by one give: state, time, every sensor value, and the random streams after
    (including a refill of a stream's block inside a period)."""
    a, b = World(_noisy_params(), seed=4), World(_noisy_params(), seed=4)
    rng = np.random.default_rng(5)
    imu_due = np.ones(10, dtype=bool)
    imu_due[[3, 7]] = False  # a sensor not due at some steps
    st_due = np.zeros(10, dtype=bool)
    st_due[[4, 9]] = True
    for period in range(120):  # 120 x 8 IMU samples x 6 normals crosses the 4096-number block of its stream
        u = rng.uniform(-0.05, 0.05, (10, a.n_wheels))
        gyro, sat, q, valid, blind = a.advance_sampled(0.01, u, imu_due, st_due)
        for j in range(10):
            b.step(0.01, u[j])
            if imu_due[j]:
                s = b.imu_sample()
                np.testing.assert_array_equal(gyro[j], s.omega_BN_B)
                assert bool(sat[j]) == s.saturated
            if st_due[j]:
                s = b.star_tracker_sample()
                np.testing.assert_array_equal(q[j], s.q_NS)
                assert (bool(valid[j]), int(blind[j])) == (s.valid, s.blind_source)
    assert a.t == b.t
    for x, y in zip(a.truth, b.truth):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.imu_sample().omega_BN_B, b.imu_sample().omega_BN_B)
    with pytest.raises(ValueError, match="finite"):
        a.advance_sampled(0.01, np.full((10, a.n_wheels), np.nan), imu_due, st_due)
    # a bad command mid-period: the steps before it are done, and the truth (also the Sun/Moon/Earth
    # directions, evaluated only where read inside a period) is that of the last step done (fresh worlds:
    # a refused period has drawn its random numbers already)
    a, b = World(_noisy_params(), seed=4), World(_noisy_params(), seed=4)
    u = rng.uniform(-0.05, 0.05, (10, a.n_wheels))
    u[6] = np.inf
    with pytest.raises(ValueError, match="finite"):
        a.advance_sampled(0.01, u, imu_due, st_due)
    for j in range(6):
        b.step(0.01, u[j])
        if imu_due[j]:
            b.imu_sample()
        if st_due[j]:
            b.star_tracker_sample()
    assert a.t == b.t
    for x, y in zip(a.truth, b.truth):
        np.testing.assert_array_equal(x, y)


def test_truth_ephemeris_nodes_kept_on_disk_are_astropy_s_numbers(tmp_path, monkeypatch):
    """A new process reads the node blocks an earlier one computed (no astropy), the very same numbers."""
    import pytest as _pytest

    from hil_sim.world import ephemeris as et

    monkeypatch.setenv(et.CACHE_ENV, str(tmp_path))
    args = (3600.0, 190001, 9)  # nodes no other test asks for
    et._astropy_nodes.cache_clear()
    computed = et._astropy_nodes(*args)
    assert len(list(tmp_path.glob("nodes-*.npy"))) == 1
    et._astropy_nodes.cache_clear()  # as in a new process
    monkeypatch.setattr(et, "_compute_nodes", lambda *a: _pytest.fail("astropy evaluated again"))
    loaded = et._astropy_nodes(*args)
    for a, b in zip(computed, loaded):
        np.testing.assert_array_equal(a, b)
    et._astropy_nodes.cache_clear()
    next(tmp_path.glob("nodes-*.npy")).write_bytes(b"garbage")  # a damaged file is recomputed
    monkeypatch.undo()
    monkeypatch.setenv(et.CACHE_ENV, str(tmp_path))
    for a, b in zip(computed, et._astropy_nodes(*args)):
        np.testing.assert_array_equal(a, b)


_FIRST_STEP_COMPILES = """
import dataclasses, sys
import numpy as np
sys.path.insert(0, {tests!r})
from test_world import _noisy_params
from hil_sim.world.params import SpacecraftParams
from hil_sim.world.world import WorldBatch, _world_period_kernel

quiet = dataclasses.replace(_noisy_params(), spacecraft=SpacecraftParams())
worlds = [WorldBatch([p] * runs, seed=3) for runs in (1, 2) for p in (_noisy_params(), quiet)]
compiled = list(_world_period_kernel.signatures)
some_due = np.array([True, False] * 5)
for world in worlds:
    for imu_due, st_due in ((np.ones(10, bool), some_due), (some_due, np.zeros(10, bool))):
        world.advance_sampled(0.01, 1, np.zeros((10, world.n_runs, world.n_wheels)), imu_due, st_due)
print(len(compiled), len(_world_period_kernel.signatures))
"""


def test_period_kernel_is_compiled_at_set_up_not_at_the_first_step():
    """The lockstep simulator's first tick must not compile (seconds on a machine without numba's cache,
    while the flight software waits for SYNC): set-up compiles the period kernel for the exact argument
    types advance_sampled passes, with and without random disturbance, for any sensor due pattern. In a
    fresh interpreter, where nothing has called the kernel yet."""
    import subprocess
    import sys
    from pathlib import Path

    code = _FIRST_STEP_COMPILES.format(tests=str(Path(__file__).parent))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         cwd=Path(__file__).parents[2])
    assert out.returncode == 0, out.stderr
    at_set_up, after_steps = map(int, out.stdout.split())
    assert at_set_up >= 1, "set-up did not compile the period kernel"
    assert after_steps == at_set_up, "a step compiled the period kernel for new argument types"
