"""The campaign report: plots, Markdown and HTML.

Plots (PNG, in ``report/``): per criterion a histogram and an empirical CDF of its metric with the
limit drawn; the worst runs' trajectories on the sphere with the keep-out zones; a scatter of the
first criterion's metric (the keep-out margin in the shipped campaigns) against every dispersed
parameter, failures in red. The verdict is statistical (Clopper-Pearson, see ``results.verdict``).
"""
from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from hil_sim.sil import skyplot
from hil_sim.campaign.execute import STATUS_ERROR, STATUS_FAIL, RunRecord
from hil_sim.campaign.results import Verdict
from hil_sim.campaign.spec import Campaign, Criterion

WORST_RUNS = 4


def slack(criterion: Criterion, value: float) -> float:
    """Distance to the limit on the passing side (negative: failing)."""
    if value is None or not math.isfinite(value):
        return -math.inf
    return value - criterion.limit if criterion.op in (">", ">=") else (
        criterion.limit - value if criterion.op in ("<", "<=") else -abs(value - criterion.limit))


# Unit of a metric or parameter column from its name's suffix (the project's naming convention).
_UNIT_SUFFIXES = (("_deg", "deg"), ("_s", "s"), ("_fraction", "-"), ("_rad_s", "rad/s"), ("_Nm", "N m"),
                  ("_days", "days"), ("_arcsec", "arcsec"), ("_events", "count"), ("_slips", "count"),
                  ("_commands", "count"), (".failed", "count"), ("scale", "-"), ("_utc", "-"))


def metric_unit(name: str, campaign: Campaign | None = None) -> str:
    """Unit of a metric or parameter column from its name's suffix (``min_margin_deg`` -> ``deg``); a
    dispersed parameter's component (``gyro_bias.0``, ``star_tracker_noise.value``) takes the unit of its
    mission path (``spacecraft.imu.bias_B_rad_s`` -> ``rad/s``)."""
    candidates = [name]
    if campaign is not None and "." in name:
        head, _, tail = name.partition(".")
        disp = next((d for d in campaign.dispersions if d.name == head), None)
        if disp is not None and (tail.isdigit() or tail == "value"):
            candidates.append(disp.path.split(".")[-1].split("[")[0])
    for candidate in candidates:
        for suffix, unit in sorted(_UNIT_SUFFIXES, key=lambda x: -len(x[0])):
            if candidate.endswith(suffix):
                return unit
    return "-"


def metric_label(name: str, campaign: Campaign | None = None) -> str:
    return f"{name} [{metric_unit(name, campaign)}]"


def worst_runs(campaign: Campaign, records: Sequence[RunRecord], count: int = WORST_RUNS) -> list[RunRecord]:
    """Errors first, then the smallest slack of the first criterion."""
    c = campaign.criteria[0]
    ranked = sorted(records, key=lambda r: (r.status != STATUS_ERROR, slack(c, r.metrics.get(c.metric, math.nan)),
                                            r.run))
    return ranked[:count]


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_distribution(df: pd.DataFrame, criterion: Criterion, path: Path) -> Path | None:
    plt = _plt()
    col = f"m.{criterion.metric}"
    if col not in df:
        return None
    values = df[col].to_numpy(dtype=float)
    finite = values[np.isfinite(values)]
    n_inf = int(values.size - finite.size)
    fig, (ax_h, ax_c) = plt.subplots(1, 2, figsize=(10, 3.6))
    unit = metric_unit(criterion.metric)
    unit = "" if unit in ("-", "count") else f" {unit}"
    limit_label = f"limit {criterion.op} {criterion.limit:g}{unit}"
    hist_range = histogram_range(finite, criterion.limit)
    if finite.size:
        ax_h.hist(finite, bins=min(40, max(5, int(np.sqrt(finite.size)) * 2)), range=hist_range, color="#4c72b0",
                  alpha=0.85)
        xs = np.sort(finite)
        ax_c.step(xs, np.arange(1, xs.size + 1) / values.size, where="post", color="#4c72b0")
    # the histogram spans the runs (and the limit only when it is near them), so the spread is visible; the
    # CDF beside it keeps the limit in view whatever the distance
    if hist_range is None or hist_range[0] <= criterion.limit <= hist_range[1]:
        ax_h.axvline(criterion.limit, color="#c44e52", lw=2, ls="--", label=limit_label)
    else:
        side = "below" if criterion.limit < hist_range[0] else "above"
        gap = abs(criterion.limit - (finite.min() if side == "below" else finite.max()))
        ax_h.plot([], [], color="#c44e52", lw=2, ls="--",
                  label=f"{limit_label}: off this scale, {gap:.3g}{unit} {side} the nearest run (CDF)")
    ax_c.axvline(criterion.limit, color="#c44e52", lw=2, ls="--", label=limit_label)
    for ax in (ax_h, ax_c):
        ax.set_xlabel(metric_label(criterion.metric))
        ax.grid(alpha=0.3)
    ax_h.set_ylabel("runs [count]")
    ax_c.set_ylabel("fraction of runs <= x [-]")
    ax_c.set_ylim(0, 1.02)
    ax_h.legend(loc="best", fontsize=8)
    title = f"{criterion.name}: {criterion.text()}"
    if n_inf:
        title += f"  ({n_inf} runs not finite, not drawn)"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def histogram_range(values: np.ndarray, limit: float) -> tuple[float, float] | None:
    """x range of a criterion's histogram: the runs' span with a 5 % pad, stretched to the limit only when
    the limit lies within one span of the runs (a limit at 0 beside margins of 8 to 9 deg left the runs a
    sliver at the right edge). None when there is nothing finite to draw."""
    if not np.size(values):
        return None
    lo, hi = float(np.min(values)), float(np.max(values))
    span = hi - lo if hi > lo else max(abs(hi) * 0.1, 1e-9)
    if lo - span <= limit <= hi + span:
        lo, hi = min(lo, limit), max(hi, limit)
        span = hi - lo
    pad = 0.05 * span
    return lo - pad, hi + pad


def plot_worst_trajectories(campaign: Campaign, worst: Sequence[RunRecord],
                            trajectories: dict[int, dict[str, np.ndarray]], path: Path) -> Path | None:
    """Boresight paths of the worst runs on the sky (Mollweide RA/Dec) with their keep-out zones."""
    shown = [(r, trajectories.get(r.run, {})) for r in worst]
    shown = [(r, t) for r, t in shown if _sphere_path(t) is not None]
    if not shown:
        return None
    plt = _plt()
    cols = min(len(shown), 2)
    rows = int(math.ceil(len(shown) / cols))
    fig = plt.figure(figsize=(6.4 * cols, 3.6 * rows))
    c = campaign.criteria[0]
    for k, (rec, traj) in enumerate(shown):
        ax = fig.add_subplot(rows, cols, k + 1, projection="mollweide")
        for key in sorted(traj):
            if key.startswith("zone_") and traj[key].ndim == 2 and traj[key].shape[1] == 3:
                skyplot.sky_line(ax, np.vstack([traj[key], traj[key][:1]]), color="#c44e52", lw=1.4,
                                 label="keep-out zone" if key == "zone_0" else None)
        x = _sphere_path(traj)
        skyplot.sky_line(ax, x, color="#4c72b0", lw=1.6, label="boresight")
        skyplot.sky_points(ax, x[:1], color="#55a868", s=25, zorder=3, label="start")
        if "target" in traj and np.asarray(traj["target"]).shape == (3,):
            skyplot.sky_points(ax, np.asarray(traj["target"]), color="k", marker="*", s=70, zorder=3,
                               label="final target")
        skyplot.format_full_sky(ax)
        ax.tick_params(labelsize=7)
        value = rec.metrics.get(c.metric, math.nan)
        ax.set_title(f"run {rec.run} [{rec.status}] {c.metric} = {value:.3g}", fontsize=9)
        if k == 0:
            ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("worst runs: instrument boresight on the sky (RA/Dec, Mollweide), zones at the end of the run",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _sphere_path(traj: dict[str, np.ndarray]) -> np.ndarray | None:
    for key in ("boresight_N", "x"):
        x = traj.get(key)
        if x is not None and x.ndim == 2 and x.shape[1] == 3 and x.shape[0] > 1:
            return x
    return None


def plot_scatter(df: pd.DataFrame, criterion: Criterion, path: Path, campaign: Campaign | None = None) -> Path | None:
    """The first criterion's metric against every dispersed parameter column."""
    col = f"m.{criterion.metric}"
    params = [c for c in df.columns if c.startswith("p.") and df[c].nunique(dropna=True) > 1]
    if col not in df or not params:
        return None
    plt = _plt()
    cols = min(3, len(params))
    rows = int(math.ceil(len(params) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    failed = df["status"].isin([STATUS_FAIL, STATUS_ERROR]).to_numpy()
    y = df[col].to_numpy(dtype=float)
    for ax, p in zip(axes.flat, params):
        x = df[p].to_numpy(dtype=float)
        ax.scatter(x[~failed], y[~failed], s=10, color="#4c72b0", label="pass")
        ax.scatter(x[failed], y[failed], s=16, color="#c44e52", marker="x", label="fail")
        ax.axhline(criterion.limit, color="#c44e52", ls="--", lw=1)
        ax.set_xlabel(metric_label(p[2:], campaign), fontsize=8)
        ax.set_ylabel(metric_label(criterion.metric), fontsize=8)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(params):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle(f"{criterion.metric} against each dispersed parameter", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_basin(campaign: Campaign, records: Sequence[RunRecord], starts: dict[int, np.ndarray],
               sample_traj: dict[str, np.ndarray], path: Path) -> Path | None:
    """Where the runs started (initial boresight, Mollweide RA/Dec) and whether they passed: the basin."""
    ok = [r for r in records if r.run in starts]
    if len(ok) < 2:
        return None
    plt = _plt()
    fig = plt.figure(figsize=(10, 5.4))
    ax = fig.add_subplot(111, projection="mollweide")
    for key in sorted(sample_traj):
        if key.startswith("zone_") and sample_traj[key].ndim == 2 and sample_traj[key].shape[1] == 3:
            skyplot.sky_points(ax, sample_traj[key], s=2, color="#c44e52")
    passed = np.array([r.status == "pass" for r in ok])
    start = np.array([starts[r.run] for r in ok])
    skyplot.sky_points(ax, start[passed], s=12, color="#4c72b0", label=f"converged ({int(passed.sum())})")
    skyplot.sky_points(ax, start[~passed], s=22, color="#c44e52", marker="x",
                       label=f"failed ({int((~passed).sum())})")
    if "target" in sample_traj and np.asarray(sample_traj["target"]).shape == (3,):
        skyplot.sky_points(ax, np.asarray(sample_traj["target"]), s=120, marker="*", color="k", label="target")
    skyplot.format_full_sky(ax)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(f"{campaign.name}: initial boresight (RA/Dec) of {len(ok)} runs; zones in red at the end "
                 "of one run", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _stats(df: pd.DataFrame, campaign: Campaign) -> list[tuple[str, str, str, str, str, str, str]]:
    rows = []
    for c in campaign.criteria:
        col = f"m.{c.metric}"
        if col not in df:
            rows.append((c.name, c.text(), "-", "-", "-", "-", "metric missing"))
            continue
        v = df[col].to_numpy(dtype=float)
        fin = v[np.isfinite(v)]
        fails = int((~df[f"v.{c.name}"]).sum())
        unit = metric_unit(c.metric)
        unit = "" if unit in ("-", "count") else f" {unit}"
        q = (lambda p: f"{np.percentile(fin, p):.4g}{unit}") if fin.size else (lambda p: "-")
        rows.append((c.name, f"{c.text()}{unit}", q(0), q(50), q(5), q(95), f"{fails}"))
    return rows


def write_report(campaign: Campaign, df: pd.DataFrame, records: Sequence[RunRecord], verdict: Verdict,
                 trajectories: dict[int, dict[str, np.ndarray]], out_dir: Path,
                 starts: dict[int, np.ndarray] | None = None) -> dict[str, Path]:
    """Write ``report/*.png``, ``report.md`` and ``report.html`` into ``out_dir``; return the paths."""
    rep = out_dir / "report"
    rep.mkdir(parents=True, exist_ok=True)
    plots: list[tuple[str, Path]] = []
    for c in campaign.criteria:
        p = plot_distribution(df, c, rep / f"distribution_{c.name}.png")
        if p:
            plots.append((f"{c.name}: histogram and CDF of {c.metric}", p))
    worst = worst_runs(campaign, records)
    p = plot_worst_trajectories(campaign, worst, trajectories, rep / "worst_trajectories.png")
    if p:
        plots.append(("worst runs on the sphere", p))
    p = plot_scatter(df, campaign.criteria[0], rep / f"scatter_{campaign.criteria[0].metric}.png", campaign)
    if p:
        plots.append((f"{campaign.criteria[0].metric} against the dispersed parameters", p))
    if starts:
        sample = next((t for t in trajectories.values() if t), {})
        p = plot_basin(campaign, records, starts, sample, rep / "basin.png")
        if p:
            plots.append(("basin: where runs start and whether they pass", p))

    stats = _stats(df, campaign)
    failing = [r for r in sorted(records, key=lambda r: r.run) if r.status != "pass"]
    md = [f"# Campaign `{campaign.name}`", "", campaign.description.strip(), "",
          f"**Verdict: {verdict.text()}**", "",
          f"Mode `{campaign.mode}`, master seed {campaign.master_seed}, {len(records)} runs.", "",
          "| requirement | predicate | min | median | p5 | p95 | failures |", "|---|---|---|---|---|---|---|"]
    md += [f"| {' | '.join(row)} |" for row in stats]
    md += ["", "## Plots", ""]
    md += [f"![{title}](report/{p.name})" for title, p in plots]
    md += ["", "## Worst runs", "", "| run | status | " + " | ".join(c.metric for c in campaign.criteria) + " |",
           "|---|---|" + "---|" * len(campaign.criteria)]
    for r in worst:
        md.append(f"| {r.run} | {r.status} | " + " | ".join(f"{r.metrics.get(c.metric, math.nan):.4g}"
                                                          for c in campaign.criteria) + " |")
    if failing:
        md += ["", f"## Failing runs ({len(failing)})", "",
               "Reproduce one with `keepout campaign rerun <this folder> --run N`; shrink it with "
               "`keepout campaign shrink <this folder> --run N`.", ""]
        for r in failing[:50]:
            why = r.error.splitlines()[0] if r.error else ", ".join(
                c.name for c in campaign.criteria if not r.verdicts.get(c.name, False))
            md.append(f"- run {r.run}: {r.status}: {why}")
    md_path = out_dir / "report.md"
    md_path.write_text("\n".join(md) + "\n", encoding="utf-8")

    body = [f"<h1>Campaign {html.escape(campaign.name)}</h1>",
            f"<p>{html.escape(campaign.description.strip())}</p>",
            f"<p><b>Verdict: {html.escape(verdict.text())}</b></p>",
            "<table border=1 cellpadding=4><tr><th>requirement</th><th>predicate</th><th>min</th><th>median</th>"
            "<th>p5</th><th>p95</th><th>failures</th></tr>"]
    body += ["<tr>" + "".join(f"<td>{html.escape(x)}</td>" for x in row) + "</tr>" for row in stats]
    body += ["</table>"]
    body += [f"<h3>{html.escape(t)}</h3><img src='report/{p.name}' style='max-width:100%'>" for t, p in plots]
    if failing:
        body += ["<h2>Failing runs</h2><ul>"] + [
            f"<li>run {r.run}: {html.escape(r.status)} {html.escape(r.error.splitlines()[0] if r.error else '')}</li>"
            for r in failing[:50]] + ["</ul>"]
    html_path = out_dir / "report.html"
    html_path.write_text("<!doctype html><html><head><meta charset='utf-8'><title>campaign "
                         f"{html.escape(campaign.name)}</title></head><body>" + "\n".join(body) + "</body></html>\n",
                         encoding="utf-8")
    return {"markdown": md_path, "html": html_path, **{p.stem: p for _, p in plots}}
