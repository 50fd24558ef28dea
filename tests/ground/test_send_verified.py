"""`keepout ground send` waits for the flight software's acknowledgements and exits by the outcome.

The flight side is the real dispatcher and telemetry sender on real UDP sockets, polled in a thread as
the flight software's cycle would; the ground side is the real command line.
"""
from __future__ import annotations

import socket
import subprocess
import sys
import threading
from collections.abc import Iterator

import pytest

from comms.dictionary import DICTIONARY
from comms.link_security import SPI_TM, SecurityAssociation, uplink_receiver, write_key_file
from fsw.telecommand import CommandDispatcher
from fsw.telemetry import TelemetrySender
from cli.ground import main


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


LINK = {}  # the link key of this module's flight and ground (made once, by _link_key)


@pytest.fixture(scope="module", autouse=True)
def _link_key(tmp_path_factory) -> None:
    path = tmp_path_factory.mktemp("link") / "link.key"
    LINK.update(path=str(path), key=write_key_file(path))


class Flight:
    """A dispatcher polled in a thread, acknowledging to ``tm_port``; link security on, as in flight."""

    def __init__(self, tm_port: int, answer: bool = True) -> None:
        self.telemetry = TelemetrySender(DICTIONARY, "127.0.0.1", tm_port,
                                         security=SecurityAssociation(LINK["key"], SPI_TM))
        self.dispatcher = CommandDispatcher(DICTIONARY, self.telemetry, "127.0.0.1", 0,
                                            security=uplink_receiver(LINK["key"]))
        self.modes: list[str] = []
        self.dispatcher.register("NOOP", lambda: None)
        self.dispatcher.register("SET_MODE", lambda mode: self.modes.append(mode))
        self.dispatcher.register("SET_GAINS", lambda **_: None)
        self.dispatcher.register("RESET_COUNTERS", self._broken)
        self.answer = answer
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    @staticmethod
    def _broken() -> None:
        raise RuntimeError("counter memory lost")

    def _run(self) -> None:
        while not self.stop.is_set():
            if self.answer:
                self.dispatcher.poll(timeout_s=0.02)
            else:
                self.stop.wait(0.02)

    @property
    def tc_port(self) -> int:
        return self.dispatcher.address[1]

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2.0)
        self.dispatcher.close()
        self.telemetry.close()


@pytest.fixture
def flight() -> Iterator[tuple[Flight, int]]:
    tm_port = _free_port()
    f = Flight(tm_port)
    yield f, tm_port
    f.close()


def _send(tc_port: int, tm_port: int, *words: str) -> list[str]:
    return ["ground", "send", *words, "--port", str(tc_port), "--tm-port", str(tm_port), "--timeout", "3",
            "--key-file", LINK["path"]]


def test_completed_command_prints_both_reports_and_exits_0(flight, capsys) -> None:
    f, tm_port = flight
    assert main(_send(f.tc_port, tm_port, "SET_MODE", "POINTING", "--seq", "12")) == 0
    out = capsys.readouterr().out
    assert "ACCEPTANCE_SUCCESS SET_MODE seq 12" in out and "COMPLETION_SUCCESS SET_MODE seq 12" in out
    assert "SET_MODE: completed" in out and f.modes == ["POINTING"]
    assert f.dispatcher.hk_values()["tc_completed"] == 1


def test_bad_argument_is_rejected_on_board_with_its_reason_code(flight, capsys) -> None:
    f, tm_port = flight
    code = main(_send(f.tc_port, tm_port, "SET_GAINS", "1", "1", "0.1", "90", "--no-check"))
    assert code == 3
    captured = capsys.readouterr()
    assert "ACCEPTANCE_FAILURE SET_GAINS" in captured.out and "ARG_OUT_OF_RANGE" in captured.out
    assert "REJECTED: ARG_OUT_OF_RANGE" in captured.err
    assert f.dispatcher.hk_values()["tc_rejected"] == 1


def test_execution_failure_exits_4(flight, capsys) -> None:
    f, tm_port = flight
    assert main(_send(f.tc_port, tm_port, "RESET_COUNTERS")) == 4
    out = capsys.readouterr().out
    assert "ACCEPTANCE_SUCCESS" in out and "COMPLETION_FAILURE RESET_COUNTERS" in out and "EXECUTION_FAILED" in out


def test_no_acknowledgement_within_the_timeout_says_so(capsys) -> None:
    tm_port = _free_port()
    silent = Flight(tm_port, answer=False)  # the socket exists, nobody reads it
    try:
        code = main(["ground", "send", "NOOP", "--port", str(silent.tc_port), "--tm-port", str(tm_port),
                     "--timeout", "0.5", "--key-file", LINK["path"]])
    finally:
        silent.close()
    assert code == 5
    assert "NO_ACK: no acknowledgement within 0.5 s" in capsys.readouterr().err


def test_command_to_a_port_nobody_serves_exits_non_zero(capsys) -> None:
    code = main(["ground", "send", "NOOP", "--port", str(_free_port()), "--tm-port", str(_free_port()),
                 "--key-file", LINK["path"]])
    assert code == 1
    assert "nothing listens for telecommands" in capsys.readouterr().err


@pytest.mark.parametrize("option, value, message", [
    ("--port", "70000", "70000 is not a UDP port; allowed: 1..65535"),
    ("--tm-port", "0", "0 is not a UDP port"),
    ("--timeout", "-1", "not a positive number of seconds"),
    ("--seq", "20000", "not a TC sequence count"),
])
def test_bad_options_are_one_line_errors(option: str, value: str, message: str) -> None:
    proc = subprocess.run([sys.executable, "-m", "cli", "ground", "send", "NOOP", option, value],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr
