"""The first `keepout sil run` after an install: time to the first lockstep tick and total wall time.

The product as a user gets it: the wheel (`make wheel`: with the compiled kernels of its own sources,
gnc/_numba_cache.py) installed without extras into a fresh venv, `keepout sil run --duration D` from an
empty folder with an empty user cache (``XDG_CACHE_HOME``: no physics verdicts, no seeded kernels).
Scenarios, each a fresh process:

* ``cold``: nothing cached (``NUMBA_CACHE_DIR`` and ``KEEPOUT_EPHEMERIS_CACHE`` empty folders): every
  kernel compiles inside the run, as a wheel without shipped kernels did;
* ``first``: the first run from the wheel as installed (its shipped kernels and ephemeris nodes);
* ``second``: the same command again (the physics verdict now cached too);
* ``other-cpu`` (``--other-cpu``): ``NUMBA_CPU_NAME=generic``: the shipped kernels do not match, the run
  compiles (the fallback of a machine with another CPU).

Time to first tick: the run is started through ``python -c`` that wraps `hil_sim.sil.lockstep.Simulator.run_tick`
(and the physics check and the flight software's start, for the split) to print the wall clock of their
calls, then calls the ``keepout`` entry point (`cli.main.main`) with the same arguments; measured from
just before the process is started.

    .venv/bin/python bench/first_run.py [--wheel dist/keepout-*.whl] [--duration 120] [--other-cpu]

Prints a table and writes bench/results/first_run.json with the host load.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _results import write_result  # bench/_results.py: this script's folder is on sys.path

ROOT = Path(__file__).resolve().parents[1]
PROBE = """\
import sys, time
def mark(name):
    print(f"PHASE {name} {time.time():.6f}", file=sys.stderr, flush=True)
mark("python_started")
import hil_sim.sil.lockstep as lockstep, hil_sim.mission.physics_checks as checks, hil_sim.sil.orchestrator as sil
def wrap(owner, attr, before, after=None, once=False):
    real = getattr(owner, attr)
    def wrapper(*args, **kwargs):
        if not (once and getattr(wrapper, "seen", False)):
            wrapper.seen = True
            mark(before)
        result = real(*args, **kwargs)
        if after:
            mark(after)
        return result
    setattr(owner, attr, wrapper)
wrap(checks, "check_mission", "check_start", "check_end")
wrap(sil, "_start_fsw", "fsw_spawn")
wrap(lockstep.Simulator, "run_tick", "first_tick", once=True)
from cli.main import main
sys.argv[0] = "keepout"
mark("imports_done")
sys.exit(main(sys.argv[1:]))
"""


def build_wheel() -> Path:
    """`make wheel` (warm-up, stale cache files pruned, a clean build) and its wheel."""
    subprocess.run(["make", "-C", str(ROOT), "wheel"], check=True)
    return Path(sorted(glob.glob(str(ROOT / "dist" / "keepout-*.whl")))[-1])


def fresh_venv(wheel: Path, where: Path) -> tuple[Path, float]:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "venv", str(where)], check=True)
    subprocess.run([str(where / "bin" / "pip"), "install", "-q", str(wheel)], check=True)
    return where / "bin" / "python", time.perf_counter() - start


def _kernel_files(venv: Path, env: dict[str, str]) -> set[Path]:
    """Every compiled-kernel data file the run could load or write: the install's, NUMBA_CACHE_DIR's, the
    user cache's."""
    roots = [venv, Path(env["XDG_CACHE_HOME"])] + ([Path(env["NUMBA_CACHE_DIR"])] if env.get("NUMBA_CACHE_DIR") else [])
    return {p for root in roots if root.exists() for p in root.rglob("*.nbc")}


def one_run(python: Path, folder: Path, duration: float, env: dict[str, str]) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    args = ["sil", "run", "--duration", str(duration), "--no-progress"]
    load = os.getloadavg()[0]
    before = _kernel_files(python.parent.parent, env)
    t0 = time.time()
    proc = subprocess.run([str(python), "-c", PROBE, *args], cwd=folder, env=env, capture_output=True, text=True)
    total = time.time() - t0
    compiled = len(_kernel_files(python.parent.parent, env) - before)  # kernels compiled (and saved) by the run
    # seconds from the start of the command to each phase (check_*: absent when the verdict was kept)
    phases = {line.split()[1]: float(line.split()[2]) - t0 for line in proc.stderr.splitlines()
              if line.startswith("PHASE ")}
    summaries = sorted(folder.glob("runs/*/summary.json"), key=lambda p: p.stat().st_mtime)
    summary = json.loads(summaries[-1].read_text()) if summaries else {}
    if proc.returncode != 0 or "first_tick" not in phases:
        raise RuntimeError(f"run failed (exit {proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return {"first_tick_s": phases["first_tick"], "total_wall_s": total, "flying_wall_s": summary.get("wall_s"),
            "check_s": phases["check_end"] - phases["check_start"] if "check_end" in phases else 0.0,
            "phases_s": phases, "kernels_compiled": compiled, "pass": summary.get("pass"),
            "exit_code": proc.returncode, "host_load_1min": load}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--wheel", type=Path, help="a built wheel (default: `make wheel`)")
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--other-cpu", action="store_true", help="also the run of a machine with another CPU")
    ap.add_argument("--no-cold", action="store_true", help="leave out the cold run (it compiles every kernel)")
    args = ap.parse_args()
    wheel = args.wheel or build_wheel()
    load_before = os.getloadavg()
    work = Path(tempfile.mkdtemp(prefix="keepout-first-run-"))
    rows: dict[str, dict] = {}
    try:
        python, install_s = fresh_venv(wheel, work / "venv")
        base = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "KEEPOUT_", "PYTHON"))}
        base["XDG_CACHE_HOME"] = str(work / "user-cache")
        scenarios = [] if args.no_cold else [("cold", {"NUMBA_CACHE_DIR": str(work / "numba-empty"),
                                                       "KEEPOUT_EPHEMERIS_CACHE": str(work / "eph-empty"),
                                                       "KEEPOUT_PHYSICS_CACHE": "off"})]
        scenarios += [("first", {}), ("second", {})]
        if args.other_cpu:
            scenarios.append(("other-cpu", {"NUMBA_CPU_NAME": "generic", "KEEPOUT_PHYSICS_CACHE": "off"}))
        for name, extra in scenarios:
            rows[name] = one_run(python, work / name if name != "second" else work / "first", args.duration,
                                 {**base, **extra})
            print(f"{name}: first tick {rows[name]['first_tick_s']:.1f} s, total {rows[name]['total_wall_s']:.1f} s",
                  flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    load_after = os.getloadavg()
    print(f"\n`keepout sil run --duration {args.duration:g}` from {wheel.name} in a fresh venv (install {install_s:.0f} s), "
          f"host load {load_before[0]:.1f} -> {load_after[0]:.1f} on {os.cpu_count()} CPUs")
    print("| scenario | first tick [s] | of it: imports / physics check / to FSW start / FSW start [s] | total wall [s] "
          "| flying [s] | kernels compiled | load | pass |\n| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, r in rows.items():
        p = r["phases_s"]
        split = (f"{p['imports_done']:.1f} / {r['check_s']:.1f} / {p['fsw_spawn'] - p['imports_done'] - r['check_s']:.1f}"
                 f" / {p['first_tick'] - p['fsw_spawn']:.1f}")
        print(f"| {name} | {r['first_tick_s']:.1f} | {split} | {r['total_wall_s']:.1f} | {r['flying_wall_s']:.1f} | "
              f"{r['kernels_compiled']} | {r['host_load_1min']:.1f} | {r['pass']} |")
    result = {"command": f"keepout sil run --duration {args.duration:g}", "wheel": wheel.name,
              "wheel_bytes": wheel.stat().st_size, "install_s": install_s, "host_load_before": load_before,
              "host_load_after": load_after, "cpus": os.cpu_count(), "scenarios": rows}
    out = ROOT / "bench" / "results" / "first_run.json"
    print(f"wrote {write_result(out, result, indent=1).relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
