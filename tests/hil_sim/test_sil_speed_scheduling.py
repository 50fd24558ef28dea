"""The SIL orchestrator's scheduling of the flight-software process in lockstep (bench/sil.py speed)."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from hil_sim.sil.orchestrator import _no_wakeup_preemption


@pytest.mark.skipif(not hasattr(os, "SCHED_BATCH"), reason="no SCHED_BATCH on this platform")
def test_lockstep_flight_software_runs_without_wakeup_preemption() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert os.sched_getscheduler(proc.pid) == os.SCHED_OTHER
        assert _no_wakeup_preemption(proc.pid)
        assert os.sched_getscheduler(proc.pid) == os.SCHED_BATCH
    finally:
        proc.kill()
        proc.wait()
    assert not _no_wakeup_preemption(proc.pid)  # gone: reported, not raised
