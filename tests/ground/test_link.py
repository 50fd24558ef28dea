"""The ground link: a run's endpoints.json, multicast fan-out to any number of clients, `--run latest`."""
from __future__ import annotations

import json
import select
import socket
import time
from pathlib import Path

import pytest

from comms.dictionary import DICTIONARY
from fsw.telemetry import TelemetrySender
from comms.telemetry import decode_tm_packet
from cli.ground import main
from ground.link import ENDPOINTS_FILE, Endpoints, LinkError, find_run, open_telemetry, random_group


def _endpoints(tm_port: int = 0, group: str | None = None, **changes) -> Endpoints:
    fields = dict(run_id="test-run", tm_transport="udp-multicast", tm_host=group or random_group(),
                  tm_port=tm_port, tc_host="127.0.0.1", tc_port=9, bus="virtual:test", started_unix_s=time.time())
    fields.update(changes)
    return Endpoints(**fields)


def _drain(sock: socket.socket, timeout_s: float = 2.0, expect: int = 1) -> list[bytes]:
    got: list[bytes] = []
    deadline = time.monotonic() + timeout_s
    while len(got) < expect and time.monotonic() < deadline:
        if select.select([sock], [], [], 0.05)[0]:
            got.append(sock.recv(65536))
    time.sleep(0.05)  # anything beyond `expect` would be a duplicate: collect it too
    while select.select([sock], [], [], 0)[0]:
        got.append(sock.recv(65536))
    return got


def test_every_client_that_joined_receives_every_packet_and_leaving_disturbs_nobody() -> None:
    first = open_telemetry(_endpoints())
    endpoints = _endpoints(first.getsockname()[1], first.getsockname()[0])
    second = open_telemetry(endpoints)
    sender = TelemetrySender(DICTIONARY, endpoints.tm_host, endpoints.tm_port)  # the flight side
    try:
        assert sender.local_address[0] == "127.0.0.1", "multicast telemetry leaves from loopback"
        sender.event("FSW_STARTED", gnc_rate_hz=10.0)
        assert [decode_tm_packet(DICTIONARY, raw).event for raw in _drain(first)] == ["FSW_STARTED"]
        assert len(_drain(second)) == 1

        late = open_telemetry(endpoints)  # attaches mid-run
        sender.event("FSW_STOPPED", cycles=1)
        assert len(_drain(first)) == len(_drain(second)) == len(_drain(late)) == 1
        late.close()  # detaches
        sender.event("FSW_STOPPED", cycles=2)
        assert len(_drain(first)) == len(_drain(second)) == 1
        assert sender.counters["send_errors"] == 0
    finally:
        for sock in (first, second):
            sock.close()
        sender.close()


def test_a_client_of_another_run_hears_nothing_of_this_one() -> None:
    mine = open_telemetry(_endpoints())
    port = mine.getsockname()[1]
    other = open_telemetry(_endpoints(port, random_group()))  # same port, other group
    try:
        assert mine.getsockname()[0] != other.getsockname()[0]
        with TelemetrySender(DICTIONARY, mine.getsockname()[0], port) as sender:
            sender.event("FSW_STARTED", gnc_rate_hz=10.0)
        assert len(_drain(mine)) == 1 and _drain(other, 0.3) == []
    finally:
        mine.close()
        other.close()


def test_unicast_link_has_one_receiver_and_says_so() -> None:
    endpoints = _endpoints(tm_transport="udp", group="127.0.0.1")
    only = open_telemetry(endpoints)
    try:
        with pytest.raises(LinkError, match=r"cannot open the telemetry of run test-run \(127\.0\.0\.1:\d+\)"):
            open_telemetry(_endpoints(only.getsockname()[1], "127.0.0.1", tm_transport="udp"))
    finally:
        only.close()


def test_endpoints_round_trip_and_bad_files_are_one_line_errors(tmp_path: Path) -> None:
    endpoints = _endpoints(50123, "239.1.2.3", pids={"sil": 1, "fsw": 2})
    endpoints.write(tmp_path)
    assert Endpoints.load(tmp_path) == endpoints
    assert json.loads((tmp_path / ENDPOINTS_FILE).read_text())["tm_host"] == "239.1.2.3"

    (tmp_path / ENDPOINTS_FILE).write_text('{"run_id": "x"}')
    with pytest.raises(LinkError, match=r"endpoints\.json: missing key\(s\) tm_transport, tm_host"):
        Endpoints.load(tmp_path)
    (tmp_path / ENDPOINTS_FILE).write_text("{not json")
    with pytest.raises(LinkError, match=r"endpoints\.json: cannot read"):
        Endpoints.load(tmp_path)
    data = endpoints.to_json_dict() | {"tm_transport": "carrier-pigeon"}
    (tmp_path / ENDPOINTS_FILE).write_text(json.dumps(data))
    with pytest.raises(LinkError, match="key tm_transport is 'carrier-pigeon'; allowed: udp-multicast, udp"):
        Endpoints.load(tmp_path)
    with pytest.raises(LinkError, match="does not exist"):
        Endpoints.load(tmp_path / "nowhere")


def test_run_latest_is_the_run_that_started_last(tmp_path: Path) -> None:
    for name, started in (("b-old", 100.0), ("a-new", 200.0), ("c-middle", 150.0)):
        (tmp_path / name).mkdir()
        _endpoints(started_unix_s=started).write(tmp_path / name)
    (tmp_path / "not-a-run").mkdir()
    assert find_run("latest", tmp_path) == tmp_path / "a-new"
    assert find_run(tmp_path / "c-middle") == tmp_path / "c-middle"
    with pytest.raises(LinkError, match="no endpoints.json there"):
        find_run(tmp_path / "not-a-run")
    with pytest.raises(LinkError, match="no run folder with endpoints.json"):
        find_run("latest", tmp_path / "not-a-run")


def test_cli_monitor_attaches_to_a_run_and_refuses_a_finished_one(tmp_path: Path, capsys) -> None:
    probe = open_telemetry(_endpoints())
    group, port = probe.getsockname()
    probe.close()
    run_dir = tmp_path / "runs" / "demo-1"
    run_dir.mkdir(parents=True)
    _endpoints(port, group).write(run_dir)
    from comms.link_security import LINK_KEY_FILE, write_key_file

    write_key_file(run_dir / LINK_KEY_FILE)  # the run's link key, as the SIL makes it
    assert main(["ground", "--run", str(run_dir), "--duration", "0.3", "--no-live"]) == 0
    out = capsys.readouterr().out
    assert f"attached to run test-run, telemetry on {group}:{port} (multicast)" in out
    assert len(list((run_dir / "attached").glob("ground-*/tm_raw.bin"))) == 1, "its own archive, in the run folder"

    _endpoints(port, group, state="finished").write(run_dir)
    assert main(["ground", "--run", str(run_dir), "--duration", "0.3", "--no-live"]) == 2
    err = capsys.readouterr().err
    assert "has finished: nothing to attach to" in err and "Traceback" not in err
    assert main(["ground", "--run", str(tmp_path / "runs"), "--no-live"]) == 2
    assert "no endpoints.json there" in capsys.readouterr().err
