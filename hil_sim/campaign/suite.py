"""A campaign suite: several campaigns (each its own base mission, dispersions and criteria) judged as one.

A release needs its promise shown over every shipped kind of mission at once: a pointing mission with a
door, the quaternion mission, the small satellite. A campaign has one base mission, so a suite lists
member campaign files and how many runs each flies; every member runs into its own folder under the
suite's (resumable, as any campaign), and the suite's verdict is the one-sided Clopper-Pearson bound on
the runs of all members together, each run judged by its own campaign's criteria. 0 failures in 2,995
runs shows 99.9 % at 95 % confidence.

    schema_version: 1
    name: release
    suite:
      - {campaign: release-pointing.yaml, runs: 1000}
      - {campaign: release-quaternion.yaml, runs: 1000}
    verdict: {confidence: 0.95, required_success: 0.999}
"""
from __future__ import annotations

import json
import re
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal

from pydantic import Field

from hil_sim.campaign.spec import NAME_PATTERN, Verdict, _Model
from keepout_config import config_path


class SuiteMember(_Model):
    """One campaign of the suite."""

    campaign: str = Field(description="campaign YAML, relative to the suite file")
    runs: int | None = Field(None, ge=1, le=1_000_000, description="runs of this member (default: its own)")


class Suite(_Model):
    """Campaigns judged together (see hil_sim.campaign.suite)."""

    schema_version: Literal[1] = Field(description="suite file format version (this is version 1)")
    name: str = Field(pattern=NAME_PATTERN, description="the output folder is named after it")
    description: str = ""
    suite: list[SuiteMember] = Field(min_length=1)
    verdict: Verdict = Field(default_factory=Verdict)


SUITE_SCHEMA_PATH = config_path("schema", "suite.schema.json")


def suite_json_schema() -> dict[str, Any]:
    """Draft-07 JSON Schema of a suite file (for editors, as the campaign schema)."""
    from hil_sim.mission.model import DRAFT07, _draft07
    raw = Suite.model_json_schema(ref_template="#/definitions/{model}")
    definitions = raw.pop("$defs", {})
    return {"$schema": DRAFT07, **_draft07(raw), "definitions": {k: _draft07(v) for k, v in sorted(definitions.items())}}


def write_suite_schema(path: str | Path = SUITE_SCHEMA_PATH) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(suite_json_schema(), indent=2) + "\n", encoding="utf-8")
    return path


def is_suite(path: str | Path) -> bool:
    """Whether a campaign file is a suite (a top-level ``suite`` key)."""
    from hil_sim.mission.loader import load_marked
    data = load_marked(path).data
    return isinstance(data, dict) and "suite" in data


def load_suite(path: str | Path) -> Suite:
    from hil_sim.mission.loader import load_model
    return load_model(path, Suite)


@dataclass
class MemberOutcome:
    name: str
    folder: Path
    runs: int
    failures: int
    errors: int
    wall_s: float
    verdict_text: str


@dataclass
class SuiteOutcome:
    suite: Suite
    members: list[MemberOutcome] = field(default_factory=list)

    def verdict(self):
        from hil_sim.campaign.results import Verdict as Result, clopper_pearson_lower
        n = sum(m.runs for m in self.members)
        failures = sum(m.failures for m in self.members)
        v = self.suite.verdict
        return Result(runs=n, failures=failures, errors=sum(m.errors for m in self.members),
                      confidence=v.confidence, required_success=v.required_success,
                      success_lower_bound=clopper_pearson_lower(n - failures, n, v.confidence))


RunMember = Callable[[Path, int | None, Path], dict[str, Any]]


def member_paths(suite: Suite, path: str | Path) -> list[Path]:
    """Each member's campaign file, relative to the suite file ``path``; a clear error for a missing one."""
    path = Path(path).resolve()
    out = []
    for member in suite.suite:
        campaign_path = (path.parent / member.campaign).resolve()
        if not campaign_path.is_file():
            raise FileNotFoundError(f"{path}: suite member '{member.campaign}' not found (looked for {campaign_path})")
        out.append(campaign_path)
    return out


def run_suite(suite: Suite, path: str | Path, out: Path, run_member: RunMember) -> SuiteOutcome:
    """Fly every member of ``suite`` (loaded from ``path``) with ``run_member(campaign file, runs, folder) ->
    finalized results`` (see `hil_sim.campaign.runner.finalize`) into ``out/<member name>``; write
    ``suite.json`` and a ``junit.xml`` holding every member's."""
    out.mkdir(parents=True, exist_ok=True)
    outcome = SuiteOutcome(suite)
    junits = []
    for member, campaign_path in zip(suite.suite, member_paths(suite, path)):
        folder = out / campaign_path.stem
        t0 = time.monotonic()
        results = run_member(campaign_path, member.runs, folder)
        v = results["verdict"]
        outcome.members.append(MemberOutcome(campaign_path.stem, folder, v.runs, v.failures, v.errors,
                                             time.monotonic() - t0, v.text()))
        junits.append(Path(results["junit"]))
    total = outcome.verdict()
    text = suite_text(total)
    (out / "suite.json").write_text(json.dumps({
        "suite": suite.name, "verdict": total.word, "text": text, "runs": total.runs,
        "failures": total.failures, "errors": total.errors, "success_lower_bound": total.success_lower_bound,
        "members": [{"campaign": m.name, "folder": m.folder.name, "runs": m.runs, "failures": m.failures,
                     "errors": m.errors, "wall_s": round(m.wall_s, 1), "verdict": m.verdict_text}
                    for m in outcome.members]}, indent=1) + "\n", encoding="utf-8")
    _merged_junit(suite, junits, total, out / "junit.xml")
    (out / "verdict.txt").write_text(text + "\n", encoding="utf-8")
    return outcome


def suite_text(total) -> str:
    """The verdict's sentence for a suite: the runs it needs are spread over the members' ``runs``."""
    return re.sub(r" \(--runs \d+\)$", " (over the members' runs)", total.text())


def _merged_junit(suite: Suite, junits: list[Path], total, path: Path) -> Path:
    """One JUnit file: every member's test suites, and the suite's own verdict."""
    merged = ET.Element("testsuites", name=f"suite.{suite.name}")
    tests = failures = errors = 0
    for junit in junits:
        root = ET.parse(junit).getroot()
        for ts in root.findall("testsuite"):
            merged.append(ts)
        tests += int(root.get("tests", "0"))
        failures += int(root.get("failures", "0"))
        errors += int(root.get("errors", "0"))
    failed = not total.passed and not total.inconclusive
    ts = ET.SubElement(merged, "testsuite", name=f"{suite.name}.verdict", tests="1", failures="1" if failed else "0",
                       errors="0", skipped="1" if total.inconclusive else "0", time="0.000")
    case = ET.SubElement(ts, "testcase", name="success_probability", classname=f"{suite.name}.verdict")
    if failed:
        ET.SubElement(case, "failure", type="StatisticalVerdict", message=suite_text(total))
    elif total.inconclusive:
        ET.SubElement(case, "skipped", type="InconclusiveVerdict", message=suite_text(total))
    ET.SubElement(case, "system-out").text = suite_text(total)
    merged.set("tests", str(tests + 1))
    merged.set("failures", str(failures + (1 if failed else 0)))
    merged.set("errors", str(errors))
    ET.indent(merged)
    path.write_bytes(ET.tostring(merged, encoding="utf-8", xml_declaration=True))
    return path
