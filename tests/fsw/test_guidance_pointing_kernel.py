"""The compiled POINTING cycle (fsw.guidance._kernels.pointing_step_nb and the kernels it calls) against the
Python it replaces: bit-identical numbers. The zones' separations on packed arrays against the zones' own
methods, the star law against `gnc.laws.StarShapedLaw`, the scalar helpers against theirs, and whole
kinematic slews past moving Sun/Moon zones and a fixed polygon flown twice, compiled and through the Python
path (forced by handing the guidance its own ephemeris as a replaced function), output for output."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fsw.config import FswConfig
from fsw.guidance import Guidance
from fsw.guidance import _kernels as K
from fsw.guidance import pointing, slew_limits
from fsw.guidance.common import angle_deg, d_s_to_deg
from gnc import sky_zones
from gnc.laws import StarShapedLaw


def _unit(v):
    return v / np.linalg.norm(v)


def _zones(rng) -> list:
    """Cones and polygon star zones (the shapes the flight guidance builds), at random centres."""
    out = []
    for k in range(6):
        c = _unit(rng.standard_normal(3))
        if k % 3 == 0:
            out.append(sky_zones.SkyZoneBuilder({"shape": "cone", "half_angle_deg": float(rng.uniform(5, 30))}, 3.0).build(c))
        elif k % 3 == 1:
            shape = {"shape": "superellipse", "semi_axes_deg": [float(rng.uniform(10, 40)), float(rng.uniform(10, 30))],
                     "exponent": 1.5, "orientation_deg": float(rng.uniform(0, 90))}
            out.append(sky_zones.SkyZoneBuilder(shape, float(rng.uniform(0, 3)), fast=True).build(c))
        else:
            shape = {"shape": "polygon", "vertices_deg": [[20, 0], [5, 5], [0, 15], [-10, 0], [0, -12]]}
            out.append(sky_zones.SkyZoneBuilder(shape, 0.0, fast=True).build(c))
    return out


def _points(rng, zones, m: int) -> np.ndarray:
    """Random unit vectors, and points near (inside, on and just outside) each zone's kernel and boundary."""
    X = [_unit(rng.standard_normal(3)) for _ in range(m)]
    for z in zones:
        g = np.asarray(z.kernel)
        X.append(g)
        for _ in range(m // 4):
            X.append(_unit(g + rng.uniform(0.0, 0.8) * _unit(rng.standard_normal(3))))
    return np.array(X)


def test_packed_zone_separations_are_the_zones_own() -> None:
    rng = np.random.default_rng(3)
    zones = _zones(rng)
    tab, arcs = K.pack_zones(zones)
    for x in _points(rng, zones, 80):
        for i, z in enumerate(zones):
            assert K.zone_signed_nb(x, tab, arcs, i, False) == z.signed_separation(x)
            assert K.zone_signed_nb(x, tab, arcs, i, True) == z.separation(x)
        assert K.zone_separations_nb(x, tab, arcs).tolist() == [z.separation(x) for z in zones]


def test_zones_the_kernels_do_not_know_are_not_packed() -> None:
    from gnc.zones import StarZone
    exact = StarZone.superellipsoid(np.array([0.0, 0.0, 1.0]), None, [0.3, 0.2], 1.5)
    assert K.pack_zones([exact]) is None


@pytest.mark.parametrize("eps", [0.01, 0.035, 0.3])
def test_star_law_on_packed_zones_is_the_star_shaped_law(eps: float) -> None:
    rng = np.random.default_rng(5)
    zones = _zones(rng)
    tab, arcs = K.pack_zones(zones)
    for trial in range(4):
        target = _unit(rng.standard_normal(3))
        law = StarShapedLaw(target, zones, k1=1.0, kappa=float(rng.uniform(0.5, 2.0)), eps=eps)
        t = tab.copy()
        t[:, K.ZT_CAP_AXIS:K.ZT_CAP_AXIS + 3] = law._cap_axes
        t[:, K.ZT_CAP_COS] = law._cap_cos
        for i, g in enumerate(law._k1_kernels_over_kappa):
            t[i, K.ZT_KERNEL:K.ZT_KERNEL + 3] = g
        active = 0
        for x in _points(rng, zones, 60):
            u = np.empty(3)
            zone = K.star_law_nb(x, eps, law.target, t, arcs, u)
            u_ref, zone_ref = law.control_and_zone(x)
            assert zone == (-1 if zone_ref is None else zone_ref)
            assert u.tobytes() == np.asarray(u_ref).tobytes()
            active += zone >= 0
        assert active > 0  # the layers were visited
    assert K.star_law_nb(np.array([1.0, 0.1, 0.0]), 0.1, law.target, t, arcs, np.empty(3)) == -2


def test_scalar_helpers_are_the_python_ones() -> None:
    rng = np.random.default_rng(7)
    for _ in range(2000):
        a, b = _unit(rng.standard_normal(3)), _unit(rng.standard_normal(3))
        if rng.uniform() < 0.2:
            b = _unit(a + 1e-7 * rng.standard_normal(3))
        assert K.angle_deg_nb(a, b) == angle_deg(a, b)
        d = float(rng.uniform(-2.0, 2.0)) * (1e-6 if rng.uniform() < 0.3 else 1.0)
        assert K.d_s_to_deg_nb(d) == d_s_to_deg(d)
        dist, accel, bw = float(rng.uniform(-1.0, 10.0)), float(rng.uniform(0.0, 1.0)), float(rng.uniform(0.1, 3.0))
        assert K.rate_for_distance_nb(dist, accel, bw) == slew_limits.rate_for_distance_deg_s(dist, accel, bw)
    for x in (0.0, 1e-300, 1.234, -7.5, 3.0e5):
        assert K.angle_deg_nb(np.array([1.0, 0.0, 0.0]), np.array([math.cos(x), math.sin(x), 0.0])) == \
            math.degrees(math.acos(max(-1.0, min(1.0, math.cos(x)))))


def test_kernel_constants_are_the_guidance_constants() -> None:
    assert K.BRAKING_RESERVE_DEG == slew_limits.BRAKING_RESERVE_DEG
    assert K.LAG_TIME_CONSTANTS == slew_limits.LAG_TIME_CONSTANTS
    assert K.LAW_REBUILD_TRIGGER_DEG == pointing.LAW_REBUILD_TRIGGER_DEG
    assert K.PHYS_REBUILD_TOL_DEG == pointing.PHYS_REBUILD_TOL_DEG


def _demo_cfg(path: bool) -> FswConfig:
    """demo-pointing's flight software in a low orbit (the zones move: rebuilds every few seconds), with a
    fixed polygon zone besides the Sun's superellipse and the Moon's cone."""
    return FswConfig.model_validate({
        "epoch_utc": "2026-04-25T12:00:00Z", "initial_mode": "POINTING",
        "spacecraft": {"max_rate_deg_s": 1.0},
        "orbit": {"radius_km": 7000.0, "inclination_deg": 50.0, "raan_deg": 40.0},
        "law": {"k1": 0.3, "kappa": 1.0, "eps": "auto", "eps_max_used": 0.035, "margin_deg": 3.0,
                "assumption_check": "off"},
        "control": {"rate_bandwidth_rad_s": 1.0, "max_command_accel_deg_s2": 0.15},
        "pointing": {"target_N": [0.8528685, -0.4924039, -0.1736482], "roll_axis_B": [1.0, 0.0, 0.0],
                     "roll_reference_N": [0.0, 0.0, 1.0], "path": {"enabled": path},
                     "zones": [
                         {"name": "sun", "body": "sun", "geometry": {"shape": "superellipse", "semi_axes_deg": [40.0, 30.0],
                                                                     "exponent": 1.5, "orientation_deg": 20.0}},
                         {"name": "moon", "body": "moon", "geometry": {"shape": "cone", "half_angle_deg": 15.0}},
                         {"name": "fixed", "body": "inertial", "direction_N": [0.0, -0.6, 0.8],
                          "geometry": {"shape": "polygon", "vertices_deg": [[12, 0], [4, 4], [0, 10], [-8, 0], [0, -9]]}}]}})


def _ra_dec(ra: float, dec: float) -> np.ndarray:
    ra, dec = math.radians(ra), math.radians(dec)
    return np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])


def _record(out) -> dict:
    return {k: (v.tobytes() if isinstance(v, np.ndarray) else repr(v)) for k, v in vars(out).items()}


def _fly(compiled: bool, path: bool) -> tuple[list[dict], list, int]:
    events = []
    g = Guidance(_demo_cfg(path), lambda name, **args: events.append((name, args)))
    if not compiled:
        g.ephem.directions = g.ephem.directions  # a replaced ephemeris: the Python path, the same numbers
    calls = [0]
    step = K.pointing_step_nb

    def counting(*a):
        calls[0] += 1
        return step(*a)

    pointing.pointing_step_nb = counting
    try:
        q = np.array([0.166366, 0.739942, -0.198267, 0.620885])
        q /= np.linalg.norm(q)
        outs = []
        for k in range(1500):
            t = 0.1 * k
            if k == 50:
                g.set_target_direction(_ra_dec(95.0, 30.0))
            if k == 900:
                g.set_target_direction(_ra_dec(200.0, 0.0))
            out = g.step(t, 0.1, q, np.zeros(3))
            outs.append(_record(out))
            if k % 7 == 0:  # the sky a compiled cycle leaves to `_settle_sky`: the Python cycle's, when read
                g._settle_sky()
                outs.append({"dirs": {b: v.tobytes() for b, v in g._dirs.items()},
                             "slots": [(s.center_N.tobytes(), repr(s.phys_drift_deg)) for s in g.slots]})
            r = Rotation.from_quat(np.roll(q, -1)) * Rotation.from_rotvec(out.omega_cmd_BN_B * 0.1)
            q = np.roll(r.as_quat(), 1)
    finally:
        pointing.pointing_step_nb = step
    return outs, events, calls[0]


@pytest.mark.parametrize("path", [True, False])
def test_compiled_pointing_cycle_is_the_python_cycle(path: bool) -> None:
    compiled, events_c, calls_c = _fly(True, path)
    python, events_p, calls_p = _fly(False, path)
    assert calls_p == 0 and calls_c == 1500 - 1  # each cycle its own way (the first builds the zones)
    assert events_c == events_p
    for k, (a, b) in enumerate(zip(compiled, python)):
        assert a == b, (k, [f for f in a if a[f] != b[f]])


def test_cycle_inputs_follow_what_the_guidance_replaces() -> None:
    """`_cycle_inputs` rewrites the target, the roll axes (SAFE swaps in its own every cycle) and the
    ephemeris rows in the kernels' input vector when they are replaced, and only then."""
    g = Guidance(_demo_cfg(False))

    def rows(fp, at, n=3):
        return fp[at:at + n]

    def ephemeris_rows(t):
        k = math.floor(t / 10.0)
        (s0, m0), (s1, m1) = g.ephem._geocentric(k), g.ephem._geocentric(k + 1)
        return np.concatenate([g.ephem.p_hat, g.ephem.q_hat, s0, s1, m0, m1])

    fp = g._cycle_inputs(0.0, 1.0)
    assert fp[K.FP_NPREV] == -1.0
    assert np.array_equal(rows(fp, K.FP_TARGET), g.target_N)
    assert np.array_equal(rows(fp, K.FP_ROLL_AXIS), g.roll_axis_B)
    assert np.array_equal(rows(fp, K.FP_ROLL_REF), g.roll_ref_N)
    assert np.array_equal(rows(fp, K.FP_EPH, 18), ephemeris_rows(0.0))
    g.target_N = _ra_dec(95.0, 30.0)
    g.roll_axis_B, g.roll_ref_N = np.array([0.0, 1.0, 0.0]), _ra_dec(10.0, -20.0)
    g._governor_margins = [4.0, 5.5, 7.25]
    fp = g._cycle_inputs(12.3, 0.0)
    assert np.array_equal(rows(fp, K.FP_TARGET), g.target_N)
    assert np.array_equal(rows(fp, K.FP_ROLL_AXIS), g.roll_axis_B)
    assert np.array_equal(rows(fp, K.FP_ROLL_REF), g.roll_ref_N)
    assert np.array_equal(rows(fp, K.FP_EPH, 18), ephemeris_rows(12.3))
    assert fp[K.FP_T] == 12.3 and fp[K.FP_F] == 12.3 / 10.0 - 1 and fp[K.FP_STEADY] == 0.0
    assert fp[K.FP_PREV:K.FP_PREV + 3].tolist() == [4.0, 5.5, 7.25] and fp[K.FP_NPREV] == 3
    assert fp[K.FP_PREV + 3:].tolist() == [0.0, 0.0, 0.0]  # no zone disarmed
