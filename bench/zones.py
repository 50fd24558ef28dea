"""Speed of the zone separations (gnc.zones), the cost every star-law call pays once per near zone.

Cases (one ``separation(x)`` call per state, timed with perf_counter_ns, timer overhead included):
- ``s3_star_layer``: the paper's S^3 superellipsoid zone (|p1|^0.4 + |p2|^0.4 + |p3|^0.4 <= 1.5 about
  g1, tangent plane), states in its eps-layer (0 < d_s < eps = 0.1). Goal: <= ~15 us median, so that the
  star law (one separation plus a few vector operations) stays within 25 us median / 75 us p99.
- ``s3_star_elsewhere``: the same zone, states uniform on S^3 (outside the zone; inside states cost
  one containment test only).
- ``s3_star_signed_layer``: ``signed_separation`` on the layer states.
- ``s2_star_polygon``: a 10-vertex star polygon on S^2 (closed form per edge), states uniform.
- ``s2_superellipse_layer``: q = 0.4 superellipse on S^2, states in its eps-layer (eps = 0.01).
- ``s3_cone``: a conic zone on S^3, states uniform (closed form, for reference).

The machine is shared (2 cores, many processes), so the load average is recorded, and next to the
wall-clock median / p99 the CPU time per call of this thread is given (what an idle core gives).
The search effort of the superellipsoid (cells scored, samples scored, Newton runs, Newton iterations)
is reported as means over the states.

Run: ``.venv/bin/python bench/zones.py`` (``--quick`` for fewer calls). Writes bench/results/zones.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from gnc.sphere import sample_uniform
from gnc.zones import ConicZone, StarZone, paper_s3_star_zone

RESULTS = Path(__file__).resolve().parent / "results" / "zones.json"
GOAL_S3_LAYER_MEDIAN_US = 15.0


def time_calls(fn, states: np.ndarray, repeats: int) -> dict:
    for x in states[:20]:  # warm-up: JIT compilation / cache load, CPU caches
        fn(x)
    wall = np.empty(repeats * len(states))
    cpu = np.empty_like(wall)
    clock = time.perf_counter_ns
    tclock = time.thread_time_ns
    k = 0
    for _ in range(repeats):
        for x in states:
            c0 = tclock()
            t0 = clock()
            fn(x)
            t1 = clock()
            c1 = tclock()
            wall[k] = t1 - t0
            cpu[k] = c1 - c0
            k += 1
    wall /= 1000.0
    cpu /= 1000.0
    return {
        "calls": int(wall.size),
        "median_us": float(np.median(wall)),
        "p90_us": float(np.percentile(wall, 90)),
        "p99_us": float(np.percentile(wall, 99)),
        "cpu_median_us": float(np.median(cpu)),
        "cpu_p99_us": float(np.percentile(cpu, 99)),
    }


def layer_states(zone, eps: float, count: int, rng: np.random.Generator) -> np.ndarray:
    """States with 0 < d_s(x, U) < eps, spread over S^n (rejection from uniform samples)."""
    out: list[np.ndarray] = []
    while len(out) < count:
        X = sample_uniform(zone.dim, 20 * count, rng)
        d = zone.separation_batch(X)
        out.extend(X[(d > 0.0) & (d < eps)])
    return np.array(out[:count])


def search_effort(zone: StarZone, states: np.ndarray) -> dict:
    stats = []
    for x in states:
        zone.nearest(x)
        stats.append(zone._stats.copy())
    s = np.array(stats, dtype=float)
    return {"cells_scored": float(s[:, 0].mean()), "samples_scored": float(s[:, 1].mean()),
            "newton_runs": float(s[:, 2].mean()), "newton_iterations": float(s[:, 3].mean()),
            "newton_iterations_max": int(s[:, 3].max())}


def star_polygon() -> StarZone:
    ang = 0.3 + np.pi * np.arange(10) / 5
    r = np.where(np.arange(10) % 2 == 0, 0.5, 0.18)
    return StarZone.polygon([0.2, 0.4, -0.9], None, np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer states and repeats")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    n_states, repeats = (300, 2) if args.quick else (1000, 5)
    rng = np.random.default_rng(2026)

    s3 = paper_s3_star_zone()
    s3_layer = layer_states(s3, 0.1, n_states, rng)
    s3_else = sample_uniform(4, n_states, rng)
    s3_else = s3_else[[not s3.contains(x) for x in s3_else]]
    poly = star_polygon()
    s2_poly_states = sample_uniform(3, n_states, rng)
    se2 = StarZone.superellipsoid([0.3, -0.5, 0.8], None, (0.6, 0.25), 0.4)
    se2_layer = layer_states(se2, 0.01, n_states, rng)
    cone = ConicZone([0.0, 0.0, 0.0, 1.0], np.pi / 12)

    cases = {
        "s3_star_layer": (s3.separation, s3_layer),
        "s3_star_elsewhere": (s3.separation, s3_else),
        "s3_star_signed_layer": (s3.signed_separation, s3_layer),
        "s2_star_polygon": (poly.separation, s2_poly_states),
        "s2_superellipse_layer": (se2.separation, se2_layer),
        "s3_cone": (cone.separation, s3_else),
    }
    results = {}
    for name, (fn, states) in cases.items():
        results[name] = time_calls(fn, states, repeats)
    results["s3_star_layer"]["search"] = search_effort(s3, s3_layer)
    results["s3_star_elsewhere"]["search"] = search_effort(s3, s3_else)
    results["s2_superellipse_layer"]["search"] = search_effort(se2, se2_layer)

    print(f"zone separation cost per call (load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cpus)")
    header = f"{'case':<24}{'calls':>7}{'median us':>11}{'p90 us':>9}{'p99 us':>9}{'cpu med':>9}{'cpu p99':>9}"
    print(header)
    print("-" * len(header))
    for name, r in results.items():
        print(f"{name:<24}{r['calls']:>7}{r['median_us']:>11.1f}{r['p90_us']:>9.1f}{r['p99_us']:>9.1f}"
              f"{r['cpu_median_us']:>9.1f}{r['cpu_p99_us']:>9.1f}")
    for name in ("s3_star_layer", "s3_star_elsewhere", "s2_superellipse_layer"):
        s = results[name]["search"]
        print(f"  {name}: cells {s['cells_scored']:.1f}, samples {s['samples_scored']:.0f}, Newton runs "
              f"{s['newton_runs']:.2f}, iterations {s['newton_iterations']:.1f} (max {s['newton_iterations_max']})")
    goal_met = results["s3_star_layer"]["median_us"] <= GOAL_S3_LAYER_MEDIAN_US
    print(f"goal s3_star_layer median <= {GOAL_S3_LAYER_MEDIAN_US} us: {'met' if goal_met else 'NOT met'}")

    payload = {
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "loadavg": list(os.getloadavg())},
        "goal": {"s3_star_layer_median_us": GOAL_S3_LAYER_MEDIAN_US, "met": bool(goal_met)},
        "states": {"count": n_states, "repeats": repeats, "eps_s3": 0.1, "eps_s2": 0.01},
        "results": results,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(payload, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
