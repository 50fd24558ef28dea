"""Aerodynamic drag (spacecraft.disturbance.aerodynamic_drag on spacecraft.facets, an exponential atmosphere
rotating with the Earth) against Basilisk 2.12.1's facetDragDynamicEffector with exponentialAtmosphere and
zeroWindModel: tests/data/basilisk/drag_reference.py wrote the references (600 geometries' torques, and one
orbit with co-rotating and with still air)."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gnc.attitude import attitude_error_angle
from hil_sim.world import dynamics as dyn
from hil_sim.world import environment as env
from hil_sim.world.params import DisturbanceParams, FacetParams

from test_srp import _propagate, _spacecraft

DATA = Path(__file__).resolve().parents[1] / "data" / "basilisk"


@pytest.fixture(scope="module")
def inputs() -> dict:
    data = json.loads((DATA / "drag_reference.json").read_text())
    data["solar_flux_W_m2"] = 1361.0  # unused: drag alone
    return data


def _drag_spacecraft(inputs: dict, drag: bool = True):
    sc = _spacecraft(inputs, srp=False)
    facets = tuple(FacetParams(area_m2=f["area_m2"], normal_B=tuple(map(float, f["normal_B"])),
                               centre_of_pressure_B_m=tuple(f["centre_of_pressure_B_m"]),
                               drag_coefficient=f["drag_coefficient"]) for f in inputs["facets"])
    dist = DisturbanceParams(aerodynamic_drag=drag, atmosphere_density_kg_m3=inputs["reference_density_kg_m3"],
                             atmosphere_reference_altitude_km=inputs["reference_altitude_km"],
                             atmosphere_scale_height_km=inputs["scale_height_km"])
    return replace(sc, facets=facets, disturbance=dist)


def test_the_torque_is_basilisks_on_600_geometries(inputs) -> None:
    """The same model (density, co-rotating air, facets): equal to rounding."""
    assert inputs["planet_radius_m"] == 1e3 * env.EARTH_RADIUS_KM
    assert inputs["earth_rotation_rad_s"] == env.EARTH_ROTATION_RAD_S
    rows = np.loadtxt(DATA / "drag_reference_torques.csv", delimiter=",", skiprows=1)
    q, r, v, theirs = rows[:, 0:4], rows[:, 4:7], rows[:, 7:10], rows[:, 14:17]
    _, _, B, _ = dyn.pack_spacecraft([_drag_spacecraft(inputs)])
    ours = np.array([env.drag_torque(B, 0, *qk, *rk, *vk) for qk, rk, vk in zip(q, r, v)])
    scale = np.abs(theirs).max()
    assert scale > 1e-7
    err = np.abs(ours - theirs).max()
    # measured 2026-11-29: 1.5e-19 N m (rounding) on torques up to 7.7e-6 N m
    assert err < 1e-12 * scale, f"max torque difference {err:.3e} N m"


@pytest.mark.parametrize("name, air_rotation", [("drag_reference_still.csv", 0.0), ("drag_reference.csv", None)])
def test_one_orbit_matches_basilisk(inputs, name, air_rotation) -> None:
    """Still air and co-rotating air. Basilisk reads the density and the air's velocity from its
    atmosphere and wind modules once per 0.1 s step, at its start; keepout evaluates both at every RK4 stage.
    On a circular orbit about a spherical Earth the density is the same at every point (the altitude is),
    so still air is the same model on both sides: agreement to the integrators' accuracy. The co-rotating air
    omega_E x r turns with the orbit (1.1e-3 rad/s): held over a step it lags by half a step, 5.7e-5 rad of
    its direction, i.e. 0.03 m/s of the 7,600 m/s relative speed; a relative change of the torque of a few
    1e-6, which accumulates over the orbit. The hub of the reference is 5e9 kg so that its orbit stays
    Keplerian, as keepout's truth orbit is (drag would lower a 50 kg one ~4 m in an orbit)."""
    ref = np.loadtxt(DATA / name, delimiter=",", skiprows=1)
    t, q_ref, w_ref = ref[:, 0], ref[:, 1:5], ref[:, 5:8]
    ours = _propagate(inputs, t, _drag_spacecraft(inputs), air_rotation)
    att = np.array([attitude_error_angle(a, b) for a, b in zip(ours[:, 0:4], q_ref)])
    rate = np.abs(ours[:, 4:7] - w_ref).max(axis=1)
    if air_rotation == 0.0:  # measured 2026-11-29: 1.7e-12 rad, 7.2e-16 rad/s
        assert att.max() < 1e-10 and rate.max() < 1e-14, (att.max(), rate.max())
    else:  # measured 2026-11-29: 4.2e-5 rad, 2.0e-8 rad/s, the rate error growing linearly from the start
        assert att.max() < 1e-4 and rate.max() < 5e-8, (att.max(), rate.max())
    plain = _propagate(inputs, t[[0, -1]], _drag_spacecraft(inputs, drag=False))
    assert attitude_error_angle(plain[-1, 0:4], q_ref[-1]) > 100 * att.max()
