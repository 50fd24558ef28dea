"""Child processes end with their parent, whatever ends the parent (even SIGKILL).

Linux's parent-death signal (``prctl(PR_SET_PDEATHSIG)``) is set by the child itself, early in its
life; the kernel then sends it the signal when the parent (the thread that forked it) ends. A parent that
died before the call cannot be caught that way, so the child also compares its parent id with the one
it was given and ends at once on a mismatch.

Here, not in ``hil_sim``: the flight software uses it for its assumption-check worker, and the flight
software never imports ``hil_sim``.
"""
from __future__ import annotations

import ctypes
import os
import signal

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
PARENT_PID_ENV = "KEEPOUT_PARENT_PID"  # set by a parent that wants its child to die with it


def die_with_parent(parent_pid: int | None = None, sig: int = signal.SIGKILL) -> bool:
    """Ask the kernel for ``sig`` when our parent ends; end now when it already has.

    ``parent_pid``: the parent we were started by (default: ``$KEEPOUT_PARENT_PID``, else the current
    parent). Returns whether the kernel call succeeded (False off Linux: nothing is set).
    """
    if parent_pid is None:
        env = os.environ.get(PARENT_PID_ENV, "")
        parent_pid = int(env) if env.isdigit() else os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        ok = libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        ok = False
    if os.getppid() != parent_pid:  # the parent died before the call above: no signal will come
        os._exit(128 + int(sig))
    return ok
