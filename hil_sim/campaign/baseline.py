"""Baselines: store a campaign's results, and compare a later campaign against them.

Two complementary checks per metric:

- paired, run by run: with the same campaign inputs (same fingerprint), run i of both campaigns had the
  same dispersions and noise seeds, so any difference beyond the metric's tolerance
  (``|new - old| > abs + rel |old|``) is a change in the software under test;
- distributional: a two-sample Kolmogorov-Smirnov test and a Mann-Whitney U test on the finite values
  (p < alpha flags a moved distribution), which also works when the inputs differ (other seeds or runs).

Any run that passed in the baseline and fails now is always a regression.

Which way is better comes from the campaign's criteria (``>``/``>=``: larger is better, ``<``/``<=``: smaller,
``==``: closer to the limit), then from the metric's known sense (``better`` argument); a metric that moved
only the better way is reported IMPROVED, not a regression. A moved metric whose better side is unknown
counts as a regression (a change nobody can judge must be looked at).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from hil_sim.campaign.spec import BaselinePolicy, Criterion, Tolerance

DEFAULT_REL = 1e-9
BASELINE_TABLE = "results.parquet"
BASELINE_META = "baseline.json"


def save_baseline(results_dir: Path, dest: Path) -> Path:
    """Copy a campaign's results table and identity into ``dest`` (a folder)."""
    src = results_dir / "results.parquet"
    if not src.exists():
        raise FileNotFoundError(f"{results_dir} has no results.parquet; run the campaign first")
    plan = json.loads((results_dir / "plan.json").read_text())
    dest.mkdir(parents=True, exist_ok=True)
    df = pd.read_parquet(src)
    df.to_parquet(dest / BASELINE_TABLE, index=False)
    (dest / BASELINE_META).write_text(json.dumps({**plan, "source": str(results_dir), "runs_in_table": len(df)},
                                                 indent=2) + "\n")
    return dest


def load_baseline(dest: Path) -> tuple[pd.DataFrame, dict]:
    if not (dest / BASELINE_TABLE).exists():
        raise FileNotFoundError(f"no baseline at {dest} (expected {BASELINE_TABLE}); "
                                "save one with `keepout campaign baseline save RESULTS_DIR`")
    return pd.read_parquet(dest / BASELINE_TABLE), json.loads((dest / BASELINE_META).read_text())


@dataclass
class MetricComparison:
    metric: str
    paired_runs: int
    runs_beyond_tolerance: int
    max_abs_diff: float
    ks_pvalue: float
    mw_pvalue: float
    baseline_median: float
    new_median: float
    flagged: bool
    reasons: list[str] = field(default_factory=list)
    better: str | None = None  # "higher" | "lower" | "closer:<limit>" | None (unknown)
    improved: bool = False  # flagged, and every change is toward the better side

    @property
    def regressed(self) -> bool:
        return self.flagged and not self.improved

    def verdict(self) -> str:
        if not self.flagged:
            return "ok"
        why = "; ".join(self.reasons)
        if self.improved:
            return f"IMPROVED ({_better_text(self.better)}): {why}"
        if self.better is None:
            return f"MOVED (no criterion says which way is better): {why}"
        return f"WORSE ({_better_text(self.better)}): {why}"


@dataclass
class Comparison:
    same_inputs: bool
    metrics: list[MetricComparison]
    new_failures: list[int]
    fixed_runs: list[int]

    @property
    def regressed(self) -> bool:
        return bool(self.new_failures) or any(m.regressed for m in self.metrics)

    def text(self) -> str:
        lines = [f"{'metric':28s} {'paired':>6s} {'beyond tol':>10s} {'max |diff|':>11s} {'KS p':>8s} "
                 f"{'MW p':>8s} {'median old':>11s} {'median new':>11s}  verdict"]
        for m in self.metrics:
            lines.append(f"{m.metric:28s} {m.paired_runs:6d} {m.runs_beyond_tolerance:10d} {m.max_abs_diff:11.4g} "
                         f"{m.ks_pvalue:8.3g} {m.mw_pvalue:8.3g} {m.baseline_median:11.4g} {m.new_median:11.4g}  "
                         + m.verdict())
        if not self.same_inputs:
            lines.append("note: the runs' seeds or dispersed values differ from the baseline's: per-run "
                         "differences are not meaningful, only the distribution tests count")
        if self.new_failures:
            lines.append(f"new failures (passed in the baseline): runs {self.new_failures}")
        if self.fixed_runs:
            lines.append(f"runs that failed in the baseline and pass now: {self.fixed_runs}")
        improved = [m.metric for m in self.metrics if m.improved]
        if self.regressed:
            lines.append("REGRESSION")
        elif improved:
            lines.append(f"no regression; improved: {', '.join(improved)}")
        else:
            lines.append("no regression beyond tolerance")
        return "\n".join(lines)


def _tolerance(policy: BaselinePolicy, metric: str) -> Tolerance:
    return policy.tolerances.get(metric, Tolerance(abs=0.0, rel=DEFAULT_REL))


def _beyond(old: np.ndarray, new: np.ndarray, tol: Tolerance) -> np.ndarray:
    both_nan = np.isnan(old) & np.isnan(new)
    same_inf = np.isinf(old) & np.isinf(new) & (np.sign(old) == np.sign(new))
    with np.errstate(invalid="ignore"):
        diff = np.abs(new - old)
        allowed = tol.abs + tol.rel * np.abs(old)
        out = ~(diff <= allowed)
    return out & ~both_nan & ~same_inf


def same_run_inputs(merged: pd.DataFrame, columns: list[str]) -> bool:
    """True when every paired run had the same simulation seed and the same dispersed parameters."""
    for col in ["sim_seed", *columns]:
        old, new = merged[f"{col}_old"].to_numpy(), merged[f"{col}_new"].to_numpy()
        if old.dtype.kind == "f" or new.dtype.kind == "f":
            if not np.array_equal(old.astype(float), new.astype(float), equal_nan=True):
                return False
        elif not np.array_equal(old, new):
            return False
    return len(merged) > 0


def better_sides(criteria: list[Criterion], known: dict[str, str] | None = None) -> dict[str, str]:
    """Metric -> which side is better: from the criteria first (``>``: "higher", ``<``: "lower", ``==``:
    "closer:<limit>"), then ``known`` (a run mode's own sense of its metrics) for metrics no criterion names."""
    out = dict(known or {})
    for c in criteria:
        out[c.metric] = ("higher" if c.op in (">", ">=") else "lower" if c.op in ("<", "<=")
                         else f"closer:{c.limit!r}")
    return out


def _score(values: np.ndarray, better: str) -> np.ndarray:
    """Larger score = better, whatever the metric's sense."""
    if better == "higher":
        return values
    if better == "lower":
        return -values
    limit = float(better.split(":", 1)[1])
    return -np.abs(values - limit)


def _better_text(better: str | None) -> str:
    if better is None:
        return "better side unknown"
    if better.startswith("closer:"):
        return f"closer to {float(better.split(':', 1)[1]):g} is better"
    return f"{'larger' if better == 'higher' else 'smaller'} is better"


def _only_better(o: np.ndarray, n: np.ndarray, beyond: np.ndarray, old_all: np.ndarray, new_all: np.ndarray,
                 better: str | None) -> bool:
    """Every paired run beyond tolerance moved to the better side, and the median did not get worse."""
    if better is None:
        return False
    with np.errstate(invalid="ignore"):
        worse = _score(n[beyond], better) < _score(o[beyond], better)
    if np.any(worse | ~np.isfinite(_score(n[beyond], better))):
        return False
    old_med, new_med = _median(_score(old_all, better)), _median(_score(new_all, better))
    if not (math.isfinite(old_med) and math.isfinite(new_med)):
        return False
    # flagged by the distribution tests alone: the median itself must have moved the better way
    return bool(new_med >= old_med) if beyond.any() else bool(new_med > old_med)


def compare(baseline: pd.DataFrame, new: pd.DataFrame, policy: BaselinePolicy,
            *, same_inputs: bool | None = None, better: dict[str, str] | None = None) -> Comparison:
    """Compare two results tables. ``same_inputs`` (default: decided from the tables) enables the paired,
    per-run check; it holds when each paired run had the same seed and the same dispersed parameters, so
    only the software or configuration under test differs. ``better``: metric -> "higher" | "lower" |
    "closer:<limit>" (see ``better_sides``); a move to the better side only is an improvement."""
    better = better or {}
    metrics = sorted(c for c in set(baseline.columns) & set(new.columns) if c.startswith("m."))
    merged = baseline.merge(new, on="run", suffixes=("_old", "_new"))
    if same_inputs is None:
        params = sorted(c for c in set(baseline.columns) & set(new.columns) if c.startswith("p."))
        same_params = set(c for c in baseline.columns if c.startswith("p.")) == \
            set(c for c in new.columns if c.startswith("p."))
        same_inputs = same_params and same_run_inputs(merged, params)
    out = []
    for col in metrics:
        name = col[2:]
        tol = _tolerance(policy, name)
        old_all = baseline[col].to_numpy(dtype=float)
        new_all = new[col].to_numpy(dtype=float)
        o = merged[f"{col}_old"].to_numpy(dtype=float)
        n = merged[f"{col}_new"].to_numpy(dtype=float)
        beyond = _beyond(o, n, tol) if same_inputs else np.zeros(o.size, dtype=bool)
        with np.errstate(invalid="ignore"):
            d = np.abs(n - o)
        d = d[np.isfinite(d)]
        ks_p, mw_p = _two_sample(old_all, new_all)
        reasons = []
        if beyond.any():
            reasons.append(f"{int(beyond.sum())} runs differ beyond abs {tol.abs:g} + rel {tol.rel:g}")
        if ks_p < policy.alpha:
            reasons.append(f"KS p = {ks_p:.3g} < {policy.alpha:g}")
        if mw_p < policy.alpha:
            reasons.append(f"Mann-Whitney p = {mw_p:.3g} < {policy.alpha:g}")
        side = better.get(name)
        out.append(MetricComparison(metric=name, paired_runs=int(o.size), runs_beyond_tolerance=int(beyond.sum()),
                                    max_abs_diff=float(d.max()) if d.size else 0.0, ks_pvalue=ks_p, mw_pvalue=mw_p,
                                    baseline_median=_median(old_all), new_median=_median(new_all),
                                    flagged=bool(reasons), reasons=reasons, better=side,
                                    improved=bool(reasons) and _only_better(o, n, beyond, old_all, new_all, side)))
    failed_old = merged["status_old"] != "pass"
    failed_new = merged["status_new"] != "pass"
    return Comparison(same_inputs=same_inputs, metrics=out,
                      new_failures=sorted(merged.loc[failed_new & ~failed_old, "run"].astype(int).tolist()),
                      fixed_runs=sorted(merged.loc[failed_old & ~failed_new, "run"].astype(int).tolist()))


def _two_sample(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if a.size < 2 or b.size < 2:
        return 1.0, 1.0
    if np.array_equal(np.sort(a), np.sort(b)):
        return 1.0, 1.0  # identical samples: the tests' p-values are exactly 1 by definition
    from scipy.stats import ks_2samp, mannwhitneyu
    ks = ks_2samp(a, b)
    try:
        mw = mannwhitneyu(a, b, alternative="two-sided")
        mw_p = float(mw.pvalue)
    except ValueError:  # all values identical across both samples
        mw_p = 1.0
    return float(ks.pvalue), mw_p if math.isfinite(mw_p) else 1.0


def _median(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else math.nan
