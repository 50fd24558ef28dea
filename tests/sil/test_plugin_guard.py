"""keepout's guard over plug-ins (`fsw.plugin_guard`), flown in fast mode (the real flight software, one
process): a law that steers at the Sun, a law that fails, an estimator that is wrong; and a plug-in
name that is not installed, refused at load time."""
from __future__ import annotations

import subprocess
import sys

import pytest
import yaml

from plugin_kit import ROOT, example_site, loaded_plugin_modules, short_mission, use_paths, write_distribution

BAD_PLUGINS = '''
import math
import numpy as np
from fsw.plugins import AttitudeEstimate


class FailsLater:
    def __init__(self, cfg):
        self.calls = 0

    def command(self, state):
        self.calls += 1
        if self.calls > 100:
            raise RuntimeError("law diverged")
        return np.zeros(3)


class NotANumber:
    def __init__(self, cfg):
        pass

    def command(self, state):
        return np.array([math.nan, 0.0, 0.0])


SEEN = []


class Recorder:
    """Holds still and keeps what it was given."""

    def __init__(self, cfg):
        pass

    def command(self, state):
        SEEN.append(state)
        return np.zeros(3)


def _qmul(a, b):
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return np.array([a0*b0 - a1*b1 - a2*b2 - a3*b3, a0*b1 + a1*b0 + a2*b3 - a3*b2,
                     a0*b2 - a1*b3 + a2*b0 + a3*b1, a0*b3 + a1*b2 - a2*b1 + a3*b0])


class Tilted:
    """The star tracker's attitude, rotated 5 deg about body x: a mounting error the user got wrong."""

    def __init__(self, cfg):
        self.q = None

    def reset(self):
        self.q = None

    def update(self, s):
        if s.q_NS is not None:
            tilt = np.array([math.cos(math.radians(2.5)), math.sin(math.radians(2.5)), 0.0, 0.0])
            self.q = _qmul(_qmul(s.q_NS, s.q_BS * np.array([1.0, -1.0, -1.0, -1.0])), tilt)
        return AttitudeEstimate(self.q, s.gyro_B[-1] if len(s.gyro_B) else np.zeros(3))
'''


@pytest.fixture()
def plugins(tmp_path, monkeypatch):
    """The example package and the bad plug-ins above, registered as installed distributions."""
    site = tmp_path / "site"
    (site / "bad_plugins.py").parent.mkdir(parents=True)
    (site / "bad_plugins.py").write_text(BAD_PLUGINS)
    write_distribution(site, "bad-plugins", {
        "keepout.guidance": {"fails-later": "bad_plugins:FailsLater", "not-a-number": "bad_plugins:NotANumber",
                             "recorder": "bad_plugins:Recorder"},
        "keepout.estimator": {"tilted": "bad_plugins:Tilted"}})
    use_paths(monkeypatch, example_site(site))
    loaded_plugin_modules()
    yield tmp_path
    loaded_plugin_modules()


def _fly(tmp_path, duration_s: float = 120.0, **plugins):
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import load_mission

    mission = load_mission(short_mission(tmp_path / "mission.yaml", duration_s, **plugins))
    return run_fast(mission, seed=1)


def _stops(result) -> list[str]:
    return [e for e in result.events if "PLUGIN_STOPPED" in e]


def test_a_law_steering_at_the_sun_is_stopped_before_the_zone(plugins):
    result = _fly(plugins, guidance="sun-seeker")
    m = result.metrics
    stops = _stops(result)
    assert len(stops) == 1 and "sun-seeker" in stops[0] and "guard limit" in stops[0], result.events
    assert m["plugin_stops"] == 1.0 and m["plugin_guidance_cycles"] > 0
    # it did steer at the Sun: from 66 deg away to inside the guard layer (law.margin_deg = 3 deg) ...
    assert m["margin_sun_deg"] < 3.0
    # ... and the guard's braking and SAFE kept the instrument out of the physical zone, judged on truth
    assert m["instrument_exposure_s"] == 0.0 and m["min_margin_deg"] > 0.0
    assert not any("KEEP_OUT" in e for e in result.events)


def _demo_quaternion(tmp_path, duration_s: float, **plugins):
    data = yaml.safe_load((ROOT / "config" / "missions" / "demo-quaternion.yaml").read_text())
    data["duration_s"] = duration_s
    data["timeline"] = []  # its second target comes later
    data["flight_software"]["plugins"] = plugins
    path = tmp_path / "q.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_the_law_is_given_its_mode_target_zones_and_sky(plugins):
    import numpy as np

    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import load_mission

    for path, mode, n_zones in ((short_mission(plugins / "p.yaml", 12.0, guidance="recorder"), "POINTING", 2),
                                (_demo_quaternion(plugins, 12.0, guidance="recorder"), "QUATERNION", 2)):
        import bad_plugins

        bad_plugins.SEEN.clear()
        mission = load_mission(path)
        run_fast(mission, seed=1)
        seen = bad_plugins.SEEN
        assert len(seen) > 30 and {s.mode for s in seen} == {mode}
        last = seen[-1]
        assert len(last.zones) == n_zones and all(hasattr(z, "signed_separation") for z in last.zones)
        assert np.isfinite(last.sun_N).all() and np.isfinite(last.moon_N).all()
        assert abs(np.linalg.norm(last.q_NB) - 1.0) < 1e-9 and last.max_rate_rad_s > 0.0
        if mode == "POINTING":
            assert np.isfinite(last.target_N).all() and np.isnan(last.q_target_NB).all()
        else:
            assert np.allclose(last.q_target_NB, mission.flight_software.quaternion.target_q_NB, atol=1e-6)
            assert np.isnan(last.target_N).all()


def test_a_law_stopped_in_quaternion_mode_hands_over_to_keepouts_law(plugins):
    """demo-quaternion's first slew runs straight at its radiator-Sun zone along the geodesic."""
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import load_mission

    result = run_fast(load_mission(_demo_quaternion(plugins, 80.0, guidance="geodesic")), seed=1)
    stops = _stops(result)
    assert len(stops) == 1 and "guard limit" in stops[0], result.events
    m = result.metrics
    assert m["margin_radiator-sun_deg"] < 2.0  # the plug-in took the attitude into the guard layer ...
    assert m["min_margin_deg"] > 0.0  # ... and keepout's law, taking over, kept it out of the zone
    assert not any("SAFE" in e for e in result.events)


@pytest.mark.parametrize("law, reason", [("fails-later", "RuntimeError: law diverged"),
                                         ("not-a-number", "is not three finite numbers")])
def test_a_failing_law_is_stopped_and_keepout_takes_over(plugins, law, reason):
    result = _fly(plugins, duration_s=40.0, guidance=law)
    stops = _stops(result)
    assert len(stops) == 1 and reason in stops[0], result.events
    assert result.metrics["plugin_stops"] == 1.0
    assert result.metrics["instrument_exposure_s"] == 0.0


def test_a_wrong_estimate_is_caught_by_keepouts_mekf(plugins):
    result = _fly(plugins, guidance="geodesic", estimator="tilted")
    stops = _stops(result)
    assert len(stops) == 1 and "ESTIMATOR" in stops[0] and "from keepout's MEKF" in stops[0], result.events
    m = result.metrics
    assert m["plugin_estimator_cycles"] < 5  # stopped at its first fix beside the MEKF's
    # flown on keepout's MEKF from then on, the plug-in law still reaches its target
    assert m["plugin_stops"] == 1.0 and m["final_error_deg"] < 0.05 and m["instrument_exposure_s"] == 0.0


def test_an_unknown_plugin_name_is_refused_at_load_time(plugins):
    mission = short_mission(plugins / "typo.yaml", 30.0, guidance="geodesc")
    from hil_sim.mission.model import load_mission
    from hil_sim.mission.loader import ConfigError

    with pytest.raises(ConfigError) as err:
        load_mission(mission)
    text = str(err.value)
    assert "typo.yaml" in text and "flight_software.plugins.guidance" in text
    assert "keepout.guidance" in text and "installed: fails-later, geodesic, not-a-number, recorder, sun-seeker" in text
    # the flight software alone (`keepout fsw MISSION`) refuses it the same way, with the configuration error's
    # exit code
    proc = subprocess.run([sys.executable, "-m", "cli", "fsw", str(mission)], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "typo.yaml" in proc.stderr and "flight_software.plugins.guidance" in proc.stderr
    assert "geodesic" in proc.stderr and "sun-seeker" in proc.stderr


def test_without_plugins_the_cycle_is_keepouts_own(plugins):
    sys.path.insert(0, str(ROOT / "tests" / "fsw"))
    from closed_loop_kit import RecordingDriver

    from fsw.assembly import build_flight_software
    from fsw.config import FswConfig
    from fsw.estimation import AttitudeEstimator
    from fsw.guidance import Guidance

    cfg = FswConfig()
    fsw = build_flight_software(cfg, driver=RecordingDriver(len(cfg.spacecraft.wheels)))
    try:
        assert type(fsw.guidance) is Guidance and type(fsw.estimator) is AttitudeEstimator and not fsw.plugins
    finally:
        fsw.shutdown()
    cfg = FswConfig.model_validate({"plugins": {"guidance": "geodesic", "estimator": "star-gyro"}})
    fsw = build_flight_software(cfg, driver=RecordingDriver(len(cfg.spacecraft.wheels)))
    try:
        assert type(fsw.guidance) is not Guidance and type(fsw.estimator) is not AttitudeEstimator
        assert [name for name, _ in fsw.telemetry.events][-2:] == ["PLUGIN_STARTED", "PLUGIN_STARTED"]
    finally:
        fsw.shutdown()
