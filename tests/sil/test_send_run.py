"""Verified commanding of a live SIL run: `keepout ground send --run RUN_DIR` against the real flight
software process, acknowledgements heard on the run's telemetry, and found again in the run's archive."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
KEEPOUT = [sys.executable, "-m", "cli"]


def _send(run_dir: Path, *words: str) -> subprocess.CompletedProcess:
    return subprocess.run([*KEEPOUT, "ground", "send", "--run", str(run_dir), *words, "--timeout", "10"],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)


def _read(path: Path) -> str:
    try:
        return path.read_text()
    except OSError:
        return ""


def test_send_run_is_acknowledged_by_the_live_flight_software(tmp_path: Path) -> None:
    sil = subprocess.Popen([*KEEPOUT, "sil", "run", "--realtime", "--duration", "120", "--out", str(tmp_path),
                            "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 600.0
        run_dir = None
        while run_dir is None:
            # endpoints.json is there from the start; the flight software says when it takes telecommands
            found = [p.parent for p in tmp_path.glob("*/endpoints.json")
                     if "fsw: ready" in _read(p.parent / "fsw.log")]
            run_dir = found[0] if found else None
            assert sil.poll() is None, sil.stdout.read()
            assert time.monotonic() < deadline, "the SIL's flight software never became ready"
            time.sleep(0.5)

        noop = _send(run_dir, "NOOP")
        assert noop.returncode == 0, noop.stdout + noop.stderr
        assert "ACCEPTANCE_SUCCESS NOOP seq 0" in noop.stdout and "COMPLETION_SUCCESS NOOP seq 0" in noop.stdout

        mode = _send(run_dir, "SET_MODE", "SAFE")
        assert mode.returncode == 0, mode.stdout + mode.stderr
        assert "COMPLETION_SUCCESS SET_MODE seq 1" in mode.stdout  # consecutive counts across calls

        bad = _send(run_dir, "SET_GAINS", "1", "1", "0.1", "90", "--no-check")
        assert bad.returncode == 3, bad.stdout + bad.stderr
        assert "ACCEPTANCE_FAILURE SET_GAINS seq 2: ARG_OUT_OF_RANGE" in bad.stdout
    finally:
        if sil.poll() is None:
            sil.send_signal(signal.SIGINT)  # an orderly stop: the archive and summary are written
        sil.wait(timeout=300)
    decoded = [json.loads(line) for line in (run_dir / "ground" / "tm_decoded.jsonl").read_text().splitlines()]
    acks = {(r["values"]["ack_report"], r["values"]["ack_opcode"], r["values"]["ack_tc_seq"], r["values"]["ack_code"])
            for r in decoded if r.get("packet") == "TC_ACK"}
    assert {("ACCEPTANCE_SUCCESS", 0x01, 0, "NONE"), ("COMPLETION_SUCCESS", 0x01, 0, "NONE"),
            ("COMPLETION_SUCCESS", 0x03, 1, "NONE"), ("ACCEPTANCE_FAILURE", 0x05, 2, "ARG_OUT_OF_RANGE")} <= acks
