"""`keepout ground send SET_TARGET GROUND --latitude-deg --longitude-deg [--altitude-m]` and `SET_TARGET NADIR`
sent to a real CommandDispatcher on loopback."""
from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from cli.ground import main
from comms.dictionary import DICTIONARY
from comms.link_security import uplink_receiver, write_key_file
from comms.telecommand import ground_target_of
from fsw.telecommand import CommandDispatcher


@pytest.fixture
def link(tmp_path: Path):
    key = write_key_file(tmp_path / "link.key")
    dispatcher = CommandDispatcher(DICTIONARY, None, "127.0.0.1", 0, security=uplink_receiver(key))
    calls: list[dict] = []
    dispatcher.register("SET_TARGET", lambda **kw: calls.append(kw))
    yield dispatcher, calls, ["--port", str(dispatcher.address[1]), "--no-wait", "--key-file", str(tmp_path / "link.key")]
    dispatcher.close()


def _received(dispatcher: CommandDispatcher, calls: list[dict], count: int = 1) -> list[dict]:
    deadline = time.monotonic() + 3.0
    while len(calls) < count and time.monotonic() < deadline:
        dispatcher.poll(timeout_s=0.1)
    return calls


def test_ground_point_from_latitude_longitude_altitude(link) -> None:
    dispatcher, calls, opts = link
    assert main(["ground", "send", "SET_TARGET", "ground", "--latitude-deg", "24.86", "--longitude-deg", "67.01",
                 "--altitude-m", "10", *opts]) == 0
    (kw,) = _received(dispatcher, calls)
    assert kw["kind"] == "GROUND" and dispatcher.counters["accepted"] == 1
    # the geodetic vertical of (24.86 N, 67.01 E) worked out by hand: cos(lat) cos(lon), cos(lat) sin(lon), sin(lat)
    assert kw["c0"] == pytest.approx(0.907338 * 0.390570, abs=1e-5)
    assert kw["c1"] == pytest.approx(0.907338 * 0.920573, abs=1e-5)
    assert kw["c2"] == pytest.approx(0.420402, abs=1e-5)
    assert kw["c3"] == pytest.approx(0.001)  # 10 m in units of 10 km
    lat, lon, alt = ground_target_of(kw["c0"], kw["c1"], kw["c2"], kw["c3"])  # what the flight software reads
    assert (lat, lon, alt) == (pytest.approx(24.86), pytest.approx(67.01), pytest.approx(10.0))


def test_ground_point_altitude_defaults_to_zero_and_west_longitude(link) -> None:
    dispatcher, calls, opts = link
    assert main(["ground", "send", "SET_TARGET", "GROUND", "--latitude-deg", "-33.9", "--longitude-deg", "-70.5",
                 *opts]) == 0
    (kw,) = _received(dispatcher, calls)
    lat, lon, alt = ground_target_of(kw["c0"], kw["c1"], kw["c2"], kw["c3"])
    assert (lat, lon, alt) == (pytest.approx(-33.9), pytest.approx(-70.5), 0.0)
    assert math.hypot(kw["c0"], kw["c1"], kw["c2"]) == pytest.approx(1.0)


def test_nadir_needs_no_components(link) -> None:
    dispatcher, calls, opts = link
    assert main(["ground", "send", "SET_TARGET", "NADIR", *opts]) == 0
    assert _received(dispatcher, calls) == [{"kind": "NADIR", "c0": 0.0, "c1": 0.0, "c2": 0.0, "c3": 0.0}]


@pytest.mark.parametrize("argv, message", [
    (["GROUND", "--latitude-deg", "91", "--longitude-deg", "0"], "--latitude-deg 91 outside -90..90"),
    (["GROUND", "--latitude-deg", "nan", "--longitude-deg", "0"], "--latitude-deg nan outside -90..90"),
    (["GROUND", "--latitude-deg", "10", "--longitude-deg", "361"], "--longitude-deg 361 outside -180..360"),
    (["GROUND", "--latitude-deg", "10", "--longitude-deg", "0", "--altitude-m", "9500"],
     "--altitude-m 9500 outside -500..9000"),
    (["GROUND", "--latitude-deg", "10"], "needs --latitude-deg and --longitude-deg"),
    (["NADIR", "--latitude-deg", "10", "--longitude-deg", "0"], "go with SET_TARGET GROUND"),
    (["DIRECTION", "1", "0", "0", "--altitude-m", "5"], "go with SET_TARGET GROUND"),
])
def test_bad_ground_point_is_refused_before_sending(link, capsys, argv, message) -> None:
    dispatcher, calls, opts = link
    assert main(["ground", "send", "SET_TARGET", *argv, *opts]) == 2
    assert message in capsys.readouterr().err
    dispatcher.poll(timeout_s=0.2)
    assert calls == [] and dispatcher.counters["accepted"] == 0 and dispatcher.counters["rejected"] == 0


def test_the_four_components_still_work(link) -> None:
    dispatcher, calls, opts = link
    assert main(["ground", "send", "SET_TARGET", "GROUND", "0", "0", "1", "0.05", *opts]) == 0
    (kw,) = _received(dispatcher, calls)
    assert (kw["kind"], kw["c2"], kw["c3"]) == ("GROUND", 1.0, 0.05)
