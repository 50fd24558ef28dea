"""Executive: rate groups, slips (lockstep and real time), throttled slip events, timing statistics."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from fsw.executive import Executive


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt


def _executive(clock, exec_times, hk_log, slip_log, throttle_s=10.0, late_log=None):
    it = iter(exec_times)

    def gnc(inputs, slipped_before):
        clock.t += next(it)

    def hk():
        hk_log.append(clock.t)
        clock.t += 0.002

    def on_slip(g, ms, n, late_ms):
        slip_log.append((g, round(ms, 3), n))
        if late_log is not None:
            late_log.append(late_ms)

    return Executive(10.0, 1.0, throttle_s, gnc, hk, on_slip, clock=clock)


def test_lockstep_counts_overruns_and_skipped_ticks_and_runs_housekeeping_every_tenth_tick() -> None:
    clock = FakeClock()
    hk, slips = [], []
    times = [0.001] * 30
    times[5] = 0.150  # one cycle longer than the 100 ms period
    ex = _executive(clock, times, hk, slips)
    ticks = list(range(0, 20)) + list(range(23, 33))  # SYNC 20..22 never arrived
    feed = iter(ticks)

    def collect(timeout):
        k = next(feed, None)
        return None if k is None else SimpleNamespace(tick=k)

    n = ex.run_lockstep(collect, timeout_s=0.1)
    assert n == 30
    assert ex.gnc.slips == 1 + 3
    assert len(hk) == 3  # ticks 0, 10 and 30 (20 was skipped)
    assert ex.gnc.cycles == 30 and ex.hk.cycles == 3
    assert ex.gnc.exec_max_ms == pytest.approx(150.0)
    assert ex.gnc.exec_mean_ms == pytest.approx((29 * 1.0 + 150.0) / 30)
    # first slip reported at once; the second within the throttle window is counted, not reported
    assert slips == [("GNC", pytest.approx(150.0, abs=0.01), 1)]


def test_slip_events_are_throttled_but_the_count_is_complete() -> None:
    clock = FakeClock()
    hk, slips = [], []
    ex = _executive(clock, [0.2] * 100, hk, slips, throttle_s=5.0)
    feed = iter(range(100))
    ex.run_lockstep(lambda t: SimpleNamespace(tick=next(feed, None)) if True else None, timeout_s=0.1, max_ticks=100)
    assert ex.gnc.slips == 100
    # 100 cycles x 0.2 s (+hk) = ~20 s of clock: one event per 5 s window
    assert 4 <= len(slips) <= 5
    assert slips[-1][2] > slips[0][2]  # running totals in the events


def test_realtime_schedule_jitter_and_missed_starts() -> None:
    clock = FakeClock()
    hk, slips = [], []
    times = [0.001] * 40
    times[12] = 0.25  # ends 2.5 periods late: starts 13 and 14 are skipped
    ex = _executive(clock, times, hk, slips)
    n = ex.run_realtime(lambda: SimpleNamespace(), duration_s=3.0, sleep=clock.sleep, spin_s=0.0)
    assert ex.gnc.slips == 2  # starts 13 and 14 came before cycle 12 ended: two slips
    assert n == 30 - 2
    assert max(ex.jitter.recent) < 1e-9  # the fake clock is exact: every start on schedule
    assert slips and slips[0][0] == "GNC"


def test_a_realtime_slip_says_how_late_the_cycle_started() -> None:
    """On a loaded host the process wakes late: the cycle starts 150 ms after its time and slips however
    short it runs. The event used to say only "exec 0.60 ms", which reads as a fast cycle."""
    clock = FakeClock()
    hk, slips, late = [], [], []
    woken = iter([0.0] * 5 + [0.15] + [0.0] * 100)

    def oversleep(dt: float) -> None:
        clock.t += dt + next(woken)

    ex = _executive(clock, [0.0006] * 40, hk, slips, late_log=late)
    ex.run_realtime(lambda: SimpleNamespace(), duration_s=2.0, sleep=oversleep, spin_s=0.0)
    assert slips and slips[0][1] < 1.0  # it ran 0.6 ms ...
    assert late[0] == pytest.approx(150.0, abs=1.0)  # ... but started 150 ms late
    assert ex.gnc.slips >= 1


def test_realtime_first_cycle_starts_at_once_then_every_period() -> None:
    """A simulator started with the flight software is already sending SYNC: the first cycle must not wait
    a period (it would leave tick 0 unanswered, a late cycle in every real-time run)."""
    clock = FakeClock()
    starts: list[float] = []

    def collect():
        starts.append(clock.t)
        return SimpleNamespace()

    ex = _executive(clock, [0.001] * 10, [], [])
    n = ex.run_realtime(collect, duration_s=0.5, sleep=clock.sleep, spin_s=0.0)
    assert n == 5
    assert starts[0] == pytest.approx(100.0, abs=1e-12)
    assert starts == pytest.approx([100.0 + 0.1 * k for k in range(5)], abs=1e-9)


def test_reset_counters() -> None:
    clock = FakeClock()
    ex = _executive(clock, [0.2], [], [])
    ex.run_lockstep(lambda t: SimpleNamespace(tick=0), 0.1, max_ticks=1)
    assert ex.gnc.slips == 1
    ex.reset_counters()
    assert ex.gnc.slips == 0 and ex.gnc.exec_max_ms == 0.0 and ex.gnc.cycles == 0


def test_stop_ends_a_long_lockstep_wait_within_a_poll_slice() -> None:
    """SIGINT while waiting for SYNC with a one-minute timeout: the loop ends within STOP_POLL_S, so the
    flight software can still shut down in order (FSW_STOPPED, background worker ended)."""
    import threading
    import time as _time

    from fsw.executive import Executive

    calls = []

    def collect(timeout_s: float):
        calls.append(timeout_s)
        _time.sleep(timeout_s)
        return None

    ex = Executive(10.0, 1.0, 10.0, gnc_task=lambda *a: None, hk_task=lambda: None)
    threading.Timer(0.3, ex.stop).start()
    t0 = _time.monotonic()
    ticks = ex.run_lockstep(collect, timeout_s=60.0)
    assert ticks == 0
    assert _time.monotonic() - t0 < 0.3 + ex.STOP_POLL_S + 0.5
    assert ex.timeouts == 0  # a stop is not a simulator timeout
    assert all(t <= ex.STOP_POLL_S for t in calls)


def test_a_real_lockstep_timeout_is_still_counted_after_the_slices_add_up() -> None:
    from fsw.executive import Executive

    ex = Executive(10.0, 1.0, 10.0, gnc_task=lambda *a: None, hk_task=lambda: None)
    ex.STOP_POLL_S = 0.01
    assert ex.run_lockstep(lambda t: None, timeout_s=0.05) == 0
    assert ex.timeouts == 1
