"""A failed reaction wheel, through the bus (virtual CAN, hil_sim devices, lockstep): FDIR detects it,
isolates it, reallocates on the other three and the mission flies on in its mode with reduced slew limits;
SAFE only on a second wheel lost. Each failure kind on each wheel, at rest and mid-slew."""
from __future__ import annotations

import math

import numpy as np
import pytest

from closed_loop_kit import BusLoop, attitude_with_boresight, fsw_config_for
from comms.dictionary import DICTIONARY
from fsw.fdir import WheelSpeedResidual
from fsw.telemetry import TelemetrySender

EPOCH = "2030-03-29T12:00:00Z"
TARGET_N = np.array([0.0, 0.6, 0.8])
KINDS = ("no_torque", "stuck", "silent_driver", "commands_lost")


def _loop(kind: str, wheel: int, t_fail_s: float, start_N: np.ndarray):
    from hil_sim.world.params import SpacecraftParams, StarTrackerParams, WorldParams
    from hil_sim.world.world import World

    wp = WorldParams(epoch_utc=EPOCH, spacecraft=SpacecraftParams(q_NB0=tuple(attitude_with_boresight(start_N))),
                     star_tracker=StarTrackerParams(sun_exclusion_deg=0.0, moon_exclusion_deg=0.0))
    cfg = fsw_config_for(wp, initial_mode="POINTING", law={"assumption_check": "off"},
                         pointing={"target_N": TARGET_N.tolist(), "zones": []})
    faults = []
    n = wheel + 1
    if kind == "silent_driver":  # the drive electronics die: no torque, no status frames
        faults.append({"kind": "silent", "message": f"RW{n}_STATUS", "start_s": t_fail_s, "end_s": 1e6})
    elif kind == "commands_lost":  # its command frames never arrive: the wheel's own timeout zeroes it
        faults.append({"kind": "drop", "message": f"RW{n}_CMD", "start_s": t_fail_s, "end_s": 1e6})
    tm = TelemetrySender(DICTIONARY, port=None)
    loop = BusLoop(cfg, World(wp, seed=3), faults=faults, telemetry=tm)
    return loop, tm


def _fail_at(loop, kind: str, wheel: int, cycles_before: int) -> None:
    loop.run(cycles_before)
    if kind in ("no_torque", "stuck"):
        loop.world.set_wheel_failure(wheel, kind)
    elif kind == "silent_driver":
        loop.world.set_wheel_failure(wheel, "no_torque")


def _names(tm, name):
    return [e.args for e in tm.recent_events if e.name == name]


def _error_deg(loop) -> float:
    from scipy.spatial.transform import Rotation

    y = Rotation.from_quat(np.roll(loop.world.truth.q_NB, -1)).apply([0.0, 0.0, 1.0])
    return math.degrees(math.acos(np.clip(y @ TARGET_N, -1.0, 1.0)))


def _assert_isolated_and_flying_on(loop, tm, wheel: int) -> None:
    assert [a["wheel"] for a in _names(tm, "WHEEL_ISOLATED")] == [wheel + 1]
    assert loop.fsw.control.isolated_mask == 1 << wheel
    assert loop.fsw.mode == "POINTING"  # one wheel of four lost: fly on
    reduced = _names(tm, "SLEW_LIMITS_REDUCED")
    assert reduced and reduced[0]["wheels"] == 3
    # three wheels of this pyramid give less than four: the slew acceleration shrinks with them
    assert reduced[0]["accel_deg_s2"] < loop.fsw.cfg.control.max_command_accel_deg_s2


@pytest.mark.parametrize("wheel", range(4))
@pytest.mark.parametrize("kind", KINDS)
def test_failed_wheel_at_rest_is_isolated_and_pointing_holds(kind: str, wheel: int) -> None:
    loop, tm = _loop(kind, wheel, t_fail_s=2.0, start_N=TARGET_N)
    try:
        _fail_at(loop, kind, wheel, 20)
        errors = []
        loop.run(30, every=lambda k: errors.append(_error_deg(loop)))
        _assert_isolated_and_flying_on(loop, tm, wheel)
        loop.run(300, every=lambda k: errors.append(_error_deg(loop)))
        # a seized wheel hands its momentum to the body: a short excursion, then back on target
        assert max(errors) < 1.0 and errors[-1] < 0.05
    finally:
        loop.close()


@pytest.mark.parametrize("wheel", range(4))
@pytest.mark.parametrize("kind", KINDS)
def test_failed_wheel_mid_slew_is_isolated_and_the_slew_completes(kind: str, wheel: int) -> None:
    start = np.array([0.6, 0.0, 0.8])  # 44 deg from the target
    loop, tm = _loop(kind, wheel, t_fail_s=15.0, start_N=start)
    try:
        _fail_at(loop, kind, wheel, 150)
        err_at_fail = _error_deg(loop)
        assert 5.0 < err_at_fail < 40.0  # mid-slew, moving
        loop.run(30)
        _assert_isolated_and_flying_on(loop, tm, wheel)
        loop.run(1500)
        assert _error_deg(loop) < 0.05  # the slew completes on three wheels
    finally:
        loop.close()


def test_a_second_wheel_lost_enters_safe() -> None:
    loop, tm = _loop("no_torque", 0, t_fail_s=2.0, start_N=TARGET_N)
    try:
        _fail_at(loop, "no_torque", 0, 20)
        loop.run(30)
        assert loop.fsw.mode == "POINTING"
        loop.world.set_wheel_failure(2, "stuck")
        loop.run(30)
        assert loop.fsw.mode == "SAFE"
        assert ("FDIR" in [a["cause"] for a in _names(tm, "MODE_CHANGED")])
    finally:
        loop.close()


def test_speed_residual_flags_a_wheel_that_ignores_its_commands() -> None:
    """The commanded-versus-measured check alone (no status flag): a wheel whose speed stays put under a
    0.05 N m command is flagged within the window; one that follows it (plus friction) is not."""
    js = np.full(2, 0.004)
    r = WheelSpeedResidual(js, window=10)
    speed = np.array([100.0, 100.0])
    flags = []
    for _ in range(12):
        flags.append(r.update(0.1, speed.copy(), np.array([0.05, 0.05])))
        speed[0] += 0.05 * 0.1 / 0.004 - 1e-4 * 0.1 / 0.004  # follows, less Coulomb friction
    assert not any(f[0] for f in flags) and flags[-1][1]
