"""``sky_zone_series(..., minimum_only=True)`` (fast mode's judge): each zone's minimum margin and last
plotted boundary are bit-identical to the full series', whose stretches it may leave unevaluated; where it
does, it holds a lower bound of the margin."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import Mission
from hil_sim.sil.judge import boresight_N, sky_zone_series

DEMO = Path(__file__).resolve().parents[2] / "config" / "missions" / "demo-pointing.yaml"

ZONES = [
    {"name": "sun", "body": "sun",
     "geometry": {"shape": "superellipse", "semi_axes_deg": [40.0, 30.0], "exponent": 1.5, "orientation_deg": 20.0}},
    {"name": "moon", "body": "moon",
     "geometry": {"shape": "superellipse", "semi_axes_deg": [12.0, 25.0], "exponent": 3.0, "orientation_deg": -35.0}},
    {"name": "earth", "body": "earth",
     "geometry": {"shape": "polygon", "vertices_deg": [[20.0, 0.0], [5.0, 5.0], [0.0, 15.0], [-10.0, 0.0], [0.0, -18.0]]}},
    {"name": "star", "body": "inertial", "direction_N": [0.0, 0.6, 0.8],
     "geometry": {"shape": "polygon", "vertices_deg": [[8.0, 0.0], [0.0, 8.0], [-8.0, 0.0], [0.0, -8.0]]}},
    {"name": "cone", "body": "moon", "geometry": {"shape": "cone", "half_angle_deg": 15.0}},
]


def _mission(add_earth_radius: bool) -> Mission:
    data = yaml.safe_load(DEMO.read_text())
    zones = [dict(z) for z in ZONES]
    zones[2]["add_body_angular_radius"] = add_earth_radius
    data["flight_software"]["pointing"]["zones"] = zones
    return Mission.model_validate(data)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _truth(rng: np.random.Generator, n: int = 600) -> dict[str, np.ndarray]:
    """A boresight wandering over the sky (a smooth random walk), fast-moving body directions (many zone
    rebuilds), and sometimes the boresight inside a zone."""
    t = np.arange(n) * 0.1

    def path(rate_rad_s: float) -> np.ndarray:
        start, axis = _unit(rng.normal(size=3)), _unit(rng.normal(size=3))
        angle = rate_rad_s * t
        k = np.cross(axis, start)
        return _unit(start[None, :] * np.cos(angle)[:, None] + k[None, :] * np.sin(angle)[:, None]
                     + axis[None, :] * (axis @ start) * (1.0 - np.cos(angle))[:, None])

    q = np.empty((n, 4))
    q[:, 0] = np.cos(0.5 * rng.uniform(0.0, 0.05) * t + rng.uniform(0.0, 3.0))
    axis = _unit(rng.normal(size=3) + 0.2 * np.sin(t[:, None] / 7.0 + np.arange(3)))
    q[:, 1:] = axis * np.sqrt(1.0 - q[:, :1] ** 2)
    return {"t_s": t, "q_NB": q, "sun_N": path(rng.uniform(2e-6, 1e-5)), "moon_N": path(rng.uniform(2e-6, 1e-5)),
            "earth_N": path(rng.uniform(2e-6, 1e-5)) * 7000.0,
            "r_sc_N_km": np.tile([42164.0, 0.0, 0.0], (n, 1))}


@pytest.mark.parametrize("seed", range(6))
def test_minimum_and_last_boundary_are_the_full_series(seed: int) -> None:
    rng = np.random.default_rng(seed)
    mission = _mission(add_earth_radius=bool(seed % 2))
    truth = _truth(rng)
    y_N = boresight_N(truth["q_NB"], np.array([0.0, 0.0, 1.0]))
    full = sky_zone_series(mission, truth, y_N)
    fast = sky_zone_series(mission, truth, y_N, minimum_only=True)
    assert [z.name for z in fast] == [z.name for z in full]
    for zf, zm in zip(full, fast):
        assert zm.margin_deg.min() == zf.margin_deg.min()  # bit-identical
        assert np.all(zm.margin_deg <= zf.margin_deg)  # a lower bound where not evaluated
        assert zm.boundary_history[-1][0] == zf.boundary_history[-1][0]
        assert np.array_equal(zm.boundary_history[-1][1], zf.boundary_history[-1][1])


def test_boresight_inside_a_zone_evaluates_every_stretch() -> None:
    rng = np.random.default_rng(11)
    mission = _mission(add_earth_radius=False)
    truth = _truth(rng)
    truth["q_NB"] = np.tile([1.0, 0.0, 0.0, 0.0], (len(truth["t_s"]), 1))  # boresight = N +z
    truth["sun_N"] = _unit(truth["sun_N"] * 0.05 + np.array([0.0, 0.0, 1.0]))  # the Sun zone around it
    y_N = boresight_N(truth["q_NB"], np.array([0.0, 0.0, 1.0]))
    full = sky_zone_series(mission, truth, y_N)
    fast = sky_zone_series(mission, truth, y_N, minimum_only=True)
    assert full[0].margin_deg.min() < 0.0
    assert np.array_equal(fast[0].margin_deg, full[0].margin_deg)
    assert math.isfinite(fast[0].margin_deg.min())
