"""Real time on a shared host: the SIL asks for SCHED_FIFO for its tick loop and says what it got, the
flight software's own slips and the ticks lost on the host are judged apart, and a run that failed on
either says what to do."""
from __future__ import annotations

from cli.sil import slip_hint


def test_the_tick_loop_asks_for_fifo_and_says_what_it_got(monkeypatch) -> None:
    import os

    from hil_sim.sil import orchestrator as sil

    asked = []
    monkeypatch.setattr(os, "sched_setscheduler", lambda pid, policy, param: asked.append((policy, param.sched_priority)))
    assert sil._pace_this_thread(20) == "SCHED_FIFO priority 20" and asked == [(os.SCHED_FIFO, 20)]

    def refuse(pid, policy, param):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    assert sil._pace_this_thread(20) == "SCHED_FIFO 20 refused: [Errno 1] Operation not permitted"
    assert sil._pace_this_thread(0).startswith("normal scheduler")


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

    from hil_sim.sil.judge import HOST_LOST_TICK_FRACTION, _judge_cycle_slips, _Requirements

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
