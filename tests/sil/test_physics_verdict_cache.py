"""The physics checks' verdict cache (`check_mission_cached`, what `keepout sil run` calls): the stored
report is the one the checks give, reused only for the same mission content, sources and libraries."""
from __future__ import annotations

import pytest

from hil_sim.mission import physics_checks as pc
from hil_sim.mission.model import load_mission
from keepout_config import config_path


@pytest.fixture
def counted(monkeypatch, tmp_path):
    """check_mission counting its calls; verdicts in a fresh folder."""
    monkeypatch.setenv(pc.CACHE_ENV, str(tmp_path / "verdicts"))
    calls = []
    real = pc.check_mission

    def check(mission, *args, **kwargs):
        calls.append(mission.name)
        return real(mission, *args, **kwargs)

    monkeypatch.setattr(pc, "check_mission", check)
    return calls


def _mission(**updates):
    mission = load_mission(config_path("missions", "paper-s3-cones.yaml"))
    return mission.model_copy(update=updates) if updates else mission


def test_second_check_of_the_same_mission_reuses_the_verdict(counted):
    fresh = pc.check_mission_cached(_mission())
    again = pc.check_mission_cached(_mission())
    assert len(counted) == 1
    assert again.to_dict() == fresh.to_dict() and again.reused_from and fresh.reused_from is None
    assert [f.loc for f in again.findings] == [f.loc for f in fresh.findings]
    assert again.format().startswith(fresh.format()) and "earlier check" in again.format()


def test_another_mission_content_or_source_checks_again(counted, monkeypatch):
    pc.check_mission_cached(_mission())
    pc.check_mission_cached(_mission(duration_s=_mission().duration_s / 2))
    assert len(counted) == 2
    import gnc._numba_cache as nc
    real = nc.source_digest
    monkeypatch.setattr(nc, "source_digest", lambda path: real(path)[::-1])  # any edit of the checks' code
    pc.check_mission_cached(_mission())
    assert len(counted) == 3


def test_a_failing_verdict_is_kept_as_failing(counted):
    mission = _mission()
    fsw = mission.flight_software  # a slew acceleration the wheels cannot give
    bad = mission.model_copy(update={"flight_software": fsw.model_copy(
        update={"control": fsw.control.model_copy(update={"max_command_accel_deg_s2": 100.0})})})
    first = pc.check_mission_cached(bad)
    second = pc.check_mission_cached(bad)
    assert len(counted) == 1 and not first.ok and not second.ok
    assert [str(f) for f in second.errors] == [str(f) for f in first.errors]


def test_corrupt_cache_or_off_runs_the_checks(counted, monkeypatch, tmp_path):
    pc.check_mission_cached(_mission())
    for path in (tmp_path / "verdicts").iterdir():
        path.write_text("{not json")
    assert pc.check_mission_cached(_mission()).reused_from is None and len(counted) == 2
    monkeypatch.setenv(pc.CACHE_ENV, "off")
    pc.check_mission_cached(_mission())
    pc.check_mission_cached(_mission())
    assert len(counted) == 4


def test_only_the_newest_verdicts_are_kept(counted, monkeypatch, tmp_path):
    import os

    monkeypatch.setattr(pc, "CACHE_MAX_VERDICTS", 2)
    base = _mission().duration_s
    for k, fraction in enumerate((0.5, 0.25, 0.125)):
        pc.check_mission_cached(_mission(duration_s=base * fraction))
        for path in (tmp_path / "verdicts").iterdir():  # distinct times whatever the file system's resolution
            if path.name == f"{pc.verdict_key(_mission(duration_s=base * fraction))}.json":
                os.utime(path, (1e9 + k, 1e9 + k))
    kept = {p.name for p in (tmp_path / "verdicts").iterdir()}
    assert kept == {f"{pc.verdict_key(_mission(duration_s=base * f))}.json" for f in (0.25, 0.125)}


def test_the_warm_up_checks_again_even_with_a_kept_verdict(counted):
    """The warm-up (`refresh=True`) must run the checks, so their kernels compile into the cache a wheel
    ships; a kept verdict would skip them. The stored verdict is the fresh one."""
    pc.check_mission_cached(_mission())
    fresh = pc.check_mission_cached(_mission(), refresh=True)
    assert len(counted) == 2 and fresh.reused_from is None
    assert pc.check_mission_cached(_mission()).to_dict() == fresh.to_dict() and len(counted) == 2
