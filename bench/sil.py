"""SIL speed: simulated seconds per wall second of `keepout sil run demo-pointing` in lockstep.

Each repetition is a full three-process run (simulator, flight software, ground monitor) of
config/missions/demo-pointing.yaml, shortened with --duration. Two figures per run:

* loop speed: simulated time / wall time of the lockstep loop (summary.json ``speed_x_realtime``),
  the SIL's sustained rate (goal >= 50x real time);
* end to end: simulated time / wall time of the whole command, including process start-up, numba
  cache loading, the physics checks, the summary and the plots.

Transports: udp_multicast on this host; socketcan:vcan0 inside ../shared/tools/vcan-vm (the host
kernel has no CAN), by re-running this script in the VM with --bus socketcan:vcan0.

    .venv/bin/python bench/sil.py [--duration 600] [--repeat 3] [--bus udp_multicast] [--vm]

Prints a table (medians) and writes bench/results/sil.json (sil-socketcan.json for the VM run).
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
VCAN_VM = ROOT.parent / "shared" / "tools" / "vcan-vm"


def one_run(bus: str, duration: float, out: Path) -> dict:
    cmd = [sys.executable, "-m", "hil_sim", "sil", "run", str(ROOT / "config" / "missions" / "demo-pointing.yaml"),
           "--bus", bus, "--duration", str(duration), "--out", str(out), "--no-progress"]
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    runs = sorted(out.glob("demo-pointing-*"), key=lambda p: p.stat().st_mtime)
    if not runs or not (runs[-1] / "summary.json").exists():
        raise RuntimeError(f"run failed (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    summary = json.loads((runs[-1] / "summary.json").read_text())
    return {"exit_code": proc.returncode, "bus": summary["bus"], "simulated_s": summary["simulated_s"],
            "loop_wall_s": summary["wall_s"], "loop_speed_x": summary["speed_x_realtime"],
            "total_wall_s": wall, "end_to_end_speed_x": summary["simulated_s"] / wall,
            "cycle_done_timeouts": summary["simulator"]["cycle_done_timeouts"], "pass": summary["pass"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=600.0, help="simulated seconds per run (600: the whole demo)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--bus", default="udp_multicast")
    parser.add_argument("--vm", action="store_true", help="run the socketcan:vcan0 variant inside vcan-vm")
    args = parser.parse_args(argv)
    if args.vm:
        cmd = [str(VCAN_VM), "--timeout", "3000", "--", sys.executable, __file__, "--bus", "socketcan:vcan0",
               "--duration", str(args.duration), "--repeat", str(args.repeat)]
        return subprocess.call(cmd, cwd=ROOT)
    out = Path(tempfile.mkdtemp(prefix="bench-sil-"))
    rows = []
    try:
        for _ in range(args.repeat):
            rows.append(one_run(args.bus, args.duration, out))
    finally:
        shutil.rmtree(out, ignore_errors=True)
    loop = statistics.median(r["loop_speed_x"] for r in rows)
    total = statistics.median(r["end_to_end_speed_x"] for r in rows)
    print(f"{'bus':34s} {'sim s':>6s} {'loop wall s':>11s} {'loop x':>7s} {'total wall s':>12s} {'total x':>7s}")
    for r in rows:
        print(f"{r['bus']:34s} {r['simulated_s']:6.0f} {r['loop_wall_s']:11.1f} {r['loop_speed_x']:7.1f} "
              f"{r['total_wall_s']:12.1f} {r['end_to_end_speed_x']:7.1f}")
    print(f"median loop speed x{loop:.1f} real time (goal >= 50), end to end x{total:.1f}; "
          f"host load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    result = {"bus": args.bus, "duration_s": args.duration, "runs": rows, "median_loop_speed_x": loop,
              "median_end_to_end_speed_x": total, "goal_x": 50.0, "goal_met": loop >= 50.0,
              "load_average_1min": os.getloadavg()[0], "cpus": os.cpu_count()}
    name = "sil-socketcan.json" if args.bus.startswith("socketcan") else "sil.json"
    results = ROOT / "bench" / "results"
    results.mkdir(parents=True, exist_ok=True)
    (results / name).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
