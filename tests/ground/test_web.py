"""`keepout ground web`: the dictionary as Open MCT objects, history from an archive, live points over the
WebSocket, and a client sending garbage is disconnected while the server and the other clients carry on.

The server runs as a real process (`keepout ground web`) on a real port; the flight side is a real
TelemetrySender on a run's multicast group, signing with the run's link key.
"""
from __future__ import annotations

import asyncio
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import aiohttp
import pytest

from comms.dictionary import DICTIONARY
from comms.link_security import LINK_KEY_FILE, SPI_TM, SecurityAssociation, load_key_file, write_key_file
from fsw.telemetry import TelemetrySender
from ground.link import Endpoints, open_telemetry, random_group
from ground.monitor import GroundMonitor
from ground.web.catalog import build_objects, channel_key

ROOT = Path(__file__).resolve().parents[2]


def _gnc(sender: TelemetrySender, cycle: int, margin_deg: float) -> None:
    sender.send_channels("GNC", {"cycle": cycle, "mode": "POINTING", "margin_min_deg": margin_deg,
                                 "boresight_N": [1.0, 0.0, 0.0], "sun_N": [0.0, 1.0, 0.0], "moon_N": [0.0, 0.0, 1.0]},
                         time_s=0.5 * cycle)


def _start_web(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "cli", "ground", "web", "--port", "0", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    line = proc.stdout.readline()
    match = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
    if match is None:
        proc.kill()
        raise AssertionError(f"the web ground did not start: {line}{proc.stdout.read()}")
    return proc, f"http://127.0.0.1:{match.group(1)}"


def _stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    proc.wait(timeout=10)


def test_every_dictionary_channel_is_an_object_with_unit_limits_and_its_group() -> None:
    objects = build_objects(DICTIONARY)
    for packet in DICTIONARY.packets:
        for channel in packet.channels:
            obj = objects[channel_key(channel.name)]
            value = obj["telemetry"]["values"][0]
            assert value["unit"] == channel.unit and obj["keepout"]["packet"] == packet.name
            if channel.limits is not None and channel.type not in ("ENUM", "BOOL"):
                assert obj["keepout"]["limits"] == {"yellow": list(channel.limits.yellow),
                                                    "red": list(channel.limits.red)}
            parent = objects[obj["location"].split(":", 1)[1]]
            assert obj["identifier"] in parent["composition"]
    # grouped as the dictionary groups them: a folder per packet, a sub-folder per vector
    quaternion = objects["group.GNC.q_est_NB"]
    assert [i["key"] for i in quaternion["composition"]] == [f"ch.q_est_NB_{k}" for k in range(4)]
    assert {"key": "group.GNC.q_est_NB", "namespace": "keepout"} in objects["packet.GNC"]["composition"]
    # everything hangs off the root, and every composition names an existing object
    reachable, todo = set(), ["root"]
    while todo:
        key = todo.pop()
        reachable.add(key)
        todo += [i["key"] for i in objects[key].get("composition", []) if i["key"] not in reachable]
    assert reachable == set(objects)
    assert objects[channel_key("mode")]["telemetry"]["values"][0]["enumerations"][0]["string"] == "SAFE"


def test_history_of_a_finished_run_comes_from_its_archive(tmp_path: Path) -> None:
    archive = tmp_path / "ground"
    monitor = GroundMonitor(DICTIONARY, "127.0.0.1", 0, archive)
    sender = TelemetrySender(DICTIONARY, "127.0.0.1", monitor.address[1])
    t0 = time.time()
    for cycle in range(5):
        _gnc(sender, cycle, margin_deg=10.0 - cycle)
    sender.event("FDIR_TRIPPED", monitor="KEEP_OUT_MARGIN", action="ENTER_SAFE", value=1.5)
    deadline = time.monotonic() + 5
    while monitor.stats.datagrams < 6 and time.monotonic() < deadline:
        monitor.poll(0.05)
    monitor.close()
    sender.close()

    proc, url = _start_web("--archive", str(archive))
    try:
        async def fetch() -> tuple[dict, list, list, list, list]:
            async with aiohttp.ClientSession() as session:
                run = await (await session.get(f"{url}/api/run")).json()
                cycles = await (await session.get(f"{url}/api/history/ch.cycle",
                                                  params={"start": t0 * 1000 - 1, "end": time.time() * 1000})).json()
                latest = await (await session.get(f"{url}/api/history/ch.margin_min_deg",
                                                  params={"start": 0, "end": 1e15, "strategy": "latest"})).json()
                fdir = await (await session.get(f"{url}/api/history/fdir")).json()
                sky = await (await session.get(f"{url}/api/history/sky")).json()
                missing = await session.get(f"{url}/api/history/ch.nope")
                assert missing.status == 404
                page = await (await session.get(f"{url}/")).text()
                assert "keepout-plugin.js" in page and "openmct.js" in page
                assert (await session.get(f"{url}/openmct/openmct.js")).status == 200
                return run, cycles, latest, fdir, sky

        run, cycles, latest, fdir, sky = asyncio.run(fetch())
    finally:
        _stop(proc)
    assert run["live"] is False and run["span_ms"][0] >= t0 * 1000
    assert [p["value"] for p in cycles] == [0, 1, 2, 3, 4]
    assert [p["onboard_s"] for p in cycles] == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert [p["value"] for p in latest] == [6.0]
    assert [(p["event"], p["severity"]) for p in fdir] == [("FDIR_TRIPPED", "WARNING_HI")]
    # the sky: one point per onboard second, boresight +x is RA 0 Dec 0, the Sun +y is RA 90
    assert [p["onboard_s"] for p in sky] == [0.0, 1.0, 2.0]
    assert sky[0]["boresight"] == pytest.approx([0.0, 0.0]) and sky[0]["bodies"]["sun"] == pytest.approx([90.0, 0.0])


@pytest.fixture()
def live_run(tmp_path: Path):
    """A run folder as `keepout sil run` writes it while flying (endpoints, link key), and its flight side."""
    run_dir = tmp_path / "runs" / "live-1"
    (run_dir / "ground").mkdir(parents=True)
    key = write_key_file(run_dir / LINK_KEY_FILE)
    probe = open_telemetry(Endpoints("live-1", "udp-multicast", random_group(), 0, "127.0.0.1", 9, "virtual:x"))
    group, port = probe.getsockname()
    probe.close()
    Endpoints("live-1", "udp-multicast", group, port, "127.0.0.1", 9, "virtual:x", started_unix_s=time.time()
              ).write(run_dir)
    sender = TelemetrySender(DICTIONARY, group, port, security=SecurityAssociation(key, SPI_TM))
    yield run_dir, sender
    sender.close()


GARBAGE = ["not json at all", '{"op": "subscribe"}', '{"op": "subscribe", "key": "ch.no_such_channel"}',
           '{"op": "delete", "key": "ch.cycle"}', "[1, 2, 3]", '{"op": "subscribe", "key": 7}', b"\x00\xff binary",
           "x" * 10000]


def test_live_points_reach_subscribers_and_garbage_disconnects_only_its_sender(live_run) -> None:
    run_dir, sender = live_run
    assert load_key_file(run_dir / LINK_KEY_FILE)
    proc, url = _start_web("--run", str(run_dir))
    ws_url = url.replace("http", "ws") + "/api/realtime"

    async def scenario() -> tuple[list, list, dict]:
        async with aiohttp.ClientSession() as session:
            good = await session.ws_connect(ws_url)
            await good.send_str(json.dumps({"op": "subscribe", "key": "ch.cycle"}))
            await good.send_str(json.dumps({"op": "subscribe", "key": "events"}))
            closes = []
            for garbage in GARBAGE:
                bad = await session.ws_connect(ws_url)
                await (bad.send_bytes(garbage) if isinstance(garbage, bytes) else bad.send_str(garbage))
                message = await bad.receive(timeout=5)
                closes.append((message.type, bad.close_code))
                await bad.close()
            await asyncio.sleep(0.3)  # the subscriptions are in place
            for cycle in range(3):
                _gnc(sender, cycle, 5.0)
            sender.event("FSW_STARTED", gnc_rate_hz=10.0)
            forged = SecurityAssociation(b"\x01" * 32, SPI_TM)  # a packet signed with another key
            TelemetrySender(DICTIONARY, *sender.destination, security=forged).event("FSW_STOPPED", cycles=99)
            points: list = []
            while len(points) < 4:
                message = await good.receive(timeout=5)
                assert message.type == aiohttp.WSMsgType.TEXT, (message, good.close_code)
                points += json.loads(message.data)
            run = await (await session.get(f"{url}/api/run")).json()
            await good.close()
            return closes, points, run

    try:
        closes, points, run = asyncio.run(scenario())
        assert proc.poll() is None, "the server lives on"
    finally:
        _stop(proc)
    assert all(kind == aiohttp.WSMsgType.CLOSE for kind, _ in closes)
    assert [code for _, code in closes[:-1]] == [1003] * (len(GARBAGE) - 1)  # unsupported data
    assert closes[-1][1] == 1009  # over the 4 KiB a client message may have: "message too big"
    assert [p["value"] for p in points if p["id"] == "ch.cycle"] == [0, 1, 2]
    assert [p["event"] for p in points if p["id"] == "events"] == ["FSW_STARTED"], "the forged event is refused"
    assert run["live"] is True and run["ws_protocol_errors"] == len(GARBAGE)
    assert run["tm_refused_by_link_security"] == 1


def test_bad_command_lines_are_one_line_errors(tmp_path: Path, capsys) -> None:
    from cli.ground import main

    assert main(["ground", "web", "--openmct", str(tmp_path), "--archive", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"--openmct {tmp_path}: no openmct.js there" in err and "Traceback" not in err
    assert main(["ground", "web", "--archive", str(tmp_path)]) == 2
    assert f"--archive {tmp_path}: no tm_raw.bin there" in capsys.readouterr().err
    assert main(["ground", "web", "--run", str(tmp_path)]) == 2
    assert "no endpoints.json there" in capsys.readouterr().err


def test_an_archive_replay_is_named_after_its_run_not_ground(tmp_path) -> None:
    """`keepout ground web --archive RUN/ground`: the tree's root said "ground"; it is the run's name."""
    from cli.ground_web import archive_title

    run = tmp_path / "demo-pointing-20261129-030421-405d1a"
    (run / "ground").mkdir(parents=True)
    (run / "mission.yaml").write_text("name: demo-pointing\n")
    assert archive_title(run / "ground") == run.name
    elsewhere = tmp_path / "copied-archive"
    elsewhere.mkdir()
    assert archive_title(elsewhere) == "copied-archive"
    bare = tmp_path / "x" / "ground"  # a folder named ground that is not in a run folder keeps its name
    bare.mkdir(parents=True)
    assert archive_title(bare) == "ground"
