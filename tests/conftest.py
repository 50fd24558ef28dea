"""Shared pytest configuration.

SocketCAN tests (marker ``socketcan``) need a real ``vcan0``. On a machine without it they are
skipped with the reason and the commands that create the interface. Inside CI's vcan-vm run,
``KEEPOUT_REQUIRE_VCAN=1`` turns a missing vcan0 into a failure, so they can never silently skip.
"""
from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

# A suite started in the background by a shell without job control inherits SIGINT ignored, and so would
# every process it starts: a test that presses Ctrl-C on a run would wait for a run that never hears it.
# Any handler set here is reset to the default when a child execs, so each started process hears Ctrl-C.
signal.signal(signal.SIGINT, signal.default_int_handler)

VCAN_HINT = (
    "no SocketCAN vcan0 here; create it with "
    "`sudo modprobe vcan && sudo ip link add dev vcan0 type vcan && sudo ip link set up vcan0` "
    "(a kernel without the vcan module: run the tests in a virtual machine whose kernel has it)"
)


def vcan0_present() -> bool:
    return Path("/sys/class/net/vcan0").exists()


def pytest_sessionstart(session: pytest.Session) -> None:
    if os.environ.get("KEEPOUT_REQUIRE_VCAN") == "1" and not vcan0_present():
        raise pytest.UsageError("KEEPOUT_REQUIRE_VCAN=1 but vcan0 does not exist: " + VCAN_HINT)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if vcan0_present():
        return
    for item in items:
        if "socketcan" in item.keywords:
            item.add_marker(pytest.mark.skip(reason=VCAN_HINT))
