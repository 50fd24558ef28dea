"""One campaign run end to end: draw its dispersions, build its mission, run it, read back, judge.

The contract with the execution modes is one function::

    run_function(mission_model, seed, mode, paths) -> RunResult

``mission_model`` is the validated, dispersed mission; ``seed`` the run's simulation seed (also written
into the mission); ``paths`` the key paths that were dispersed: the mode must report, in
``RunResult.used``, the value at each path as read back from the objects the run actually used
(world parameters, flight software configuration), so a dispersion that does not land is caught.
``hil_sim.campaign.fast.run_fast`` is the ``fast`` mode; tests inject their own function here.
"""
from __future__ import annotations

import importlib
import math
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol, Sequence

import numpy as np
from pydantic import BaseModel, ValidationError

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.seeds import RunSeeds
from hil_sim.campaign.spec import Campaign

STATUS_PASS, STATUS_FAIL, STATUS_ERROR = "pass", "fail", "error"
MAX_TRAJECTORY_POINTS = 2000


@dataclass
class RunResult:
    """What an execution mode returns for one run."""

    metrics: dict[str, float]
    used: dict[str, Any]
    trajectory: dict[str, np.ndarray] = field(default_factory=dict)
    sim_time_s: float = math.nan
    events: list[str] = field(default_factory=list)


class RunFunction(Protocol):
    def __call__(self, mission: Any, seed: int, mode: str, paths: Sequence[str]) -> RunResult: ...


@dataclass
class RunRecord:
    """Everything recorded about one run (JSON-ready except ``trajectory``)."""

    run: int
    status: str
    params: dict[str, dict[str, float]]
    values: dict[str, Any]
    used: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)
    verdicts: dict[str, bool] = field(default_factory=dict)
    sim_seed: int = 0
    error: str = ""
    wall_s: float = 0.0
    sim_time_s: float = math.nan
    events: list[str] = field(default_factory=list)
    trajectory: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def to_json(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in ("run", "status", "params", "values", "used", "metrics", "verdicts",
                                             "sim_seed", "error", "wall_s", "sim_time_s", "events")}
        return dsp.to_plain(out)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "RunRecord":
        return cls(**data)


@dataclass
class Plan:
    """A campaign ready to execute: everything a worker needs, picklable."""

    campaign: Campaign
    base_raw: dict[str, Any]
    nominal: dict[str, Any]
    model_class: type[BaseModel]
    run_function: Callable[..., RunResult]
    mode: str
    seed_path: str | None = "seed"

    def draw(self, index: int) -> dict[str, dict[str, float]]:
        """The dispersion parameters of run ``index`` (depends on master seed, index and names only)."""
        seeds = RunSeeds(self.campaign.master_seed, index)
        return {d.name: dsp.draw(d, seeds.dispersion_rng(d.name), self.nominal[d.name])
                for d in self.campaign.dispersions}

    def values(self, params: dict[str, dict[str, float]]) -> dict[str, Any]:
        """Value to write at each path (a dispersion's ``also_paths`` get the same value)."""
        out: dict[str, Any] = {}
        for d in self.campaign.dispersions:
            # dispersions that append faults compose: each appends to what the earlier ones wrote
            nominal = out.get(d.path, self.nominal[d.name]) if dsp.appends(d) else self.nominal[d.name]
            value = dsp.realize(d, params[d.name], nominal)
            for path in (d.path, *d.also_paths):
                out[path] = value
        return out

    def mission(self, params: dict[str, dict[str, float]], sim_seed: int) -> tuple[dict[str, Any], Any]:
        """Raw dispersed mission dict and its validated model."""
        raw = dsp.apply_values(self.base_raw, self.values(params))
        if self.seed_path:
            dsp.write_path(raw, dsp.parse_path(self.seed_path), int(sim_seed))
        if self.campaign.duration_s is not None:
            end = float(self.campaign.duration_s)
            raw["duration_s"] = end
            for key, time_key in (("timeline", "t_s"), ("faults", "start_s")):
                if isinstance(raw.get(key), list):
                    raw[key] = [e for e in raw[key] if not (isinstance(e, dict) and float(e.get(time_key, 0)) > end)]
        self._expect_fdir_events(raw, params)
        return raw, validate_mission(self.model_class, raw)

    def _expect_fdir_events(self, raw: dict[str, Any], params: dict[str, dict[str, float]]) -> None:
        """A run in which a fault was drawn expects the FDIR event that fault gives (so the isolation is not
        counted as unexpected, and its absence is counted as missing), in every mode: it is written into
        the run's own ``requirements.expected_fdir_events``."""
        end_s = float(raw.get("duration_s", math.inf))
        drawn = [m for d in self.campaign.dispersions for m in dsp.expected_fdir_events(d, params[d.name], end_s)]
        if drawn:
            req = raw.setdefault("requirements", {})
            expected = list(req.get("expected_fdir_events") or [])
            req["expected_fdir_events"] = expected + [m for m in dict.fromkeys(drawn) if m not in expected]


def validate_mission(model_class: type[BaseModel], raw: dict[str, Any]) -> Any:
    """Validate a (dispersed) mission; cross-field problems (``semantic_problems``) are errors too."""
    try:
        model = model_class.model_validate(raw)
    except ValidationError as exc:
        msgs = [f"{dsp.format_path(tuple(e['loc']))}: {e['msg']}" for e in exc.errors()]
        raise dsp.DispersionError("dispersed mission is invalid: " + "; ".join(msgs)) from None
    problems = model.semantic_problems() if hasattr(model, "semantic_problems") else []
    if problems:
        raise dsp.DispersionError("dispersed mission is invalid: " +
                                  "; ".join(f"{dsp.format_path(tuple(loc))}: {msg}" for loc, msg in problems))
    return model


def resolve_run_function(spec: str) -> Callable[..., RunResult]:
    """``"package.module:function"`` -> the function."""
    module, _, name = spec.partition(":")
    return getattr(importlib.import_module(module), name)


def execute_run(plan: Plan, index: int) -> RunRecord:
    """Run ``index`` of the campaign (draws from its own seeds)."""
    return evaluate(plan, index, plan.draw(index))


def evaluate(plan: Plan, index: int, params: dict[str, dict[str, float]]) -> RunRecord:
    """Run the mission with the given dispersion parameters (used by runs, reruns and shrinking)."""
    sim_seed = RunSeeds(plan.campaign.master_seed, index).simulation_seed
    values = plan.values(params)
    record = RunRecord(run=index, status=STATUS_ERROR, params=params, values=values, sim_seed=sim_seed)
    start = time.perf_counter()
    try:
        _, mission = plan.mission(params, sim_seed)
        result = plan.run_function(mission, sim_seed, plan.mode, list(values))
        record.used = {p: dsp.to_plain(v) for p, v in result.used.items()}
        record.metrics = {k: float(v) for k, v in result.metrics.items()}
        record.sim_time_s = float(result.sim_time_s)
        record.events = list(result.events)
        record.trajectory = {k: np.asarray(v) for k, v in result.trajectory.items()}
        dsp.check_landed(values, record.used)
        record.verdicts = {c.name: c.judged(record.metrics) for c in plan.campaign.criteria}
        record.status = STATUS_PASS if all(record.verdicts.values()) else STATUS_FAIL
    except Exception as exc:  # a run that crashes is recorded and counted, never kills the campaign
        record.status = STATUS_ERROR
        record.error = f"{type(exc).__name__}: {exc}"
        if not isinstance(exc, (dsp.DispersionError, dsp.DispersionNotLanded)):
            record.error += "\n" + "".join(traceback.format_exc(limit=-4))
    record.wall_s = time.perf_counter() - start
    return record
