"""Onboard eclipse knowledge (fsw.eclipse, gnc.sky_ephemeris.SkyEphemeris.sunlit_fraction) against the truth's
shadow: the truth orbit (hil_sim.world.orbit) and the truth Sun (hil_sim.world.ephemeris, astropy nodes), with
the one conical-shadow geometry both ends share (gnc.eclipse).

Bound: on the 600 km example Earth-observation orbit, sampled every second over two orbits, the onboard
shadow flag (sunlit fraction < 1) equals the truth's except within 1 s of a truth edge. Why: the onboard
orbit is the truth's (circular, knowledge from the truth's elements: metres apart), so the edges move only
with the onboard Sun's error (the analytic series, within 0.01 deg), which shifts an edge by 0.01 deg over
the orbital rate 0.06 deg/s, about 0.2 s; the measured fractions differ by less than 0.01 in the
penumbra (about 0.2 s of its 22 s). In a higher orbit the same Sun error is more seconds (GEO: ~2.4 s), and an
eccentric truth orbit adds the circular knowledge's own error. Events come from the housekeeping group,
so they are at most one housekeeping period (1 s) late.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from closed_loop_kit import RecordingDriver

from fsw.config import FswConfig
from fsw.eclipse import EclipseMonitor, shadow_state
from gnc.eclipse import sunlit_fraction
from hil_sim.mission.model import load_mission, world_params
from hil_sim.world.orbit import orbit_elements_array, orbit_position_N_km
from hil_sim.world.world import WorldBatch

MISSION = Path(__file__).resolve().parents[2] / "config" / "missions" / "earth-observation.yaml"
EDGE_S = 1.0  # the agreement bound next to a shadow edge (module docstring)


@pytest.fixture(scope="module")
def orbit_truth():
    """(mission, t [s], truth sunlit fraction) every second over two orbits of the example mission."""
    mission = load_mission(MISSION)
    wp = world_params(mission)
    period_s = 2.0 * math.pi * math.sqrt(wp.orbit.semi_major_axis_km**3 / 398600.4418)
    t = np.arange(0.0, 2.0 * period_s, 1.0)
    sun_km, _ = WorldBatch([wp]).ephemeris.positions_N_km(t)
    elements = orbit_elements_array(wp.orbit)
    r = np.empty((t.size, 3))
    for k in range(t.size):
        orbit_position_N_km(elements, float(t[k]), r[k])
    return mission, t, sunlit_fraction(r, sun_km)


def _edges(t: np.ndarray, shaded: np.ndarray) -> np.ndarray:
    """Times of the samples where the shadow flag changes (the later sample of each pair)."""
    return t[1:][np.diff(shaded.astype(int)) != 0]


def _differ_away_from_edges(t: np.ndarray, ours: np.ndarray, truth: np.ndarray) -> list[float]:
    """Sample times where the two flags differ more than EDGE_S from every edge of the truth's."""
    edges = _edges(t, truth)
    return [float(x) for x in t[ours != truth] if np.min(np.abs(edges - x)) > EDGE_S]


def test_onboard_shadow_agrees_with_the_truth_over_two_orbits(orbit_truth) -> None:
    mission, t, truth = orbit_truth
    monitor = EclipseMonitor(mission.flight_software, lambda name, **args: None)
    ours = np.array([monitor.ephem.sunlit_fraction(float(x)) for x in t])
    truth_edges = _edges(t, truth < 1.0)
    assert len(truth_edges) == 4  # two shadows, each entered and left: the test sees eclipses at all
    assert np.count_nonzero(truth == 0.0) > 3000  # umbra over ~35 min of each orbit
    assert _differ_away_from_edges(t, ours < 1.0, truth < 1.0) == []  # shadow (penumbra or umbra)
    assert _differ_away_from_edges(t, ours == 0.0, truth == 0.0) == []  # umbra
    assert float(np.max(np.abs(ours - truth))) < 0.02


def test_monitor_raises_one_entry_and_one_exit_per_shadow(orbit_truth) -> None:
    mission, t, truth = orbit_truth
    raised: list[tuple[float, str, dict]] = []
    clock = {"t": 0.0}
    monitor = EclipseMonitor(mission.flight_software, lambda name, **args: raised.append((clock["t"], name, args)))
    states = set()
    for x in t.tolist():
        clock["t"] = x
        monitor.update(x)
        states.add(monitor.values()["eclipse_state"])
    assert states == {"SUNLIT", "PENUMBRA", "UMBRA"}
    names = [name for _, name, _ in raised]
    assert names == ["ECLIPSE_ENTRY", "ECLIPSE_EXIT"] * 2
    truth_edges = _edges(t, truth < 1.0)
    for (when, _, _), edge in zip(raised, truth_edges):
        assert abs(when - edge) <= EDGE_S
    for (t_in, _, entry), (t_out, _, leave) in zip(raised[0::2], raised[1::2]):
        assert 0.0 < entry["sunlit_fraction"] < 1.0  # first seen in the penumbra
        assert leave["duration_s"] == pytest.approx(t_out - t_in)
        assert leave["least_sunlit_fraction"] == 0.0  # through the umbra


def test_starting_in_the_shadow_is_an_entry(orbit_truth) -> None:
    mission, t, truth = orbit_truth
    start = float(t[np.flatnonzero(truth == 0.0)[10]])
    raised = []
    monitor = EclipseMonitor(mission.flight_software, lambda name, **args: raised.append(name))
    monitor.update(start)
    assert raised == ["ECLIPSE_ENTRY"] and monitor.state == "UMBRA" and monitor.fraction == 0.0


def test_without_an_orbit_the_state_is_unknown_and_no_event_is_raised() -> None:
    """The default orbit (GEO, the placeholder of a configuration that names none) is in the Earth's shadow
    near local midnight at the equinox epoch: the same orbit written out is known and shaded there, the
    unnamed one stays UNKNOWN and silent."""
    named = EclipseMonitor(FswConfig.model_validate({"orbit": {}}), lambda name, **args: None)
    midnight = next(x for x in np.arange(0.0, 86400.0, 60.0) if named.ephem.sunlit_fraction(float(x)) == 0.0)
    raised = []
    monitor = EclipseMonitor(FswConfig(), lambda name, **args: raised.append(name))
    assert monitor.ephem is None
    for x in (0.0, float(midnight), float(midnight) + 60.0):
        monitor.update(x)
    assert raised == [] and monitor.state == "UNKNOWN" and math.isnan(monitor.fraction)
    named.update(float(midnight))
    assert named.state == "UMBRA"


@pytest.mark.parametrize("fraction, state", [(1.0, "SUNLIT"), (0.999, "PENUMBRA"), (1e-9, "PENUMBRA"),
                                             (0.0, "UMBRA"), (math.nan, "UNKNOWN")])
def test_shadow_state_names(fraction: float, state: str) -> None:
    assert shadow_state(fraction) == state


def test_the_housekeeping_packet_carries_the_shadow(orbit_truth) -> None:
    """Through the flight software's housekeeping group: the HK values and the events at onboard time."""
    from fsw.app import FlightSoftware

    mission, t, truth = orbit_truth
    cfg = mission.flight_software
    fsw = FlightSoftware(cfg, RecordingDriver(len(cfg.spacecraft.wheels)))
    try:
        assert fsw.hk_values()["eclipse_state"] == "UNKNOWN"  # nothing evaluated before the first period
        fsw.t_s = float(t[np.flatnonzero(truth == 0.0)[0]])
        fsw.housekeeping()
        hk = fsw.hk_values()
        assert hk["eclipse_state"] == "UMBRA" and hk["sunlit_fraction"] == 0.0
        assert ("ECLIPSE_ENTRY", {"sunlit_fraction": 0.0}) in fsw.telemetry.events
    finally:
        fsw.shutdown()


def test_the_shadow_comes_from_the_guidances_ephemeris() -> None:
    """One onboard Sun and orbit: the flight software's monitor reads the guidance's ephemeris (not a second
    one), and still none without an orbit."""
    from fsw.guidance import Guidance

    cfg = FswConfig.model_validate({"orbit": {}})
    guidance = Guidance(cfg)
    monitor = EclipseMonitor(cfg, lambda name, **args: None, guidance.ephem)
    assert monitor.ephem is guidance.ephem
    assert EclipseMonitor(FswConfig(), lambda name, **args: None, guidance.ephem).ephem is None
    from comms.bus import Icd, open_bus
    from fsw.assembly import build_flight_software

    mission = load_mission(MISSION).flight_software
    bus = open_bus("virtual:eclipseshare", light=True)
    fsw = build_flight_software(mission.model_copy(update={"law": mission.law.model_copy(
        update={"assumption_check": "off"})}), bus, Icd())
    try:
        assert fsw.eclipse.ephem is fsw.guidance.ephem
    finally:
        fsw.shutdown()
        bus.shutdown()
