"""Draw dispersed values and write them into a mission by key path.

Every dispersion is described by a small set of named scalar *parameters* (``params``):
a scalar's value, a direction's rotation vector away from the nominal, an inertia's scale and
misalignment rotation vector, an epoch's offset in seconds, ... ``draw`` samples them,
``realize`` turns parameters into the value written into the mission, and ``nominal_params`` are the
parameters that reproduce the nominal mission. This one representation serves three needs:

- the results table and the scatter plots (one column per parameter),
- shrinking (move each parameter linearly toward its nominal value: for rotation vectors this is
  the geodesic between the nominal and the drawn direction or attitude),
- reproducibility (``realize(params)`` is all a rerun needs).

Conventions: quaternions scalar first [eta, q1, q2, q3]; a dispersed attitude is
q = q_nominal * exp(rotvec), the small rotation expressed in body axes.
"""
from __future__ import annotations

import copy
import math
import re
from datetime import datetime, timedelta, timezone
from typing import Any, Sequence

import numpy as np
from pydantic import BaseModel
from scipy.spatial.transform import Rotation

from hil_sim.campaign.spec import (AttitudeDispersion, ChoiceDispersion, ClippedNormal, DirectionDispersion,
                                   Dispersion, EpochDispersion, InertiaDispersion, Normal, ScalarDispersion,
                                   Uniform, VectorDispersion, WheelFailureDispersion, FaultDispersion)

Loc = tuple[str | int, ...]
Params = dict[str, float]


class DispersionError(ValueError):
    """A dispersion cannot be applied to the mission (bad path, wrong value shape)."""


class DispersionNotLanded(RuntimeError):
    """A dispersed value was not what the run actually used (read back from the objects)."""


# ---------------------------------------------------------------------------------------------
# Key paths
# ---------------------------------------------------------------------------------------------

_TOKEN = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def parse_path(path: str) -> Loc:
    """``a.b[2].c`` (or ``a.b.2.c``) -> ("a", "b", 2, "c")."""
    if not path or path.startswith(".") or path.endswith(".") or ".." in path:
        raise DispersionError(f"bad key path '{path}': use dots between keys and [i] for list items")
    loc: list[str | int] = []
    pos = 0
    for match in _TOKEN.finditer(path):
        if path[pos:match.start()] not in ("", "."):
            raise DispersionError(f"bad key path '{path}' near '{path[pos:match.start()]}'")
        key, index = match.groups()
        loc.append(int(index) if index is not None else (int(key) if key.isdigit() else key))
        pos = match.end()
    if pos != len(path):
        raise DispersionError(f"bad key path '{path}' near '{path[pos:]}'")
    return tuple(loc)


def format_path(loc: Loc) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


def to_plain(value: Any) -> Any:
    """JSON-ready plain data from models, tuples, numpy arrays and datetimes."""
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    if isinstance(value, datetime):
        return _iso(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, dict):
        return {k: to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    return value


def read_path(obj: Any, loc: Loc) -> Any:
    """The value at ``loc`` in a model/dict/list tree, as plain data; a clear error if it is not there."""
    node = obj
    for depth, part in enumerate(loc):
        where = format_path(loc[:depth]) or "the mission"
        if isinstance(part, int):
            if not isinstance(node, (list, tuple)) or part >= len(node):
                size = len(node) if isinstance(node, (list, tuple)) else "no"
                raise DispersionError(f"'{format_path(loc)}': {where} has {size} list items; index {part} "
                                      "does not exist")
            node = node[part]
        elif isinstance(node, BaseModel):
            fields = type(node).model_fields
            if part not in fields:
                raise DispersionError(f"'{format_path(loc)}': {where} has no key '{part}'; keys there: "
                                      f"{', '.join(sorted(fields))}")
            node = getattr(node, part)
        elif isinstance(node, dict):
            if part not in node:
                raise DispersionError(f"'{format_path(loc)}': {where} has no key '{part}'; keys there: "
                                      f"{', '.join(sorted(map(str, node)))}")
            node = node[part]
        else:
            raise DispersionError(f"'{format_path(loc)}': {where} is a {type(node).__name__}, not a mapping")
    return to_plain(node)


def write_path(data: dict[str, Any], loc: Loc, value: Any) -> None:
    """Set ``loc`` in a plain dict tree (creating missing mappings along the way)."""
    node: Any = data
    for depth, part in enumerate(loc[:-1]):
        nxt = loc[depth + 1]
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                raise DispersionError(f"'{format_path(loc)}': list index {part} does not exist in the mission")
            node = node[part]
        else:
            if part not in node or node[part] is None:
                if isinstance(nxt, int):
                    raise DispersionError(f"'{format_path(loc)}': '{format_path(loc[:depth + 1])}' is not "
                                          "given in the mission file, so its items cannot be dispersed")
                node[part] = {}
            node = node[part]
    last = loc[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or last >= len(node):
            raise DispersionError(f"'{format_path(loc)}': list index {last} does not exist in the mission")
    node[last] = value


def apply_values(base: dict[str, Any], values: dict[str, Any]) -> dict[str, Any]:
    """A deep copy of the raw mission dict with each path in ``values`` set."""
    out = copy.deepcopy(base)
    for path, value in values.items():
        write_path(out, parse_path(path), value)
    return out


# ---------------------------------------------------------------------------------------------
# Sampling helpers
# ---------------------------------------------------------------------------------------------

def sample_scalar(dist: Uniform | Normal | ClippedNormal, rng: np.random.Generator) -> float:
    if isinstance(dist, Uniform):
        return float(rng.uniform(dist.low, dist.high))
    x = float(rng.normal(dist.mean, dist.sigma))
    if isinstance(dist, ClippedNormal):
        x = min(max(x, dist.low), dist.high)
    return x


def _combine(nominal: float, draw: float, how: str) -> float:
    return {"set": draw, "add": nominal + draw, "multiply": nominal * draw}[how]


def _iso(t: datetime) -> str:
    return t.astimezone(timezone.utc).isoformat().replace("+00:00", "Z")


def _parse_iso(text: str) -> datetime:
    return datetime.fromisoformat(text.replace("Z", "+00:00")).astimezone(timezone.utc)


def _rotvec_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation vector of the shortest rotation taking unit vector a to unit vector b."""
    axis = np.cross(a, b)
    s, c = float(np.linalg.norm(axis)), float(np.dot(a, b))
    if s < 1e-15:
        if c > 0:
            return np.zeros(3)
        # Antipodal: any axis normal to a.
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return axis / np.linalg.norm(axis) * math.pi
    return axis / s * math.atan2(s, c)


def _quat_sf(rot: Rotation) -> np.ndarray:
    q = rot.as_quat(scalar_first=True)
    return q if q[0] >= 0 else -q


def _vector(nominal: Any, what: str, n: int | None = None) -> np.ndarray:
    arr = np.asarray(nominal, dtype=float)
    if arr.ndim != 1 or (n is not None and arr.shape[0] != n):
        raise DispersionError(f"{what}: nominal value {nominal!r} is not a {n or ''}-vector")
    return arr


# ---------------------------------------------------------------------------------------------
# The operations of each kind
# ---------------------------------------------------------------------------------------------

def draw(disp: Dispersion, rng: np.random.Generator, nominal: Any) -> Params:
    """Sample this dispersion's parameters."""
    if isinstance(disp, ScalarDispersion):
        return {"value": _combine(_nominal_number(disp, nominal), sample_scalar(disp.distribution, rng),
                                  disp.apply)}
    if isinstance(disp, VectorDispersion):
        nom = _vector(nominal, disp.path)
        dists = disp.distribution if isinstance(disp.distribution, list) else [disp.distribution] * len(nom)
        if len(dists) != len(nom):
            raise DispersionError(f"{disp.name}: {len(dists)} distributions for a {len(nom)}-vector at {disp.path}")
        return {f"{i}": _combine(float(nom[i]), sample_scalar(d, rng), disp.apply) for i, d in enumerate(dists)}
    if isinstance(disp, DirectionDispersion):
        nom = _unit(_vector(nominal, disp.path, 3))
        if disp.cone_half_angle_deg is None:
            g = rng.normal(size=3)
            target = g / np.linalg.norm(g)
        else:
            # Uniform in a cap: cos(theta) uniform in [cos(alpha), 1], azimuth uniform.
            cos_t = rng.uniform(math.cos(math.radians(disp.cone_half_angle_deg)), 1.0)
            phi = rng.uniform(0.0, 2 * math.pi)
            e1 = np.cross(nom, [1.0, 0.0, 0.0] if abs(nom[0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(nom, e1)
            sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
            target = cos_t * nom + sin_t * (math.cos(phi) * e1 + math.sin(phi) * e2)
        return _rv_params(_rotvec_between(nom, target))
    if isinstance(disp, AttitudeDispersion):
        q_nom = Rotation.from_quat(_vector(nominal, disp.path, 4), scalar_first=True)
        if disp.max_angle_deg is None:
            g = rng.normal(size=4)  # uniform on S^3 = Haar measure on SO(3)
            dq = q_nom.inv() * Rotation.from_quat(g / np.linalg.norm(g), scalar_first=True)
            return _rv_params(dq.as_rotvec())
        g = rng.normal(size=3)
        angle = rng.uniform(0.0, math.radians(disp.max_angle_deg))
        return _rv_params(g / np.linalg.norm(g) * angle)
    if isinstance(disp, InertiaDispersion):
        scale = sample_scalar(disp.scale, rng) if disp.scale is not None else 1.0
        rv = rng.normal(0.0, math.radians(disp.misalignment_sigma_deg), size=3) \
            if disp.misalignment_sigma_deg > 0 else np.zeros(3)
        return {"scale": scale, **_rv_params(rv)}
    if isinstance(disp, EpochDispersion):
        nom = _parse_iso(str(nominal))
        t = rng.uniform(0.0, (_parse_iso(disp.end_utc) - _parse_iso(disp.start_utc)).total_seconds())
        return {"offset_s": (_parse_iso(disp.start_utc) - nom).total_seconds() + t}
    if isinstance(disp, ChoiceDispersion):
        p = disp.probabilities
        return {"index": float(rng.choice(len(disp.values), p=p))}
    if isinstance(disp, WheelFailureDispersion):
        failed = rng.uniform(size=disp.n_wheels) < disp.probability
        order = rng.permutation(disp.n_wheels)  # which failures survive the max_failed cap
        keep = [int(i) for i in order if failed[i]][: disp.max_failed]
        params = {f"wheel{i + 1}": float(i in keep) for i in range(disp.n_wheels)}
        params["start_s"] = sample_scalar(disp.start_s, rng)
        # the draws below exist only with the options that ask for them: campaigns without them draw as before
        if disp.independent_starts:
            params.update({f"start{i + 1}_s": sample_scalar(disp.start_s, rng) for i in range(disp.n_wheels)})
        if disp.fault_kinds:
            params.update({f"kind{i + 1}": float(rng.integers(len(disp.fault_kinds))) for i in range(disp.n_wheels)})
        return params
    if isinstance(disp, FaultDispersion):
        hit = rng.uniform() < disp.probability
        index = int(rng.integers(len(disp.faults)))
        return {"index": float(index if hit else -1), "start_s": sample_scalar(disp.start_s, rng)}
    raise DispersionError(f"unknown dispersion kind {type(disp).__name__}")


def nominal_params(disp: Dispersion, nominal: Any, drawn: Params) -> Params:
    """Parameters that reproduce the nominal mission (``drawn`` fills what has no nominal)."""
    if isinstance(disp, ScalarDispersion):
        return {"value": float(nominal)} if isinstance(nominal, (int, float)) else dict(drawn)
    if isinstance(disp, VectorDispersion):
        return {f"{i}": float(v) for i, v in enumerate(_vector(nominal, disp.path))}
    if isinstance(disp, (DirectionDispersion, AttitudeDispersion)):
        return _rv_params(np.zeros(3))
    if isinstance(disp, InertiaDispersion):
        return {"scale": 1.0, **_rv_params(np.zeros(3))}
    if isinstance(disp, EpochDispersion):
        return {"offset_s": 0.0}
    if isinstance(disp, ChoiceDispersion):
        plain = [to_plain(v) for v in disp.values]
        return {"index": float(plain.index(nominal))} if nominal in plain else {"index": -1.0}
    if isinstance(disp, WheelFailureDispersion):
        return {**drawn, **{k: 0.0 for k in drawn if k.startswith("wheel")}}
    if isinstance(disp, FaultDispersion):
        return {**drawn, "index": -1.0}
    raise DispersionError(f"unknown dispersion kind {type(disp).__name__}")


def discrete_params(disp: Dispersion) -> set[str]:
    """Parameters that take only their drawn or nominal value when shrinking (no in-between)."""
    if isinstance(disp, ChoiceDispersion):
        return {"index"}
    if isinstance(disp, WheelFailureDispersion):
        return {f"wheel{i + 1}" for i in range(disp.n_wheels)} | {f"kind{i + 1}" for i in range(disp.n_wheels)}
    if isinstance(disp, FaultDispersion):
        return {"index"}
    return set()


# End of a wheel failure's fault window: the longest the mission schema allows (faults[].end_s <= 10 days),
# i.e. after the end of any run.
NEVER_ENDS_S = 10 * 86400.0


def realize(disp: Dispersion, params: Params, nominal: Any) -> Any:
    """The value to write at ``disp.path`` for these parameters."""
    if isinstance(disp, ScalarDispersion):
        return float(params["value"])
    if isinstance(disp, VectorDispersion):
        return [float(params[f"{i}"]) for i in range(len(params))]
    if isinstance(disp, DirectionDispersion):
        nom = _unit(_vector(nominal, disp.path, 3))
        return Rotation.from_rotvec(_rv(params)).apply(nom).tolist()
    if isinstance(disp, AttitudeDispersion):
        q_nom = Rotation.from_quat(_vector(nominal, disp.path, 4), scalar_first=True)
        return _quat_sf(q_nom * Rotation.from_rotvec(_rv(params))).tolist()
    if isinstance(disp, InertiaDispersion):
        J = np.asarray(nominal, dtype=float)
        if J.shape != (3, 3):
            raise DispersionError(f"{disp.name}: nominal value at {disp.path} is not a 3x3 inertia matrix")
        R = Rotation.from_rotvec(_rv(params)).as_matrix()
        J_new = params["scale"] * (R @ J @ R.T)
        J_new = 0.5 * (J_new + J_new.T)  # exactly symmetric despite rounding
        return J_new.tolist()
    if isinstance(disp, EpochDispersion):
        return _iso(_parse_iso(str(nominal)) + timedelta(seconds=params["offset_s"]))
    if isinstance(disp, ChoiceDispersion):
        i = int(round(params["index"]))
        return copy.deepcopy(to_plain(disp.values[i])) if i >= 0 else copy.deepcopy(nominal)
    if isinstance(disp, WheelFailureDispersion):
        entries = list(copy.deepcopy(nominal or []))
        for i in range(disp.n_wheels):
            if params[f"wheel{i + 1}"] >= 0.5:
                kind, message = _wheel_fault(disp, params, i)
                entries.append({"kind": kind, "message": message, "start_s": _wheel_start_s(params, i),
                                "end_s": NEVER_ENDS_S})
        return entries
    if isinstance(disp, FaultDispersion):
        entries = list(copy.deepcopy(nominal or []))
        i = int(round(params["index"]))
        if i >= 0:
            f = disp.faults[i]
            start = float(params["start_s"])
            entry = {"kind": f.kind, "message": f.message, "start_s": start,
                     "end_s": NEVER_ENDS_S if f.duration_s is None else start + f.duration_s}
            entry.update({k: v for k, v in (("delay_s", f.delay_s), ("bit", f.bit)) if v is not None})
            if f.probability < 1.0:
                entry["probability"] = f.probability
            entries.append(entry)
        return entries
    raise DispersionError(f"unknown dispersion kind {type(disp).__name__}")


def _wheel_fault(disp: WheelFailureDispersion, params: Params, i: int) -> tuple[str, str]:
    """(fault kind, DBC message) of failed wheel ``i`` (0-based)."""
    if not disp.fault_kinds:
        return disp.fault_kind, disp.message_template.format(n=i + 1)
    kind = disp.fault_kinds[int(round(params[f"kind{i + 1}"]))]
    return kind, f"RW{i + 1}_{'STATUS' if kind == 'silent' else 'CMD'}"


def _wheel_start_s(params: Params, i: int) -> float:
    """Onset of wheel ``i``'s failure: its own draw with ``independent_starts``, else the shared one."""
    return float(params.get(f"start{i + 1}_s", params["start_s"]))


def expected_fdir_events(disp: Dispersion, params: Params, end_s: float) -> list[str]:
    """FDIR monitors a run with these drawn parameters must trip: a drawn wheel failure that starts early
    enough before the end of the run (``end_s``) to be detected expects its ``expected_fdir_event``."""
    if not isinstance(disp, WheelFailureDispersion) or disp.expected_fdir_event is None:
        return []
    starts = [_wheel_start_s(params, i) for i in range(disp.n_wheels) if params[f"wheel{i + 1}"] >= 0.5]
    return [disp.expected_fdir_event] if starts and min(starts) + disp.detection_s <= end_s else []


def features(disp: Dispersion, params: Params) -> dict[str, float]:
    """Scalar columns for tables and scatter plots (derived quantities a person reads easily)."""
    out = {f"{disp.name}.{k}": float(v) for k, v in params.items()}
    if isinstance(disp, (DirectionDispersion, AttitudeDispersion)):
        out = {f"{disp.name}.angle_deg": math.degrees(float(np.linalg.norm(_rv(params))))}
    elif isinstance(disp, InertiaDispersion):
        out = {f"{disp.name}.scale": float(params["scale"]),
               f"{disp.name}.misalignment_deg": math.degrees(float(np.linalg.norm(_rv(params))))}
    elif isinstance(disp, WheelFailureDispersion):
        failed = [i for i in range(disp.n_wheels) if params[f"wheel{i + 1}"] >= 0.5]
        starts = sorted(_wheel_start_s(params, i) for i in failed)
        out = {f"{disp.name}.failed": float(len(failed)),
               f"{disp.name}.start_s": starts[0] if starts else float(params["start_s"])}
        if disp.independent_starts and len(starts) > 1:
            out[f"{disp.name}.last_start_s"] = starts[-1]
    elif isinstance(disp, EpochDispersion):
        out = {f"{disp.name}.offset_days": float(params["offset_s"]) / 86400.0}
    elif isinstance(disp, FaultDispersion):
        out = {f"{disp.name}.index": float(params["index"]), f"{disp.name}.start_s": float(params["start_s"])}
    return out


def _nominal_number(disp: ScalarDispersion, nominal: Any) -> float:
    if disp.apply == "set":
        return float(nominal) if isinstance(nominal, (int, float)) else math.nan
    if not isinstance(nominal, (int, float)):
        raise DispersionError(f"{disp.name}: apply '{disp.apply}' needs a number at {disp.path}, "
                              f"found {nominal!r}")
    return float(nominal)


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n < 1e-12:
        raise DispersionError("nominal direction is a zero vector")
    return v / n


def _rv_params(rv: np.ndarray) -> Params:
    return {"rx": float(rv[0]), "ry": float(rv[1]), "rz": float(rv[2])}


def _rv(params: Params) -> np.ndarray:
    return np.array([params["rx"], params["ry"], params["rz"]], dtype=float)


# ---------------------------------------------------------------------------------------------
# Read-back comparison
# ---------------------------------------------------------------------------------------------

def same_value(drawn: Any, used: Any, *, rtol: float = 1e-9, atol: float = 1e-12) -> bool:
    """Did the value the run used equal the value drawn? Numbers within tolerance, ISO instants equal,
    mappings compared on the drawn keys (the model may add defaults)."""
    if isinstance(drawn, bool) or isinstance(used, bool):
        return drawn == used
    if isinstance(drawn, (int, float)) and isinstance(used, (int, float)):
        return math.isclose(float(drawn), float(used), rel_tol=rtol, abs_tol=atol)
    if isinstance(drawn, str) and isinstance(used, str):
        if drawn == used:
            return True
        try:
            return abs((_parse_iso(drawn) - _parse_iso(used)).total_seconds()) < 1e-6
        except ValueError:
            return False
    if isinstance(drawn, dict) and isinstance(used, dict):
        return all(k in used and same_value(v, used[k], rtol=rtol, atol=atol) for k, v in drawn.items())
    if isinstance(drawn, (list, tuple)) and isinstance(used, (list, tuple)):
        return len(drawn) == len(used) and all(same_value(a, b, rtol=rtol, atol=atol) for a, b in zip(drawn, used))
    return drawn == used


def check_landed(drawn: dict[str, Any], used: dict[str, Any]) -> None:
    """Raise ``DispersionNotLanded`` naming every path whose used value differs from the drawn one."""
    bad = []
    for path, value in drawn.items():
        if path not in used:
            bad.append(f"{path}: not read back from the run (the run did not report using it)")
        elif not same_value(value, used[path]):
            bad.append(f"{path}: drawn {_short(value)} but the run used {_short(used[path])}")
    if bad:
        raise DispersionNotLanded("dispersion did not land: " + "; ".join(bad))


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) < 160 else text[:157] + "..."


# ---------------------------------------------------------------------------------------------
# All dispersions of a run
# ---------------------------------------------------------------------------------------------

def appends(disp: Dispersion) -> bool:
    """Whether ``disp`` appends to the list at its path (faults) rather than replacing the value there, so
    that several such dispersions may share a path, each appending to what the earlier ones wrote."""
    return isinstance(disp, (WheelFailureDispersion, FaultDispersion)) and not disp.also_paths


def nominal_values(dispersions: Sequence[Dispersion], mission_model: Any) -> dict[str, Any]:
    """Nominal value at each dispersion's path, read from the validated base mission (defaults included).
    Raises DispersionError naming the dispersion when a path does not exist."""
    out: dict[str, Any] = {}
    for disp in dispersions:
        loc = parse_path(disp.path)
        try:
            out[disp.name] = read_path(mission_model, loc)
        except DispersionError as exc:
            raise DispersionError(f"dispersion '{disp.name}': {exc}") from None
        for extra in disp.also_paths:
            try:
                read_path(mission_model, parse_path(extra))
            except DispersionError as exc:
                raise DispersionError(f"dispersion '{disp.name}' also_paths: {exc}") from None
    paths = [p for d in dispersions for p in (d.path, *d.also_paths)]
    composed = {d.path for d in dispersions if appends(d)} - {d.path for d in dispersions if not appends(d)}
    dupes = sorted({p for p in paths if paths.count(p) > 1} - composed)
    if dupes:
        raise DispersionError(f"several dispersions write the same path: {dupes}")
    return out
