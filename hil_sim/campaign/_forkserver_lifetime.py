"""Imported by the campaign pool's forkserver (a preload module): the forkserver dies with the campaign
driver that started it, even a SIGKILLed one. Its workers die with the forkserver (``runner._init_worker``),
so a killed `keepout campaign run` leaves no process behind flying runs.

The driver names itself in ``DRIVER_PID_ENV`` before the forkserver starts; only the process whose parent
is that driver (the forkserver) acts on it, so importing this module anywhere else does nothing. Two ways,
since the parent-death signal alone left a forkserver behind in one CI run of ours: the kernel's signal, and
a watcher thread that ends the forkserver once it has been reparented (its forked workers do not inherit
the thread).
"""
from __future__ import annotations

import os
import threading
import time

DRIVER_PID_ENV = "KEEPOUT_CAMPAIGN_DRIVER_PID"
WATCH_PERIOD_S = 0.5


def _watch(driver: int) -> None:
    while True:
        time.sleep(WATCH_PERIOD_S)
        if os.getppid() != driver:  # the driver is gone: we were reparented
            os._exit(1)


_driver = os.environ.get(DRIVER_PID_ENV, "")
if _driver.isdigit() and os.getppid() == int(_driver):
    from fsw.lifetime import die_with_parent

    die_with_parent(int(_driver))
    threading.Thread(target=_watch, args=(int(_driver),), daemon=True, name="driver-watch").start()
