"""Speed of the paper's laws (gnc.laws).

Cases
- ``conic control(x)``: GradientLaw, the paper's seven S^3 cones, one state per call (states spread over
  S^3, a third of them in an eps-layer). Goal <= 10 us median.
- ``star control(x)``: StarShapedLaw with the paper's S^3 superellipsoid zone (tangent plane at g1),
  every state inside the eps-layer (0 < d_s(x, U) < eps), so every call needs the exact non-convex
  separation. Goals <= 25 us median, <= 75 us p99. The zone's own ``separation(x)`` on the same states is
  timed too, to show which part of the cost is the law and which is the zone (gnc.zones).
- ``conic control_batch``: 100,000 states, seven cones. Goal >= 2 million states/s.

Each single call is timed with perf_counter_ns (the ~0.1 us timer overhead is included). The machine is
shared, so the load average is recorded with the numbers.

Run: ``.venv/bin/python bench/laws.py`` (``--quick`` for fewer calls). Writes bench/results/laws.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from gnc.laws import GradientLaw, StarShapedLaw
from gnc.zones import ConicZone, paper_s3_star_zone

RESULTS = Path(__file__).resolve().parent / "results" / "laws.json"
GOALS = {"conic_median_us": 10.0, "star_median_us": 25.0, "star_p99_us": 75.0, "batch_states_per_s": 2.0e6}


def seven_cones() -> list:
    E = np.eye(4)
    return [ConicZone(a, np.pi / 12) for a in (E[1], E[2], E[3], -E[1], -E[2], -E[3], -E[0])]


def per_call_us(fn, states: np.ndarray, repeats: int) -> tuple[np.ndarray, float]:
    """Wall time of every call [us], and the mean CPU time per call of this process [us].

    On a shared, overloaded machine the wall time includes waiting for a core; the CPU time per call is
    what an idle core would give (it includes the timer calls).
    """
    for x in states[:50]:  # warm-up (JIT, caches)
        fn(x)
    samples = np.empty(repeats * len(states))
    k = 0
    clock = time.perf_counter_ns
    c0 = time.process_time()
    for _ in range(repeats):
        for x in states:
            t0 = clock()
            fn(x)
            samples[k] = clock() - t0
            k += 1
    cpu_us = (time.process_time() - c0) / samples.size * 1e6
    return samples / 1000.0, cpu_us


def layer_states(zone, eps: float, count: int, rng: np.random.Generator) -> np.ndarray:
    """States with 0 < d_s(x, U) < eps: boundary points pushed outward along random tangents, kept if in the layer."""
    out = []
    while len(out) < count:
        b = zone.boundary(4 * count)
        t = rng.normal(size=b.shape)
        t -= b * np.sum(t * b, axis=1, keepdims=True)
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        ang = rng.uniform(0.0, np.arccos(1.0 - eps), size=(len(b), 1))
        X = np.cos(ang) * b + np.sin(ang) * t
        d = zone.separation_batch(X)
        out.extend(X[(d > 0.0) & (d < eps)])
    return np.array(out[:count])


def summary(timing: tuple[np.ndarray, float]) -> dict:
    us, cpu_us = timing
    return {
        "cpu_mean_us": float(cpu_us),
        "median_us": float(np.median(us)),
        "p90_us": float(np.percentile(us, 90)),
        "p99_us": float(np.percentile(us, 99)),
        "calls": int(us.size),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    reps = 1 if args.quick else 5
    n_states = 500 if args.quick else 2000

    x_d = np.eye(4)[0]
    cones = seven_cones()
    grad = GradientLaw(x_d, cones, k1=1.0, eps=0.125)
    X = rng.normal(size=(n_states, 4))
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    X = X[[not any(z.contains(x) for z in cones) for x in X]]
    in_layer = np.mean([grad.diagnose(x).active_zone is not None for x in X])
    conic = summary(per_call_us(grad.control, X, reps))
    conic["fraction_in_layer"] = float(in_layer)

    zone = paper_s3_star_zone()
    star_law = StarShapedLaw(x_d, [zone], k1=1.0, kappa=1.0, eps=0.1)
    S = layer_states(zone, 0.1, n_states // 2, rng)
    star = summary(per_call_us(star_law.control, S, reps))
    zone_only = summary(per_call_us(zone.separation, S, reps))

    B = rng.normal(size=(100_000, 4))
    B /= np.linalg.norm(B, axis=1, keepdims=True)
    grad.control_batch(B[:10])
    times = []
    for _ in range(3 if args.quick else 7):
        t0 = time.perf_counter()
        grad.control_batch(B)
        times.append(time.perf_counter() - t0)
    batch_s = statistics.median(times)
    batch = {"states": 100_000, "median_s": batch_s, "states_per_s": 100_000 / batch_s}

    result = {
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "loadavg": os.getloadavg()},
        "goals": GOALS,
        "conic_control": conic,
        "star_control": star,
        "star_zone_separation_only": zone_only,
        "conic_control_batch": batch,
        "met": {
            "conic_median": conic["median_us"] <= GOALS["conic_median_us"],
            "star_median": star["median_us"] <= GOALS["star_median_us"],
            "star_p99": star["p99_us"] <= GOALS["star_p99_us"],
            "batch": batch["states_per_s"] >= GOALS["batch_states_per_s"],
        },
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")

    rows = [
        ("conic control(x), 7 cones", f"{conic['median_us']:.2f} us", f"{conic['p99_us']:.2f} us", "<= 10 us median", result["met"]["conic_median"]),
        ("star control(x), S^3 superellipsoid, in layer", f"{star['median_us']:.2f} us", f"{star['p99_us']:.2f} us", "<= 25 / 75 us", result["met"]["star_median"] and result["met"]["star_p99"]),
        ("  of which zone.separation(x) alone", f"{zone_only['median_us']:.2f} us", f"{zone_only['p99_us']:.2f} us", "", None),
        ("conic control_batch, 100,000 states", f"{batch['states_per_s'] / 1e6:.2f} M states/s", f"{batch_s * 1e3:.1f} ms", ">= 2 M/s", result["met"]["batch"]),
    ]
    cpu = ["%.2f us" % conic["cpu_mean_us"], "%.2f us" % star["cpu_mean_us"], "%.2f us" % zone_only["cpu_mean_us"], ""]
    print(f"{'case':48s} {'median':>16s} {'p99 / time':>12s} {'cpu mean':>10s}  {'goal':16s} met")
    for (name, med, p99, goal, met), c in zip(rows, cpu):
        print(f"{name:48s} {med:>16s} {p99:>12s} {c:>10s}  {goal:16s} {'' if met is None else ('yes' if met else 'NO')}")
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
