"""The kernel's real-time bandwidth limit, measured: why a 100 %-busy SCHED_FIFO loop stalls.

Linux stops a SCHED_FIFO task that has used sched_rt_runtime_us of every sched_rt_period_us (by default
950 ms of each second) for the rest of that period. A 10 Hz flight loop is ~1 % busy and never meets the
limit; a lockstep run faster than real time is 100 % busy and does (bench/soak.py rests between steps for
that reason, design note 11). For each duty cycle this busy-loops under SCHED_FIFO on one CPU, resting
(1 - duty) of every 20 ms, and records every gap over 5 ms between consecutive clock reads.

    .venv/bin/python bench/rt_bandwidth.py [--cpu 0] [--seconds 4]    # root (SCHED_FIFO)

Prints a table and writes bench/results/rt_bandwidth.json.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WINDOW_S = 0.02


def busy_loop(seconds: float, duty: float) -> list[tuple[float, float]]:
    """(time [s], gap [ms]) of every gap over 5 ms between clock reads, resting (1 - duty) per window."""
    gaps = []
    start = last = since = time.perf_counter()
    while last - start < seconds:
        now = time.perf_counter()
        if now - last > 0.005:
            gaps.append((round(now - start, 3), round(1e3 * (now - last), 2)))
        last = now
        if duty < 1.0 and now - since >= WINDOW_S:
            time.sleep((now - since) * (1.0 - duty) / duty)
            last = since = time.perf_counter()
    return gaps


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cpu", type=int, default=0, help="CPU to run on (default 0)")
    ap.add_argument("--seconds", type=float, default=4.0, help="length of each run (default 4)")
    ap.add_argument("--priority", type=int, default=10, help="SCHED_FIFO priority (default 10)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "rt_bandwidth.json"))
    args = ap.parse_args(argv)
    limits = {name: int(Path(f"/proc/sys/kernel/{name}").read_text()) for name in ("sched_rt_runtime_us", "sched_rt_period_us")}
    os.sched_setaffinity(0, {args.cpu})
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.priority))
    rows = []
    try:
        for duty in (1.0, 0.95, 0.9):
            gaps = busy_loop(args.seconds, duty)
            rows.append({"duty": duty, "stalls": len(gaps), "longest_ms": max((g for _, g in gaps), default=0.0),
                         "stalls_at_s": [t for t, _ in gaps]})
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    print(f"SCHED_FIFO {args.priority} on CPU {args.cpu}, {args.seconds:g} s per run; kernel: {limits}")
    print(f"{'busy fraction':>13s} {'stalls > 5 ms':>13s} {'longest ms':>10s}  at [s]")
    for r in rows:
        print(f"{r['duty']:13.2f} {r['stalls']:13d} {r['longest_ms']:10.1f}  {r['stalls_at_s']}")
    Path(args.out).write_text(json.dumps({"command": "bench/rt_bandwidth.py", "kernel": limits, "cpu": args.cpu,
                                          "load_average": list(os.getloadavg()), "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
