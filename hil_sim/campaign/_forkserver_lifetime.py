"""Imported by the campaign pool's forkserver (a preload module): the forkserver dies with the campaign
driver that started it, even a SIGKILLed one. Its workers die with the forkserver (``runner._init_worker``),
so a killed `keepout campaign run` leaves no process behind flying runs.

The driver names itself in ``DRIVER_PID_ENV`` before the forkserver starts; only the process whose parent
is that driver (the forkserver) acts on it, so importing this module anywhere else does nothing.
"""
from __future__ import annotations

import os

DRIVER_PID_ENV = "KEEPOUT_CAMPAIGN_DRIVER_PID"

_driver = os.environ.get(DRIVER_PID_ENV, "")
if _driver.isdigit() and os.getppid() == int(_driver):
    from fsw.lifetime import die_with_parent

    die_with_parent(int(_driver))
