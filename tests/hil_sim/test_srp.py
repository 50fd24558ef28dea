"""Solar radiation pressure (spacecraft.disturbance.solar_radiation_pressure on spacecraft.facets) against
Basilisk 2.12.1's facetSRPDynamicEffector with the eclipse module's shadow factor: tests/data/basilisk/
srp_reference.py wrote the references (600 geometries' torques, and one orbit through the Earth's shadow).
Off, nothing changes (the identity of the existing missions is checked on whole runs elsewhere)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gnc.attitude import attitude_error_angle
from hil_sim.world import dynamics as dyn
from hil_sim.world import environment as env
from hil_sim.world.orbit import orbit_elements_array
from hil_sim.world.params import DisturbanceParams, FacetParams, OrbitParams, SpacecraftParams, WheelParams

DATA = Path(__file__).resolve().parents[1] / "data" / "basilisk"


@pytest.fixture(scope="module")
def inputs() -> dict:
    return json.loads((DATA / "srp_reference.json").read_text())


def _mrp_to_q(sigma) -> tuple[float, float, float, float]:
    s = np.asarray(sigma, dtype=float)
    s2 = float(s @ s)
    return ((1 - s2) / (1 + s2), *(2 * s / (1 + s2)))


def _spacecraft(inputs: dict, srp: bool = True) -> SpacecraftParams:
    # a wheel of negligible spin inertia that is never commanded: the reference has none
    wheel = WheelParams(axis_B=(1.0, 0.0, 0.0), Js_kgm2=1e-12, max_torque_Nm=1e-9, max_speed_rad_s=1e3)
    facets = tuple(FacetParams(area_m2=f["area_m2"], normal_B=tuple(map(float, f["normal_B"])),
                               centre_of_pressure_B_m=tuple(f["centre_of_pressure_B_m"]), specular=f["specular"],
                               diffuse=f["diffuse"]) for f in inputs["facets"])
    # Basilisk's solar flux (1368 W/m^2 in facetSRPDynamicEffector.cpp; keepout's default is 1361)
    return SpacecraftParams(inertia_B_kgm2=tuple(map(tuple, inputs["inertia_B_kgm2"])), wheels=(wheel,),
                            disturbance=DisturbanceParams(solar_radiation_pressure=srp,
                                                          solar_flux_W_m2=inputs["solar_flux_W_m2"]),
                            facets=facets, q_NB0=_mrp_to_q(inputs["sigma_BN0"]),
                            omega_BN_B0_rad_s=tuple(inputs["omega_BN_B0_rad_s"]))


def test_the_torque_is_basilisks_on_600_geometries(inputs) -> None:
    """The same model: equal to rounding where Basilisk's shadow factor and keepout's sunlit fraction agree
    (umbra and full Sun); in the penumbra the two differ by the Sun's and the Earth's radii alone (IAU 2015
    695,700 km and WGS-84 6378.137 km here, 695,000 and 6378.1366 km in Basilisk: test_eclipse.py bounds
    that at 1e-3), so there the torque per unit of sunlit fraction is compared."""
    from gnc.eclipse import sunlit_fraction

    rows = np.loadtxt(DATA / "srp_reference_torques.csv", delimiter=",", skiprows=1)
    q, r, sun, factor, theirs = rows[:, 0:4], rows[:, 4:7], rows[:, 7:10], rows[:, 10], rows[:, 11:14]
    assert (factor == 0).sum() > 50 and ((factor > 0) & (factor < 1)).sum() > 30 and (factor == 1).sum() > 50
    _, _, B, _ = dyn.pack_spacecraft([_spacecraft(inputs)])
    env.hold_sun(B, sun[0])
    ours = np.array([env.srp_torque(B, 0, *qk, *rk) for qk, rk in zip(q, r)])
    lit = sunlit_fraction(r, sun)
    assert np.abs(lit - factor).max() < 1e-3
    scale = np.abs(theirs).max()
    assert scale > 1e-7  # a torque to compare: the facets are not balanced about the centre of mass
    err = np.abs(ours * factor[:, None] - theirs * lit[:, None]).max()
    # measured 2026-11-29: 3.8e-21 N m (rounding) on torques up to 3.0e-6 N m
    assert err < 1e-12 * scale, f"max torque difference {err:.3e} N m"
    assert np.all(ours[factor == 0] == 0.0)


def _propagate(inputs: dict, times: np.ndarray, sc: SpacecraftParams, earth_rotation_rad_s: float | None = None
               ) -> np.ndarray:
    """q_NB and omega_BN_B at ``times`` for spacecraft ``sc`` on the reference's orbit (and fixed Sun): the
    dynamics step itself, with Basilisk's step (RK4, 0.1 s). ``earth_rotation_rad_s``: the air's, if not the
    Earth's."""
    G, W, B, X = dyn.pack_spacecraft([sc])
    if B.shape[0] > dyn.B_FIELDS:
        env.hold_sun(B, np.asarray(inputs.get("sun_N_km", [1.5e8, 0.0, 0.0])))
        if earth_rotation_rad_s is not None:
            B[env.ENV_OMEGA_E] = earth_rotation_rad_s
    o = inputs["orbit"]
    orb = orbit_elements_array(OrbitParams(
        semi_major_axis_km=inputs["earth_radius_m"] / 1e3 + o["altitude_km"], eccentricity=0.0,
        inclination_deg=o["inclination_deg"], raan_deg=o["raan_deg"], arg_perigee_deg=o["arg_perigee_deg"],
        mean_anomaly_deg=o["true_anomaly_deg"], mu_km3_s2=inputs["earth_mu_m3_s2"] / 1e9))[None, :]
    dt = float(inputs["integrator"].split(",")[1].split()[0])
    decay, gm, has_coulomb = dyn.step_coefficients(W, B, dt)
    work = np.empty(dyn.work_shape(1, 1))
    D, temp, applied, flags = np.zeros((3, 1)), W[dyn.W_TAMB].copy(), np.zeros((1, 1)), np.zeros((1, 1), np.int64)
    out = [X[0:7, 0].copy()]
    for t0, t1 in zip(times[:-1], times[1:]):
        n_sub = int(round((t1 - t0) / dt))
        assert dyn.dynamics_step_batch(X, D, temp, G, W, B, np.zeros((1, 1)), np.zeros(3 * n_sub), dt, n_sub, applied,
                                       flags, decay, gm, has_coulomb, work, orb, float(t0))
        out.append(X[0:7, 0].copy())
    return np.array(out)


def test_one_orbit_through_the_shadow_matches_basilisk(inputs) -> None:
    ref = np.loadtxt(DATA / "srp_reference.csv", delimiter=",", skiprows=1)
    t, q_ref, w_ref, shadow = ref[:, 0], ref[:, 1:5], ref[:, 5:8], ref[:, 11]
    assert (shadow == 0).sum() > 100 and (shadow == 1).sum() > 100
    ours = _propagate(inputs, t, _spacecraft(inputs))
    att = np.array([attitude_error_angle(a, b) for a, b in zip(ours[:, 0:4], q_ref)])
    rate = np.abs(ours[:, 4:7] - w_ref).max(axis=1)
    # Up to the first shadow entry the models are the same (the Sun held, the facets, the step): agreement to
    # the integrators' accuracy. (measured 2026-11-29: 4.9e-14 rad, 9.8e-17 rad/s over the first 1,770 s)
    sunlit = np.arange(t.size) < np.argmax(shadow < 1.0)
    assert sunlit.sum() > 100
    assert att[sunlit].max() < 1e-11, f"sunlit arc: attitude differs by {att[sunlit].max():.3e} rad"
    assert rate[sunlit].max() < 1e-14, f"sunlit arc: body rate differs by {rate[sunlit].max():.3e} rad/s"
    # Through the shadow they differ in how the shadow's edge is met: Basilisk holds the eclipse module's
    # factor over each 0.1 s step (computed at its start, with its radii), keepout evaluates the sunlit
    # fraction at every RK4 stage with the IAU/WGS-84 radii (the edge moves by ~0.5 km, ~0.07 s of flight).
    # The torque, up to 3e-6 N m, is held ~0.05 s longer or shorter at each of the two edges: ~1e-7 N m s
    # on 8-15 kg m^2, a rate offset of order 1e-8 rad/s, which the attitude integrates over the ~2,000 s
    # left. (measured 2026-11-29: 7.1e-9 rad/s and 1.65e-5 rad at the end of the orbit; 0.61 rad without SRP)
    assert rate.max() < 2e-8, f"body rate differs by {rate.max():.3e} rad/s"
    assert att.max() < 5e-5, f"attitude differs by {att.max():.3e} rad"
    # and the effect is there to see: without it the attitude is off by far more
    plain = _propagate(inputs, t[[0, -1]], _spacecraft(inputs, srp=False))
    assert attitude_error_angle(plain[-1, 0:4], q_ref[-1]) > 100 * att.max()
