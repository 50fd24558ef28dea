"""The ``fast`` execution mode: one run in one process, the real flight software on a ``virtual`` CAN bus.

Per GNC tick: ``Simulator.begin_tick()`` (SYNC + device frames through the ICD, E2E protected),
``FswBusDriver.collect_tick(0)`` and ``FlightSoftware.run_cycle`` (the flight software's own code,
unchanged), ``Simulator.end_tick(wait_s=0)`` (wheel commands taken off the bus, world stepped). The
ground's timeline is sent as real CCSDS telecommand packets to the flight software's dispatcher at the
tick of their time. Nothing waits on a clock, so a run is deterministic and as fast as the code allows.

The run is judged on truth, like the SIL: the instrument boresight (or the attitude in QUATERNION mode)
from the world, the keep-out zones built with ``gnc.sky_zones`` (exact shapes, no margin) around the
truth Sun/Moon/Earth directions. Every dispersed path is read back from the objects the run used
(``WorldParams`` of the world, the flight software's config, the telecommands actually decoded, the
fault injector's specs), so a dispersion that does not land is caught by ``execute``.
"""
from __future__ import annotations

import itertools
import math
import os
from typing import Any, Sequence

import numpy as np

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.execute import MAX_TRAJECTORY_POINTS, RunResult

_channel_ids = itertools.count()
FDIR_SEVERITIES = ("WARNING_HI", "FATAL")
NOT_FDIR = ("CMD_REJECTED", "TARGET_REJECTED")  # command outcomes, counted separately
ZONE_REBUILD_S = 10.0  # truth zones are rebuilt this often (the Moon moves < 0.002 deg in 10 s)

# Mission paths whose value lands in WorldParams under another name (read back from the world).
_WORLD_FIELDS = {
    ("spacecraft", "inertia_B_kgm2"): ("spacecraft", "inertia_B_kgm2"),
    ("spacecraft", "disturbance"): ("spacecraft", "disturbance"),
    ("spacecraft", "imu"): ("imu",),
    ("spacecraft", "star_tracker"): ("star_tracker",),
    ("orbit",): ("orbit",),
    ("epoch_utc",): ("epoch_utc",),
}
_WHEEL_FIELDS = {"Js_kgm2": "Js_kgm2", "max_torque_Nm": "max_torque_Nm", "max_speed_rad_s": "max_speed_rad_s",
                 "viscous_friction_Nm_per_rad_s": "viscous_friction_Nm_per_rad_s",
                 "coulomb_friction_Nm": "coulomb_friction_Nm", "axis_B": "axis_B", "failure": "failure"}


class _EventRecorder:
    """The flight software's telemetry sink in fast mode: keeps events, counts packets (no sockets)."""

    def __init__(self) -> None:
        self.events: list[tuple[float, str, dict]] = []
        self.counters = {"packets_sent": 0, "send_errors": 0, "events_sent": 0, "events_throttled": 0}
        self.now = 0.0

    def send_channels(self, packet_name, values=None, time_s=None):
        self.counters["packets_sent"] += 1

    def event(self, name, /, time_s=None, **args):
        self.events.append((self.now if time_s is None else float(time_s), name, args))
        self.counters["events_sent"] += 1
        return True

    def reset_counters(self):
        for k in self.counters:
            self.counters[k] = 0


def _timeline_packets(mission: Any) -> list[tuple[float, str, bytes]]:
    """The ground's timeline as TC packets (what the ground monitor would send), by time."""
    from fsw.dictionary import DICTIONARY
    from fsw.telecommand import encode_command
    law = mission.flight_software.law
    out = []
    for seq, entry in enumerate(mission.timeline):
        name = entry.command
        if name == "SET_TARGET":
            v = entry.target_direction_N()
            if v is not None:
                args = {"kind": "DIRECTION", "c0": v[0], "c1": v[1], "c2": v[2], "c3": 0.0}
            else:
                q = entry.q_target_NB
                args = {"kind": "QUATERNION", "c0": q[0], "c1": q[1], "c2": q[2], "c3": q[3]}
        elif name == "SET_MODE":
            args = {"mode": entry.mode}
        elif name == "SET_GAINS":
            eps = entry.eps if entry.eps is not None else (0.0 if law.eps == "auto" else law.eps)
            args = {"k1": entry.k1 if entry.k1 is not None else law.k1,
                    "kappa": entry.kappa if entry.kappa is not None else law.kappa, "eps": eps,
                    "rate_limit_deg_s": entry.rate_limit_deg_s if entry.rate_limit_deg_s is not None
                    else mission.flight_software.spacecraft.max_rate_deg_s}
        else:
            args = {}
        out.append((float(entry.t_s), name, encode_command(DICTIONARY, name, args, seq_count=seq)))
    return out


def _zone_truth_center(zone_cfg: Any, truth: Any) -> np.ndarray:
    if zone_cfg.body == "inertial":
        return np.asarray(zone_cfg.direction_N, dtype=float)
    return np.asarray({"sun": truth.sun_N, "moon": truth.moon_N, "earth": truth.earth_N}[zone_cfg.body], dtype=float)


class _Recording:
    """Truth per tick (preallocated arrays: appending Python lists would cost more than the step)."""

    def __init__(self, n: int, n_wheels: int, n_zones: int) -> None:
        self.t = np.empty(n)
        self.q_NB = np.empty((n, 4))
        self.wheel_speeds = np.empty((n, n_wheels))
        self.centers = np.empty((n, n_zones, 3))
        self.k = 0

    def add(self, truth: Any, centers: list[np.ndarray]) -> None:
        k = self.k
        self.t[k] = truth.t
        self.q_NB[k] = truth.q_NB
        self.wheel_speeds[k] = truth.wheel_speeds_rad_s
        for i, c in enumerate(centers):
            self.centers[k, i] = c
        self.k += 1


def _boresights(q_NB: np.ndarray, b_B: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    return Rotation.from_quat(q_NB, scalar_first=True).apply(b_B)


def _signed_margins_deg(zone_cfgs: Sequence[Any], rec: _Recording, y_N: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Signed angular margin [deg] of each boresight sample to each physical zone (negative inside)."""
    from gnc.sky_zones import SkyZoneBuilder
    n = y_N.shape[0]
    out = np.empty((n, len(zone_cfgs)))
    for i, cfg in enumerate(zone_cfgs):
        builder = SkyZoneBuilder(cfg.geometry, 0.0, fast=False)
        start = 0
        while start < n:
            stop = int(np.searchsorted(t, t[start] + ZONE_REBUILD_S, side="left"))
            stop = max(stop, start + 1)
            mid = (start + stop - 1) // 2
            zone = builder.build(rec.centers[mid, i])
            d = np.asarray(zone.separation_batch(y_N[start:stop]), dtype=float)
            ang = np.degrees(np.arccos(np.clip(1.0 - d, -1.0, 1.0)))
            for j in np.nonzero(d <= 0.0)[0]:  # inside (or on) the zone: depth from its signed separation
                s = float(zone.signed_separation(y_N[start + j]))
                ang[j] = -math.degrees(math.acos(min(1.0, max(-1.0, 1.0 - abs(s)))))
            out[start:stop, i] = ang
            start = stop
    return out


_S3_STRIDE = 5  # S^3 star-zone separations are costly: every 5th tick (0.5 s at 10 Hz) is enough here


def _s3_physical_zones(cfg: Any) -> list[tuple[Any, str]]:
    """The forbidden-attitude zones on S^3 as configured (no margin), like fsw.guidance builds them."""
    from gnc import zones as gz
    if getattr(cfg, "quaternion", None) is None:
        return []
    out = []
    for zc in cfg.quaternion.zones:
        centers = [np.asarray(zc.center_q, dtype=float)]
        if zc.antipodal_copy:
            centers.append(-centers[0])
        for c in centers:
            if zc.shape == "cone":
                out.append((gz.ConicZone(c, math.radians(zc.half_angle_deg)), zc.name))
            else:
                out.append((gz.StarZone.superellipsoid(c, None, np.asarray(zc.semi_axes, dtype=float),
                                                       zc.exponent), zc.name))
    return out


def _settling(t: np.ndarray, err_deg: np.ndarray, t_command: float, tol_deg: float) -> float:
    """Time after ``t_command`` from which the error stays below ``tol_deg`` (inf: never)."""
    after = t >= t_command - 1e-9
    idx = np.nonzero(after)[0]
    if idx.size == 0:
        return math.inf
    above = np.nonzero(err_deg[idx] >= tol_deg)[0]
    if above.size == 0:
        return 0.0
    last = idx[above[-1]]
    if last == t.size - 1:
        return math.inf
    return float(t[last + 1] - t_command)


def run_fast(mission: Any, seed: int, mode: str = "fast", paths: Sequence[str] = ()) -> RunResult:
    """Run one mission in this process (see the module docstring). ``seed``: the world's noise seed."""
    from fsw.app import FlightSoftware
    from fsw.bus import FswBusDriver, Icd, open_bus
    from fsw.telecommand import CommandDispatcher
    from hil_sim.lockstep import Simulator
    from hil_sim.mission import world_params
    from hil_sim.world import World

    params = world_params(mission)
    world = World(params, seed=seed)
    initial = world.truth
    icd = _icd()
    channel = f"virtual:campaign{os.getpid()}x{next(_channel_ids)}"
    sim_bus, fsw_bus = open_bus(channel), open_bus(channel)
    cfg = mission.flight_software
    if cfg.law.assumption_check != "off":
        # The full assumption check (gnc.checks) only feeds events and telemetry, never the control (the
        # per-cycle eps bound does not depend on it). In 'process' mode it answers after a wall-clock
        # delay, so its events would land on different ticks from run to run (no exact rerun), and it
        # forks a process per run; 'inline' is deterministic but costs ~1.5 s of CPU per check. The
        # campaign judges keep-out on truth instead, so fast mode switches it off: the GNC is unchanged.
        cfg = cfg.model_copy(update={"law": cfg.law.model_copy(update={"assumption_check": "off"})})
    fsw = None
    try:
        sim = Simulator(world, sim_bus, icd, gnc_period_s=cfg.gnc_period_s, faults=mission.faults,
                        fault_seed=seed)
        driver = FswBusDriver(fsw_bus, icd, world.n_wheels)
        telemetry = _EventRecorder()
        dispatcher = CommandDispatcher(telemetry=None, port=None)
        # The flight software's clock is the simulation clock: a cycle's execution time on this (shared)
        # host must not change its behaviour (a slip feeds FDIR), or runs would not reproduce exactly.
        # Execution-time overruns are a real-time property, measured by `keepout sil run --realtime`.
        fsw = FlightSoftware(cfg, driver, telemetry=telemetry, dispatcher=dispatcher, clock=lambda: sim.t_s)
        packets = _timeline_packets(mission)
        sent_commands: list[tuple[float, str, dict]] = []
        zone_cfgs = list(cfg.pointing.zones) if cfg.pointing is not None else []
        n_ticks = int(round(mission.duration_s / cfg.gnc_period_s))
        rec = _Recording(n_ticks + 1, world.n_wheels, len(zone_cfgs))
        rec.add(initial, [_zone_truth_center(z, initial) for z in zone_cfgs])
        next_packet = 0
        for _ in range(n_ticks):
            t_now = sim.t_s
            telemetry.now = t_now
            while next_packet < len(packets) and packets[next_packet][0] <= t_now + 1e-9:
                t_cmd, name, data = packets[next_packet]
                dispatcher.handle_datagram(data)
                sent_commands.append((t_cmd, name, _decoded_args(data)))
                next_packet += 1
            sim.begin_tick()
            inputs = driver.collect_tick(0.0)
            if inputs is not None:
                fsw.run_cycle(inputs)
            sim.end_tick(wait_s=0.0)
            truth = world.truth
            rec.add(truth, [_zone_truth_center(z, truth) for z in zone_cfgs])
        metrics, trajectory = _judge(mission, rec, sent_commands, telemetry, sim, fsw, zone_cfgs)
        used = _read_back(paths, mission, world, initial, fsw, sent_commands, sim)
        return RunResult(metrics=metrics, used=used, trajectory=trajectory, sim_time_s=float(rec.t[rec.k - 1]),
                         events=[f"{t:.1f} {n} {a}" for t, n, a in telemetry.events
                                 if _severity(n) in FDIR_SEVERITIES][:200])
    finally:
        if fsw is not None:
            fsw.shutdown()
        sim_bus.shutdown()
        fsw_bus.shutdown()


_ICD = None


def _icd():
    global _ICD  # one parsed DBC per worker process (parsing costs ~100 ms)
    if _ICD is None:
        from fsw.bus import Icd
        _ICD = Icd()
    return _ICD


def _decoded_args(data: bytes) -> dict:
    from fsw.dictionary import DICTIONARY
    from fsw.telecommand import decode_command
    _, args, _ = decode_command(DICTIONARY, data)
    return dict(args)


def _severity(name: str) -> str:
    from fsw.dictionary import DICTIONARY
    try:
        return DICTIONARY.event(name).severity.value
    except Exception:
        return ""


def _judge(mission, rec, sent_commands, telemetry, sim, fsw, zone_cfgs) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    n = rec.k
    t = rec.t[:n]
    q = rec.q_NB[:n]
    req = mission.requirements
    metrics: dict[str, float] = {}
    b_B = np.asarray(mission.spacecraft.instrument_boresight_B, dtype=float)
    y_N = _boresights(q, b_B)
    traj: dict[str, np.ndarray] = {}
    # keep-out margins, per zone and overall
    if zone_cfgs:
        margins = _signed_margins_deg(zone_cfgs, rec, y_N, t)
        for i, z in enumerate(zone_cfgs):
            metrics[f"margin_{z.name}_deg"] = float(margins[:, i].min())
        metrics["min_margin_deg"] = float(margins.min())
    else:
        metrics["min_margin_deg"] = math.inf
    s3_zones = _s3_physical_zones(mission.flight_software)
    if s3_zones:  # forbidden attitudes: margin on S^3 (an S^3 angle is half the rotation angle)
        s3 = np.array([[float(z.signed_separation(x)) for z, _ in s3_zones] for x in q[::_S3_STRIDE]])
        s3_deg = np.where(s3 >= 0, 1.0, -1.0) * np.degrees(np.arccos(np.clip(1.0 - np.abs(s3), -1.0, 1.0)))
        for i, (_, name) in enumerate(s3_zones):
            metrics[f"margin_{name}_deg"] = min(metrics.get(f"margin_{name}_deg", math.inf), float(s3_deg[:, i].min()))
        metrics["min_margin_deg"] = min(metrics["min_margin_deg"], float(s3_deg.min()))
    # pointing / attitude error to the last commanded target (or the configured one)
    targets = [(tc, a) for tc, name, a in sent_commands if name == "SET_TARGET"]
    t_cmd = targets[-1][0] if targets else 0.0
    q_t = None
    if targets and str(targets[-1][1]["kind"]) == "QUATERNION":
        a = targets[-1][1]
        q_t = np.array([a["c0"], a["c1"], a["c2"], a["c3"]], dtype=float)
    elif not targets and mission.flight_software.initial_mode == "QUATERNION":
        q_t = np.asarray(mission.flight_software.quaternion.target_q_NB, dtype=float)
    if q_t is not None:
        err = np.degrees(2.0 * np.arccos(np.clip(np.abs(q @ (q_t / np.linalg.norm(q_t))), -1.0, 1.0)))
        traj["q_NB"] = q[:: max(1, int(math.ceil(n / MAX_TRAJECTORY_POINTS)))]
        traj["target_q_NB"] = q_t / np.linalg.norm(q_t)
    else:
        if targets:
            a = targets[-1][1]
            target = np.array([a["c0"], a["c1"], a["c2"]], dtype=float)
        else:
            target = np.asarray(mission.flight_software.pointing.target_N, dtype=float)
        target = target / np.linalg.norm(target)
        err = np.degrees(np.arccos(np.clip(y_N @ target, -1.0, 1.0)))
        traj["target"] = target
    metrics["settling_time_s"] = _settling(t, err, t_cmd, req.settling_tolerance_deg)
    metrics["final_error_deg"] = float(err[-1])
    limits = np.array([w.max_speed_rad_s for w in mission.spacecraft.wheels])
    metrics["peak_wheel_speed_fraction"] = float(np.max(np.abs(rec.wheel_speeds[:n]) / limits))
    # skipped ticks (the executive counts them as slips) and ticks without CYCLE_DONE
    metrics["cycle_slips"] = float(fsw.executive.gnc.slips + sim.stats.cycle_done_timeouts)
    fdir = [name for _, name, _ in telemetry.events if _severity(name) in FDIR_SEVERITIES and name not in NOT_FDIR]
    expected = set(req.expected_fdir_events)
    metrics["unexpected_fdir_events"] = float(sum(1 for name in fdir if name not in expected))
    metrics["missing_expected_fdir_events"] = float(len(expected - set(fdir)))
    metrics["rejected_commands"] = float(sum(1 for _, name, _ in telemetry.events if name in NOT_FDIR))
    # trajectory for the report (decimated)
    step = max(1, int(math.ceil(n / MAX_TRAJECTORY_POINTS)))
    traj.update({"t_s": t[::step], "boresight_N": y_N[::step], "error_deg": err[::step]})
    for i, z in enumerate(zone_cfgs):
        from gnc.sky_zones import SkyZoneBuilder
        zone = SkyZoneBuilder(z.geometry, 0.0, fast=False).build(rec.centers[n - 1, i])
        traj[f"zone_{i}"] = np.asarray(zone.boundary(180), dtype=float)
    return metrics, traj


def _read_back(paths: Sequence[str], mission, world, initial, fsw, sent_commands, sim) -> dict[str, Any]:
    """Each dispersed path's value as used by the run's objects (see the module docstring)."""
    out: dict[str, Any] = {}
    for path in paths:
        loc = dsp.parse_path(path)
        out[path] = _used_value(loc, mission, world, initial, fsw, sent_commands, sim)
    return out


def _used_value(loc, mission, world, initial, fsw, sent_commands, sim) -> Any:
    p = world.params
    if loc[:1] == ("flight_software",):
        return dsp.read_path(fsw.cfg, loc[1:])
    if loc[:1] == ("initial_state",):
        field = loc[1] if len(loc) > 1 else None
        value = {"q_NB": initial.q_NB, "omega_BN_B_rad_s": initial.omega_BN_B,
                 "wheel_speeds_rad_s": initial.wheel_speeds_rad_s}.get(field)
        if value is not None:
            value = dsp.to_plain(np.asarray(value))
            if field == "q_NB" and np.dot(value, dsp.read_path(mission, loc)) < 0:
                value = [-x for x in value]  # q and -q are the same attitude
            return value[loc[2]] if len(loc) > 2 else value
    if loc[:1] == ("timeline",) and len(loc) >= 3:
        entry = mission.timeline[loc[1]]
        sent = [a for t, name, a in sent_commands if name == entry.command and abs(t - entry.t_s) < 1e-9]
        if sent and entry.command == "SET_TARGET" and loc[2] in ("ra_dec_deg", "target_N"):
            v = np.array([sent[0]["c0"], sent[0]["c1"], sent[0]["c2"]], dtype=float)
            if loc[2] == "target_N":
                return (v / np.linalg.norm(v)).tolist()
            return [math.degrees(math.atan2(v[1], v[0])) % 360.0,
                    math.degrees(math.asin(max(-1.0, min(1.0, v[2] / np.linalg.norm(v)))))]
    if loc[:1] == ("faults",):
        used = [{"kind": f.kind, "message": f.message, "start_s": f.start_s, "end_s": f.end_s}
                for f in sim.injector.faults] if sim.injector is not None else []
        return dsp.read_path({"faults": used}, loc)
    if loc[:2] == ("spacecraft", "wheels") and len(loc) >= 4 and loc[3] in _WHEEL_FIELDS:
        return dsp.to_plain(getattr(p.spacecraft.wheels[loc[2]], _WHEEL_FIELDS[loc[3]]))
    for prefix, target in _WORLD_FIELDS.items():
        if loc[:len(prefix)] == prefix:
            node: Any = p
            for part in target:
                node = getattr(node, part)
            rest = loc[len(prefix):]
            try:
                return dsp.read_path(dsp.to_plain(_dataclass_dict(node)), rest) if rest else _epoch_or_plain(node)
            except dsp.DispersionError:
                break  # named differently in the world: fall back to the mission model below
    return dsp.read_path(mission, loc)


def _dataclass_dict(node: Any) -> Any:
    import dataclasses
    return dataclasses.asdict(node) if dataclasses.is_dataclass(node) else node


def _epoch_or_plain(node: Any) -> Any:
    return dsp.to_plain(_dataclass_dict(node))
