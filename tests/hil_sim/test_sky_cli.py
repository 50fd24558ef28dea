"""`keepout sky`: where the bodies and zones are, and when a target is free, on the validator's own geometry."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cli import main as cli, sky as sky_cli
from hil_sim.mission.model import load_mission
from hil_sim.mission.physics_checks import SkyZones, _sweep_times, check_mission, schedule

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = ROOT / "config" / "missions"


def _low_orbit_mission(tmp_path: Path) -> Path:
    """The small satellite (550 km, the Earth zone sweeps the sky once an orbit) over 6000 s, its second
    target on the equator at RA 180, which the Earth zone covers for part of each orbit."""
    text = (MISSIONS / "smallsat-example.yaml").read_text()
    text = text.replace("duration_s: 400", "duration_s: 6000").replace(
        "ra_dec_deg: [259.0, 0.0]}", "ra_dec_deg: [180.0, 0.0]}")
    path = tmp_path / "leo.yaml"
    path.write_text(text)
    return path


def test_free_windows_agree_with_the_validators_target_check(tmp_path):
    mission = load_mission(_low_orbit_mission(tmp_path))
    report = check_mission(mission, quick=True)
    found = [f for f in report.errors if f.check == "target"]
    assert len(found) == 1 and "timeline[0]" in found[0].message and "'earth'" in found[0].message, report.format()
    t_reject, margin_reject = found[0].numbers["t_s"], found[0].numbers["margin_deg"]

    sky = SkyZones(mission)
    by_source = {t.label: t for t in sky_cli.targets(mission)}
    segments = {s.source: s for s in schedule(mission)}
    # the validator's own sample times over each target's commanded interval
    rejected = by_source["timeline[0]"]
    times = _sweep_times(segments["timeline[0]"], sky, None)
    free = sky_cli.free_samples(sky, rejected.direction_N, times)
    first_blocked = float(times[np.argmin(free)])
    assert not free.all() and first_blocked == t_reject  # the first time the validator found it inside
    assert sky_cli.blocking(sky, rejected.direction_N, first_blocked) == ["earth"]
    phys, _ = sky_cli.target_margins(sky, rejected.direction_N, first_blocked)[sky.names.index("earth")]
    assert phys == pytest.approx(margin_reject, abs=1e-12)
    runs = sky_cli.windows(times, free)
    kinds = [f for _, _, f in runs]  # inside and outside in turn as the Earth goes round
    assert True in kinds and False in kinds and all(a != b for a, b in zip(kinds, kinds[1:]))

    accepted = by_source["flight_software.pointing.target_N"]  # no error: free at every sample of its interval
    assert sky_cli.free_samples(sky, accepted.direction_N,
                                _sweep_times(segments[accepted.label], sky, None)).all()


def test_bodies_and_zones_are_where_the_validator_puts_them():
    mission = load_mission(MISSIONS / "demo-pointing.yaml")
    sky = SkyZones(mission)
    bodies = {b.name: b for b in sky_cli.bodies_at(sky, 0.0)}
    ra, dec = sky_cli._ra_dec(bodies["sun"].direction_N)
    assert ra == pytest.approx(32.6, abs=0.1) and dec == pytest.approx(13.2, abs=0.1)  # the mission's own comment
    assert 0.26 < bodies["sun"].angular_radius_deg < 0.27 and 0.24 < bodies["moon"].angular_radius_deg < 0.28
    assert bodies["earth"].angular_radius_deg == pytest.approx(8.70, abs=0.01)  # geostationary
    zones = {z.name: z for z in sky_cli.zones_at(sky, 0.0)}
    moon = zones["moon"]  # a 15 deg cone, inflated by the 3 deg law margin and the 0.1 deg rebuild tolerance
    assert moon.radius_deg == pytest.approx(15.0, abs=1e-6)
    assert moon.inflated_radius_deg == pytest.approx(18.1, abs=1e-6)
    assert np.allclose(moon.center_N, bodies["moon"].direction_N)
    assert zones["sun"].inflated_radius_deg > zones["sun"].radius_deg + 2.9


def test_the_command_prints_the_sky_and_draws_it(tmp_path, capsys):
    png = tmp_path / "sky.png"
    assert cli.main(["sky", str(_low_orbit_mission(tmp_path)), "--from", "0", "--to", "6000", "--step", "60",
                     "--at", "2026-04-25T12:10:00Z", "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "the sky at t = 600 s (2026-04-25T12:10:00Z)" in out
    assert "earth limb" in out and "inflated [deg]" in out
    line = next(x for x in out.splitlines() if "over 0 to 6000 s" in x and "inside 'earth'" in x)
    assert "(101 samples)" in line and "; free " in line
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize("args, message", [
    (["--at", "soon"], "--at 'soon': give seconds after the epoch"),
    (["--from", "100", "--to", "50"], "--to (50 s) is before --from (100 s)"),
    (["--step", "0"], "--step 0: give a positive number of seconds"),
    (["--at", "2026-04-25T12:10:00"], "give the time zone"),
])
def test_bad_times_are_refused_with_what_to_give(capsys, args, message):
    assert cli.main(["sky", str(MISSIONS / "demo-pointing.yaml"), *args]) == sky_cli.EXIT_REJECTED
    assert message in capsys.readouterr().err
