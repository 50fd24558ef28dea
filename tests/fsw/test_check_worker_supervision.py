"""The assumption-check worker is no single point of failure: SIGKILL of the worker used to kill the flight
software at its next check ("fatal: BrokenPipeError"). Now its death is reported, a new worker is started
(at most MAX_RESTARTS times), then the background check is dropped, and the GNC cycle goes on throughout."""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from fsw.assumption_check import MAX_RESTARTS, AssumptionChecker
from gnc.zones import ConicZone

SNAPSHOT = (np.array([1.0, 0.0, 0.0]), [ConicZone(np.array([0.0, 1.0, 0.0]), math.radians(20.0))], 0.01, 1.0, "star")


def _result(checker: AssumptionChecker, timeout_s: float = 60.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        res = checker.poll()
        if res is not None:
            return res
        time.sleep(0.01)
    raise AssertionError("no check result")


def _kill_worker(checker: AssumptionChecker) -> None:
    pid = checker.worker.pid
    os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + 10.0  # dead, not reaped: the checker must find out by itself
    while psutil.Process(pid).status() != psutil.STATUS_ZOMBIE and time.monotonic() < deadline:
        time.sleep(0.01)


@pytest.fixture
def supervised():
    """A process-mode checker and the list its worker-lost callback fills: (reason, restarts, dropped)."""
    lost: list = []
    checker = AssumptionChecker("process", on_worker_lost=lambda *a: lost.append(a))
    yield checker, lost
    checker.close()


def test_a_killed_idle_worker_is_reported_and_replaced(supervised) -> None:
    checker, lost = supervised
    checker.start()
    first = checker.worker.pid
    _kill_worker(checker)
    assert checker.submit(SNAPSHOT)  # used to raise BrokenPipeError; now sent to a new worker
    assert lost == [("exit code -9", 1, False)]
    assert checker.worker.pid != first
    assert _result(checker).ok


def test_a_worker_killed_during_a_check_gives_a_failed_check_and_a_new_worker(supervised) -> None:
    checker, lost = supervised
    assert checker.submit(SNAPSHOT)
    _kill_worker(checker)
    res = _result(checker)
    assert res.errors and res.errors[0].startswith("check failed: worker ended")
    assert [a[1:] for a in lost] == [(1, False)]
    assert checker.submit(SNAPSHOT)
    assert _result(checker).ok


def test_after_max_restarts_the_check_is_dropped_not_the_flight_software(supervised) -> None:
    checker, lost = supervised
    assert checker.submit(SNAPSHOT)
    for death in range(1, MAX_RESTARTS + 2):
        _kill_worker(checker)
        assert _result(checker).errors[0].startswith("check failed: worker ended")
        assert lost[-1][1] == death
        if death <= MAX_RESTARTS:
            assert checker.submit(SNAPSHOT)  # on a new worker
    assert lost[-1][1:] == (MAX_RESTARTS + 1, True)
    assert checker.mode == "off" and checker.worker is None
    assert not checker.submit(SNAPSHOT)  # no more workers: the per-cycle eps bound still guards


@pytest.mark.slow
def test_sigkill_of_the_worker_in_a_live_run_is_an_event_and_the_run_passes(tmp_path: Path) -> None:
    root = Path(__file__).resolve().parents[2]
    cmd = [sys.executable, "-m", "cli", "sil", "run", str(root / "config/missions/demo-pointing.yaml"),
           "--bus", "udp_multicast", "--realtime", "--duration", "25", "--out", str(tmp_path), "--no-progress"]
    proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    killed = None
    try:
        deadline = time.monotonic() + 60.0
        while killed is None and time.monotonic() < deadline and proc.poll() is None:
            for ep in tmp_path.glob("*/endpoints.json"):
                try:
                    fsw_pid = json.loads(ep.read_text())["pids"]["fsw"]
                    workers = [c for c in psutil.Process(fsw_pid).children()
                               if "fsw.assumption_check" in " ".join(c.cmdline())]
                except (ValueError, KeyError, psutil.Error):
                    workers = []
                if workers:
                    time.sleep(2.0)  # flying
                    workers[0].kill()
                    killed = workers[0].pid
            time.sleep(0.05)
        output, _ = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert killed is not None, "no check worker found"
    run_dir = next(tmp_path.glob("demo-pointing-*"))
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed", output[-2000:]
    events = [json.loads(line) for line in (run_dir / "ground" / "events.jsonl").read_text().splitlines()]
    assert any(e.get("event") == "CHECK_WORKER_LOST" for e in events), output[-2000:]
    assert not any(e.get("event") == "FATAL_ERROR" for e in events)
