"""Sun and Moon cones that touch, overlap or leave a gap narrower than the merge gap.

The flight software merges (inflated) zones closer than ``law.merge_gap_deg`` into one zone and flies round
it; the load-time physics check must judge that merged geometry, not the zones one by one. Zones here are
fixed inertial cones (named sun and moon) on the first slew of the demo mission, so the geometry does not
depend on the ephemeris: each must pass `config check` and fly in `keepout sil run` with every physical
margin > 0. A geometry the flight software cannot fly (the target in the narrow gap between two zones it
cannot merge around the target) is still rejected.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil_sim.mission.model import Mission
from hil_sim.mission.physics_checks import check_mission

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "config" / "missions" / "demo-pointing.yaml"
SUN_HALF_DEG, MOON_HALF_DEG = 10.0, 5.0
START_RA_DEC = (330.0, -10.0)  # the demo's initial boresight (target A)
TOWARDS_RA_DEC = (60.0, -10.0)  # the slew runs along the great circle towards this direction
SUN_FROM_START_DEG = 35.0


def _unit(ra_deg: float, dec_deg: float) -> np.ndarray:
    ra, dec = math.radians(ra_deg), math.radians(dec_deg)
    return np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])


def _along(angle_deg: float) -> np.ndarray:
    """The point angle_deg from the start along the slew's great circle."""
    a, b = _unit(*START_RA_DEC), _unit(*TOWARDS_RA_DEC)
    e = b - (b @ a) * a
    e /= np.linalg.norm(e)
    t = math.radians(angle_deg)
    return math.cos(t) * a + math.sin(t) * e


def _ra_dec(v: np.ndarray) -> list[float]:
    return [round(math.degrees(math.atan2(v[1], v[0])) % 360.0, 6), round(math.degrees(math.asin(v[2])), 6)]


def _mission_data(centre_distance_deg: float, target_deg: float | None = None) -> dict:
    """The demo with the Sun cone SUN_FROM_START_DEG along the slew and the Moon cone centre_distance_deg
    beyond it; the target (SET_TARGET at 5 s) 25 deg past the Moon cone unless given."""
    data = yaml.safe_load(DEMO.read_text())
    sun, moon = _along(SUN_FROM_START_DEG), _along(SUN_FROM_START_DEG + centre_distance_deg)
    data["flight_software"]["pointing"]["zones"] = [
        {"name": "sun", "body": "inertial", "direction_N": sun.round(9).tolist(),
         "geometry": {"shape": "cone", "half_angle_deg": SUN_HALF_DEG}},
        {"name": "moon", "body": "inertial", "direction_N": moon.round(9).tolist(),
         "geometry": {"shape": "cone", "half_angle_deg": MOON_HALF_DEG}},
    ]
    if target_deg is None:
        target_deg = SUN_FROM_START_DEG + centre_distance_deg + MOON_HALF_DEG + 25.0
    data["timeline"] = [{"t_s": 5.0, "command": "SET_TARGET", "ra_dec_deg": _ra_dec(_along(target_deg))}]
    return data


def _physical_gap_deg(centre_distance_deg: float) -> float:
    return centre_distance_deg - SUN_HALF_DEG - MOON_HALF_DEG


# centre distances: cones overlapping by 3 deg, touching, 3 deg apart (the inflated zones overlap), and
# the inflated zones 2 deg apart (below the 4 deg merge gap; margin 3 + rebuild tolerance 0.1 each side)
GEOMETRIES = {"overlap-3deg": 12.0, "touching": 15.0, "gap-3deg": 18.0, "inflated-gap-2deg": 23.2}


@pytest.mark.parametrize("name", list(GEOMETRIES))
def test_close_sun_and_moon_cones_pass_the_check_as_one_merged_zone(name):
    distance = GEOMETRIES[name]
    mission = Mission.model_validate(_mission_data(distance))
    assert mission.flight_software.law.merge_gap_deg == 4.0
    report = check_mission(mission)
    assert report.ok, report.format()
    merges = [f for f in report.findings if f.check == "merge"]
    assert merges and "zones 'sun' and 'moon' are closer than law.merge_gap_deg" in merges[0].message


def test_target_in_a_gap_the_flight_software_cannot_merge_is_rejected():
    # inflated zones 2 deg apart with the target in the middle of the gap: a zone merged round both would
    # swallow the target, so the flight software leaves them apart and steers out of the gap instead
    distance = GEOMETRIES["inflated-gap-2deg"]
    gap_middle = SUN_FROM_START_DEG + SUN_HALF_DEG + 0.5 * _physical_gap_deg(distance)
    report = check_mission(Mission.model_validate(_mission_data(distance, target_deg=gap_middle)))
    assert not report.ok
    errors = [f for f in report.errors if f.check == "merge"]
    assert len(errors) == 1, report.format()
    assert "cannot merge" in errors[0].message and "'sun' and 'moon'" in errors[0].message


SIL_DURATION_S = 200.0


@pytest.fixture(scope="module")
def sil_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("merged")
    procs = {}
    for name, distance in GEOMETRIES.items():
        data = _mission_data(distance)
        data["name"] = f"merged-{name}"
        path = out / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        cmd = [sys.executable, "-m", "cli", "sil", "run", str(path), "--bus", "udp_multicast",
               "--duration", str(SIL_DURATION_S), "--out", str(out / name), "--no-progress"]
        procs[name] = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    results = {}
    for name, proc in procs.items():
        try:
            text, _ = proc.communicate(timeout=1500)
        except subprocess.TimeoutExpired:
            proc.kill()
            text, _ = proc.communicate()
        results[name] = (proc.returncode, text, out / name)
    return results


@pytest.mark.slow
@pytest.mark.parametrize("name", list(GEOMETRIES))
def test_close_sun_and_moon_cones_fly_in_sil_with_positive_margins(sil_runs, name):
    code, output, out = sil_runs[name]
    assert code != 2, f"mission rejected:\n{output}"
    summaries = list(out.glob("*/summary.json"))
    assert len(summaries) == 1, output
    summary = json.loads(summaries[0].read_text())
    keepout = [r for r in summary["requirements"] if r["name"].startswith("keep-out margin")]
    assert len(keepout) == 2, summary["requirements"]
    for r in keepout:
        assert r["pass"] and r["value"] > 0.0, r
    assert code == 0, output  # and it reaches its target: every requirement passes
