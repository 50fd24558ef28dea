"""Shrink a failing run: move its dispersed values toward nominal while it still fails.

The run keeps its simulation seed (the same sensor noise), so only the dispersions move. Each
dispersion d has a fraction t_d in [0, 1] of its drawn deviation from nominal (parameters
p = p_nominal + t_d (p_drawn - p_nominal); for directions and attitudes the parameters are rotation
vectors, so this walks the geodesic). First every dispersion is tried at nominal on its own (t_d = 0)
and kept there when the run still fails; then each remaining one is bisected for the smallest t_d that
still fails. Discrete dispersions (choices, wheel failures) only take t_d in {0, 1}. The result is a
local minimum: no single dispersion can be moved further toward nominal without the run passing.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.execute import STATUS_ERROR, STATUS_PASS, Plan, RunRecord, evaluate

Params = dict[str, dict[str, float]]


@dataclass
class ShrinkResult:
    original: RunRecord
    shrunk: RunRecord
    fractions: dict[str, float]  # t_d per dispersion: 0 nominal, 1 as drawn
    evaluations: int
    trace: list[str] = field(default_factory=list)

    @property
    def remaining(self) -> list[str]:
        return [name for name, t in self.fractions.items() if t > 0]

    def text(self, plan: Plan) -> str:
        by_name = {d.name: d for d in plan.campaign.dispersions}
        lines = [f"run {self.original.run}: smallest failing case after {self.evaluations} evaluations "
                 f"(same simulation seed {self.original.sim_seed})",
                 f"failing: {', '.join(failed_criteria(plan, self.shrunk)) or self.shrunk.error.splitlines()[0]}",
                 f"{'dispersion':16s} {'kept':>6s}  drawn -> shrunk"]
        for name, t in self.fractions.items():
            drawn = dsp.features(by_name[name], self.original.params[name])
            small = dsp.features(by_name[name], self.shrunk.params[name])
            change = ", ".join(f"{k.split('.', 1)[1]} {drawn[k]:.4g} -> {small[k]:.4g}" for k in drawn)
            lines.append(f"{name:16s} {t:6.3f}  {change if t > 0 else 'nominal (not needed to fail)'}")
        return "\n".join(lines)


def failed_criteria(plan: Plan, record: RunRecord) -> list[str]:
    return [c.name for c in plan.campaign.criteria if not record.verdicts.get(c.name, False)]


def _interpolate(plan: Plan, drawn: Params, fractions: dict[str, float]) -> Params:
    out: Params = {}
    for d in plan.campaign.dispersions:
        nominal = dsp.nominal_params(d, plan.nominal[d.name], drawn[d.name])
        t = fractions[d.name]
        out[d.name] = {k: nominal[k] + t * (v - nominal[k]) for k, v in drawn[d.name].items()}
    return out


def shrink_run(plan: Plan, index: int, *, bisect_steps: int = 6, max_evaluations: int = 80,
               criteria: set[str] | None = None) -> ShrinkResult:
    """Shrink run ``index`` of the plan's campaign while it still fails one of ``criteria`` (default: the
    criteria it failed as drawn). Raises ValueError when that run passes them."""
    drawn = plan.draw(index)
    original = evaluate(plan, index, drawn)
    failed = set(failed_criteria(plan, original))
    if criteria:
        unknown = criteria - {c.name for c in plan.campaign.criteria}
        if unknown:
            raise ValueError(f"unknown criteria {sorted(unknown)}; the campaign has "
                             f"{[c.name for c in plan.campaign.criteria]}")
    target = (failed & criteria) if criteria else failed
    if original.status == STATUS_PASS or (criteria and not target and original.status != STATUS_ERROR):
        raise ValueError(f"run {index} passes{' ' + ', '.join(sorted(criteria)) if criteria else ''}: "
                         "nothing to shrink")
    evals = 1
    trace: list[str] = []

    def still_fails(fractions: dict[str, float]) -> tuple[bool, RunRecord]:
        nonlocal evals
        evals += 1
        rec = evaluate(plan, index, _interpolate(plan, drawn, fractions))
        if original.status == STATUS_ERROR:
            return rec.status == STATUS_ERROR, rec
        return rec.status != STATUS_PASS and bool(target & set(failed_criteria(plan, rec))), rec

    fractions = {d.name: 1.0 for d in plan.campaign.dispersions}
    best = original
    # Pass 1: which dispersions are needed at all?
    for d in plan.campaign.dispersions:
        if evals >= max_evaluations:
            break
        trial = {**fractions, d.name: 0.0}
        fails, rec = still_fails(trial)
        trace.append(f"{d.name} -> nominal: {'still fails' if fails else 'passes'}")
        if fails:
            fractions, best = trial, rec
    # Pass 2: bisect the needed continuous ones toward nominal.
    for d in plan.campaign.dispersions:
        if fractions[d.name] == 0.0 or dsp.discrete_params(d) >= set(drawn[d.name]):
            continue
        lo, hi = 0.0, fractions[d.name]  # lo passes (pass 1 showed it), hi fails
        for _ in range(bisect_steps):
            if evals >= max_evaluations:
                break
            mid = 0.5 * (lo + hi)
            fails, rec = still_fails({**fractions, d.name: mid})
            if fails:
                hi, best = mid, rec
            else:
                lo = mid
        trace.append(f"{d.name}: smallest failing fraction in ({lo:.4f}, {hi:.4f}]")
        fractions[d.name] = hi
    if best.params != _interpolate(plan, drawn, fractions):
        best = evaluate(plan, index, _interpolate(plan, drawn, fractions))
        evals += 1
    return ShrinkResult(original=original, shrunk=best, fractions=fractions, evaluations=evals, trace=trace)


def shrunk_mission(plan: Plan, result: ShrinkResult) -> dict[str, Any]:
    """The raw mission dict of the smallest failing case (to run it with ``keepout sil run``)."""
    raw, _ = plan.mission(result.shrunk.params, result.shrunk.sim_seed)
    return raw
