"""Compile every numerical kernel once, at install, so the first run afterwards starts flying at once.

    keepout warmup            # `make setup` runs it after `pip install` (cli/warmup.py)
    keepout warmup --prune    # `make wheel`: then drop cache files no current kernel loads

The GNC laws, zone distances, the assumption checks, the MEKF and the world's integrator are numba kernels
compiled with ``cache=True``: compiled once per machine and source version, then loaded from the cache
(``__pycache__`` beside the sources, see gnc/_numba_cache.py for the stamp and the places) in
milliseconds. Without this step the first ``keepout sil run`` after an install spends 15-80 s compiling
before its first tick (bench/first_run.py). This runs exactly what a run runs, on every shipped mission,
briefly: the load-time physics check (its verdict is kept too, `physics_checks.check_mission_cached`) and
a few seconds of the fast-mode closed loop (the same flight software and world as the SIL), so every
kernel is compiled with the argument types a run uses, whichever kernels the code has by then.

A built wheel ships these cache files (pyproject.toml's package data): `--prune` first removes those of
older sources, so the wheel holds only kernels its own sources compile to.
"""
from __future__ import annotations

import sys
import time


def warm(missions: list[str] | None = None, seconds: float = 2.0, out=sys.stdout) -> float:
    """Run the check and a short closed loop of each mission; returns the wall time [s]."""
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import load_mission
    from hil_sim.mission.physics_checks import check_mission_cached
    from keepout_config import config_path

    paths = sorted(config_path("missions").glob("*.yaml")) if not missions else list(missions)
    start = time.perf_counter()
    for k, path in enumerate(paths, 1):
        t0 = time.perf_counter()
        mission = load_mission(path)
        print(f"[{k}/{len(paths)}] {mission.name}: physics check ...", end="", file=out, flush=True)
        check_mission_cached(mission, refresh=True)  # a kept verdict would skip compiling the checks' kernels
        print(" closed loop ...", end="", file=out, flush=True)
        run_fast(mission.model_copy(update={"duration_s": seconds}), 0)
        print(f" ready ({time.perf_counter() - t0:.1f} s)", file=out, flush=True)
    from hil_sim.world.environment import compile_field_kernels

    compile_field_kernels()  # IGRF's field for a magnetometer, which no shipped mission flies
    return time.perf_counter() - start


def prune(out=sys.stdout) -> int:
    """Delete the packages' cache files that no current kernel loads; returns how many."""
    from gnc._numba_cache import stale_files

    stale = stale_files()
    for path in stale:
        path.unlink(missing_ok=True)
    print(f"removed {len(stale)} stale kernel cache file(s)", file=out, flush=True)
    return len(stale)
