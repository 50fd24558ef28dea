"""Operating a live run: a real-time SIL run, two ground monitors attached with
`keepout ground --run`, Open MCT (`keepout ground web --run`) in Debian's headless Chromium driven by
Playwright, telecommands sent with `keepout ground send`, and their acknowledgements seen in the page and
in every archive; then the finished run replayed in a new page. The screenshot goes to the test's folder, or
to docs/img/openmct.png with KEEPOUT_UPDATE_SCREENSHOT=1 (so a test run leaves the checkout as it was).

Everything is real: processes, UDP multicast telemetry, the link key, the browser (the system Chromium;
Playwright downloads nothing).
"""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run"]
DOCS_SCREENSHOT = ROOT / "docs" / "img" / "openmct.png"
KEEPOUT = [sys.executable, "-m", "cli"]


def _keepout(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([*KEEPOUT, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, **kwargs)


def _wait_for(predicate, timeout_s: float, what: str, poll_s: float = 0.25):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(poll_s)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _send(run_dir: Path, *command: str) -> subprocess.CompletedProcess:
    """`keepout ground send --run RUN_DIR COMMAND`: sends, waits for the acknowledgements, prints them."""
    return subprocess.run([*KEEPOUT, "ground", "send", "--run", str(run_dir), *command, "--timeout", "20"],
                          capture_output=True, text=True, timeout=120)


def _acks(archive: Path) -> list[tuple[str, int]]:
    """(report, opcode) of every TC_ACK packet in a ground archive's decoded JSONL."""
    out = []
    for line in (archive / "tm_decoded.jsonl").read_text().splitlines():
        record = json.loads(line)
        if record.get("packet") == "TC_ACK":
            out.append((record["values"]["ack_report"], record["values"]["ack_opcode"]))
    return out


LAD_VALUE_JS = """name => {
    const row = [...document.querySelectorAll('tr.js-lad-table__body__row')]
        .find(r => r.querySelector('.js-first-data').textContent.trim() === name);
    return row ? row.querySelector('.js-third-data').textContent.trim() : null;
}"""
TABLE_TEXT_JS = "() => [...document.querySelectorAll('.js-telemetry-table__content')].map(t => t.innerText).join('\\n')"
LEGEND_JS = "() => [...document.querySelectorAll('.plot-series-name')].map(e => e.textContent.trim())"
ALARM_SOURCES_JS = "() => [...document.querySelectorAll('.keepout-alarms__row')].map(r => r.children[2].textContent)"


@pytest.mark.slow
def test_live_run_two_monitors_open_mct_and_verified_commands(tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright

    assert CHROMIUM.exists(), "Debian's chromium is needed (apt-get install -y chromium; .ci/run installs it)"
    from comms.dictionary import DICTIONARY

    opcodes = {DICTIONARY.command(name).opcode: name for name in ("NOOP", "SET_MODE")}
    processes: list[subprocess.Popen] = []
    # a shared CI computer can stall the real-time loop for a second: that is not a hung flight software
    sil = _keepout("sil", "run", "--realtime", "--duration", "600", "--no-progress", "--out", str(tmp_path / "runs"),
                   "--max-missed-ticks", "100", cwd=ROOT)
    processes.append(sil)
    try:
        with sync_playwright() as playwright:
            # the browser starts before the run: its start-up is the heaviest thing here
            browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_FLAGS)
            run_dir = _wait_for(lambda: sil.poll() is None and next(
                (p.parent for p in (tmp_path / "runs").glob("*/endpoints.json")), None), 120, "the run's endpoints.json")
            monitors = [_keepout("ground", "--run", str(run_dir), "--no-live", cwd=ROOT) for _ in range(2)]
            web = _keepout("ground", "web", "--run", str(run_dir), "--port", "0", cwd=ROOT)
            processes += [*monitors, web]
            url = re.search(r"http://127\.0\.0\.1:\d+/", web.stdout.readline())
            assert url, "the web ground printed no address"
            _wait_for(lambda: json.loads((run_dir / "endpoints.json").read_text())["pids"].get("fsw"), 600,
                      "the flight software to start")
            _wait_for(lambda: (run_dir / "ground" / "tm_raw.bin").exists()
                      and (run_dir / "ground" / "tm_raw.bin").stat().st_size > 20000, 600, "telemetry in the archive")

            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.goto(url.group(0))
            first = _wait_for(lambda: (page.evaluate(LAD_VALUE_JS, "cycle") or "---") != "---"
                              and page.evaluate(LAD_VALUE_JS, "cycle"), 60, "a cycle value in the page")
            _wait_for(lambda: page.evaluate(LAD_VALUE_JS, "cycle") not in (None, first), 30,
                      f"the cycle value to update from {first}")
            # the console reads at a glance live too: series named after the mission's zones, values to
            # their resolution, the alarm list filled as the run raises them
            legend = _wait_for(lambda: page.evaluate(LEGEND_JS), 30, "the margins legend")
            assert {"margin to sun (estimate) deg", "margin to moon (estimate) deg"} <= set(legend), legend
            assert re.fullmatch(r"-?\d+\.\d\d", page.evaluate(LAD_VALUE_JS, "pointing_error_deg") or ""), \
                page.evaluate(LAD_VALUE_JS, "pointing_error_deg")
            _wait_for(lambda: page.evaluate(ALARM_SOURCES_JS), 60, "an alarm in the alarm view")

            results = [_send(run_dir, "NOOP"), _send(run_dir, "SET_MODE", "POINTING")]
            for name, result in zip(("NOOP", "SET_MODE"), results):
                assert result.returncode == 0, result.stdout + result.stderr
                assert f"{name}: completed" in result.stdout and "COMPLETION_SUCCESS" in result.stdout
            for name in ("NOOP", "SET_MODE"):
                _wait_for(lambda: re.search(rf"COMPLETION_SUCCESS\s+{name} seq", page.evaluate(TABLE_TEXT_JS)), 30,
                          f"the page to show {name} completed")
            assert "FSW_STARTED" in page.evaluate(TABLE_TEXT_JS), "the event log shows the flight software's events"
            page.wait_for_timeout(1500)  # let the plots and the sky catch up before the picture
            screenshot = (DOCS_SCREENSHOT if os.environ.get("KEEPOUT_UPDATE_SCREENSHOT") == "1"
                          else tmp_path / "openmct.png")
            page.screenshot(path=str(screenshot))
            assert screenshot.stat().st_size > 10_000, "a rendered page, not a blank one"

            # A command to a port nobody serves fails, and says so.
            nobody = subprocess.run([*KEEPOUT, "ground", "send", "--key-file", str(run_dir / "link.key"),
                                     "--port", str(_free_udp_port()), "--tm-port", str(_free_udp_port()),
                                     "--timeout", "1", "NOOP"], capture_output=True, text=True, timeout=60)
            assert nobody.returncode != 0 and nobody.stderr.strip(), nobody.stdout + nobody.stderr

            os.killpg(sil.pid, signal.SIGINT)  # end the run as an operator would; it writes its summary
            sil.wait(timeout=180)
            assert f"attach with `keepout ground --run {run_dir}`" in sil.stdout.read()
            for monitor in monitors:  # attached monitors stop by themselves when the run has finished
                monitor.wait(timeout=60)
                assert monitor.returncode == 0, monitor.stdout.read()

            # The finished run replayed: a new web ground over its archive shows the same acknowledgements.
            replay = _keepout("ground", "web", "--run", str(run_dir), "--port", "0", cwd=ROOT)
            processes.append(replay)
            line = replay.stdout.readline()
            assert "finished: replay" in line, line
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.goto(re.search(r"http://127\.0\.0\.1:\d+/", line).group(0))
            for name in ("NOOP", "SET_MODE"):
                _wait_for(lambda: re.search(rf"COMPLETION_SUCCESS\s+{name} seq", page.evaluate(TABLE_TEXT_JS)), 60,
                          f"the replay to show {name} completed")
            browser.close()
    finally:
        for proc in reversed(processes):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(timeout=30)

    archives = [run_dir / "ground", *sorted((run_dir / "attached").glob("ground-*"))]
    assert len(archives) == 3
    for archive in archives:
        completed = {opcodes.get(op) for report, op in _acks(archive) if report == "COMPLETION_SUCCESS"}
        assert {"NOOP", "SET_MODE"} <= completed, f"{archive}: acknowledgements {_acks(archive)}"
        summary = json.loads((archive / "ground_summary.json").read_text())
        assert summary["rejected_by_link_security"] == 0
