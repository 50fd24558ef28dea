"""CAN device behaviour: wheel command timeout, sensor rates/latencies, status mapping, clamping."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from comms.bus.e2e import E2EReceiver
from comms.bus.icd import Icd
from hil_sim.devices.nodes import (FAULT_CMD_TIMEOUT, FAULT_DRIVE, FAULT_OVERSPEED, Devices, DeviceTiming, ImuNode,
                             StarTrackerNode, WheelNode)


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


class ScriptedWorld:
    """Deterministic stand-in with the World's sensor methods; values are functions of time."""

    n_wheels = 3
    imu_period_s = 0.01
    star_tracker_period_s = 0.1

    def __init__(self) -> None:
        self.t = 0.0
        self.q = np.array([-0.5, 0.5, 0.5, 0.5])
        self.wheel_fault = 0

    def imu_sample(self):
        return SimpleNamespace(omega_BN_B=np.array([self.t, -0.001, 2.0]), saturated=False, t=self.t)

    def star_tracker_sample(self):
        return SimpleNamespace(q_NS=self.q, valid=True, blind_source=2)

    def wheel_status(self):
        return [SimpleNamespace(speed_rad_s=100.0 * (i + 1), torque_Nm=0.01, current_A=0.3, temp_C=25.4,
                                fault=self.wheel_fault) for i in range(self.n_wheels)]


def _decode(icd: Icd, frames):
    rx = E2EReceiver(icd)
    out = [rx.classify(f, 0.0) for f in frames]
    assert all(f.delivered for f in out), [f.status for f in out]
    return out


def test_wheel_applies_latest_command_and_zeroes_after_timeout(icd: Icd) -> None:
    wheel = WheelNode(1, icd, cmd_timeout_s=0.3)
    assert wheel.torque_at(0.0) == 0.0  # nothing commanded yet
    wheel.on_command({"torque_cmd": 0.02, "tick_lsb": 1}, 0.1)
    wheel.on_command({"torque_cmd": -0.05, "tick_lsb": 2}, 0.2)
    assert wheel.torque_at(0.25) == -0.05
    assert wheel.torque_at(0.5) == -0.05          # exactly at the timeout: still held
    assert wheel.torque_at(0.5001) == 0.0         # after it: zero torque
    status = SimpleNamespace(speed_rad_s=1.0, torque_Nm=0.0, current_A=0.0, temp_C=20.0, fault=0)
    (frame,) = _decode(icd, [wheel.status_frame(status, 0.6)])
    assert frame.signals["fault"] == FAULT_CMD_TIMEOUT


def test_wheel_status_maps_truth_fault_bits_and_clamps_speed(icd: Icd) -> None:
    wheel = WheelNode(2, icd)
    stuck = SimpleNamespace(speed_rad_s=0.0, torque_Nm=0.0, current_A=0.0, temp_C=20.0, fault=1)
    limit = SimpleNamespace(speed_rad_s=5000.0, torque_Nm=0.0, current_A=0.0, temp_C=20.0, fault=0)
    a, b = _decode(icd, [wheel.status_frame(stuck, 0.0), wheel.status_frame(limit, 0.0)])
    assert a.name == "RW2_STATUS" and a.signals["fault"] == FAULT_DRIVE
    assert b.signals["fault"] == FAULT_OVERSPEED
    assert b.signals["speed"] == pytest.approx(icd.signal_range("RW2_STATUS", "speed")[1])


def test_imu_samples_at_its_rate_and_publishes_after_its_latency(icd: Icd) -> None:
    world = ScriptedWorld()
    devices = Devices.for_world(world, icd, DeviceTiming(imu_latency_s=0.004, star_tracker_latency_s=0.05))
    for j in range(11):  # dynamics at 100 Hz over [0, 0.1]
        world.t = 0.01 * j
        devices.sample_sensors(world, world.t)
    assert devices.imu.samples == 11 and devices.star_tracker.samples == 2  # t = 0 and t = 0.1
    frames = _decode(icd, devices.frames_due(0.1))
    imu = [f for f in frames if f.name == "IMU_RATE"]
    # sample at t is due at t + 0.004: samples 0.00..0.09 are due by 0.1, the one at 0.10 is not
    assert [round(f.signals["omega_x"], 5) for f in imu] == pytest.approx([0.01 * j for j in range(10)])
    assert [f.name for f in frames if f.name.startswith("ST")] == ["ST_QUAT_A", "ST_QUAT_B"]
    later = _decode(icd, devices.frames_due(0.2))
    assert [f.name for f in later] == ["IMU_RATE", "ST_QUAT_A", "ST_QUAT_B"]


def test_imu_clamps_to_the_icd_range_and_flags_saturation(icd: Icd) -> None:
    world = ScriptedWorld()
    imu = ImuNode(icd, rate_hz=100.0, latency_s=0.0)
    (pending,) = imu.poll(world, 0.0)
    (frame,) = _decode(icd, [pending.build(0.0)])
    assert frame.signals["omega_z"] == pytest.approx(icd.signal_range("IMU_RATE", "omega_z")[1])
    assert frame.signals["saturated"] == 1


def test_star_tracker_age_is_measured_at_transmission_and_sign_is_canonical(icd: Icd) -> None:
    world = ScriptedWorld()
    st = StarTrackerNode(icd, rate_hz=10.0, latency_s=0.05)
    a, b = st.poll(world, 1.0)
    assert a.due_s == pytest.approx(1.05)
    fa, fb = _decode(icd, [a.build(1.1), b.build(1.1)])
    assert fb.signals["age_ms"] == 100                # sent with the tick at 1.1 s, exposed at 1.0 s
    assert fa.signals["sample_seq"] == fb.signals["sample_seq"]
    assert fa.signals["blind_source"] == 2
    q = np.array([fa.signals["q_w"], fa.signals["q_x"], fb.signals["q_y"], fb.signals["q_z"]])
    assert q[0] >= 0
    r_sent = Rotation.from_quat(np.roll(q, -1))       # scipy is scalar last
    r_true = Rotation.from_quat(np.roll(world.q, -1))
    assert (r_sent.inv() * r_true).magnitude() < 1e-5


def test_device_timing_rejects_negative_latency() -> None:
    with pytest.raises(ValueError, match="imu_latency_s"):
        DeviceTiming(imu_latency_s=-0.1)


def test_too_many_wheels_for_the_icd(icd: Icd) -> None:
    world = ScriptedWorld()
    world.n_wheels = 7
    with pytest.raises(ValueError, match="RW1..RW6"):
        Devices.for_world(world, icd)


@pytest.mark.parametrize("rate_hz", [100.0, 30.0, 7.0])
def test_due_flags_of_a_period_match_one_sample_due_call_per_step(icd: Icd, rate_hz: float) -> None:
    batch, single = ImuNode(icd, rate_hz), ImuNode(icd, rate_hz)
    rng = np.random.default_rng(2)
    t, flags, ref = 0.0, [], []
    for _ in range(200):
        steps = [t + j * 0.01 for j in range(1, 11)]
        if rng.random() < 0.1:
            steps = [s + 0.05 for s in steps]  # a gap: several periods skipped at once
        t = steps[-1]
        flags += batch.due_flags(steps)
        ref += [single._sample_due(s) for s in steps]
        assert batch.next_due_s == single.next_due_s
    assert flags == ref and any(flags)
    if rate_hz < 100.0:
        assert not all(flags)  # slower than the dynamics steps: some steps sample nothing
