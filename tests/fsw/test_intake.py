"""The GNC cycle's one input shape: `fsw.intake.SensorIntake` makes a `SensorSnapshot` of whatever the caller
brings, the estimator's public `update` reads it, and the cycle's modules call nothing private of another."""
from __future__ import annotations

import ast
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from closed_loop_kit import BusLoop, fsw_config_for
from fsw.bus.driver import ImuSample, LatestInputs, StarTrackerSample, TickInputs, WheelStatus
from fsw.estimation import AttitudeEstimator
from fsw.intake import SensorIntake
from fsw.records import SensorSnapshot

ROOT = Path(__file__).resolve().parents[2]


def _same(a: SensorSnapshot, b: SensorSnapshot) -> None:
    for name, x, y in zip(SensorSnapshot._fields, a, b):
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True), name
            assert np.asarray(x).dtype == np.asarray(y).dtype, name
        else:
            assert x == y, (name, x, y)


def test_a_drivers_tick_and_the_same_tick_built_by_hand_give_one_snapshot() -> None:
    """The driver's own tick carries its gyro rows and wheel status as arrays (the fast path); a test's
    tick lists samples. Both are one snapshot."""
    from hil_sim.world.params import WorldParams
    from hil_sim.world.world import World

    wp = WorldParams()
    cfg = fsw_config_for(wp, initial_mode="SAFE", law={"assumption_check": "inline"})
    lp = BusLoop(cfg, World(wp, seed=3))
    try:
        lp.run(12)
        lp.sim.begin_tick()
        tick = lp.driver.collect_tick(0.0)
        intake = lambda: SensorIntake(lp.driver, 4, cfg.gnc_period_s, cfg.estimator.star_tracker_max_age_s)  # noqa: E731
        fast = intake().snapshot(tick, cycle=0)
        # (reading the lists builds the samples: the tick no longer takes the array path)
        by_hand = TickInputs(tick.tick, tick.t, tick.period_s, tick.imu, tick.star_tracker, list(tick.wheels),
                             list(tick.imu_samples))
        slow = intake().snapshot(by_hand, cycle=0)
        lp.sim.end_tick(wait_s=0.0)
    finally:
        lp.close()
    assert fast.gyro_B.shape[0] > 1 and not fast.realtime and fast.tick == 12
    assert np.isfinite(fast.wheel_speed_rad_s).all() and (fast.wheel_fault >= 0).all()
    _same(fast, slow)


def _latest(t: float, imu_age: float, st_age: float, q_NS, wheel_ages) -> LatestInputs:
    imu = ImuSample(np.array([0.01, -0.02, 0.03]), False, t)
    wheels = [WheelStatus(10.0 * (i + 1), 0.0, 0.1, 20.0, 0, t) for i in range(4)]
    return LatestInputs(t=t, imu=imu, imu_age_s=imu_age, star_tracker=StarTrackerSample(np.asarray(q_NS), True, 0, t),
                        star_tracker_age_s=st_age, wheels=wheels, wheel_ages_s=wheel_ages, imu_samples=[imu])


def test_real_time_inputs_are_judged_by_their_age() -> None:
    """Real time: onboard time counts from the first cycle, the tick is the cycle count; a gyro sample older
    than 2.5 cycles, a wheel report older than 3 and a fix older than star_tracker_max_age_s are not used."""
    intake = SensorIntake(SimpleNamespace(counters={}), 4, 0.1, 0.5)
    s = intake.snapshot(_latest(1000.0, 0.01, 0.05, [1.0, 0.0, 0.0, 0.0], [0.01, 0.31, None, 0.29]), cycle=7)
    assert len(s) == len(SensorSnapshot._fields)  # (built field by field, in their declared order)
    assert (s.t_s, s.tick, s.realtime, s.imu_valid, s.st_fresh, s.st_latency_s) == (0.0, 7, True, True, True, 0.05)
    assert np.array_equal(s.wheel_speed_rad_s, [10.0, math.nan, math.nan, 40.0], equal_nan=True)
    assert s.wheel_fault.tolist() == [0, -1, -1, 0]
    assert s.gyro_B.shape == (1, 3) and np.array_equal(s.q_NS, [1.0, 0.0, 0.0, 0.0])
    s = intake.snapshot(_latest(1000.5, 0.26, 0.6, [1.0, 0.0, 0.0, 0.0], [0.01] * 4), cycle=8)
    assert (s.t_s, s.tick, s.imu_valid, s.st_heard, s.st_fresh, s.q_NS) == (0.5, 8, False, True, False, None)
    # a fix whose norm is 20 % off is not one the estimator can use
    s = intake.snapshot(_latest(1000.6, 0.01, 0.05, [1.2, 0.0, 0.0, 0.0], [0.01] * 4), cycle=9)
    assert not s.st_fresh and s.q_NS is None and abs(s.q_NS_norm - 1.2) < 1e-15


def _snapshot(dt: float, gyro_B: np.ndarray, q_NS: np.ndarray | None, latency: float) -> SensorSnapshot:
    nq = math.sqrt(sum(float(x) * float(x) for x in q_NS)) if q_NS is not None else 1.0
    return SensorSnapshot.of_measurements(dt, gyro_B, q_NS, latency, nq)


def test_the_estimators_update_is_its_step_on_the_snapshots_samples() -> None:
    """`update(snapshot)` (the GNC cycle's) and `step_samples` (the measurements one by one, the fix made
    unit by the caller) leave the same filter, to the last bit: fixes, coasting, cycles without gyro."""
    from hil_sim.world.params import WorldParams

    cfg = fsw_config_for(WorldParams()).estimator
    q_BS = np.array([0.5, 0.5, 0.5, 0.5])
    a, b = AttitudeEstimator(cfg, q_BS), AttitudeEstimator(cfg, q_BS)
    rng = np.random.default_rng(5)
    q = np.array([0.9, 0.3, -0.2, 0.25])
    for k in range(40):
        gyro = np.ascontiguousarray(rng.normal(0.0, 0.01, (k % 4, 3)))
        fix = None if k % 3 == 2 else np.ascontiguousarray(q + rng.normal(0.0, 1e-5, 4))
        latency = 0.02 * (k % 5)
        est = a.update(_snapshot(0.1, gyro, fix, latency))
        status = b.step_samples(0.1, gyro, None if fix is None else fix / _snapshot(0.1, gyro, fix, latency).q_NS_norm,
                                latency)
        assert np.array_equal(est.q_NB, b.q_NB) and np.array_equal(est.omega_BN_B, b.omega_BN_B)
        assert np.array_equal(a.P, b.P) and np.array_equal(a.bias_B, b.bias_B)
        assert est.initialized == status.initialized
        assert est.innovation_deg == status.innovation_deg or (math.isnan(est.innovation_deg)
                                                                and math.isnan(status.innovation_deg))
    assert a.initialized and a.cov_trace_rad2 > 0.0


def test_the_cycles_modules_call_nothing_private_of_another() -> None:
    """Stages talk through their records and public methods: in the modules that run the cycle, a private
    name (``_x``) is only ever read from ``self``, and none is imported from another module."""
    for name in ("app", "intake", "housekeeping", "command_handlers", "runtime"):
        path = ROOT / "fsw" / f"{name}.py"
        if not path.exists():
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                assert isinstance(node.value, ast.Name) and node.value.id == "self", (name, node.lineno, node.attr)
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("fsw"):
                assert not [a.name for a in node.names if a.name.startswith("_")], (name, node.lineno)
