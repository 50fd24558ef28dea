"""The fixed-rate executive: rate groups driven by one tick source.

Rate groups: GNC at ``rates.gnc_rate_hz`` (every tick) and housekeeping every
``gnc_rate_hz / housekeeping_rate_hz`` ticks, run after the GNC group in the same tick.

Tick sources:

* lockstep (``run_lockstep``): one tick per simulator SYNC frame (`FswBusDriver.collect_tick`). Time is the
  simulation time of the tick, so runs are deterministic at any host speed. A cycle *slips* when the work
  of its tick takes longer than the period (it would have overrun on the real spacecraft) or when ticks
  were skipped (SYNC k+2 after k): each skipped tick counts as a slip.
* real time (``run_realtime``): cycles scheduled on the monotonic clock at t0 + k P
  (`FswBusDriver.collect_latest`). Start jitter (actual - scheduled start) is measured. A cycle slips when
  it ends after the next scheduled start; missed start times are skipped and each counts as a slip.

Slips are counted per rate group, reported in housekeeping (slips_gnc, slips_hk) and as a CYCLE_SLIP
warning event throttled to one per ``slip_event_throttle_s`` per group (the count in the event is the
running total, so nothing is lost). Execution time max and mean per group are kept.
"""
from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class RateGroupStats:
    name: str
    cycles: int = 0
    exec_total_s: float = 0.0
    exec_max_s: float = 0.0
    slips: int = 0
    last_exec_s: float = 0.0
    last_slip_event_t: float = -math.inf

    def record(self, exec_s: float) -> None:
        self.cycles += 1
        self.exec_total_s += exec_s
        self.last_exec_s = exec_s
        if exec_s > self.exec_max_s:
            self.exec_max_s = exec_s

    @property
    def exec_mean_ms(self) -> float:
        return 1e3 * self.exec_total_s / self.cycles if self.cycles else 0.0

    @property
    def exec_max_ms(self) -> float:
        return 1e3 * self.exec_max_s

    def reset(self) -> None:
        self.cycles = 0
        self.exec_total_s = 0.0
        self.exec_max_s = 0.0
        self.slips = 0


@dataclass
class JitterStats:
    """Real-time start jitter [s]: running max and a bounded recent window for percentiles."""

    max_s: float = 0.0
    recent: collections.deque = field(default_factory=lambda: collections.deque(maxlen=100_000))

    def record(self, jitter_s: float) -> None:
        self.recent.append(jitter_s)
        if jitter_s > self.max_s:
            self.max_s = jitter_s

    def reset(self) -> None:
        self.max_s = 0.0
        self.recent.clear()


class Executive:
    """Runs ``gnc_task(inputs, slipped_before)`` every tick and ``hk_task()`` every ``hk_divider`` ticks.

    ``on_slip(group, exec_ms, total, late_ms)`` is called (throttled) to emit the warning event: how long the
    cycle ran and, in real time, how late it started (a cycle that starts late on a loaded host slips
    however short it runs; in lockstep the start is the SYNC's, so late_ms is 0).
    """

    STOP_POLL_S = 0.2  # longest a stop request waits for a blocking lockstep receive [s]; a wake-up this often costs nothing

    def __init__(self, gnc_rate_hz: float, hk_rate_hz: float, slip_event_throttle_s: float,
                 gnc_task: Callable[..., object], hk_task: Callable[[], object],
                 on_slip: Callable[[str, float, int, float], object] | None = None,
                 clock: Callable[[], float] = time.perf_counter):
        self.period_s = 1.0 / gnc_rate_hz
        self.hk_divider = max(1, round(gnc_rate_hz / hk_rate_hz))
        self.throttle_s = slip_event_throttle_s
        self.gnc_task = gnc_task
        self.hk_task = hk_task
        self.on_slip = on_slip or (lambda group, exec_ms, total, late_ms: None)
        self.start_late_s = 0.0  # real time: how late the current cycle started
        self.clock = clock
        self.gnc = RateGroupStats("GNC")
        self.hk = RateGroupStats("HK")
        self.jitter = JitterStats()
        self.ticks = 0
        self.last_tick: int | None = None
        self.slipped_last = False  # the previous GNC cycle slipped (FDIR input)
        self.stop_requested = False
        self.timeouts = 0
        self.tick_start = 0.0  # self.clock() as the current tick began (the GNC task times itself from it)

    def reset_counters(self) -> None:
        self.gnc.reset()
        self.hk.reset()
        self.jitter.reset()

    def _slip(self, group: RateGroupStats, exec_s: float, count: int = 1) -> None:
        group.slips += count
        now = self.clock()
        if now - group.last_slip_event_t >= self.throttle_s:
            group.last_slip_event_t = now
            self.on_slip(group.name, 1e3 * exec_s, group.slips, 1e3 * self.start_late_s)

    def run_tick(self, inputs, tick: int, budget_s: float) -> float:
        """GNC (and HK when due) for one tick; returns the end time on self.clock."""
        t0 = self.tick_start = self.clock()  # one clock read (a system call in the vcan-vm guest) for both
        self.gnc_task(inputs, self.slipped_last)
        t1 = self.clock()
        self.gnc.record(t1 - t0)
        end = t1
        if tick % self.hk_divider == 0:
            self.hk_task()
            end = self.clock()
            self.hk.record(end - t1)
        self.ticks += 1
        total = end - t0
        self.slipped_last = total > budget_s
        if self.slipped_last:
            self._slip(self.gnc, total)
        return end

    # ----------------------------------------------------------------------------------- lockstep
    def run_lockstep(self, collect: Callable[[float], object], timeout_s: float, max_ticks: int | None = None,
                     on_timeout: Callable[[], bool] | None = None) -> int:
        """Loop on SYNC ticks until ``max_ticks``, ``stop()``, or a timeout that ``on_timeout`` does not
        excuse (returns True to keep waiting). Returns the number of ticks run."""
        n = 0
        self.stop_requested = False
        # Wait in slices so that stop() (SIGINT/SIGTERM) ends the loop within a slice even when the
        # timeout is long (the SIL allows a minute for the simulator's first SYNC): an orderly stop is what
        # sends FSW_STOPPED and ends the background check worker.
        slice_s = min(timeout_s, self.STOP_POLL_S) if timeout_s > 0.0 else 0.0
        waited = 0.0
        while not self.stop_requested and (max_ticks is None or n < max_ticks):
            inputs = collect(slice_s)
            if inputs is None:
                waited += slice_s
                if self.stop_requested:
                    break
                if waited < timeout_s:
                    continue
                waited = 0.0
                self.timeouts += 1
                if on_timeout is not None and on_timeout():
                    continue
                break
            waited = 0.0
            tick = int(inputs.tick)
            if self.last_tick is not None and tick > self.last_tick + 1:
                self._slip(self.gnc, 0.0, tick - self.last_tick - 1)
            self.last_tick = tick
            self.run_tick(inputs, tick, self.period_s)
            n += 1
        return n

    # ---------------------------------------------------------------------------------- real time
    def run_realtime(self, collect: Callable[[], object], duration_s: float | None = None,
                     sleep: Callable[[float], object] = time.sleep, spin_s: float = 0.002) -> int:
        """Cycles at t0 + k P on the monotonic clock for ``duration_s`` (None: until stop()).

        Sleeps until ``spin_s`` before each start then spins, so the start jitter stays well below the
        OS sleep granularity.
        """
        P = self.period_s
        # the first cycle at once: a simulator already sending SYNC (the SIL starts it when the flight
        # software has started) has its tick 0 answered, not left to look late
        t0 = self.clock()
        k = 0
        n = 0
        self.stop_requested = False
        while not self.stop_requested:
            start_sched = t0 + k * P
            if duration_s is not None and start_sched - t0 >= duration_s:
                break
            while True:
                now = self.clock()
                remaining = start_sched - now
                if remaining <= 0:
                    break
                if remaining > spin_s:
                    sleep(remaining - spin_s)
            self.jitter.record(now - start_sched)
            self.start_late_s = now - start_sched
            inputs = collect()
            end = self.run_tick(inputs, k, P - (now - start_sched))
            n += 1
            # Skip start times already in the past: each one is a slipped cycle.
            k_next = k + 1
            if end > t0 + k_next * P:
                missed = int((end - (t0 + k_next * P)) // P) + 1
                if not self.slipped_last:
                    self._slip(self.gnc, end - now)
                    self.slipped_last = True
                if missed > 1:
                    self._slip(self.gnc, end - now, missed - 1)
                k_next += missed
            k = k_next
        return n

    def stop(self) -> None:
        self.stop_requested = True
