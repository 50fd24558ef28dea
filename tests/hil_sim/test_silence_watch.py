"""When a SIL run takes its flight software for hung: ticks in a row with nothing heard from it."""
from __future__ import annotations

from hil_sim.sil.orchestrator import SilenceWatch


def test_in_real_time_late_answers_keep_the_run_going_silence_ends_it() -> None:
    watch = SilenceWatch(realtime=True)
    # three CYCLE_DONEs in a row that came after the next tick began: slips, not silence
    assert [watch.after_tick(False, True) for _ in range(3)] == [0, 0, 0]
    assert [watch.after_tick(False, False) for _ in range(3)] == [1, 2, 3]
    assert watch.after_tick(True, True) == 0


def test_in_lockstep_only_the_awaited_answer_counts() -> None:
    watch = SilenceWatch(realtime=False)
    # a CYCLE_DONE for another tick (stale, replayed) is not the tick's answer
    assert [watch.after_tick(False, True) for _ in range(3)] == [1, 2, 3]
    assert watch.after_tick(True, True) == 0
