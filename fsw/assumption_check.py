"""The paper's full assumption check (gnc.checks), run away from the GNC cycle.

The check can take seconds (Assumption 2 is a numerical search), so in flight it runs in a worker
process. The flight process itself runs no other Python thread: a helper thread (such as the feeder
and manager threads of concurrent.futures.ProcessPoolExecutor) holds the GIL while it pickles, and when
the host preempts it there the real-time cycle thread waits for the GIL. The 24 h soak measured that as
cycle slips of 0.1-0.2 s. Here the cycle thread pickles the snapshot itself (0.2 ms for three zones)
and writes it to a pipe enlarged so that the write never blocks; the result is read with a
non-blocking poll.
"""
from __future__ import annotations

import math
import pickle
from dataclasses import dataclass

_PIPE_BYTES = 1 << 20  # Linux's default pipe-max-size; a snapshot of six zones is ~0.2 MB


@dataclass
class CheckResult:
    ok: bool
    errors: list[str]
    eps_max: float
    kappa_bar: float | None
    duration_s: float


def run_full_check(target, zones, eps, kappa, law) -> CheckResult:
    """gnc.checks.check_assumptions as a plain function of a snapshot."""
    import time as _time

    from gnc.checks import check_assumptions

    t0 = _time.perf_counter()
    rep = check_assumptions(target, zones, eps, kappa=kappa, law=law)
    eps_max = float(rep.eps_max) if rep.eps_max is not None and math.isfinite(rep.eps_max) else float("inf")
    return CheckResult(bool(rep.ok), [str(e) for e in rep.errors], eps_max, rep.kappa_bar, _time.perf_counter() - t0)


def _failed(reason: str) -> CheckResult:
    return CheckResult(False, [f"check failed: {reason}"[:200]], float("inf"), None, float("nan"))


def _background_priority(parent_pid: int) -> None:
    """In the worker: lowest CPU priority, so the check never preempts the GNC cycle; Ctrl-C on the
    terminal's process group is for the flight software to handle (it stops the worker in `close`);
    killed with the flight software (even by SIGKILL, which runs no `close`)."""
    import os
    import signal

    from fsw.lifetime import die_with_parent

    die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # a forked worker inherits the flight software's SIGTERM handler (stop the executive): `close` must
    # be able to end it
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        # a worker forked from a SCHED_FIFO cycle thread would inherit its policy and preempt it
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass
    try:
        os.nice(19)
    except OSError:
        pass


def _worker(requests, results, parent_pid: int, parent_ends=()) -> None:
    _background_priority(parent_pid)
    for conn in parent_ends:  # forked copies of the parent's ends: without closing them, no EOF ever comes
        conn.close()
    while True:
        try:
            snapshot = pickle.loads(requests.recv_bytes())
        except EOFError:
            return
        try:
            result = run_full_check(*snapshot)
        except Exception as exc:  # noqa: BLE001 - a failing check is reported, never fatal
            result = _failed(f"{type(exc).__name__}: {exc}")
        results.send(result)


class AssumptionChecker:
    """Runs the full assumption check away from the GNC cycle.

    mode 'process': one worker process (fork); `submit` hands it a snapshot, `poll` returns the result
    once finished (never blocks). mode 'inline': `submit` runs it at once (deterministic, tests).
    mode 'off': never checks. At most one check is in flight.
    """

    def __init__(self, mode: str = "process"):
        self.mode = mode
        self.worker = None
        self._requests = None
        self._results = None
        self._capacity = 0
        self._in_flight = False
        self._ready: CheckResult | None = None
        self.submitted = 0
        self.completed = 0
        self.failures = 0
        self.last_duration_s = float("nan")

    @property
    def busy(self) -> bool:
        return self._in_flight

    def start(self) -> None:
        """Start the worker process now (forking later, mid-mission, would delay a cycle)."""
        if self.mode != "process" or self.worker is not None:
            return
        import fcntl
        import multiprocessing
        import os

        ctx = multiprocessing.get_context("fork")
        req_r, req_w = ctx.Pipe(duplex=False)
        res_r, res_w = ctx.Pipe(duplex=False)
        try:
            self._capacity = fcntl.fcntl(req_w.fileno(), fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
        except OSError:
            self._capacity = fcntl.fcntl(req_w.fileno(), fcntl.F_GETPIPE_SZ)
        self.worker = ctx.Process(target=_worker, args=(req_r, res_w, os.getpid(), (req_w, res_r)), name="keepout-assumption-check", daemon=True)
        self.worker.start()
        req_r.close()
        res_w.close()
        self._requests, self._results = req_w, res_r

    def submit(self, snapshot) -> bool:
        if self.mode == "off" or snapshot is None or self.busy:
            return False
        self.submitted += 1
        if self.mode == "inline":
            self._ready = run_full_check(*snapshot)
            return True
        self.start()
        payload = pickle.dumps(snapshot, protocol=pickle.HIGHEST_PROTOCOL)
        if len(payload) + 8 > self._capacity:  # the write would wait for the worker: never in a cycle
            self._ready = _failed(f"snapshot of {len(payload)} bytes exceeds the {self._capacity}-byte pipe")
            return True
        self._requests.send_bytes(payload)
        self._in_flight = True
        return True

    def poll(self) -> CheckResult | None:
        res = None
        if self._ready is not None:
            res, self._ready = self._ready, None
        elif self._in_flight and self._results.poll():
            self._in_flight = False
            try:
                res = self._results.recv()
            except (EOFError, OSError) as exc:  # the worker died: report it, start a new one next time
                self.close()
                res = _failed(f"worker ended: {type(exc).__name__}")
        if res is None:
            return None
        if res.errors and res.errors[0].startswith("check failed:"):
            self.failures += 1
        else:
            self.completed += 1
        self.last_duration_s = res.duration_s
        return res

    def close(self) -> None:
        """Stop the worker at once: a check in progress can take seconds, and the flight software must
        neither wait for it nor leave it running after it exits."""
        if self.worker is not None:
            self.worker.terminate()
            self.worker.join(timeout=2.0)
            if self.worker.is_alive():
                self.worker.kill()
                self.worker.join(timeout=2.0)
            for conn in (self._requests, self._results):
                conn.close()
            self.worker = self._requests = self._results = None
        self._in_flight = False
