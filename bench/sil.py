"""SIL speed: simulated seconds per wall second of `keepout sil run demo-pointing` in lockstep.

Each repetition is a full three-process run (simulator, flight software, ground monitor) of
config/missions/demo-pointing.yaml, shortened with --duration. Two figures per run:

* loop speed: simulated time / wall time of the lockstep loop (summary.json ``speed_x_realtime``),
  the SIL's sustained rate (goal >= 100x real time);
* end to end: simulated time / wall time of the whole command, including process start-up, numba
  cache loading, the physics checks, the summary and the plots;
* CPU ms per tick of each process during the loop (simulator.json ``loop_cpu_s``): on a loaded host the
  wall figures swing with the load, these much less; on one CPU (the guest) their sum is the tick.

Transports: udp_multicast on this host; socketcan:vcan0 inside a CAN-enabled guest ($KEEPOUT_VCAN_RUN, default `vcan-vm`; the host
kernel has no CAN; the guest is one CPU of this host), one guest boot per run. ``--both`` alternates a
host udp_multicast run and a guest socketcan run, so both transports are measured under the same host
load (the machine is shared: the 1-minute load average of the host is recorded with every run).

    .venv/bin/python bench/sil.py [--duration 600] [--repeat 3] [--bus udp_multicast] [--vm | --both]

Prints a table (medians) and writes bench/results/sil.json and/or sil-socketcan.json.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# a command that runs its arguments in a guest that has vcan0 (the host kernel has no CAN)
VCAN_VM = os.environ.get("KEEPOUT_VCAN_RUN", "vcan-vm")


def one_run(bus: str, duration: float, out: Path) -> dict:
    cmd = [sys.executable, "-m", "cli", "sil", "run", str(ROOT / "config" / "missions" / "demo-pointing.yaml"),
           "--bus", bus, "--duration", str(duration), "--out", str(out), "--no-progress"]
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    runs = sorted(out.glob("demo-pointing-*"), key=lambda p: p.stat().st_mtime)
    if not runs or not (runs[-1] / "summary.json").exists():
        raise RuntimeError(f"run failed (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    summary = json.loads((runs[-1] / "summary.json").read_text())
    stats = json.loads((runs[-1] / "simulator.json").read_text())
    ticks = max(1, int(stats.get("ticks", 0)))
    cpu = stats.get("loop_cpu_s") or {}
    # CPU per tick of each process in the loop: noisy hosts change the wall time, much less these
    cpu_ms = {k: (None if v is None else 1e3 * v / ticks) for k, v in cpu.items()}
    return {"cpu_ms_per_tick": cpu_ms, "exit_code": proc.returncode, "bus": summary["bus"], "simulated_s": summary["simulated_s"],
            "loop_wall_s": summary["wall_s"], "loop_speed_x": summary["speed_x_realtime"],
            "total_wall_s": wall, "end_to_end_speed_x": summary["simulated_s"] / wall,
            "cycle_done_timeouts": summary["simulator"]["cycle_done_timeouts"], "pass": summary["pass"]}


def one_run_vm(duration: float) -> dict:
    """One socketcan:vcan0 run inside the guest (this script with --rows-out, in the VM)."""
    with tempfile.NamedTemporaryFile(dir=ROOT / "bench" / "results", prefix=".vm-row-", suffix=".json") as tmp:
        cmd = [str(VCAN_VM), "--timeout", "3000", "--", sys.executable, __file__, "--bus", "socketcan:vcan0",
               "--duration", str(duration), "--repeat", "1", "--rows-out", tmp.name]
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        text = Path(tmp.name).read_text()
        if proc.returncode != 0 or not text:
            raise RuntimeError(f"guest run failed (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
        (row,) = json.loads(text)
    row["where"] = "vcan-vm guest (1 CPU)"
    return row


def _host_run(bus: str, duration: float) -> dict:
    out = Path(tempfile.mkdtemp(prefix="bench-sil-"))
    try:
        row = one_run(bus, duration, out)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    row["where"] = "host"
    return row


def _table(rows: list[dict]) -> None:
    print(f"{'bus':34s} {'where':22s} {'sim s':>6s} {'loop wall s':>11s} {'loop x':>7s} {'total wall s':>12s} "
          f"{'total x':>7s} {'host load':>9s}  CPU ms/tick: sim   fsw ground   sum")
    for r in rows:
        cpu = r.get("cpu_ms_per_tick") or {}
        parts = [cpu.get(k) for k in ("simulator", "fsw", "ground")]
        total = sum(parts) if parts and None not in parts else None
        cells = " ".join("     -" if v is None else f"{v:6.3f}" for v in (*parts, total))
        print(f"{r['bus']:34s} {r['where']:22s} {r['simulated_s']:6.0f} {r['loop_wall_s']:11.1f} "
              f"{r['loop_speed_x']:7.1f} {r['total_wall_s']:12.1f} {r['end_to_end_speed_x']:7.1f} "
              f"{r['host_load_1min']:9.1f}             {cells}")


GOAL_X = 100.0  # lockstep demo-pointing at >= 100x real time, over udp_multicast and socketcan


def _median_cpu(rows: list[dict]) -> dict:
    """Median CPU ms per tick of each process (and of their sum: the loop's wall time on one CPU)."""
    out = {}
    for k in ("simulator", "fsw", "ground"):
        values = [r["cpu_ms_per_tick"].get(k) for r in rows if r.get("cpu_ms_per_tick")]
        values = [v for v in values if v is not None]
        out[k] = statistics.median(values) if values else None
    sums = [sum(r["cpu_ms_per_tick"].values()) for r in rows
            if r.get("cpu_ms_per_tick") and None not in r["cpu_ms_per_tick"].values()]
    out["sum"] = statistics.median(sums) if sums else None
    return out


def _result(bus: str, duration: float, rows: list[dict]) -> dict:
    loop = statistics.median(r["loop_speed_x"] for r in rows)
    cpu = _median_cpu(rows)
    if cpu["sum"] is not None:
        print(f"{bus}: median CPU ms per tick: simulator {cpu['simulator']:.3f}, fsw {cpu['fsw']:.3f}, ground "
              f"{cpu['ground']:.3f}, sum {cpu['sum']:.3f}")
    total = statistics.median(r["end_to_end_speed_x"] for r in rows)
    print(f"{bus}: median loop speed x{loop:.1f} real time (goal >= {GOAL_X:.0f}), end to end x{total:.1f}; median host "
          f"load {statistics.median(r['host_load_1min'] for r in rows):.1f} on {os.cpu_count()} CPUs")
    return {"bus": bus, "duration_s": duration, "runs": rows, "median_loop_speed_x": loop,
            "median_end_to_end_speed_x": total, "median_cpu_ms_per_tick": cpu, "goal_x": GOAL_X, "goal_met": loop >= GOAL_X,
            "median_host_load_1min": statistics.median(r["host_load_1min"] for r in rows),
            "host_cpus": os.cpu_count(), "guest_cpus": 1 if bus.startswith("socketcan") else None}


def _write(result: dict) -> None:
    name = "sil-socketcan.json" if result["bus"].startswith("socketcan") else "sil.json"
    results = ROOT / "bench" / "results"
    results.mkdir(parents=True, exist_ok=True)
    (results / name).write_text(json.dumps(result, indent=1) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=600.0, help="simulated seconds per run (600: the whole demo)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--bus", default="udp_multicast")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--vm", action="store_true", help="run the socketcan:vcan0 variant inside vcan-vm")
    where.add_argument("--both", action="store_true",
                       help="alternate udp_multicast (host) and socketcan:vcan0 (vcan-vm) runs; write both results")
    parser.add_argument("--rows-out", type=Path, help=argparse.SUPPRESS)  # the guest's side of --vm/--both
    args = parser.parse_args(argv)
    if args.rows_out is not None:
        rows = [_host_run(args.bus, args.duration) for _ in range(args.repeat)]
        args.rows_out.write_text(json.dumps(rows))
        return 0
    kinds = ["udp_multicast", "socketcan:vcan0"] if args.both else ["socketcan:vcan0"] if args.vm else [args.bus]
    rows: dict[str, list[dict]] = {k: [] for k in kinds}
    for _ in range(args.repeat):
        for kind in kinds:
            row = one_run_vm(args.duration) if kind.startswith("socketcan") and (args.vm or args.both) \
                else _host_run(kind, args.duration)
            row["host_load_1min"] = os.getloadavg()[0]
            rows[kind].append(row)
    _table([r for kind in kinds for r in rows[kind]])
    for kind in kinds:
        _write(_result(kind, args.duration, rows[kind]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
