"""DETUMBLE's B-dot stage (`fsw.detumble.Detumbler`) against hand-derived cases: the dipole of a known field
change, its sign (the torque m x B takes rotational energy away, checked on a body turning in a fixed field
whose samples come from scipy's Rotation), the per-rod saturation, the filter, a lost field, and the rate
test that ends the mode (after the dwell, never before)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fsw.config import DetumbleConfig
from fsw.detumble import Detumbler

DT = 0.1


def _stage(**kw) -> Detumbler:
    base = {"gain_Am2_s_T": 1.0e5, "filter_time_constant_s": 0.0, "rate_threshold_deg_s": 0.5, "dwell_s": 3.0,
            "max_dipole_Am2": [1.0, 1.0, 1.0]}
    return Detumbler(DetumbleConfig(**{**base, **kw}), DT)


def test_a_known_field_change_gives_minus_k_times_its_rate() -> None:
    d = _stage()
    slow = np.zeros(3)
    assert np.array_equal(d.step(np.array([20e-6, 0.0, 0.0]), slow, DT), np.zeros(3))  # one sample: no rate yet
    m = d.step(np.array([20e-6, 1e-7, -2e-7]), slow, DT)
    # dB/dt = [0, 1e-6, -2e-6] T/s; m = -1e5 * that
    assert m == pytest.approx([0.0, -0.1, 0.2], abs=1e-12)


def test_the_dipole_takes_rotational_energy_away() -> None:
    """A body turning at omega in a fixed inertial field sees b_B(t) = R(t)^T B_N; the torque of the B-dot
    dipole, m x b, must have omega . tau < 0 (to first order -k |omega x b|^2)."""
    B_N = np.array([12e-6, -25e-6, 30e-6])
    k = 1.0e4
    rng = np.random.default_rng(3)
    for _ in range(20):
        omega = rng.normal(size=3) * math.radians(3.0)
        q0 = Rotation.random(random_state=rng)
        d = _stage(gain_Am2_s_T=k, max_dipole_Am2=[30.0, 30.0, 30.0])
        samples = [(q0 * Rotation.from_rotvec(omega * DT * i)).inv().apply(B_N) for i in range(2)]
        d.step(samples[0], omega, DT)
        m = d.step(samples[1], omega, DT)
        b = samples[1]
        tau = np.cross(m, b)
        power = float(omega @ tau)
        assert power < 0.0
        assert power == pytest.approx(-k * float(np.linalg.norm(np.cross(omega, b)) ** 2), rel=0.05)


def test_each_rod_within_its_limit_and_the_direction_kept() -> None:
    d = _stage(gain_Am2_s_T=1.0e9, max_dipole_Am2=[0.2, 0.5, 1.0])
    d.step(np.zeros(3), np.zeros(3), DT)
    m = d.step(np.array([1e-6, -1e-6, 1e-6]), np.zeros(3), DT)
    # the raw command is 1e9 * 1e-5 = 1e4 A m^2 on each rod (signs -, +, -): the 0.2 rod limits it
    assert m == pytest.approx([-0.2, 0.2, -0.2])


def test_rods_along_other_axes_get_the_least_squares_share() -> None:
    s = 1.0 / math.sqrt(2.0)
    d = _stage(rod_axes_B=[[s, s, 0.0], [-s, s, 0.0], [0.0, 0.0, 1.0]])
    d.step(np.zeros(3), np.zeros(3), DT)
    m = d.step(np.array([1e-7, 0.0, 0.0]), np.zeros(3), DT)
    body = m[0] * np.array([s, s, 0.0]) + m[1] * np.array([-s, s, 0.0]) + m[2] * np.array([0.0, 0.0, 1.0])
    assert body == pytest.approx([-0.1, 0.0, 0.0], abs=1e-12)


def test_the_filter_follows_a_steady_rate_and_smooths_a_step() -> None:
    d = _stage(filter_time_constant_s=1.0)
    rate = np.array([0.0, 1e-6, 0.0])
    for i in range(3):
        d.step(rate * DT * i, np.zeros(3), DT)
    assert d.b_dot_B_T_s == pytest.approx(rate)  # the first difference starts it, a steady rate stays
    d.step(rate * DT * 2 + np.array([1e-6, 0.0, 0.0]), np.zeros(3), DT)  # a 1 uT jump in one sample
    raw_x = 1e-6 / DT
    assert d.b_dot_B_T_s[0] == pytest.approx(raw_x * DT / (1.0 + DT))


def test_no_field_zero_dipole_and_no_difference_across_the_gap() -> None:
    d = _stage()
    d.step(np.array([20e-6, 0.0, 0.0]), np.zeros(3), DT)
    d.step(np.array([20e-6, 1e-7, 0.0]), np.zeros(3), DT)
    assert np.any(d.command_Am2 != 0.0)
    assert np.array_equal(d.step(np.full(3, np.nan), np.zeros(3), DT), np.zeros(3))
    # back: a first sample again (no rate across the gap), then a rate
    assert np.array_equal(d.step(np.array([40e-6, 0.0, 0.0]), np.zeros(3), DT), np.zeros(3))
    assert d.step(np.array([40e-6, 0.0, 1e-7]), np.zeros(3), DT) == pytest.approx([0.0, 0.0, -0.1])


def test_complete_after_the_dwell_below_the_threshold_not_before() -> None:
    d = _stage(rate_threshold_deg_s=0.5, dwell_s=3.0)
    field = np.array([20e-6, 0.0, 0.0])
    slow = np.radians([0.3, 0.0, 0.2])  # 0.36 deg/s
    fast = np.radians([0.4, 0.3, 0.0])  # 0.5 deg/s: not below
    for _ in range(30):
        d.step(field, slow, DT)
    assert not d.complete and d.below_s == pytest.approx(2.9)  # 30 samples span 2.9 s
    d.step(field, fast, DT)  # one sample at the threshold restarts the count
    for _ in range(30):
        d.step(field, slow, DT)
    assert not d.complete
    d.step(field, slow, DT)
    assert d.complete  # 31 samples in a row: 3.0 s from the first to the last
    d.step(field, fast, DT)
    assert d.complete  # it stays so until reset
    d.reset()
    assert not d.complete and d.below_s == 0.0


def test_an_unknown_rate_does_not_count() -> None:
    d = _stage(dwell_s=0.0)
    d.step(np.zeros(3), np.full(3, np.nan), DT)
    assert not d.complete


def test_set_mode_detumble_is_refused_where_it_is_not_configured() -> None:
    from types import SimpleNamespace

    from comms.telecommand import CommandValidationError
    from fsw.command_handlers import CommandHandlers

    handlers = CommandHandlers(SimpleNamespace(detumble=None))
    with pytest.raises(CommandValidationError, match="flight_software.detumble"):
        handlers.set_mode("DETUMBLE")


def test_fdir_does_not_end_detumble_early() -> None:
    """An FDIR action that asks for SAFE while DETUMBLE runs (the star tracker blind at separation rates, say)
    is deferred with an event: SAFE would ask the wheels to stop a tumble they cannot hold, and DETUMBLE
    ends in SAFE by itself. In any other mode it enters SAFE as before."""
    from types import SimpleNamespace

    from fsw.app import FlightSoftware
    from fsw.fdir import FdirAction

    def app(mode):
        calls = []
        fake = SimpleNamespace(guidance=SimpleNamespace(mode=mode), events=calls,
                               event=lambda name, **a: calls.append((name, a)),
                               set_mode=lambda m, why: calls.append(("set_mode", m, why)))
        return fake

    detumbling = app("DETUMBLE")
    FlightSoftware._execute(detumbling, FdirAction("safe", "ST_STALE"))
    assert detumbling.events == [("FDIR_SAFE_DEFERRED", {"monitor": "ST_STALE"})]
    pointing = app("POINTING")
    FlightSoftware._execute(pointing, FdirAction("safe", "ST_STALE"))
    assert pointing.events == [("set_mode", "SAFE", "FDIR")]
