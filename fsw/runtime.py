"""What the flight software asks of the operating system: a cycle thread prepared for steady timing (the
start-up heap frozen out of the garbage collector, BLAS on the calling thread, SCHED_FIFO and locked memory
for a real-time loop) and the process's resident size for housekeeping.

Nothing here knows about GNC; `fsw.app` calls it before its cycle loops and `fsw.housekeeping` once a
housekeeping cycle.
"""
from __future__ import annotations

import gc
import os

_statm: tuple[int, int, int] | None = None  # (pid, descriptor of /proc/<pid>/statm, page size)


def resident_bytes() -> int | None:
    """This process's resident set size [bytes], what ``psutil.Process().memory_info().rss`` reports on
    Linux (resident pages of /proc/self/statm), read through one descriptor kept open: psutil costs
    ~0.2 ms a call, once per housekeeping cycle. None where /proc is not available."""
    global _statm
    try:
        pid = os.getpid()
        if _statm is None or _statm[0] != pid:  # "self" is resolved at open: a forked child opens its own
            _statm = (pid, os.open(f"/proc/{pid}/statm", os.O_RDONLY), os.sysconf("SC_PAGE_SIZE"))
        return int(os.pread(_statm[1], 128, 0).split()[1]) * _statm[2]
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def freeze_heap() -> None:
    """Move everything allocated so far out of the cyclic garbage collector's reach.

    A full collection walks every tracked object: with numpy, scipy, astropy, numba and the ICD loaded that
    is ~200 k objects and 0.1-0.2 s, which lands inside some GNC cycle as a slip (seen in the 24 h soak).
    Start-up objects live as long as the process, so they are frozen once before the first cycle and
    later collections only visit what the cycles allocate.
    """
    gc.collect()
    gc.freeze()


def single_threaded_math() -> None:
    """Run numpy's and scipy's BLAS on the calling thread only.

    OpenBLAS splits a large enough product over worker threads of its own, one per CPU, under normal
    scheduling; a real-time cycle thread would then wait for a worker that the host has preempted. Every
    library that threadpoolctl knows gets one thread, for the rest of the process.
    """
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)  # applied at once; the returned handle is only needed to undo it


def prepare_cycle_thread() -> None:
    """What every cycle loop does before its first cycle: ``freeze_heap`` and ``single_threaded_math``."""
    freeze_heap()
    single_threaded_math()


def enter_realtime(priority: int) -> list[tuple[str, str]]:
    """Prepare this thread for paced cycles; returns (event name, reason) pairs to report.

    Freezes the start-up heap and keeps BLAS on this thread (``prepare_cycle_thread``). With
    ``priority`` > 0 the thread runs SCHED_FIFO (no time-sharing with the host's other work) and all pages
    are locked in memory (no page fault mid-cycle).
    """
    import ctypes
    import ctypes.util

    prepare_cycle_thread()
    if priority <= 0:
        return []
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return [("RT_SCHEDULING_UNAVAILABLE", f"SCHED_FIFO {priority}: {exc}")]
    events = [("RT_SCHEDULING", f"SCHED_FIFO priority {priority}")]
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    MCL_CURRENT, MCL_FUTURE = 1, 2
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        events.append(("RT_SCHEDULING_UNAVAILABLE", f"mlockall: {os.strerror(ctypes.get_errno())}"))
    return events
