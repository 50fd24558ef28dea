"""FDIR rules, each triggered through the bus (virtual CAN, hil_sim devices and fault injector in
lockstep) with the event and the action shown."""
from __future__ import annotations

import math

import numpy as np
import pytest

from closed_loop_kit import attitude_with_boresight, blind_free_bus_loop
from comms.dictionary import DICTIONARY
from comms.telecommand import encode_command

EPOCH = "2030-03-29T12:00:00Z"


def _setup(faults=(), fsw_sections=None, q0=(1.0, 0.0, 0.0, 0.0)):
    sections = {"initial_mode": "POINTING", "law": {"assumption_check": "inline"},
                "pointing": {"target_N": [0.0, 0.6, 0.8], "zones": []}}
    sections.update(fsw_sections or {})
    return blind_free_bus_loop(EPOCH, sections, seed=2, faults=faults, q0=q0)


def _events(tm, name=None):
    return [(e.name, e.args) for e in tm.recent_events if name is None or e.name == name]


def _tripped(tm, monitor):
    return [a for n, a in _events(tm, "FDIR_TRIPPED") if a["monitor"] == monitor]


@pytest.fixture
def closing():
    loops = []
    yield loops.append
    for loop in loops:
        loop.close()


def test_stale_imu_frames_trip_and_enter_safe(closing) -> None:
    loop, tm, _ = _setup(faults=[{"kind": "drop", "message": "IMU_RATE", "start_s": 3.0, "end_s": 8.0}])
    closing(loop)
    loop.run(30)
    assert loop.fsw.mode == "POINTING" and not _tripped(tm, "IMU_STALE")
    loop.run(20)  # IMU frames dropped from t = 3 s
    trip = _tripped(tm, "IMU_STALE")
    assert trip and trip[0]["action"] == "ENTER_SAFE"
    assert ("SENSOR_STALE", {"sensor": "IMU", "cycles": 5}) in _events(tm)
    assert loop.fsw.mode == "SAFE"
    assert ("MODE_CHANGED", {"from_mode": "POINTING", "to_mode": "SAFE", "cause": "FDIR"}) in _events(tm)
    assert loop.driver.counters["IMU_RATE"]["timeout"] >= 1
    loop.run(40)  # IMU back: the monitor clears, SAFE is kept (no automatic return)
    assert ("FDIR_CLEARED", {"monitor": "IMU_STALE"}) in _events(tm)
    assert loop.fsw.mode == "SAFE"


def test_corrupt_star_tracker_frames_are_counted_and_the_estimator_coasts(closing) -> None:
    loop, tm, _ = _setup(faults=[{"kind": "corrupt", "message": "ST_QUAT_B", "start_s": 2.0, "end_s": 6.0, "bit": 9}])
    closing(loop)
    loop.run(20)
    cov_before = loop.fsw.estimator.cov_trace_deg2
    loop.run(30)
    assert loop.driver.counters["ST_QUAT_B"]["crc_error"] >= 30
    assert any(a["sensor"] == "STAR_TRACKER" for _, a in _events(tm, "SENSOR_CORRUPT"))
    trip = _tripped(tm, "ST_CORRUPT")
    assert trip and trip[0]["action"] == "EVENT_ONLY"
    assert loop.fsw.estimator.coasting_s > 2.5
    assert loop.fsw.estimator.cov_trace_deg2 > cov_before  # covariance grows while coasting
    assert loop.fsw.mode == "POINTING"  # event only: the estimator coasts on the gyro
    loop.run(30)
    assert _events(tm, "ST_RECOVERED") and loop.fsw.estimator.coasting_s < 0.2


def test_stuck_wheel_is_isolated_and_the_mission_flies_on(closing) -> None:
    loop, tm, _ = _setup()
    closing(loop)
    loop.run(20)
    loop.world.set_wheel_failure(1, "stuck")
    loop.run(10)
    assert any(a["wheel"] == 2 for _, a in _events(tm, "WHEEL_FAULT"))
    trip = _tripped(tm, "WHEEL_FAULT")
    assert trip and trip[0]["action"] == "ISOLATE_WHEEL"
    assert ("WHEEL_ISOLATED", {"wheel": 2}) in _events(tm)
    assert loop.fsw.control.isolated_mask == 0b10 and loop.fsw.mode == "POINTING"
    loop.run(5)
    # the isolated wheel gets a zero command on the bus, the others still control the body
    assert loop.sim.devices.wheels[1].torque_cmd_Nm == 0.0
    assert loop.fsw.hk_values()["wheels_isolated"] == 0b10


def test_target_inside_a_zone_is_rejected_by_telecommand(closing) -> None:
    from gnc.ephemeris import julian_date_tdb, sun_direction_N

    sun = sun_direction_N(julian_date_tdb(EPOCH))
    zones = [{"name": "sun", "body": "sun", "geometry": {"shape": "cone", "half_angle_deg": 30.0}}]
    loop, tm, tc = _setup(fsw_sections={"pointing": {"target_N": [0.0, 0.6, 0.8], "zones": zones}})
    closing(loop)
    loop.run(3)
    before = loop.fsw.guidance.target_N.copy()
    result = tc.handle_datagram(encode_command(DICTIONARY, "SET_TARGET", {"kind": "DIRECTION", "c0": sun[0], "c1": sun[1], "c2": sun[2]}, seq_count=1))
    assert not result.accepted and result.error == "VALIDATION"
    rej = _events(tm, "TARGET_REJECTED")
    assert rej and rej[0][1]["zone"] == 0 and rej[0][1]["body"] == "SUN" and rej[0][1]["margin_deg"] < -29.0
    assert any(n == "CMD_REJECTED" for n, _ in _events(tm))
    np.testing.assert_array_equal(loop.fsw.guidance.target_N, before)
    assert tc.counters["rejected"] == 1 and tc.counters["validation"] == 1
    # the acknowledgement says why, with the dictionary's reason code
    assert result.code == "TARGET_IN_KEEP_OUT" and tm.latest("TC_ACK")["ack_tc_seq"] == 1
    assert DICTIONARY.packet("TC_ACK").channels[-1].enum[tm.latest("TC_ACK")["ack_code"]] == "TARGET_IN_KEEP_OUT"
    ok = tc.handle_datagram(encode_command(DICTIONARY, "SET_TARGET", {"kind": "DIRECTION", "c0": 0.0, "c1": 0.0, "c2": 1.0}, seq_count=2))
    assert ok.accepted and loop.fsw.guidance.target_N == pytest.approx([0, 0, 1])


def test_injected_overrun_trips_the_cycle_slip_rule(closing) -> None:
    loop, tm, _ = _setup(fsw_sections={"fdir": {"cycle_slip": {"limit": 0.5, "persistence_cycles": 2, "action": "safe"}}})
    closing(loop)
    loop.run(5)
    for _ in range(3):
        loop.fsw.inject_overrun_s = 0.12  # longer than the 100 ms period
        loop.step()
    assert loop.fsw.executive.gnc.slips == 3
    assert _events(tm, "CYCLE_SLIP")[0][1]["count"] == 1
    trip = _tripped(tm, "CYCLE_SLIP")
    assert trip and trip[0]["action"] == "ENTER_SAFE"
    assert loop.fsw.mode == "SAFE"
    assert loop.fsw.hk_values()["slips_gnc"] == 3


def test_innovation_too_large_resets_the_estimator(closing) -> None:
    loop, tm, _ = _setup()
    closing(loop)
    loop.run(20)
    from scipy.spatial.transform import Rotation

    # A bad onboard mounting (5 deg) is uploaded: every star-tracker sample disagrees with the gyro.
    bad = Rotation.from_rotvec([math.radians(5.0), 0, 0])
    loop.fsw.estimator.q_SB = np.roll((Rotation.from_quat(np.roll(loop.fsw.estimator.q_SB, -1)) * bad).as_quat(), 1)
    loop.run(10)
    assert _events(tm, "INNOVATION_HIGH")
    trip = _tripped(tm, "INNOVATION")
    assert trip and trip[0]["action"] == "RESET_ESTIMATOR"
    assert any("INNOVATION" in a["reason"] for _, a in _events(tm, "ESTIMATOR_RESET"))
    loop.run(10)  # re-initialised from the star tracker: consistent again
    assert loop.fsw.estimator.initialized and loop.fsw.estimator.last_innovation_deg < 0.5


def test_keep_out_margin_yellow_and_red(closing) -> None:
    # boresight (+z body) starts 2 deg inside an inertial cone zone around +z_N
    zones = [{"name": "keep", "body": "inertial", "direction_N": [0, 0, 1], "geometry": {"shape": "cone", "half_angle_deg": 2.0}}]
    q0 = attitude_with_boresight(np.array([0.0, math.sin(math.radians(1.0)), math.cos(math.radians(1.0))]))
    loop, tm, _ = _setup(fsw_sections={"pointing": {"target_N": [0.0, 1.0, 0.0], "zones": zones}}, q0=q0)
    closing(loop)
    loop.run(4)
    low = _events(tm, "KEEP_OUT_MARGIN_LOW")
    assert low and low[0][1]["body"] == "INERTIAL" and low[0][1]["margin_deg"] == pytest.approx(-1.0, abs=0.05)
    viol = _events(tm, "KEEP_OUT_VIOLATION")
    assert viol and viol[0][1]["zone"] == 0
    trip = _tripped(tm, "KEEP_OUT_MARGIN")
    assert trip and trip[0]["action"] == "ENTER_SAFE"
    assert loop.fsw.mode == "SAFE"


def test_keep_out_violation_is_raised_in_safe_mode_from_the_onboard_estimate(closing) -> None:
    """SAFE keeps out too, so FDIR watches its margins: a boresight inside a zone in SAFE (a zone placed on
    the initial boresight, body z = N z) raises KEEP_OUT_VIOLATION from the flight software's estimate."""
    zones = [{"name": "block", "body": "inertial", "direction_N": [0.0, 0.0, 1.0],
              "geometry": {"shape": "cone", "half_angle_deg": 5.0}}]
    loop, tm, _ = _setup(fsw_sections={"initial_mode": "SAFE", "pointing": {"target_N": [0.0, 1.0, 0.0],
                                                                             "zones": zones}})
    closing(loop)
    loop.run(10)
    assert loop.fsw.mode == "SAFE"
    violations = _events(tm, "KEEP_OUT_VIOLATION")
    assert violations and violations[0][1]["body"] == "INERTIAL" and violations[0][1]["margin_deg"] < -4.0
