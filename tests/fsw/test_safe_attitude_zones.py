"""SAFE in QUATERNION missions: Sun acquisition keeps the attitude out of the forbidden-attitude zones.

Before 2026-11-29 SAFE turned ``sun_axis_B`` straight to the Sun whatever the attitude zones: entered at a
zone's edge, the Sun-pointing rotation went through the zone. Here SAFE is entered just outside the
demo-quaternion radiator-sun cone, on the side the straight Sun-pointing rotation crosses, and flown with a
kinematic integration (the body rate follows the command) through rate damping and Sun acquisition; the
attitude-zone margin is measured on the physical zones (no law margin) along the path, lifted as the judge
lifts it (continuous sign), with each zone's separation (`gnc.zones`).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig
from fsw.guidance import Guidance, signed_margin_deg

MISSION = Path(__file__).resolve().parents[2] / "config" / "missions" / "demo-quaternion.yaml"


def mission_fsw_config(path: Path) -> FswConfig:
    """The flight software's section of a mission file as written (guidance needs nothing the truth adds)."""
    return FswConfig.model_validate(yaml.safe_load(path.read_text())["flight_software"])


def _propagate(q: np.ndarray, omega_B: np.ndarray, dt: float) -> np.ndarray:
    """q_NB after rotating with body rate omega_B for dt, sign kept continuous (scipy: R exp(omega dt))."""
    r = Rotation.from_quat(np.roll(q, -1)) * Rotation.from_rotvec(np.asarray(omega_B) * dt)
    q2 = np.roll(r.as_quat(), 1)
    return q2 if float(q2 @ q) >= 0.0 else -q2


def _edge_attitude(zone, direction: np.ndarray, margin_deg: float) -> np.ndarray:
    """The attitude ``margin_deg`` outside ``zone`` on the great circle from its kernel towards ``direction``."""
    c = np.asarray(zone.kernel, dtype=float)
    v = direction - (direction @ c) * c
    v = v / np.linalg.norm(v)
    for a in np.arange(0.5, 90.0, 0.01):
        x = math.cos(math.radians(a)) * c + math.sin(math.radians(a)) * v
        if signed_margin_deg(zone, x) >= margin_deg:
            return x
    raise AssertionError("no edge attitude")


def _fly_safe(g: Guidance, q: np.ndarray, seconds: float, rate0_B=(0.0, 0.0, 0.0)) -> tuple[float, np.ndarray, list]:
    """Fly SAFE kinematically from ``q`` (sign as the judge's lift); (min physical margin [deg], final q, outputs).

    The rate decays from ``rate0_B`` while SAFE damps it (first-order, 2 s) and then follows the command."""
    omega = np.asarray(rate0_B, dtype=float)
    worst, outs = math.inf, []
    for k in range(int(seconds / 0.1)):
        out = g.step(0.1 * k, 0.1, q, omega)
        outs.append(out)
        omega = omega + (out.omega_cmd_BN_B - omega) * (1.0 - math.exp(-0.1 / 2.0))
        q = _propagate(q, omega, 0.1)
        worst = min(worst, min(signed_margin_deg(z, q) for z in g.s3_phys))
    return worst, q, outs


# the Sun-pointing rotation from here crosses the radiator-sun cone (found by sampling its edge)
EDGE_DIRECTION = np.array([0.9178320561575954, -0.045679271113372624, 0.0866945987524883, 0.3846839838454638])


def test_safe_entered_at_an_attitude_zone_edge_never_enters_it_and_reaches_a_sun_safe_attitude() -> None:
    cfg = mission_fsw_config(MISSION)
    g = Guidance(cfg)
    q0 = _edge_attitude(g.s3_phys[0], EDGE_DIRECTION, 0.3)
    g.step(0.0, 0.1, q0, np.zeros(3))  # QUATERNION first, as the mission flies: SAFE keeps its lift
    g.set_mode("SAFE")
    worst, q, outs = _fly_safe(g, q0, 400.0, rate0_B=np.radians([0.05, -0.03, 0.02]))
    assert worst > 0.0, f"SAFE entered a forbidden-attitude zone: {worst:.3f} deg"
    assert outs[-1].safe_phase == "SUN_POINTING"
    sun_axis_N = Rotation.from_quat(np.roll(q, -1)).apply(g.sun_axis_B)
    assert math.degrees(math.acos(min(1.0, float(sun_axis_N @ outs[-1].sun_N)))) < 1.0


def test_safe_aims_at_a_clear_sun_safe_attitude_and_quaternion_resumes_its_own_target() -> None:
    cfg = mission_fsw_config(MISSION)
    g = Guidance(cfg)
    held = g.q_target.copy()
    q0 = _edge_attitude(g.s3_phys[0], EDGE_DIRECTION, 0.3)
    g.step(0.0, 0.1, q0, np.zeros(3))
    g.set_mode("SAFE")
    _, _, outs = _fly_safe(g, q0, 5.0)  # damped within 1 s, then acquiring
    out = outs[-1]
    assert out.mode == "SAFE" and out.safe_phase == "SUN_ACQUISITION"
    aim = out.q_target_NB
    sun_axis_N = Rotation.from_quat(np.roll(aim, -1)).apply(g.sun_axis_B)
    assert math.degrees(math.acos(min(1.0, float(sun_axis_N @ out.sun_N)))) < 1e-3  # the Sun axis on the Sun
    standoff = cfg.law.retreat_standoff_deg
    assert min(signed_margin_deg(z, aim) for z in g.s3_law_zones) > standoff - 1e-9  # clear by the standoff
    assert len(out.margins_deg) == len(g.s3_phys) and out.margin_min_deg > 0.0  # attitude margins in telemetry
    assert out.omega_cmd_BN_B @ out.omega_cmd_BN_B <= math.radians(cfg.safe.max_rate_deg_s) ** 2 + 1e-15
    # the straight turn (the shortest rotation putting the Sun axis on the Sun) is blocked, so the aim is not it
    assert math.degrees(float(np.arccos(min(1.0, abs(float(aim @ q0)))))) > 1.0
    g.set_mode("QUATERNION")
    np.testing.assert_array_equal(g.q_target, held)
    assert np.array_equal(g.step(10.0, 0.1, q0, np.zeros(3)).q_target_NB, held)


def test_nearest_clear_attitude_leaves_a_zone_by_the_standoff_on_the_shortest_way() -> None:
    from fsw.guidance.safe import _nearest_clear_attitude
    from gnc.zones import ConicZone

    zone = ConicZone(np.array([1.0, 0.0, 0.0, 0.0]), math.radians(20.0))
    center = np.array([math.cos(math.radians(5.0)), math.sin(math.radians(5.0)), 0.0, 0.0])  # 15 deg deep
    d_free = 1.0 - math.cos(math.radians(3.0))
    x = _nearest_clear_attitude(center, [zone], d_free, center)
    assert zone.separation(x) > d_free
    moved = math.degrees(math.acos(min(1.0, float(x @ center))))
    assert 18.0 <= moved <= 18.0 + 1.0 + 6.0  # 15 deg deep + 3 deg standoff, on 1 deg shells, 64 directions
