"""The DBC interface control document: contract messages, E2E layout, scalings vs sensor noise."""
from __future__ import annotations

import math
import re
from pathlib import Path

import cantools
import numpy as np
import pytest

from comms.bus.icd import DEFAULT_DBC_PATH, E2ESender, Icd, IcdError

CONTRACT_MESSAGES = {"SYNC", "IMU_RATE", "ST_QUAT_A", "ST_QUAT_B", "FSW_HEARTBEAT", "CYCLE_DONE"} | {
    f"RW{i}_{kind}" for i in range(1, 7) for kind in ("CMD", "STATUS")} | {"DOOR_CMD", "DOOR_STATUS"} | {
    "MAG_FIELD", "CSS_CURRENTS", "MTQ_COMMAND", "MTQ_STATUS"}


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


def test_contract_messages_present_and_nothing_else(icd: Icd) -> None:
    assert set(icd.messages) == CONTRACT_MESSAGES


def test_every_message_has_cycle_time_e2e_and_fits_classic_can(icd: Icd) -> None:
    for spec in icd.messages.values():
        assert spec.cycle_time_s > 0, spec.name
        assert 1 <= spec.dlc <= 8 and spec.frame_id < 0x800, spec.name
        assert spec.timeout_s >= spec.cycle_time_s, spec.name
    assert len({s.data_id for s in icd.messages.values()}) == len(icd.messages)


def test_sync_has_highest_priority_and_commands_beat_sensors(icd: Icd) -> None:
    ids = {n: s.frame_id for n, s in icd.messages.items()}
    assert ids["SYNC"] == min(ids.values())
    assert max(ids[f"RW{i}_CMD"] for i in range(1, 7)) < ids["IMU_RATE"]


def test_magnetic_and_sun_sensor_frames_cover_their_devices(icd: Icd) -> None:
    """The magnetometer frame holds the +-100 uT full scale at a resolution below its truth model's
    typical noise; the rods' frames hold the default saturation; six cells fit the sun sensor frame;
    the new devices' frames rank among their kind (commands before sensors, sensors before statuses)."""
    from hil_sim.world.magnetic_devices import MagnetometerParams, MagnetorquerParams
    from hil_sim.world.sun_sensors import SunSensorParams

    full_scale_uT = 1e6 * MagnetometerParams().full_scale_T
    assert icd.signal_range("MAG_FIELD", "b_x")[1] >= full_scale_uT
    assert icd.resolution("MAG_FIELD", "b_x") * 1e-6 < 20e-9  # below 20 nT, the low end of magnetometer noise
    assert icd.signal_range("MTQ_COMMAND", "dipole_1")[1] >= max(MagnetorquerParams().max_dipole_Am2)
    assert len([s for s in icd.spec("CSS_CURRENTS").signals if s.startswith("cell_")]) == len(
        SunSensorParams().normals_B)
    assert icd.signal_range("CSS_CURRENTS", "cell_1")[1] >= SunSensorParams().full_scale
    ids = {n: s.frame_id for n, s in icd.messages.items()}
    assert ids["MTQ_COMMAND"] < ids["IMU_RATE"] < ids["MAG_FIELD"] < ids["RW1_STATUS"] < ids["MTQ_STATUS"]
    sender = E2ESender(icd)
    row = {"b_x": -100.0, "b_y": 12.345, "b_z": 100.0, "valid": 1}
    name, back = icd.decode(sender.frame("MAG_FIELD", row))
    assert name == "MAG_FIELD" and back["b_y"] == pytest.approx(12.345, abs=0.0025)


def test_every_signal_comment_states_its_resolution(icd: Icd) -> None:
    """Each physical (scaled) signal's comment states the resolution, and the number matches the scale."""
    for spec in icd.messages.values():
        for sig in spec.db_message.signals:
            if sig.scale == 1 or sig.name.startswith("E2E_"):
                continue
            comment = sig.comment or ""
            m = re.search(r"[Rr]esolution ([0-9.eE+-]+)", comment)
            assert m, f"{spec.name}.{sig.name}: comment lacks 'Resolution <value>'"
            assert float(m.group(1)) == pytest.approx(sig.scale), f"{spec.name}.{sig.name}"


def test_resolutions_are_below_the_default_sensor_noise(icd: Icd) -> None:
    """Quantisation must not dominate: compare LSBs with the truth models' default noise (hil_sim.world.params)."""
    from hil_sim.world.params import ImuParams, StarTrackerParams, WheelParams

    imu = ImuParams()
    per_sample_noise = imu.angle_random_walk_rad_per_sqrt_s * math.sqrt(imu.rate_hz)
    assert icd.resolution("IMU_RATE", "omega_x") < per_sample_noise
    assert icd.signal_range("IMU_RATE", "omega_x")[1] >= imu.saturation_rad_s
    st = StarTrackerParams()
    # quaternion component error ~ half the rotation angle
    q_noise = 0.5 * math.radians(st.cross_boresight_std_arcsec / 3600.0)
    assert icd.resolution("ST_QUAT_A", "q_w") < q_noise
    wheel = WheelParams(axis_B=(0.0, 0.0, 1.0))
    assert icd.signal_range("RW1_CMD", "torque_cmd")[1] >= wheel.max_torque_Nm
    assert icd.signal_range("RW1_STATUS", "speed")[1] >= wheel.max_speed_rad_s
    assert icd.resolution("RW1_CMD", "torque_cmd") < 0.01 * wheel.max_torque_Nm


def test_encode_decode_round_trip_within_half_lsb(icd: Icd) -> None:
    rng = np.random.default_rng(1)
    sender = E2ESender(icd)
    for spec in icd.messages.values():
        for _ in range(20):
            values = {}
            for sig in spec.db_message.signals:
                if sig.name.startswith("E2E_"):
                    continue
                lo, hi = spec.ranges[sig.name]
                v = rng.uniform(lo, hi)
                values[sig.name] = round(v) if sig.scale == 1 and sig.offset == 0 else v
            frame = sender.frame(spec.name, values)
            name, decoded = icd.decode(frame)
            assert name == spec.name
            for k, v in values.items():
                scale = spec.db_message.get_signal_by_name(k).scale
                assert abs(decoded[k] - v) <= 0.5 * scale + 1e-12, (spec.name, k)


def test_out_of_range_value_is_refused_naming_the_signal(icd: Icd) -> None:
    with pytest.raises(cantools.database.EncodeError, match="omega_x"):
        icd.encode("IMU_RATE", dict(omega_x=1.0, omega_y=0, omega_z=0, saturated=0), 0)
    with pytest.raises(KeyError, match="NOPE"):
        icd.encode("NOPE", {}, 0)


def test_dbc_without_e2e_signals_is_rejected(tmp_path: Path) -> None:
    text = DEFAULT_DBC_PATH.read_text().replace("SG_ E2E_CRC : 0|8@1+", "SG_ E2E_XYZ : 0|8@1+", 1)
    bad = tmp_path / "bad.dbc"
    bad.write_text(text)
    with pytest.raises(IcdError, match="E2E_CRC"):
        Icd(bad)
    overlap = tmp_path / "overlap.dbc"
    overlap.write_text(DEFAULT_DBC_PATH.read_text().replace("SG_ E2E_CRC : 0|8@1+", "SG_ E2E_CRC : 56|8@1+", 1))
    with pytest.raises(IcdError, match="overlapping"):
        Icd(overlap)
    with pytest.raises(IcdError, match="not found"):
        Icd(tmp_path / "missing.dbc")


def test_nan_missing_and_unknown_signals_are_refused(icd: Icd) -> None:
    good = dict(omega_x=0.0, omega_y=0.0, omega_z=0.0, saturated=0)
    with pytest.raises(cantools.database.EncodeError, match="omega_y"):
        icd.encode("IMU_RATE", dict(good, omega_y=float("nan")), 0)
    with pytest.raises(cantools.database.EncodeError, match="missing"):
        icd.encode("IMU_RATE", {k: v for k, v in good.items() if k != "omega_z"}, 0)
    with pytest.raises(cantools.database.EncodeError, match="unknown"):
        icd.encode("IMU_RATE", dict(good, spin=1.0), 0)
    lo, hi = icd.signal_range("IMU_RATE", "omega_x")
    for edge in (lo, hi):  # the range ends themselves are valid
        assert icd.encode("IMU_RATE", dict(good, omega_x=edge), 0).dlc == 8


def _cantools_frame_bytes(spec, values: dict, counter: int) -> bytes:
    """The reference: the frame as cantools packs it (CRC signal zero, CRC over bytes 1.., then again)."""
    from comms.bus.crc import e2e_crc

    v = dict(values, E2E_Counter=counter & 0x0F, E2E_CRC=0)
    payload = spec.db_message.encode(v, scaling=True, padding=False, strict=False)
    v["E2E_CRC"] = e2e_crc(spec.data_id, payload[1:])
    return bytes(spec.db_message.encode(v, scaling=True, padding=False, strict=False))


def _random_values(spec, rng: np.random.Generator) -> dict:
    values = {}
    for sig in spec.db_message.signals:
        if sig.name.startswith("E2E_"):
            continue
        lo, hi = spec.ranges[sig.name]
        pick = rng.integers(0, 4)
        if pick == 0:  # the range ends
            v = lo if rng.integers(0, 2) else hi
        elif pick == 1:  # exactly half an LSB between two raw values (rounding ties)
            v = (int(rng.integers(round(lo / sig.scale), round(hi / sig.scale))) + 0.5) * sig.scale + sig.offset
            v = min(max(v, lo), hi)
        else:
            v = rng.uniform(lo, hi)
        if sig.scale == 1 and sig.offset == 0 and rng.integers(0, 2):
            v = round(v)  # integers as senders pass them (and floats for the same signal, too)
        elif sig.scale == 1 and sig.offset != 0:
            v = round(v)
        values[sig.name] = v
    return values


def test_compiled_codec_is_bit_exact_with_cantools_for_every_message(icd: Icd) -> None:
    """Icd packs frames with its own per-message codec (speed); every byte and every decoded value (with
    its type) must equal what cantools gives, for every message of the DBC."""
    rng = np.random.default_rng(7)
    assert all(spec.codec is not None for spec in icd.messages.values())  # else the test proves nothing
    for spec in icd.messages.values():
        for i in range(300):
            values = _random_values(spec, rng)
            counter = i % 16
            got = bytes(icd.encode(spec.name, values, counter).data)
            assert got == _cantools_frame_bytes(spec, values, counter), (spec.name, values)
        for _ in range(300):  # any payload at all, including raw values outside the DBC ranges
            data = rng.integers(0, 256, spec.dlc, dtype=np.uint8).tobytes()
            ref = spec.db_message.decode(data, decode_choices=False, scaling=True)
            got = spec.codec.unpack(data)
            assert list(got) == list(ref), spec.name
            for k in ref:
                assert got[k] == ref[k] and type(got[k]) is type(ref[k]), (spec.name, k, got[k], ref[k])
            # and the receiver's checked decode: None exactly when a value is outside its accepted range
            in_range = all(spec.accept_bounds[k][0] <= v <= spec.accept_bounds[k][1] for k, v in ref.items())
            assert icd.decode_checked(spec, data) == (ref if in_range else None), spec.name


def test_encoded_frames_are_plain_classic_data_frames(icd: Icd) -> None:
    """Icd builds its can.Message slot by slot (speed): every slot as the keyword constructor sets it."""
    import can

    msg = icd.encode("SYNC", {"tick": 7, "frames_following": 3, "period_ms": 100}, 1)
    ref = can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data), is_extended_id=False, is_fd=False)
    for slot in can.Message.__slots__:
        if slot != "__weakref__":
            assert getattr(msg, slot) == getattr(ref, slot), slot
    assert type(msg.data) is bytearray and msg.dlc == icd.spec("SYNC").dlc


def test_the_wheel_count_limit_is_the_icds() -> None:
    """MAX_WHEELS (comms.dictionary: the mission schema, the bus driver, the kernels' wheel slots, the telemetry)
    is the number of wheels the ICD has frames for: RWn_CMD and RWn_STATUS for n = 1..MAX_WHEELS, and no more."""
    from comms.dictionary import MAX_WHEELS

    icd = Icd()
    for kind in ("CMD", "STATUS"):
        wheels = sorted(int(name[2:].split("_")[0]) for name in icd.messages if name.startswith("RW") and name.endswith(kind))
        assert wheels == list(range(1, MAX_WHEELS + 1)), (kind, wheels)


def test_the_wheel_fault_bits_are_the_dbcs() -> None:
    """comms.bus.icd's RWn_STATUS.fault bits are the ones the DBC's comment on the signal names, for every wheel."""
    from comms.bus.icd import WHEEL_FAULT_CMD_TIMEOUT, WHEEL_FAULT_DRIVE, WHEEL_FAULT_OVERSPEED

    icd = Icd()
    names = [n for n in icd.messages if n.startswith("RW") and n.endswith("_STATUS")]
    assert names
    for name in names:
        comment = icd.spec(name).db_message.get_signal_by_name("fault").comment
        assert f"{WHEEL_FAULT_OVERSPEED} overspeed" in comment, comment
        assert f"{WHEEL_FAULT_CMD_TIMEOUT} command timeout" in comment, comment
        assert f"{WHEEL_FAULT_DRIVE} drive fault" in comment, comment
