"""Real time on a shared host: the SIL asks for SCHED_FIFO for its tick loop and the flight software (where
the mission leaves the flight software's own priority at 0), and a run that failed on cycle slips says
what to do."""
from __future__ import annotations

from cli.sil import slip_hint
from hil_sim.mission import load_mission
from hil_sim.sil import DEFAULT_MISSION, DEFAULT_RT_PRIORITY, _config_used


def _used(mission, realtime: bool, rt_priority: int = DEFAULT_RT_PRIORITY) -> dict:
    return _config_used(mission, bus_spec="udp_multicast", tm_host="127.0.0.1", tm_port=None, tc_port=None,
                        realtime=realtime, rt_priority=rt_priority)


def test_the_flight_software_asks_for_fifo_one_below_the_tick_loop_in_real_time_only() -> None:
    mission = load_mission(DEFAULT_MISSION)
    assert mission.flight_software.rates.realtime_priority == 0
    assert _used(mission, realtime=True)["flight_software"]["rates"]["realtime_priority"] == DEFAULT_RT_PRIORITY - 1
    assert _used(mission, realtime=False)["flight_software"]["rates"]["realtime_priority"] == 0
    assert _used(mission, realtime=True, rt_priority=0)["flight_software"]["rates"]["realtime_priority"] == 0
    own = mission.model_copy(deep=True)
    own.flight_software.rates.realtime_priority = 42  # the mission's own choice stands
    assert _used(own, realtime=True)["flight_software"]["rates"]["realtime_priority"] == 42


def test_a_real_time_run_failed_on_slips_says_what_to_do() -> None:
    failed = {"requirements": [{"name": "cycle slips", "value": 5, "pass": False}]}
    hint = slip_hint(failed, realtime=True, got="SCHED_FIFO 20 refused: [Errno 1] Operation not permitted")
    assert "Operation not permitted" in hint and "--rt-priority" in hint and "lockstep" in hint
    assert slip_hint(failed, realtime=False, got="") == ""
    passed = {"requirements": [{"name": "cycle slips", "value": 0, "pass": True}]}
    assert slip_hint(passed, realtime=True, got="SCHED_FIFO priority 20") == ""
    lost = {"requirements": [{"name": "cycle slips", "value": 0, "pass": True},
                             {"name": "ticks lost on the host", "value": 4, "pass": False}]}
    assert slip_hint(lost, realtime=True, got="SCHED_FIFO priority 20").startswith("ticks lost on the host:")


def test_real_time_judges_the_flight_softwares_slips_strictly_and_lost_ticks_against_the_tolerance() -> None:
    from types import SimpleNamespace

    from hil_sim.summary import HOST_LOST_TICK_FRACTION, _judge_cycle_slips, _Requirements

    def judged(fsw_slips: int, late: int) -> dict[str, dict]:
        reqs = _Requirements()
        _judge_cycle_slips(reqs, {"clock": "realtime", "ticks": 1200, "cycle_done_late": late},
                           {"slips_gnc": fsw_slips}, SimpleNamespace(max_cycle_slips=0))
        return {r["name"]: r for r in reqs.results}

    allowed = int(HOST_LOST_TICK_FRACTION * 1200)
    assert allowed == 2  # one tick in 500
    ok = judged(0, allowed)
    assert ok["cycle slips"]["pass"] and ok["ticks lost on the host"]["pass"]
    assert not judged(0, allowed + 1)["ticks lost on the host"]["pass"]
    assert not judged(1, 0)["cycle slips"]["pass"]  # the flight software's own overrun: no tolerance
