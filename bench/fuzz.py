"""Fuzzing at volume: telecommands, CAN frames, mission files and telemetry packets, counting crashes.

    .venv/bin/python bench/fuzz.py --jobs 2         # 1e6 TC, 1e6 CAN, 1e5 missions, 1e6 TM (~25 min, 2 CPUs)
    .venv/bin/python bench/fuzz.py --scale 0.01     # a quick look

The targets and input generators are those of the hypothesis suite (tests/fuzz/fuzz_kit.py): the flight
dispatcher with link security and the real command handlers, the flight bus receiver (lockstep and real
time), the ground's telemetry path (with and without link security) and the mission loader on files.
A crash is any exception out of the entry point (for the loader: anything but ConfigError); a hang is an
input that takes longer than --hang-s (interrupted by SIGALRM, counted as a crash). After a crash the
target is rebuilt, so one bad input cannot hide the next. Each target's inputs are cut into chunks (own
seed, own target instance), run by --jobs worker processes. Prints a table and writes
bench/results/fuzz.json (counts, outcomes, rates, the slowest input, up to 5 crash samples per target
with the input in hex, and the host load).
"""
from __future__ import annotations

import argparse
import collections
import json
import multiprocessing
import os
import random
import signal
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "fuzz"))  # fuzz_kit: the targets, shared with the hypothesis suite

from fuzz_kit import CanTarget, MissionTarget, TcTarget, TmTarget  # noqa: E402

FULL = {"telecommands": 1_000_000, "can_frames": 1_000_000, "mission_files": 100_000, "telemetry_packets": 1_000_000}
CHUNKS = {"telecommands": 4, "can_frames": 4, "mission_files": 10, "telemetry_packets": 4}
ORDER = ("telecommands", "can_frames", "mission_files", "telemetry_packets")


class Hang(Exception):
    """An input ran longer than the hang limit."""


def _on_alarm(signum, frame):  # noqa: ARG001
    raise Hang("input ran longer than the hang limit")


def _input_hex(item) -> str:
    if isinstance(item, (bytes, bytearray)):
        return bytes(item[:256]).hex()
    return repr(item)[:512]  # a can.Message


def _make(name: str, folder: str):
    return {"telecommands": TcTarget, "can_frames": CanTarget, "telemetry_packets": TmTarget,
            "mission_files": lambda: MissionTarget(folder)}[name]()


def _chunk(job: tuple) -> tuple[str, dict]:
    """One chunk in a worker process: (target name, inputs, seed, hang limit, folder for files)."""
    name, n, seed, hang_s, folder = job
    warnings.simplefilter("ignore")  # numpy overflow warnings from hostile values are expected, not news
    signal.signal(signal.SIGALRM, _on_alarm)
    chunk_folder = tempfile.mkdtemp(dir=folder)
    result = fuzz(name, lambda: _make(name, chunk_folder), n, seed, hang_s, report_every=0)
    print(f"  {name}: chunk of {n} (seed {seed}) done, {result['crashes']} crashes, "
          f"{result['inputs_per_s']:,.0f}/s", file=sys.stderr, flush=True)
    return name, result


def _merge(parts: list[dict]) -> dict:
    out = {"inputs": sum(p["inputs"] for p in parts), "crashes": sum(p["crashes"] for p in parts),
           "hangs": sum(p["hangs"] for p in parts), "crash_sites": collections.Counter(), "samples": [],
           "wall_s": sum(p["wall_s"] for p in parts), "chunks": len(parts), "seeds": [p["seed"] for p in parts],
           "outcomes": collections.Counter()}
    for p in parts:
        out["crash_sites"].update(p["crash_sites"])
        out["samples"] += p["samples"][:max(0, 5 - len(out["samples"]))]
        out["outcomes"].update(p["outcomes_of_last_target"])
    slowest = max(parts, key=lambda p: p["slowest_input_ms"])
    out.update(slowest_input_ms=slowest["slowest_input_ms"], slowest_input_hex=slowest["slowest_input_hex"],
               inputs_per_s=out["inputs"] / out["wall_s"] if out["wall_s"] > 0 else None,
               crash_sites=dict(out["crash_sites"]), outcomes=dict(out["outcomes"]))
    return out


def fuzz(name: str, make, n: int, seed: int, hang_s: float, report_every: int) -> dict:
    rng = random.Random(seed)
    target = make()
    crashes, hangs, samples = 0, 0, []
    sites: collections.Counter[str] = collections.Counter()
    slowest = (0.0, "")
    start = time.perf_counter()
    for i in range(n):
        item = target.generate(rng)
        t0 = time.perf_counter()
        signal.setitimer(signal.ITIMER_REAL, hang_s)
        try:
            target.feed(item)
        except Exception as exc:  # noqa: BLE001 - that is what is counted
            signal.setitimer(signal.ITIMER_REAL, 0)
            crashes += 1
            hangs += isinstance(exc, Hang)
            tb = traceback.extract_tb(exc.__traceback__)
            site = f"{type(exc).__name__} at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else type(exc).__name__
            sites[site] += 1
            if len(samples) < 5:
                samples.append({"index": i, "exception": f"{type(exc).__name__}: {exc}"[:300], "site": site,
                                "input_hex": _input_hex(item)})
            try:
                target.close()
            except Exception:  # noqa: BLE001
                pass
            target = make()
            continue
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        dt = time.perf_counter() - t0
        if dt > slowest[0]:
            slowest = (dt, _input_hex(item)[:160])
        if report_every and (i + 1) % report_every == 0:
            rate = (i + 1) / (time.perf_counter() - start)
            print(f"  {name}: {i + 1}/{n}, {crashes} crashes, {rate:,.0f}/s", file=sys.stderr, flush=True)
    wall = time.perf_counter() - start
    outcomes = dict(getattr(target, "outcomes", {}) or {})
    target.close()
    return {"inputs": n, "crashes": crashes, "hangs": hangs, "crash_sites": dict(sites), "samples": samples,
            "wall_s": wall, "inputs_per_s": n / wall if wall > 0 else None, "slowest_input_ms": 1e3 * slowest[0],
            "slowest_input_hex": slowest[1], "outcomes_of_last_target": outcomes, "seed": seed}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scale", type=float, default=1.0, help="fraction of the full counts (default 1)")
    p.add_argument("--only", choices=sorted(FULL), action="append", help="run only these targets")
    p.add_argument("--seed", type=int, default=20261125)
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--hang-s", type=float, default=10.0, help="an input taking longer is a hang (crash)")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "fuzz.json")
    args = p.parse_args(argv)
    load_before = os.getloadavg()
    started = time.perf_counter()
    results: dict = {"date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "host": os.uname().nodename,
                     "host_cpus": os.cpu_count(), "host_loadavg_before": load_before, "jobs": args.jobs,
                     "command": "bench/fuzz.py " + " ".join(argv if argv is not None else sys.argv[1:]),
                     "targets": {}}
    shm = Path("/dev/shm") if Path("/dev/shm").is_dir() else None  # mission files on tmpfs: no disk
    with tempfile.TemporaryDirectory(dir=shm) as folder:
        jobs = []
        for t, name in enumerate(ORDER):
            if args.only and name not in args.only:
                continue
            n = max(1, int(FULL[name] * args.scale))
            k = min(CHUNKS[name], n)
            jobs += [(name, n // k + (c < n % k), args.seed + 1000 * t + c, args.hang_s, folder) for c in range(k)]
        print(f"{len(jobs)} chunks on {args.jobs} worker(s)", file=sys.stderr, flush=True)
        parts: dict[str, list[dict]] = collections.defaultdict(list)
        planned = collections.Counter(job[0] for job in jobs)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with multiprocessing.get_context("fork").Pool(args.jobs) as pool:
            for name, part in pool.imap_unordered(_chunk, jobs):
                parts[name].append(part)
                # written after every chunk: an interrupted run still leaves what it measured
                for done in ORDER:
                    if done in parts:
                        results["targets"][done] = {**_merge(parts[done]),
                                                    "complete": len(parts[done]) == planned[done]}
                results["host_loadavg_after"] = os.getloadavg()
                results["wall_s"] = time.perf_counter() - started
                args.out.write_text(json.dumps(results, indent=1) + "\n")
    print()
    print(f"{'target':<18} {'inputs':>10} {'crashes':>8} {'hangs':>6} {'inputs/s/CPU':>13} {'slowest ms':>11}  outcomes")
    for name, r in results["targets"].items():
        top = sorted(r["outcomes"].items(), key=lambda kv: -kv[1])[:4]
        print(f"{name:<18} {r['inputs']:>10,} {r['crashes']:>8} {r['hangs']:>6} {r['inputs_per_s']:>13,.0f} "
              f"{r['slowest_input_ms']:>11.1f}  " + ", ".join(f"{k} {v}" for k, v in top))
        for site, count in r["crash_sites"].items():
            print(f"    crash x{count}: {site}")
    print(f"host: {results['host_cpus']} CPUs, {args.jobs} worker(s), {results['wall_s']:.0f} s wall; load average "
          f"{load_before[0]:.1f} before, {results['host_loadavg_after'][0]:.1f} after")
    print(f"wrote {args.out.relative_to(ROOT) if args.out.is_relative_to(ROOT) else args.out}")
    return 0 if all(r["crashes"] == 0 for r in results["targets"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
