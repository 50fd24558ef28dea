"""Every end recorded: SIGKILL of `keepout sil run` left summary.json and endpoints.json saying "running" for
ever. Now the next keepout command that reads the folder (`keepout sil run` in the same runs folder,
`keepout ground --run`) marks it "crashed: orchestrator killed"; a live run's folder is left alone."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from ground.link import ORCHESTRATOR_KILLED, Endpoints, find_run, settle_orphaned_run

ROOT = Path(__file__).resolve().parents[2]


def _start(out: Path, realtime: bool = True) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "cli", "sil", "run", str(ROOT / "config/missions/demo-pointing.yaml"),
           "--bus", "udp_multicast", "--duration", "60", "--out", str(out), "--no-progress"]
    if realtime:
        cmd.append("--realtime")
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def _wait_running(out: Path, timeout_s: float = 60.0) -> Path:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for ep in out.glob("*/endpoints.json"):
            try:
                data = json.loads(ep.read_text())
            except ValueError:
                continue
            if data.get("state") == "running" and "fsw" in data.get("pids", {}):
                return ep.parent
        time.sleep(0.05)
    raise AssertionError("the run never started")


def test_a_killed_orchestrator_s_run_is_marked_by_the_next_reader(tmp_path: Path) -> None:
    proc = _start(tmp_path)
    try:
        run_dir = _wait_running(tmp_path)
        assert not settle_orphaned_run(run_dir)  # alive: left alone
        os.killpg(proc.pid, signal.SIGKILL)  # the orchestrator and whatever is in its session
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert json.loads((run_dir / "summary.json").read_text())["status"] == "running"  # what was left
    assert find_run(run_dir) == run_dir  # `keepout ground --run DIR` reads it ...
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == ORCHESTRATOR_KILLED and summary["pass"] is False
    assert Endpoints.load(run_dir).state == "crashed"
    assert not settle_orphaned_run(run_dir)  # once


def test_the_next_sil_run_marks_earlier_orphans_in_its_runs_folder(tmp_path: Path) -> None:
    orphan = tmp_path / "demo-pointing-20260101-000000-000000"
    orphan.mkdir()
    # a folder the orchestrator reserved before it was killed, before writing its endpoints
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (orphan / "summary.json").write_text(json.dumps({"status": "running", "pass": False, "run_dir": str(orphan),
                                                     "orchestrator": {"pid": int(dead.stdout), "started_s": 1.0}}))
    result = subprocess.run([sys.executable, "-m", "cli", "sil", "run", "--bus", "udp_multicast",
                             "--duration", "5", "--out", str(tmp_path), "--no-progress"], cwd=ROOT,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode in (0, 1), result.stdout[-2000:] + result.stderr[-2000:]
    assert json.loads((orphan / "summary.json").read_text())["status"] == ORCHESTRATOR_KILLED


def test_a_full_disk_gives_one_line_and_exit_4(tmp_path: Path) -> None:
    """--out on a 2 MB tmpfs: the run used to print "No space left" lines, then an EOFError traceback loading
    the empty truth.npz, exit 1, and summary.json stayed "running"."""
    import shutil

    import pytest

    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("needs root to mount a 2 MB tmpfs (CI runs as root)")
    disk = tmp_path / "full"
    disk.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)], check=True)
    try:
        result = subprocess.run([sys.executable, "-m", "cli", "sil", "run", "--bus", "udp_multicast",
                                 "--duration", "60", "--out", str(disk), "--no-progress"], cwd=ROOT,
                                capture_output=True, text=True, timeout=600)
        assert result.returncode == 4, result.stdout[-2000:] + result.stderr[-2000:]
        assert "Traceback" not in result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("crashed: ") and "No space left on device" in lines[0]
        summary = json.loads(next(disk.glob("demo-pointing-*/summary.json")).read_text())
        assert summary["status"].startswith("crashed: ") and "No space left on device" in summary["status"]
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)
