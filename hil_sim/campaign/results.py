"""The campaign's tables: one row per run (Parquet and CSV), JUnit XML, and the statistical verdict.

Columns: ``run``, ``status``, ``sim_seed``, ``wall_s``, ``sim_time_s``, ``error``, then one column per
dispersion parameter (``p.<dispersion>.<param>``, e.g. ``p.inertia.scale``, ``p.attitude.angle_deg``),
one per metric (``m.<metric>``) and one per criterion (``v.<criterion>``, True when it holds).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import pandas as pd

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.execute import STATUS_ERROR, STATUS_FAIL, STATUS_PASS, RunRecord
from hil_sim.campaign.spec import Campaign


def table(campaign: Campaign, records: Sequence[RunRecord]) -> pd.DataFrame:
    """One row per run, sorted by run index."""
    by_name = {d.name: d for d in campaign.dispersions}
    rows = []
    for r in sorted(records, key=lambda r: r.run):
        row: dict[str, object] = {"run": r.run, "status": r.status, "sim_seed": r.sim_seed, "wall_s": r.wall_s,
                                  "sim_time_s": r.sim_time_s, "error": r.error.splitlines()[0] if r.error else ""}
        for name, params in r.params.items():
            if name in by_name:
                row.update({f"p.{k}": v for k, v in dsp.features(by_name[name], params).items()})
        row.update({f"m.{k}": v for k, v in r.metrics.items()})
        for c in campaign.criteria:
            row[f"v.{c.name}"] = bool(r.verdicts.get(c.name, False))
        rows.append(row)
    return pd.DataFrame(rows)


def write_tables(df: pd.DataFrame, out_dir: Path) -> tuple[Path, Path]:
    parquet, csv = out_dir / "results.parquet", out_dir / "results.csv"
    df.to_parquet(parquet, index=False)
    df.to_csv(csv, index=False)
    return parquet, csv


# ---------------------------------------------------------------------------------------------
# Statistical verdict
# ---------------------------------------------------------------------------------------------

# Exit codes of `keepout campaign run|report` (documented in docs/campaign/README.md).
EXIT_PASS, EXIT_FAIL, EXIT_INCONCLUSIVE = 0, 1, 4


@dataclass(frozen=True)
class Verdict:
    """PASS: the lower confidence bound reaches the requirement. FAIL: some run failed and the bound does
    not reach it. INCONCLUSIVE: no run failed, but there are too few runs for the bound to reach the
    requirement even without a failure (``runs_needed``), so the campaign says nothing either way."""

    runs: int
    failures: int
    errors: int
    confidence: float
    required_success: float
    success_lower_bound: float  # one-sided Clopper-Pearson

    @property
    def passed(self) -> bool:
        return self.runs > 0 and self.success_lower_bound >= self.required_success

    @property
    def inconclusive(self) -> bool:
        return not self.passed and self.failures == 0

    @property
    def word(self) -> str:
        return "PASS" if self.passed else ("INCONCLUSIVE" if self.inconclusive else "FAIL")

    @property
    def exit_code(self) -> int:
        return EXIT_PASS if self.passed else (EXIT_INCONCLUSIVE if self.inconclusive else EXIT_FAIL)

    @property
    def runs_needed(self) -> int:
        return runs_needed(self.required_success, self.confidence)

    def text(self) -> str:
        req = (f"{100 * self.required_success:.1f} % at {100 * self.confidence:.0f} % confidence")
        if self.inconclusive:
            return (f"INCONCLUSIVE: 0 failed of {self.runs} runs, but {self.runs} runs without a failure can only "
                    f"show a success probability >= {100 * self.success_lower_bound:.2f} %; showing {req} needs "
                    f"at least {self.runs_needed} runs (--runs {self.runs_needed})")
        return (f"{self.word}: {self.failures} failed of {self.runs} runs ({self.errors} errors); success probability "
                f">= {100 * self.success_lower_bound:.2f} % at {100 * self.confidence:.0f} % confidence "
                f"(required {100 * self.required_success:.1f} %)")


def clopper_pearson_lower(successes: int, trials: int, confidence: float) -> float:
    """One-sided lower confidence bound on a binomial success probability (exact, Clopper-Pearson):
    the p with P(X >= successes | p) = 1 - confidence, i.e. Beta(1-confidence; s, n-s+1)."""
    if trials <= 0:
        return 0.0
    if successes <= 0:
        return 0.0
    from scipy.stats import binomtest
    ci = binomtest(successes, trials, alternative="greater").proportion_ci(confidence_level=confidence,
                                                                            method="exact")
    return float(ci.low)


def verdict(campaign: Campaign, records: Sequence[RunRecord]) -> Verdict:
    n = len(records)
    failures = sum(r.status in (STATUS_FAIL, STATUS_ERROR) for r in records)
    errors = sum(r.status == STATUS_ERROR for r in records)
    return Verdict(runs=n, failures=failures, errors=errors, confidence=campaign.verdict.confidence,
                   required_success=campaign.verdict.required_success,
                   success_lower_bound=clopper_pearson_lower(n - failures, n, campaign.verdict.confidence))


def runs_needed(required_success: float, confidence: float) -> int:
    """Runs without a failure needed to show ``required_success`` at ``confidence`` (59 for 95 %/95 %)."""
    return int(math.ceil(math.log(1.0 - confidence) / math.log(required_success)))


# ---------------------------------------------------------------------------------------------
# JUnit XML: one test case per (run, requirement), plus the campaign verdict
# ---------------------------------------------------------------------------------------------

def junit_xml(campaign: Campaign, records: Sequence[RunRecord], path: Path) -> Path:
    """Write JUnit XML in the structure Jenkins, GitLab and GitHub test reporters read."""
    suites = ET.Element("testsuites", name=f"campaign.{campaign.name}")
    total = fails = errs = 0
    total_time = 0.0
    for r in sorted(records, key=lambda r: r.run):
        suite = ET.SubElement(suites, "testsuite", name=f"{campaign.name}.run-{r.run:06d}")
        n = f = e = 0
        for c in campaign.criteria:
            case = ET.SubElement(suite, "testcase", name=c.name, classname=f"{campaign.name}.run-{r.run:06d}",
                                 time=_time(r.wall_s / max(1, len(campaign.criteria))))
            n += 1
            if r.status == STATUS_ERROR:
                err = ET.SubElement(case, "error", type="RunError", message=r.error.splitlines()[0] if r.error else "")
                err.text = r.error
                e += 1
            elif not r.verdicts.get(c.name, False):
                value = r.metrics.get(c.metric)
                fail = ET.SubElement(case, "failure", type="RequirementFailed",
                                     message=f"{c.text()} does not hold: {c.metric} = {value}")
                fail.text = f"run {r.run} (sim seed {r.sim_seed}); dispersed values: {r.values}"
                f += 1
        suite.set("tests", str(n))
        suite.set("failures", str(f))
        suite.set("errors", str(e))
        suite.set("time", _time(r.wall_s))
        total, fails, errs, total_time = total + n, fails + f, errs + e, total_time + r.wall_s
    v = verdict(campaign, records)
    failed = not v.passed and not v.inconclusive
    summary = ET.SubElement(suites, "testsuite", name=f"{campaign.name}.verdict", tests="1",
                            failures="1" if failed else "0", errors="0", skipped="1" if v.inconclusive else "0",
                            time=_time(0.0))
    case = ET.SubElement(summary, "testcase", name="success_probability", classname=f"{campaign.name}.verdict")
    if failed:
        ET.SubElement(case, "failure", type="StatisticalVerdict", message=v.text())
    elif v.inconclusive:  # not shown either way: too few runs (the exit code says so too)
        ET.SubElement(case, "skipped", type="InconclusiveVerdict", message=v.text())
    out = ET.SubElement(case, "system-out")
    out.text = v.text()
    suites.set("tests", str(total + 1))
    suites.set("failures", str(fails + (1 if failed else 0)))
    suites.set("errors", str(errs))
    suites.set("time", _time(total_time))
    ET.indent(suites)
    path.write_bytes(ET.tostring(suites, encoding="utf-8", xml_declaration=True))
    return path


def _time(seconds: float) -> str:
    # Surefire-style time: plain decimal seconds with at most 3 decimals.
    return f"{max(0.0, seconds):.3f}"


STATUSES = (STATUS_PASS, STATUS_FAIL, STATUS_ERROR)
