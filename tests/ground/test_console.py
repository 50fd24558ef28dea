"""The operator's console (`keepout ground web`): series named after the mission, values shown to their
resolution, limit lines, the alarm list with acknowledgement, the sky map across RA 0/360 and round a pole,
and a finished run replayed on onboard time.

The browser test flies a real lockstep SIL run (`keepout sil run --duration 120`), serves its archive with a
real `keepout ground web` process and reads the page in Debian's headless Chromium (Playwright drives it,
downloads nothing). The page's screenshot goes to the test's folder, or to docs/img/openmct-replay.png with
KEEPOUT_UPDATE_SCREENSHOT=1.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from fsw.config import load_fsw_run_config
from hil_sim.mission.model import load_mission
from comms.dictionary import DICTIONARY, Severity
from comms.telemetry import DecodedTm
from ground.web.alarms import ACKS_FILE, AlarmBook
from ground.web.catalog import build_objects, channel_key, decimals, resolution, zone_labels
from ground.web.points import History

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "config" / "missions" / "demo-pointing.yaml"
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run"]
KEEPOUT = [sys.executable, "-m", "cli"]


def _gnc(time_s: float, **values: float) -> DecodedTm:
    return DecodedTm(apid=0, seq_count=0, time_s=time_s, kind="channels", packet="GNC", values=values)


def _event(time_s: float, name: str, severity: str, message: str) -> DecodedTm:
    return DecodedTm(apid=0, seq_count=0, time_s=time_s, kind="event", packet="EVENT", event=name, severity=severity,
                     message=message)


def test_margin_series_carry_the_missions_zone_names_and_only_the_zones_in_use() -> None:
    cfg = load_mission(DEMO).flight_software
    labels = zone_labels(cfg)
    assert labels == [z.name for z in cfg.pointing.zones] and len(labels) == 2
    objects = build_objects(DICTIONARY, "demo", cfg)
    for i, label in enumerate(labels):
        obj = objects[channel_key(f"margin_deg_{i}")]
        assert obj["name"] == f"margin to {label} (estimate)"
        assert obj["telemetry"]["values"][0]["name"] == obj["name"]
        assert obj["notes"].startswith(f"margin_deg_{i}: ")  # the dictionary's name stays findable
    plot = objects["margins"]
    assert [i["key"] for i in plot["composition"]] == ["ch.margin_deg_0", "ch.margin_deg_1", "ch.margin_min_deg"]
    lines = {s["identifier"]["key"]: s["limitLines"] for s in plot["configuration"]["series"]}
    assert lines == {"ch.margin_deg_0": False, "ch.margin_deg_1": False, "ch.margin_min_deg": True}
    assert objects[channel_key("wheel_speed_rad_s_0")]["name"] == "RW1 speed"
    # without a mission, the dictionary's names and every slot
    bare = build_objects(DICTIONARY)
    assert bare[channel_key("margin_deg_0")]["name"] == "margin_deg_0"
    assert len(bare["margins"]["composition"]) == sum(c.startswith("margin_deg_") for c in DICTIONARY.channel_names) + 1


def test_float_channels_are_shown_to_their_resolution() -> None:
    assert decimals(0.01) == 2 and decimals(1e-6) == 6 and decimals(0.1) == 1 and decimals(1.0) == 0
    objects = build_objects(DICTIONARY)
    for packet in DICTIONARY.packets:
        for channel in packet.channels:
            value = objects[channel_key(channel.name)]["telemetry"]["values"][0]
            step = resolution(channel)
            if channel.type in ("F32", "F64"):
                assert value["formatString"] == f"%.{decimals(step)}f" and value["resolution"] == step
            else:
                assert "formatString" not in value
    assert objects[channel_key("pointing_error_deg")]["telemetry"]["values"][0]["formatString"] == "%.2f"


def test_alarms_rise_clear_and_stay_acknowledged_across_a_restart(tmp_path: Path) -> None:
    acks = tmp_path / ACKS_FILE
    book = AlarmBook(DICTIONARY, {"margin_min_deg": "smallest margin (estimate)"}, acks)
    for t, margin in ((0.0, 10.0), (1.0, 1.5), (2.0, -0.5), (3.0, 1.0), (4.0, 5.0), (5.0, 6.0)):
        book.observe(1000.0 + t, _gnc(t, margin_min_deg=margin))
    book.observe(1006.0, _event(6.0, "FDIR_TRIPPED", Severity.WARNING_HI.value, "FDIR KEEP_OUT_MARGIN tripped"))
    book.observe(1007.0, _event(7.0, "TARGET_SET", "ACTIVITY_HI", "target set"))  # not an alarm
    alarms = book.to_json()["alarms"]
    smallest = "smallest margin (estimate)"
    assert [(a["severity"], a["source"], a["onboard_s"]) for a in alarms] == [
        ("YELLOW", smallest, 1.0), ("RED", smallest, 2.0), ("WARNING_HI", "FDIR_TRIPPED", 6.0)]
    assert [a["message"] for a in alarms[:2]] == ["1.5 deg, below 2 deg (yellow limit)",
                                                  "-0.5 deg, below 0 deg (red limit)"]
    assert alarms[0]["cleared_onboard_s"] is None  # superseded by RED, which cleared when back in yellow
    assert alarms[1]["cleared_onboard_s"] == 3.0
    assert book.to_json()["unacknowledged"] == 3
    with pytest.raises(KeyError, match="no alarm 7"):
        book.acknowledge([0, 7])
    assert book.to_json()["unacknowledged"] == 3  # a bad request acknowledges nothing
    assert book.acknowledge([1, 1], operator="ops") == 1 and book.acknowledge([1]) == 0
    again = AlarmBook(DICTIONARY, None, acks)
    for t, margin in ((0.0, 10.0), (1.0, 1.5), (2.0, -0.5)):
        again.observe(1000.0 + t, _gnc(t, margin_min_deg=margin))
    assert [a["acknowledged"] for a in again.to_json()["alarms"]] == [False, True]


def test_history_answers_in_onboard_time_as_well_as_ground_time() -> None:
    history = History()
    history.points["events"] = [{"id": "events", "utc": 5000.0 + 10 * i, "onboard_s": 100.0 + i} for i in range(5)]
    by_onboard = history.query("events", {}, 101.0, 103.0, domain="onboard_s")
    by_ground = history.query("events", {}, 5010.0, 5030.0)
    assert [p["onboard_s"] for p in by_onboard] == [101.0, 102.0, 103.0] and by_ground == by_onboard
    with pytest.raises(ValueError, match="domain"):
        history.query("events", {}, 0, 1, domain="tai")


SKY_JS = """async () => {
    const sky = await (await fetch('/api/history/sky?domain=onboard_s')).json();
    const trail = sky.map((p) => p.boresight);
    const jumps = trail.filter((p, i) => i && p && trail[i - 1] && Math.abs(p[0] - trail[i - 1][0]) > 180).length;
    const segments = KeepoutSky.trailSegments(trail);
    const worst = Math.max(...segments.map((s) => Math.max(0, ...s.map((p, i) => i ? Math.abs(p[0] - s[i - 1][0]) : 0))));
    const polar = []; for (let i = 0; i < 24; i++) { polar.push([i * 15, 75]); }
    const cap = KeepoutSky.zoneRing(polar);
    return {points: trail.length, jumps: jumps, segments: segments.length, worst: worst, pole: cap.pole,
            capTop: Math.max(...cap.ring.map((p) => p[1]))};
}"""
LEGEND_JS = "() => [...document.querySelectorAll('.plot-series-name')].map(e => e.textContent.trim())"
LAD_VALUE_JS = """name => {
    const row = [...document.querySelectorAll('tr.js-lad-table__body__row')]
        .find(r => r.querySelector('.js-first-data').textContent.trim() === name);
    return row ? row.querySelector('.js-third-data').textContent.trim() : null;
}"""
ALARM_ROWS_JS = """() => [...document.querySelectorAll('.keepout-alarms__row')].map(r => ({
    id: Number(r.dataset.alarmId), acknowledged: r.classList.contains('is-acknowledged'), text: r.innerText}))"""


def _wait(page, js: str, arg, predicate, what: str, timeout_ms: int = 60_000):
    deadline = timeout_ms / 250
    for _ in range(int(deadline)):
        value = page.evaluate(js, arg) if arg is not None else page.evaluate(js)
        if predicate(value):
            return value
        page.wait_for_timeout(250)
    raise AssertionError(f"the page never showed {what}: last {value!r}")


@pytest.mark.slow
def test_replayed_run_reads_at_a_glance_in_the_browser(tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright

    assert CHROMIUM.exists(), "Debian's chromium is needed (apt-get install -y chromium; .ci/run installs it)"
    flown = subprocess.run([*KEEPOUT, "sil", "run", str(DEMO), "--duration", "120", "--no-progress",
                            "--out", str(tmp_path / "runs")], capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert flown.returncode == 0, flown.stdout + flown.stderr
    run_dir = next((tmp_path / "runs").glob("*/summary.json")).parent
    web = subprocess.Popen([*KEEPOUT, "ground", "web", "--run", str(run_dir), "--port", "0"], cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        line = web.stdout.readline()
        assert "finished: replay" in line, line
        url = re.search(r"http://127\.0\.0\.1:\d+/", line).group(0)
        run = json.loads(urllib.request.urlopen(f"{url}api/run").read())
        assert run["onboard_span_s"][0] < 1.0 and run["onboard_span_s"][1] > 110.0
        with pytest.raises(urllib.error.HTTPError) as refused:  # an acknowledgement must name alarms
            urllib.request.urlopen(urllib.request.Request(f"{url}api/alarms/ack", data=b'{"ids": ["x"]}',
                                                          headers={"Content-Type": "application/json"}))
        assert refused.value.code == 400
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_FLAGS)
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.goto(url)
            # the series are named after the mission's zones, with their unit
            cfg = load_fsw_run_config(run_dir / "fsw.yaml").flight_software
            legend = _wait(page, LEGEND_JS, None, lambda names: len(names) >= 3, "the margins legend")
            for label in zone_labels(cfg):
                assert f"margin to {label} (estimate) deg" in legend, legend
            # a value shown to its resolution (0.01 deg), not float32's digits
            error = _wait(page, LAD_VALUE_JS, "pointing_error_deg", lambda v: v not in (None, "---"), "a pointing error")
            assert re.fullmatch(r"-?\d+\.\d\d", error), error
            # replayed on onboard time: the plots' x axis is the packets' own clock
            assert page.locator(".gl-plot-x-label").first.inner_text().strip() == "Onboard time"
            # the alarm list: what the run's limits raised, acknowledged from the page
            alarms = json.loads(urllib.request.urlopen(f"{url}api/alarms").read())["alarms"]
            assert alarms, "a 120 s demo run raises limit alarms (its first estimate's covariance, its cycle times)"
            rows = _wait(page, ALARM_ROWS_JS, None, lambda r: len(r) == len(alarms), "every alarm")
            first = alarms[0]
            assert any(r["id"] == first["alarm_id"] and first["source"] in r["text"] and not r["acknowledged"]
                       for r in rows), rows
            page.locator(f'.keepout-alarms__row[data-alarm-id="{first["alarm_id"]}"] .keepout-alarms__ack').click()
            _wait(page, ALARM_ROWS_JS, None,
                  lambda r: any(x["id"] == first["alarm_id"] and x["acknowledged"] for x in r), "the acknowledgement")
            assert json.loads((run_dir / "ground" / ACKS_FILE).read_text().splitlines()[0])["alarm_id"] == first["alarm_id"]
            # the sky: demo-pointing's boresight crosses RA 0/360; the map breaks the trail there
            sky = page.evaluate(SKY_JS)
            assert sky["points"] > 100 and sky["jumps"] >= 1, f"the run's trail does not cross RA 0: {sky}"
            assert sky["segments"] == sky["jumps"] + 1 and sky["worst"] < 180, sky
            assert sky["pole"] == 90 and sky["capTop"] == 90, "a zone round the pole is closed over the pole"
            page.wait_for_timeout(1000)
            shot = (ROOT / "docs" / "img" / "openmct-replay.png" if os.environ.get("KEEPOUT_UPDATE_SCREENSHOT") == "1"
                    else tmp_path / "openmct-replay.png")
            page.screenshot(path=str(shot))
            assert shot.stat().st_size > 10_000
            browser.close()
    finally:
        os.killpg(web.pid, signal.SIGTERM)
        web.wait(timeout=30)
