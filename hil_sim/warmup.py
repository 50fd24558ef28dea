"""Compile every numerical kernel once, at install, so the first run afterwards starts flying at once.

    python -m hil_sim.warmup        # `make setup` runs it after `pip install`

The GNC laws, zone distances, the assumption checks, the MEKF and the world's integrator are numba kernels
compiled with ``cache=True``: compiled once per machine and source version, then loaded from numba's cache
(``__pycache__`` beside the sources, or ``NUMBA_CACHE_DIR``) in milliseconds. Without this step the first
``keepout sil run`` after an install spends 15-80 s compiling before its first tick (measured with an empty
``NUMBA_CACHE_DIR``; see docs/campaign/README.md). This runs exactly what a run runs, on every shipped
mission, briefly: the load-time physics check and a few seconds of the fast-mode closed loop (the same
flight software and world as the SIL), so every kernel is compiled with the argument types a run uses.
"""
from __future__ import annotations

import argparse
import sys
import time


def warm(missions: list[str] | None = None, seconds: float = 2.0, out=sys.stdout) -> float:
    """Run the check and a short closed loop of each mission; returns the wall time [s]."""
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission import load_mission
    from hil_sim.physics_checks import check_mission
    from keepout_config import config_path

    paths = sorted(config_path("missions").glob("*.yaml")) if not missions else list(missions)
    start = time.perf_counter()
    for k, path in enumerate(paths, 1):
        t0 = time.perf_counter()
        mission = load_mission(path)
        print(f"[{k}/{len(paths)}] {mission.name}: physics check ...", end="", file=out, flush=True)
        check_mission(mission)
        print(" closed loop ...", end="", file=out, flush=True)
        run_fast(mission.model_copy(update={"duration_s": seconds}), 0)
        print(f" ready ({time.perf_counter() - t0:.1f} s)", file=out, flush=True)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("missions", nargs="*", help="mission YAMLs (default: every shipped mission)")
    args = ap.parse_args(argv)
    print("compiling the numerical kernels once (later runs load them from numba's cache)", flush=True)
    total = warm(args.missions)
    print(f"kernels ready in {total:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
