"""The campaign file: a base mission, its dispersions, how many runs, the seed, the mode and the pass criteria.

A campaign YAML is validated like a mission (pydantic v2, ``extra="forbid"``, every problem reported as
``file:line:col key.path: message`` by ``hil_sim.mission.loader``). Dispersions name key paths into the
mission model, e.g. ``spacecraft.inertia_B_kgm2`` or ``timeline[1].target_N``; a path that does not exist
in the base mission is reported at load time with the keys that do exist there.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, model_validator

from comms.dictionary import FDIR_MONITORS
from hil_sim.devices.faults import FAULT_KINDS
from keepout_config import config_path

SCHEMA_VERSION = 1
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
PATH_DESCRIPTION = ("key path into the mission, dots between keys and [i] for list items, "
                    "e.g. spacecraft.inertia_B_kgm2 or timeline[1].target_N")


class _Model(BaseModel):
    # allow_inf_nan=False: a NaN or inf bound or sigma would draw NaN missions
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


# ---------------------------------------------------------------------------------------------
# Scalar distributions (also used inside compound dispersions)
# ---------------------------------------------------------------------------------------------

class _Bounded(_Model):
    """A distribution with bounds ``low`` and ``high``, declared by the subclass (so its field order,
    hence its schema, stays its own); an empty or reversed interval is rejected."""

    @model_validator(mode="after")
    def _ordered(self) -> "_Bounded":
        if not self.high > self.low:  # type: ignore[attr-defined]
            raise ValueError(f"high ({self.high}) must be greater than low ({self.low})")  # type: ignore[attr-defined]
        return self


class Uniform(_Bounded):
    """Uniform on [low, high]."""

    dist: Literal["uniform"]
    low: float
    high: float


class Normal(_Model):
    """Gaussian N(mean, sigma^2)."""

    dist: Literal["normal"]
    mean: float = 0.0
    sigma: float = Field(gt=0)


class ClippedNormal(_Bounded):
    """Gaussian N(mean, sigma^2) clipped to [low, high] (draws beyond a bound land on the bound)."""

    dist: Literal["clipped_normal"]
    mean: float = 0.0
    sigma: float = Field(gt=0)
    low: float
    high: float


ScalarDistribution = Annotated[Union[Uniform, Normal, ClippedNormal], Field(discriminator="dist")]


# ---------------------------------------------------------------------------------------------
# Dispersions: each one draws a value and writes it at ``path`` in the mission
# ---------------------------------------------------------------------------------------------

class _Dispersion(_Model):
    name: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,47}$",
                      description="column name in the results table; also keys this dispersion's own seed, "
                      "so adding or removing another dispersion never changes this one's draws")
    path: str = Field(min_length=1, description=PATH_DESCRIPTION)
    also_paths: list[str] = Field(default_factory=list, description="the same value is written at these paths "
                                  "too, e.g. flight_software.epoch_utc next to epoch_utc")


class ScalarDispersion(_Dispersion):
    """A number: set to the draw, or add it to / multiply the nominal by it."""

    kind: Literal["scalar"]
    distribution: ScalarDistribution
    apply: Literal["set", "add", "multiply"] = Field(
        "set", description="set: value = draw; add: nominal + draw; multiply: nominal * draw")


class VectorDispersion(_Dispersion):
    """A vector (or a flat list) drawn per component with one distribution each (or one for all)."""

    kind: Literal["vector"]
    distribution: ScalarDistribution | list[ScalarDistribution]
    apply: Literal["set", "add", "multiply"] = "add"


class DirectionDispersion(_Dispersion):
    """A unit vector: uniform on the whole sphere, or uniform in a cap around the nominal direction."""

    kind: Literal["direction"]
    cone_half_angle_deg: float | None = Field(
        None, gt=0, le=180, description="uniform in the cap of this half-angle around the nominal direction "
        "(omit: uniform on the whole sphere)")


class AttitudeDispersion(_Dispersion):
    """A unit quaternion (scalar first): uniform on SO(3), or a rotation of random axis and bounded angle
    applied to the nominal (q = q_nominal * dq, i.e. about body axes)."""

    kind: Literal["attitude"]
    max_angle_deg: float | None = Field(
        None, gt=0, le=180, description="uniform rotation angle in [0, max] about a uniformly random axis "
        "(omit: uniform on SO(3))")


class InertiaDispersion(_Dispersion):
    """A 3x3 inertia matrix: J = s R J_nominal R^T, with s a scale draw and R a small misalignment
    (rotation vector with components N(0, misalignment_sigma_deg^2))."""

    kind: Literal["inertia"]
    scale: ScalarDistribution | None = Field(None, description="scale factor s on every element")
    misalignment_sigma_deg: float = Field(0.0, ge=0, le=30, description="per-axis 1-sigma of the principal "
                                          "axes misalignment rotation vector [deg]")


class EpochDispersion(_Dispersion):
    """An instant uniform in [start, end]: moves the Sun and Moon (ISO-8601 UTC strings)."""

    kind: Literal["epoch"]
    start_utc: str = Field(description="ISO 8601 with a zone, e.g. 2026-01-01T00:00:00Z")
    end_utc: str

    @model_validator(mode="after")
    def _ordered(self) -> "EpochDispersion":
        from datetime import datetime
        try:
            start = datetime.fromisoformat(self.start_utc.replace("Z", "+00:00"))
            end = datetime.fromisoformat(self.end_utc.replace("Z", "+00:00"))
        except ValueError as exc:
            raise ValueError(f"start_utc/end_utc must be ISO 8601: {exc}") from None
        if start.tzinfo is None or end.tzinfo is None:
            raise ValueError("give start_utc and end_utc with a time zone (e.g. a trailing Z)")
        if not end > start:
            raise ValueError("end_utc must be after start_utc")
        return self


class ChoiceDispersion(_Dispersion):
    """One of a list of values (any YAML value), with optional probabilities."""

    kind: Literal["choice"]
    values: list[Any] = Field(min_length=1)
    probabilities: list[float] | None = None

    @model_validator(mode="after")
    def _probabilities(self) -> "ChoiceDispersion":
        if self.probabilities is not None:
            if len(self.probabilities) != len(self.values) or any(p < 0 for p in self.probabilities):
                raise ValueError("probabilities: one non-negative number per value")
            if not math.isclose(sum(self.probabilities), 1.0, abs_tol=1e-9):
                raise ValueError(f"probabilities must sum to 1 (they sum to {sum(self.probabilities)})")
        return self


class WheelFailureDispersion(_Dispersion):
    """Fail each wheel independently with a probability (at most ``max_failed``), from a random time.

    The failure is appended as faults to the list at ``path`` (normally ``faults``), composed with the base
    mission's own. By default the wheel's command frames stop reaching it (``message_template`` with {n} =
    1-based wheel number), so the wheel device's command timeout zeroes its torque, as a dead drive
    electronics would; ``fault_kind`` wheel_stuck / wheel_no_torque fail the mechanism itself instead.
    """

    kind: Literal["wheel_failure"]
    n_wheels: int = Field(ge=1, le=6)
    probability: float = Field(gt=0, le=1, description="per wheel, independent")
    max_failed: int = Field(1, ge=1, le=6)
    start_s: ScalarDistribution = Field(description="failure onset, simulated time [s]")
    fault_kind: Literal["drop", "silent", "wheel_stuck", "wheel_no_torque"] = Field(
        "drop", description="drop / silent: the wheel's frames (message_template); wheel_stuck / wheel_no_torque: the "
        "wheel itself fails (seized bearing, dead motor) at the drawn time")
    message_template: str = Field("RW{n}_CMD", description="DBC message of wheel n (1-based)")
    fault_kinds: list[Literal["drop", "silent", "wheel_stuck", "wheel_no_torque"]] | None = Field(
        None, min_length=1, description="draw each failed wheel's kind uniformly from this list instead of "
        "fault_kind (silent then names the wheel's RWn_STATUS, the others its RWn_CMD; message_template is unused)")
    independent_starts: bool = Field(False, description="each failed wheel draws its own onset from start_s "
                                     "(false: all fail at one drawn time)")
    expected_fdir_event: Literal[FDIR_MONITORS] | None = Field(  # type: ignore[valid-type]
        "WHEEL_FAULT", description="FDIR monitor that must trip in a run where a failure was drawn (added to the "
        "run's requirements.expected_fdir_events, so the isolation is expected and its absence fails); "
        "null: none expected")
    detection_s: float = Field(5.0, ge=0, description="a failure starting less than this before the end of the run "
                               "expects no event (the wheel's command timeout and FDIR persistence take time) [s]")


class FaultTemplate(_Model):
    """A mission fault (see the mission's ``faults``) without its window: the dispersion draws the onset."""

    kind: Literal[FAULT_KINDS] = Field(  # type: ignore[valid-type]
        description="a mission fault kind (drop, delay, ..., door_stuck_open, wheel_stuck, ...)")
    message: str = Field(description="DBC message, as in the mission's faults")
    duration_s: float | None = Field(None, gt=0, description="window length [s]; omit: to the end of the run")
    delay_s: float | None = Field(None, gt=0)
    bit: int | None = Field(None, ge=0, le=63)
    probability: float = Field(1.0, gt=0, le=1, description="per frame, as in the mission's faults")


class FaultDispersion(_Dispersion):
    """With probability ``probability``, one fault drawn uniformly from ``faults`` and appended to the list at
    ``path`` (normally ``faults``, composed with the base mission's own), from an onset drawn from
    ``start_s``: bus, sensor, door or wheel faults at any time of the run."""

    kind: Literal["fault"]
    faults: list[FaultTemplate] = Field(min_length=1)
    probability: float = Field(1.0, gt=0, le=1, description="chance that a run gets a fault at all")
    start_s: ScalarDistribution = Field(description="fault onset, simulated time [s]")


Dispersion = Annotated[Union[ScalarDispersion, VectorDispersion, DirectionDispersion, AttitudeDispersion,
                             InertiaDispersion, EpochDispersion, ChoiceDispersion, WheelFailureDispersion,
                             FaultDispersion],
                       Field(discriminator="kind")]


# ---------------------------------------------------------------------------------------------
# Pass criteria, verdict, baseline tolerances
# ---------------------------------------------------------------------------------------------

class Condition(_Model):
    """``metric op limit`` on a run's metrics (a missing or NaN metric does not hold)."""

    metric: str = Field(description="a metric of the run summary, e.g. min_margin_deg")
    op: Literal["<", "<=", ">", ">=", "=="]
    limit: float

    def holds(self, value: float | None) -> bool:
        if value is None or not math.isfinite(float(value)):
            return False
        v = float(value)
        return {"<": v < self.limit, "<=": v <= self.limit, ">": v > self.limit,
                ">=": v >= self.limit, "==": v == self.limit}[self.op]

    def text(self) -> str:
        return f"{self.metric} {self.op} {self.limit:g}"


class Criterion(Condition):
    """A per-run requirement: ``metric op limit`` must hold (a missing or NaN metric fails), in every run or,
    with ``only_if``, in the runs where that condition holds (e.g. only_if wheels_lost <= 1)."""

    name: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,47}$")
    description: str = ""
    only_if: Condition | None = Field(None, description="judge only the runs where this holds; the others pass it")

    def judged(self, metrics: dict[str, float]) -> bool:
        """Whether this run's ``metrics`` meet the criterion (true where ``only_if`` excludes the run; a run
        without the condition's metric is judged: what cannot be told apart is not excused)."""
        cond = self.only_if
        if cond is not None and cond.metric in metrics and not cond.holds(metrics[cond.metric]):
            return True
        return self.holds(metrics.get(self.metric))

    def text(self) -> str:
        return super().text() + (f" where {self.only_if.text()}" if self.only_if is not None else "")


class Verdict(_Model):
    """Statistical campaign verdict: the one-sided Clopper-Pearson lower bound on the success probability
    at ``confidence`` must reach ``required_success``."""

    confidence: float = Field(0.95, gt=0, lt=1)
    required_success: float = Field(0.95, gt=0, lt=1)


class Tolerance(_Model):
    """How far a metric may move against a baseline before ``compare`` flags it."""

    abs: float = Field(0.0, ge=0, description="per-run |new - old| allowed (absolute)")
    rel: float = Field(0.0, ge=0, description="per-run |new - old| allowed relative to |old|")


class BaselinePolicy(_Model):
    alpha: float = Field(0.01, gt=0, lt=0.5, description="significance of the two-sample tests")
    tolerances: dict[str, Tolerance] = Field(default_factory=dict, description="per metric; metrics not "
                                             "listed must reproduce to 1e-9 relative")


class Campaign(_Model):
    """A dispersed campaign of one base mission."""

    schema_version: Literal[1] = Field(description="campaign file format version (this is version 1)")
    name: str = Field(pattern=NAME_PATTERN, description="output folders are named after it")
    description: str = ""
    base_mission: str = Field(description="mission YAML, relative to this file")
    runs: int = Field(ge=1, le=1_000_000)
    master_seed: int = Field(ge=0, le=2**63 - 1, description="root of numpy.random.SeedSequence")
    mode: Literal["fast", "sil"] = "fast"
    duration_s: float | None = Field(None, gt=0, description="overrides the mission's duration_s; timeline "
                                     "commands and faults after the new end are dropped")
    dispersions: list[Dispersion] = Field(default_factory=list)
    criteria: list[Criterion] = Field(min_length=1)
    verdict: Verdict = Field(default_factory=Verdict)
    baseline: BaselinePolicy = Field(default_factory=BaselinePolicy)

    @model_validator(mode="after")
    def _unique_names(self) -> "Campaign":
        for what, names in (("dispersions", [d.name for d in self.dispersions]),
                            ("criteria", [c.name for c in self.criteria])):
            dupes = sorted({n for n in names if names.count(n) > 1})
            if dupes:
                raise ValueError(f"{what}: names must be unique; repeated: {dupes}")
        return self

    def fingerprint(self) -> str:
        """Hash of everything that determines the runs' inputs except the base mission's file name (its
        content is hashed separately) and ``runs`` (extending a campaign keeps finished runs valid)."""
        data = self.model_dump(mode="json", exclude={"runs", "description", "verdict", "baseline", "base_mission"})
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def load_campaign(path: str | Path, *, text: str | None = None) -> Campaign:
    """Load and validate a campaign file; raise ``hil_sim.mission.loader.ConfigError`` listing every problem."""
    from hil_sim.mission.loader import load_model
    return load_model(path, Campaign, text=text)


def resolve_base_mission(campaign_path: str | Path, campaign: Campaign) -> Path:
    """The base mission file, relative to the campaign file; a clear error when it is missing."""
    base = (Path(campaign_path).resolve().parent / campaign.base_mission).resolve()
    if not base.is_file():
        raise FileNotFoundError(f"{campaign_path}: base_mission '{campaign.base_mission}' not found "
                                f"(looked for {base})")
    return base


SCHEMA_PATH = config_path("schema", "campaign.schema.json")


def campaign_json_schema() -> dict[str, Any]:
    """Draft-07 JSON Schema of a campaign file (same rewriting as the mission schema)."""
    from hil_sim.mission.model import DRAFT07, _draft07
    raw = Campaign.model_json_schema(ref_template="#/definitions/{model}")
    definitions = raw.pop("$defs", {})
    body = _draft07(raw)
    return {"$schema": DRAFT07, **body, "definitions": {k: _draft07(v) for k, v in sorted(definitions.items())}}


def write_json_schema(path: str | Path = SCHEMA_PATH) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(campaign_json_schema(), indent=2) + "\n", encoding="utf-8")
    return path
