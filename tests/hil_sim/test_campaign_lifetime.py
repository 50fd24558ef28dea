"""A campaign's pool processes die with the campaign: SIGKILL of `keepout campaign run` used to leave the
resource tracker, the forkserver and its workers behind, a worker still flying runs 68 s later."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_sigkill_of_the_campaign_driver_leaves_no_process_behind(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "cli", "campaign", "run", "config/campaigns/regression.yaml", "--runs", "40",
           "--workers", "2", "--no-report", "--out", str(tmp_path / "c")]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    driver = psutil.Process(proc.pid)
    try:
        deadline = time.monotonic() + 120.0
        workers: list[psutil.Process] = []
        while time.monotonic() < deadline and proc.poll() is None:
            tree = driver.children(recursive=True)
            workers = [p for p in tree if p.ppid() != proc.pid]  # the forkserver's children: the workers
            if len(workers) >= 2 and (tmp_path / "c").exists():
                break
            time.sleep(0.1)
        assert len(workers) >= 2, "the pool never started its workers"
        tree = driver.children(recursive=True)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        gone, alive = psutil.wait_procs(tree, timeout=15)
        assert not alive, [(p.pid, p.cmdline()[-1][:60]) for p in alive]
    finally:
        if proc.poll() is None:
            proc.kill()
        for p in psutil.Process().children(recursive=True):
            p.kill()
