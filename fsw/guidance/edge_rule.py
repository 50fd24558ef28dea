"""One rule for the edge: the eps the law flies with, and whether a target lies in a zone's eps-layer.

The paper's law needs its target outside every eps-layer (Assumption 1: d_s(x_d, U) > eps). Near an
inflated zone the admissible layer shrinks with the target's separation; below ``EPS_MAX_FLOOR`` the
flight software does not follow it down (a layer thinner than that leaves the rate loop no room to turn
the boresight), so a target whose separation is below the floored layer is unusable: the law steers to the
nearest safe direction instead (ASSUMPTION_VIOLATED "target in the eps-layer of zone ...") and holds there.
The flight software's guidance and the ground's `config check` both call these functions, so what the
check accepts is flown to its target and what the guidance would hold short of is refused at load.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

# smallest admissible-eps bound the law follows (d_s units; about 0.26 deg of layer)
EPS_MAX_FLOOR = 1e-5
# the thinnest layer the law is ever given (d_s units)
EPS_MIN = 1e-6
TARGET_IN_LAYER = "target in the eps-layer of zone {zone}: steering to the nearest safe direction"


def law_eps(law: Any, eps_max: float, eps_setting: float | str | None = None) -> float:
    """The eps the law flies with for the admissible bound ``eps_max``: ``law.eps_fraction`` of it (floored
    at ``EPS_MAX_FLOOR``) capped at ``law.eps_max_used`` with eps 'auto', else the fixed eps, lowered to
    that fraction when it is not admissible. ``eps_setting``: the eps in force (SET_GAINS may change it;
    default ``law.eps``)."""
    setting = law.eps if eps_setting is None else eps_setting
    eps_max = max(float(eps_max), EPS_MAX_FLOOR)
    auto = setting == "auto"
    eps = min(law.eps_fraction * eps_max, law.eps_max_used) if auto else float(setting)
    if not auto and eps >= eps_max:
        eps = law.eps_fraction * eps_max
    return max(eps, EPS_MIN)


def target_layer(target: np.ndarray, zones: Sequence[Any], law: Any, unmerged: Sequence[tuple[int, int]] = (),
                 eps_setting: float | str | None = None) -> tuple[int, float]:
    """(index of the zone whose eps-layer holds ``target``, -1 when the law can fly to it; the eps) for
    the law's zones as flown (inflated and merged; ``unmerged``: close pairs set aside by the merge)."""
    from fsw.guidance.zone_merging import ZoneGeometry

    target = np.asarray(target, dtype=float)
    eps = law_eps(law, ZoneGeometry.fast_eps_max(target, list(zones), list(unmerged)), eps_setting)
    return ZoneGeometry.occulting(target, list(zones), eps), eps


def clearance_needed_deg(target: np.ndarray, zone: Any, zones: Sequence[Any], law: Any,
                         unmerged: Sequence[tuple[int, int]] = (), step_deg: float = 0.01,
                         start_deg: float = 0.0, span_deg: float = 10.0) -> float:
    """How far [deg] ``target`` must move away from ``zone``'s centre (along the great circle through
    both) before `target_layer` accepts it, searched from ``start_deg`` (a distance known to fall short)
    in steps of ``step_deg``; ``start_deg + span_deg`` when no such point lies within the span."""
    target = np.asarray(target, dtype=float)
    centre = np.asarray(zone.kernel, dtype=float)
    away = (target @ centre) * target - centre  # tangent at the target, pointing away from the centre
    norm = float(np.linalg.norm(away))
    if norm < 1e-12:
        return start_deg + span_deg
    away /= norm
    first = int(math.floor(start_deg / step_deg))
    for k in range(first + 1, first + int(round(span_deg / step_deg)) + 1):
        a = math.radians(k * step_deg)
        moved = math.cos(a) * target + math.sin(a) * away
        if target_layer(moved / np.linalg.norm(moved), zones, law, unmerged)[0] < 0:
            return k * step_deg
    return start_deg + span_deg
