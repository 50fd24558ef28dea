"""The slew limits behind the keep-out promise on the real spacecraft (fsw.guidance.slew_limits): the
braking-distance rule (onboard on SET_GAINS, and `config check` on the timeline, one function), the rate
governor near zones, and the rate limit holding for the true body rate."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from closed_loop_kit import attitude_with_boresight, blind_free_bus_loop
from fsw.config import FswConfig
from comms.dictionary import DICTIONARY
from fsw.guidance import Guidance
from fsw.guidance.slew_limits import (
    allowed_braking_deg,
    BRAKING_RESERVE_DEG, braking_distance_deg, braking_problem, layer_angle_deg, rate_for_distance_deg_s,
)
from comms.telecommand import encode_command

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "config" / "missions" / "demo-pointing.yaml"
EPOCH = "2030-03-29T12:00:00Z"


def test_braking_distance_is_kinematics_and_the_governor_rate_is_its_inverse() -> None:
    # 1 deg/s at 0.15 deg/s^2: 1 / 0.3 = 3.33 deg to stop, plus 1 s of loop lag at 1 rad/s = 1 deg and the
    # jerk-limited command's start of the braking, w / (2 kp) = 0.5 deg (fsw.control)
    assert braking_distance_deg(1.0, 0.15, 1.0) == pytest.approx(1.0 / 0.3 + 1.0 + 0.5)
    for d in (0.1, 2.5, 17.7, 90.0):
        w = rate_for_distance_deg_s(d, 0.11, 0.8)
        assert braking_distance_deg(w, 0.11, 0.8) == pytest.approx(d)
    assert rate_for_distance_deg_s(-1.0, 0.15, 1.0) == 0.0
    assert layer_angle_deg(1.0 - math.cos(math.radians(15.0))) == pytest.approx(15.0)


def test_rule_refuses_the_demo_commands_that_entered_the_moon_zone() -> None:
    """SET_GAINS k1 = 1 with 20 deg/s, or 4 deg/s alone, took the demo's boresight 12.5-13.7 deg into
    the Moon zone. With the demo's 3 deg margin, 0.035 eps cap, 0.15 deg/s^2 and 1 rad/s both are refused;
    the configured 1 deg/s passes."""
    args = dict(accel_deg_s2=0.15, bandwidth_rad_s=1.0, margin_deg=3.0, eps=0.035)
    assert braking_problem(1.0, **args) is None
    for rate in (20.0, 4.0):
        reason = braking_problem(rate, **args)
        assert reason is not None and reason.startswith("BRAKING_DISTANCE: ")


def _bus(fsw_sections=None, q0=(1.0, 0.0, 0.0, 0.0)):
    sections = {"initial_mode": "POINTING", "law": {"assumption_check": "off"},
                "pointing": {"target_N": [0.0, 0.0, 1.0], "zones": []}}
    sections.update(fsw_sections or {})
    return blind_free_bus_loop(EPOCH, sections, seed=4, q0=q0)


def test_set_gains_beyond_the_braking_distance_is_rejected_by_telecommand_with_its_reason() -> None:
    loop, tm, tc = _bus()
    try:
        loop.run(3)
        bad = tc.handle_datagram(encode_command(DICTIONARY, "SET_GAINS", {"k1": 1.0, "kappa": 1.0, "eps": 0.0,
                                                                          "rate_limit_deg_s": 20.0}, seq_count=1))
        assert not bad.accepted and bad.error == "VALIDATION" and "BRAKING_DISTANCE" in bad.reason
        assert any(e.name == "CMD_REJECTED" and "BRAKING_DISTANCE" in e.args["reason"] for e in tm.recent_events)
        assert loop.fsw.guidance.max_rate_rad_s == pytest.approx(math.radians(loop.fsw.cfg.spacecraft.max_rate_deg_s))
        ok = tc.handle_datagram(encode_command(DICTIONARY, "SET_GAINS", {"k1": 0.2, "kappa": 1.0, "eps": 0.0,
                                                                         "rate_limit_deg_s": 0.5}, seq_count=2))
        assert ok.accepted and loop.fsw.guidance.max_rate_rad_s == pytest.approx(math.radians(0.5))
    finally:
        loop.close()


def test_config_check_applies_the_onboard_rule_to_every_timeline_command(tmp_path) -> None:
    from hil_sim.mission.model import load_mission
    from hil_sim.mission.physics_checks import check_mission

    data = yaml.safe_load(DEMO.read_text())
    data["timeline"][:0] = [{"t_s": 5.0, "command": "SET_GAINS", "k1": 1.0, "rate_limit_deg_s": 20.0},
                            {"t_s": 6.0, "command": "SET_GAINS", "rate_limit_deg_s": 0.8}]
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data))
    report = check_mission(load_mission(path))
    errors = [f.message for f in report.errors if f.check == "braking"]
    fsw = load_mission(path).flight_software
    onboard = Guidance(fsw)
    with pytest.raises(ValueError) as refused:
        onboard.set_gains(1.0, 1.0, "auto", 20.0)
    assert len(errors) == 1 and errors[0].startswith("timeline[0] SET_GAINS at 5 s")
    assert errors[0].endswith(str(refused.value))  # the same rule, the same words, as onboard
    assert not any(f.check == "braking" for f in check_mission(load_mission(DEMO)).errors)


def test_governor_slows_towards_a_zone_being_approached_and_not_away_from_one() -> None:
    cfg = FswConfig.model_validate({"control": {"max_command_accel_deg_s2": 0.15, "rate_bandwidth_rad_s": 1.0}})
    g = Guidance(cfg)
    omega = np.radians([0.0, 1.0, 0.0])
    g._govern(omega, [3.2])
    approaching = g._govern(omega, [3.0])
    expected = rate_for_distance_deg_s(3.0 - BRAKING_RESERVE_DEG, 0.15, 1.0)
    assert math.degrees(np.linalg.norm(approaching)) == pytest.approx(expected) and expected < 1.0
    np.testing.assert_allclose(approaching / np.linalg.norm(approaching), [0.0, 1.0, 0.0])  # same path
    leaving = g._govern(omega, [3.1])
    np.testing.assert_array_equal(leaving, omega)
    assert np.linalg.norm(g._govern(omega, [0.2])) == 0.0  # inside the reserve and closing: stop


def test_true_body_rate_stays_within_the_limit_on_a_slew_with_a_large_roll_error() -> None:
    """The roll rate about the boresight came on top of the law's full rate (+12 % on a
    150 deg slew). A 60 deg slew that also has to roll 90 deg: true |omega| within the limit + 5 %."""
    y0 = np.array([math.sin(math.radians(60.0)), 0.0, math.cos(math.radians(60.0))])
    loop, _, _ = _bus({"pointing": {"target_N": [0.0, 0.0, 1.0], "zones": [], "roll_axis_B": [0.0, 1.0, 0.0],
                                    "roll_reference_N": [1.0, 0.0, 0.0]}}, q0=attitude_with_boresight(y0))
    rates = []
    try:
        loop.run(900, every=lambda k: rates.append(np.linalg.norm(loop.world.truth.omega_BN_B)))
    finally:
        loop.close()
    limit = math.radians(loop.fsw.cfg.spacecraft.max_rate_deg_s)
    assert max(rates) > 0.9 * limit  # the slew ran at the limit
    assert max(rates) <= 1.05 * limit


def test_set_gains_says_the_real_reason_and_credits_no_layer_wider_than_the_cap() -> None:
    """eps 0.99 credited an 89 deg eps-layer to the braking rule: SET_GAINS with 4 deg/s was accepted and the
    true body rate reached 3.33 deg/s, 333 % of the configured limit. The rule now credits at most the
    eps cap's layer; a rate the star tracker cannot track or the gyro cannot measure is refused as such,
    and the acknowledgement carries the reason's own code."""
    loop, tm, tc = _bus({"spacecraft": {"star_tracker_max_rate_deg_s": 30.0, "imu_range_rad_s": 0.35}})
    try:
        loop.run(3)
        cfg = loop.fsw.cfg
        accel, bw, margin, cap = (cfg.control.max_command_accel_deg_s2, cfg.control.rate_bandwidth_rad_s,
                                  cfg.law.margin_deg, cfg.law.eps_max_used)
        capped = rate_for_distance_deg_s(allowed_braking_deg(margin, cap), accel, bw)
        wide_layer = rate_for_distance_deg_s(allowed_braking_deg(margin, 0.99), accel, bw)
        rate = 1.5 * capped  # brakes in time only if the 0.99 layer were credited
        assert capped < rate < wide_layer and rate < 20.0
        send = lambda seq, **a: tc.handle_datagram(encode_command(  # noqa: E731
            DICTIONARY, "SET_GAINS", {"k1": 1.0, "kappa": 1.0, "eps": 0.0, "rate_limit_deg_s": 0.5, **a}, seq_count=seq))
        wide = send(1, eps=0.99, rate_limit_deg_s=rate)
        assert not wide.accepted and wide.code == "BRAKING_DISTANCE", wide
        assert send(2, rate_limit_deg_s=0.5).accepted
    finally:
        loop.close()
    # a rate that brakes in time but that the star tracker cannot follow
    g = Guidance(FswConfig.model_validate({"spacecraft": {"star_tracker_max_rate_deg_s": 0.4}}))
    assert braking_problem(0.45, g.accel_deg_s2, g.bandwidth_rad_s, g.cfg.law.margin_deg, g.cfg.law.eps_max_used) is None
    with pytest.raises(ValueError) as refused:
        g.set_gains(1.0, 1.0, "auto", 0.45)
    assert refused.value.code == "RATE_ABOVE_SENSOR_LIMIT" and "star tracker 0.4 deg/s" in str(refused.value)
    g.set_gains(1.0, 1.0, "auto", 0.35)
    assert g.max_rate_rad_s == pytest.approx(math.radians(0.35))
