"""The paper's full assumption check (gnc.checks), run away from the GNC cycle.

The check can take seconds (Assumption 2 is a numerical search), so in flight it runs in a worker
process. The flight process itself runs no other Python thread: a helper thread (such as the feeder
and manager threads of concurrent.futures.ProcessPoolExecutor) holds the GIL while it pickles, and when
the host preempts it there the real-time cycle thread waits for the GIL. The 24 h soak measured that as
cycle slips of 0.1-0.2 s. Here the cycle thread pickles the snapshot itself (0.2 ms for three zones)
and writes it to a pipe enlarged so that the write never blocks; the result is read with a
non-blocking poll.

The worker is a new interpreter (``python -c``, started with the pipes' ends), not a fork of the flight
process: after a fork every page the flight process writes first (an object's reference count is enough)
is copied on a page fault. That was ~1,000 faults in a lockstep run, most in its first cycles and in the
first slew's, and in the one-CPU vcan-vm guest, where a fault is a round trip through the host, the first
two cycles took 110-140 ms each (4-12 ms without the fork).
"""
from __future__ import annotations

import fcntl
import math
import os
import pickle
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection

_PIPE_BYTES = 1 << 20  # Linux's default pipe-max-size; a snapshot of six zones is ~0.2 MB
# The worker is no single point of failure: when it dies (killed, out of memory) the flight software says so
# and starts a new one, at most this many times; then it drops the background check and says that too. The
# GNC cycle never waits for the worker: the per-cycle eps bound guards the zones without it.
MAX_RESTARTS = 3


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
    import signal

    from fsw.lifetime import die_with_parent

    die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # `close` ends the worker with it
    try:
        # a worker started from a SCHED_FIFO cycle thread inherits its policy (through exec too) and would
        # preempt it
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass
    try:
        os.nice(19)
    except OSError:
        pass


def serve(requests_fd: int, results_fd: int, parent_pid: int) -> None:
    """The worker process's loop: a snapshot in, a ``CheckResult`` out, until the flight software closes
    its end. The check's modules are loaded at once, at background priority, so the first check does not
    load them while the flight software is cycling."""
    _background_priority(parent_pid)
    import gnc.checks  # noqa: F401

    requests, results = Connection(requests_fd, writable=False), Connection(results_fd, readable=False)
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

    mode 'process': one worker process (a new interpreter); `submit` hands it a snapshot, `poll` returns
    the result once finished (never blocks). mode 'inline': `submit` runs it at once (deterministic, tests).
    mode 'off': never checks. At most one check is in flight.
    """

    def __init__(self, mode: str = "process", on_worker_lost: Callable[[str, int, bool], object] | None = None):
        """``on_worker_lost(reason, restarts, dropped)`` is called when the worker is found dead: ``restarts``
        the deaths so far, ``dropped`` when the check is given up (after MAX_RESTARTS)."""
        self.mode = mode
        self.on_worker_lost = on_worker_lost or (lambda reason, restarts, dropped: None)
        self.restarts = 0
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
        """Start the worker process now (starting it later, mid-mission, would delay a cycle)."""
        if self.mode != "process" or self.worker is not None:
            return
        req_r, req_w = os.pipe()
        res_r, res_w = os.pipe()
        try:
            self._capacity = fcntl.fcntl(req_w, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
        except OSError:
            self._capacity = fcntl.fcntl(req_w, fcntl.F_GETPIPE_SZ)
        code = f"from fsw.assumption_check import serve; serve({req_r}, {res_w}, {os.getpid()})"
        try:
            self.worker = subprocess.Popen([sys.executable, "-c", code], pass_fds=(req_r, res_w),
                                           stdin=subprocess.DEVNULL)
        finally:
            os.close(req_r)
            os.close(res_w)
        self._requests = Connection(req_w, readable=False)
        self._results = Connection(res_r, writable=False)

    def submit(self, snapshot) -> bool:
        if self.mode == "off" or snapshot is None or self.busy:
            return False
        self.submitted += 1
        if self.mode == "inline":
            self._ready = run_full_check(*snapshot)
            return True
        if self.worker is not None and self.worker.poll() is not None:
            self._lost(f"exit code {self.worker.returncode}")
            if self.mode == "off":
                return False
        self.start()
        payload = pickle.dumps(snapshot, protocol=pickle.HIGHEST_PROTOCOL)
        if len(payload) + 8 > self._capacity:  # the write would wait for the worker: never in a cycle
            self._ready = _failed(f"snapshot of {len(payload)} bytes exceeds the {self._capacity}-byte pipe")
            return True
        try:
            self._requests.send_bytes(payload)
        except OSError as exc:  # BrokenPipeError: it died between the check above and the write
            self._lost(type(exc).__name__)
            return False
        self._in_flight = True
        return True

    def _lost(self, reason: str) -> None:
        """The worker is dead: close its ends, count it, and drop the check after MAX_RESTARTS."""
        self.close()
        self.restarts += 1
        dropped = self.restarts > MAX_RESTARTS
        if dropped:
            self.mode = "off"
        self.on_worker_lost(reason, self.restarts, dropped)

    def poll(self) -> CheckResult | None:
        res = None
        if self._ready is not None:
            res, self._ready = self._ready, None
        elif self._in_flight and self._results.poll():
            self._in_flight = False
            try:
                res = self._results.recv()
            except (EOFError, OSError) as exc:  # the worker died: report it, start a new one next time
                self._lost(type(exc).__name__)
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
            try:
                self.worker.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self.worker.kill()
                self.worker.wait(timeout=2.0)
            for conn in (self._requests, self._results):
                try:
                    conn.close()
                except OSError:
                    pass
            self.worker = self._requests = self._results = None
        self._in_flight = False
