"""The ``fast`` execution mode: one run in one process, the real flight software on a ``virtual`` CAN bus.

Per GNC tick: ``Simulator.begin_tick()`` (SYNC + device frames through the ICD, E2E protected),
``FswBusDriver.collect_tick(0)`` and ``FlightSoftware.run_cycle`` (the flight software's own code,
unchanged), ``Simulator.end_tick(wait_s=0)`` (wheel commands taken off the bus, world stepped). The
ground's timeline is released by the SIL's own ``hil_sim.sil.orchestrator.Timeline`` as real CCSDS telecommand packets
into the flight software's dispatcher at the tick of their time. Nothing waits on a clock, so a run is
deterministic and as fast as the code allows.

The run is recorded (``hil_sim.sil.orchestrator.TruthRecorder``) and judged on truth with the SIL's functions
(``hil_sim.sil.judge``: keep-out margins to the physical zones around the truth Sun/Moon/Earth, S^3 zones,
errors and settling per commanded target), so ``fast`` and ``sil`` judge alike. Every dispersed path is read back from the objects the run used
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
from hil_sim.devices.faults import WHEEL_FAULT_MODES, WHEEL_MESSAGE

_channel_ids = itertools.count()
# the events a run's result lists: FDIR's trips, and a plug-in stopped by keepout's guard
_RESULT_EVENTS = ("FDIR_TRIPPED", "PLUGIN_STOPPED", "COARSE_ATTITUDE_ON", "COARSE_ATTITUDE_OFF",
                  "COARSE_ATTITUDE_FOUND")

# Mission paths whose value lands in WorldParams under another name (read back from the world).
_WORLD_FIELDS = {
    ("spacecraft", "inertia_B_kgm2"): ("spacecraft", "inertia_B_kgm2"),
    ("spacecraft", "disturbance"): ("spacecraft", "disturbance"),
    ("spacecraft", "imu"): ("imu",),
    ("spacecraft", "star_tracker"): ("star_tracker",),
    ("orbit",): ("orbit",),
    ("epoch_utc",): ("epoch_utc",),
}
_WHEEL_FIELDS = {"Js_kgm2": "Js_kgm2", "spin_inertia_kgm2": "Js_kgm2", "max_torque_Nm": "max_torque_Nm", "max_speed_rad_s": "max_speed_rad_s",
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


class _TruthRows:
    """The truth ``hil_sim.sil.orchestrator.TruthRecorder`` keeps, for judging only: the world's state column and its
    Sun/Moon/Earth row copied as they are each tick (the SIL recorder builds a ``World.truth`` first)."""

    def __init__(self, n_ticks: int, world: Any) -> None:
        from hil_sim.world.world import AUX_EARTH, AUX_MOON, AUX_R_SC, AUX_SUN

        self.batch = world.batch
        self.n = 0
        self._rows = n_ticks + 1
        self.t_s = np.zeros(n_ticks + 1)
        self.X = np.zeros((n_ticks + 1, self.batch.X.shape[0]))
        self.AUX = np.zeros((n_ticks + 1, self.batch.AUX.shape[1]))
        self._cols = {"r_sc_N_km": AUX_R_SC, "sun_N": AUX_SUN, "moon_N": AUX_MOON, "earth_N": AUX_EARTH}
        self._bind()

    def _bind(self) -> None:
        # views of the run's column and row, made once: the world steps its arrays in place (re-made
        # should it ever replace them)
        b = self.batch
        self._X_src, self._AUX_src = b.X, b.AUX
        self._x0, self._aux0 = b.X[:, 0], b.AUX[0]

    def record(self) -> None:
        i = self.n
        if i < self._rows:
            b = self.batch
            if b.X is not self._X_src or b.AUX is not self._AUX_src:
                self._bind()
            self.t_s[i] = b.t
            self.X[i] = self._x0
            self.AUX[i] = self._aux0
            self.n = i + 1

    def arrays(self) -> dict[str, np.ndarray]:
        n = self.n
        out = {"t_s": self.t_s[:n], "q_NB": self.X[:n, 0:4], "omega_BN_B": self.X[:n, 4:7],
               "wheel_speed_rad_s": self.X[:n, 7:]}
        for name, col in self._cols.items():
            out[name] = self.AUX[:n, col:col + 3]
        return {k: np.ascontiguousarray(v) for k, v in out.items()}


class _EstimateRows:
    """The MEKF's attitude and attitude covariance at each tick, to judge its consistency on truth
    (`hil_sim.sil.consistency`): only fast mode can read the flight software's full covariance."""

    def __init__(self, n_rows: int) -> None:
        self._n_rows = n_rows
        self.rows = np.full(n_rows, -1)
        self.q = np.zeros((n_rows, 4))
        self._cov: np.ndarray | None = None  # the whole covariance per row (no slice per tick), sized at the first
        self.n = 0

    @property
    def P(self) -> np.ndarray:
        """The attitude covariance (rows, 3, 3) [rad^2]."""
        if self._cov is None:
            return np.zeros((len(self.rows), 3, 3))
        return np.ascontiguousarray(self._cov[:, :3, :3])

    def record(self, truth_row: int, estimator: Any) -> None:
        n = self.n
        if estimator.initialized and n < self._n_rows:
            P = estimator.P
            if self._cov is None:
                self._cov = np.zeros((len(self.rows),) + P.shape)
            self.rows[n] = truth_row
            self.q[n] = estimator.q_NB
            self._cov[n] = P
            self.n = n + 1

    def metrics(self, truth: dict[str, np.ndarray]) -> dict[str, float]:
        """``nees_mean`` and ``nees_band_fraction`` (cycles inside the 95 % chi-square band)."""
        from hil_sim.sil.consistency import attitude_nees, band_fraction

        keep = self.rows[:self.n] < len(truth["q_NB"])
        rows = self.rows[:self.n][keep]
        nees = attitude_nees(truth["q_NB"][rows], self.q[:self.n][keep], self.P[:self.n][keep])
        # the largest angle between the estimated and the true attitude (after the first fix)
        dots = np.abs(np.einsum("ij,ij->i", truth["q_NB"][rows], self.q[:self.n][keep]))
        error_deg = np.degrees(2.0 * np.arccos(np.clip(dots, 0.0, 1.0)))
        return {"nees_mean": float(np.mean(nees)) if nees.size else math.nan, "nees_band_fraction": band_fraction(nees),
                "max_attitude_error_deg": float(np.max(error_deg)) if error_deg.size else math.nan}


class _InProcessSender:
    """The ground's command sender for the SIL ``Timeline``, delivering into the flight software's
    dispatcher in this process: the same CCSDS TC packets, encoded with the same dictionary."""

    def __init__(self, dispatcher: Any) -> None:
        self.dispatcher = dispatcher
        self.seq = 0
        self.decoded: list[tuple[str, dict]] = []

    def send(self, name: str, **args: Any) -> None:
        from comms.dictionary import DICTIONARY
        from comms.telecommand import decode_command, encode_command
        data = encode_command(DICTIONARY, name, args, seq_count=self.seq)
        self.seq += 1
        self.decoded.append((name, dict(decode_command(DICTIONARY, data)[1])))
        self.dispatcher.handle_datagram(data)


def run_fast(mission: Any, seed: int, mode: str = "fast", paths: Sequence[str] = ()) -> RunResult:
    """Run one mission in this process (see the module docstring). ``seed``: the world's noise seed."""
    from fsw.assembly import build_flight_software
    from comms.bus import open_bus
    from fsw.telecommand import CommandDispatcher
    from hil_sim.sil.lockstep import Simulator
    from hil_sim.mission.model import door_params, magnetic_device_params, world_params
    from hil_sim.sil.orchestrator import Timeline
    from hil_sim.world.world import World

    params = world_params(mission)
    world = World(params, seed=seed)
    initial = world.truth
    icd = _icd()
    channel = f"virtual:campaign{os.getpid()}x{next(_channel_ids)}"
    sim_bus, fsw_bus = open_bus(channel, light=True), open_bus(channel, light=True)
    cfg = _without_assumption_check(mission.flight_software)
    fsw = None
    try:
        sim = Simulator(world, sim_bus, icd, gnc_period_s=cfg.gnc_period_s, faults=mission.faults,
                        fault_seed=seed, door=door_params(mission), magnetic=magnetic_device_params(mission))
        telemetry = _EventRecorder()
        dispatcher = CommandDispatcher(telemetry=None, port=None)
        # The flight software's clock is the simulation clock: a cycle's execution time on this (shared)
        # host must not change its behaviour (a slip feeds FDIR), or runs would not reproduce exactly.
        # Execution-time overruns are a real-time property, measured by `keepout sil run --realtime`.
        # It reads sim.t_s as set by _run_ticks at each tick's start and at the stop: the simulator advances
        # its tick only in end_tick, so between those points sim.t_s is that value (read ~5 times a cycle).
        now_s = [sim.t_s]
        fsw = build_flight_software(cfg, fsw_bus, icd, telemetry=telemetry, dispatcher=dispatcher,
                                    clock=lambda: now_s[0])
        timeline = Timeline(mission, _InProcessSender(dispatcher))
        n_ticks = int(round(mission.duration_s / cfg.gnc_period_s))
        record, estimates = _run_ticks(n_ticks, world, sim, fsw, timeline, telemetry, now_s)
        metrics, trajectory = _judge_run(mission, record, estimates, telemetry, sim, fsw)
        used = _read_back(paths, mission, world, initial, fsw, timeline.sent, sim)
        return RunResult(metrics=metrics, used=used, trajectory=trajectory, sim_time_s=float(record["t_s"][-1]),
                         events=[f"{t:.1f} {n} {a}" for t, n, a in telemetry.events if n in _RESULT_EVENTS][:200])
    finally:
        if fsw is not None:
            now_s[0] = sim.t_s  # the flight software's clock at its stop
            fsw.shutdown()
        sim_bus.shutdown()
        fsw_bus.shutdown()


def _without_assumption_check(cfg: Any) -> Any:
    """The flight software's configuration with the full assumption check off.

    The full assumption check (gnc.checks) only feeds events and telemetry, never the control (the per-cycle
    eps bound does not depend on it). In 'process' mode it answers after a wall-clock delay, so its events
    would land on different ticks from run to run (no exact rerun), and it starts a process per run;
    'inline' is deterministic but costs ~1.5 s of CPU per check. The campaign judges keep-out on truth
    instead, so fast mode switches it off: the GNC is unchanged."""
    if cfg.law.assumption_check == "off":
        return cfg
    return cfg.model_copy(update={"law": cfg.law.model_copy(update={"assumption_check": "off"})})


def _run_ticks(n_ticks: int, world: Any, sim: Any, fsw: Any, timeline: Any, telemetry: _EventRecorder,
               now_s: list[float]) -> tuple[dict[str, np.ndarray], _EstimateRows]:
    """The run's ``n_ticks`` lockstep ticks: the timeline's telecommands as they fall due, the simulator's
    frames, the flight software's cycle, the world's step. Returns the truth record (with the wheel torque
    commands and, with a door, its position) and the estimates at each tick."""
    driver = fsw.driver
    truth = _TruthRows(n_ticks, world)
    truth.record()
    door = sim.devices.door  # the aperture door's truth (its position) beside the world's, when there is one
    door_position = np.zeros(n_ticks + 1) if door is not None else None
    if door is not None:
        door_position[0] = door.position
    estimates = _EstimateRows(n_ticks + 1)
    torques = np.zeros((n_ticks + 1, world.n_wheels))
    next_command_s = _next_command_s(timeline)
    for row in range(n_ticks):  # row: the truth row of this tick (recorded before it)
        t_s = sim.t_s
        now_s[0] = t_s
        telemetry.now = t_s
        if next_command_s <= t_s + 1e-9:  # Timeline.release's own test, asked only when it can pass
            timeline.release(t_s)
            next_command_s = _next_command_s(timeline)
        sim.begin_tick()
        inputs = driver.collect_tick(0.0)
        if inputs is not None:
            fsw.run_cycle(inputs)
            estimates.record(row, fsw.estimator)  # the estimate of the truth row at this tick
            torques[row] = fsw.last.wheel_torque_cmd_Nm  # held over the tick that follows
        sim.end_tick(wait_s=0.0)
        truth.record()
        if door is not None:
            door_position[row + 1] = door.position
    record = truth.arrays()
    record["wheel_torque_Nm"] = torques[:len(record["t_s"])]
    if door is not None:
        record["door_position"] = door_position[:len(record["t_s"])]
    return record, estimates


def _judge_run(mission: Any, record: dict[str, np.ndarray], estimates: _EstimateRows, telemetry: _EventRecorder,
               sim: Any, fsw: Any) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """(metrics, trajectory) of the run: `judge` on truth and the events, the estimation's metrics, the
    plug-ins' and the door's."""
    from hil_sim.sil.judge import acknowledged_rate_limits

    trips = [str(a.get("monitor", "?")) for _, name, a in telemetry.events if name == "FDIR_TRIPPED"]
    rejected = sum(1 for _, name, _ in telemetry.events if name in ("CMD_REJECTED", "TARGET_REJECTED"))
    acked = acknowledged_rate_limits(telemetry.events)
    metrics, trajectory = judge(mission, record, trips, float(sim.stats.cycle_done_timeouts), rejected, acked)
    metrics.update(estimates.metrics(record))
    if fsw.plugins:
        from fsw.assembly import plugin_metrics
        metrics.update(plugin_metrics(fsw))
    if mission.flight_software.detumble is not None:  # onboard time of DETUMBLE_COMPLETE (inf: never)
        done = [float(a.get("t_s", math.nan)) for _, name, a in telemetry.events if name == "DETUMBLE_COMPLETE"]
        metrics["detumble_time_s"] = done[0] if done else math.inf
    if "door_position" in record:  # how often the flight software shut the aperture door (DOOR_CLOSING events)
        metrics["door_closes"] = float(sum(1 for _, name, _ in telemetry.events if name == "DOOR_CLOSING"))
    return metrics, trajectory


def _next_command_s(timeline: Any) -> float:
    """Scheduled time of the timeline's next telecommand [s] (inf when none is left)."""
    return timeline.entries[0].t_s if timeline.entries else math.inf


_ICD = None


def _icd():
    global _ICD  # one parsed DBC per worker process (parsing costs ~100 ms)
    if _ICD is None:
        from comms.bus import Icd
        _ICD = Icd()
    return _ICD


# Which side of each metric ``judge`` writes is better, for ``keepout campaign compare`` when no criterion
# of the campaign names the metric (the criteria's own sense comes first).
_METRIC_BETTER = {"detumble_time_s": "lower", "min_margin_deg": "higher", "settling_time_s": "lower", "final_error_deg": "lower",
                  "peak_wheel_speed_fraction": "lower", "peak_body_rate_fraction": "lower", "cycle_slips": "lower",
                  "unexpected_fdir_events": "lower", "missing_expected_fdir_events": "lower",
                  "rejected_commands": "lower", "instrument_exposure_s": "lower",
                  "instrument_exposure_depth_deg": "lower", "wheels_lost": "lower"}


def metric_better(name: str) -> str | None:
    """"higher" or "lower" for a metric of ``judge`` (per-zone margins ``margin_<zone>_deg`` included)."""
    if name.startswith("margin_") and name.endswith("_deg"):
        return "higher"
    return _METRIC_BETTER.get(name)


def wheels_lost(mission, end_s: float) -> set[int]:
    """The wheels (0-based) that stop producing torque for good by ``end_s``: failed at start, seized or dead
    (wheel_stuck, wheel_no_torque), or cut off from their commands (drop on RWn_CMD to the end of the run).
    A wheel whose only fault is its status (drop or silent on RWn_STATUS) still obeys and is not lost."""
    lost = {i for i, w in enumerate(mission.spacecraft.wheels) if w.failure != "none"}
    for f in mission.faults:
        match = WHEEL_MESSAGE.fullmatch(f.message)
        if match is None or f.start_s > end_s:
            continue
        wheel = int(match.group(1)) - 1
        if f.kind in WHEEL_FAULT_MODES:
            lost.add(wheel)
        elif f.kind == "drop" and match.group(2) == "CMD" and f.probability >= 1.0 and f.end_s >= end_s:
            lost.add(wheel)
    return lost


def judge(mission, truth: dict[str, np.ndarray], fdir_trips: Sequence[str], cycle_slips: float,
          rejected_commands: int = 0, gains_set: Sequence[tuple[float, float]] = (),
          ) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """A run's metrics, judged on truth with the SIL's own functions (``hil_sim.sil.judge``), so the fast and
    sil modes agree. ``truth``: the arrays of ``hil_sim.sil.orchestrator.TruthRecorder``; ``fdir_trips``: the monitor of
    every FDIR_TRIPPED event; ``cycle_slips``: lockstep ticks the flight software never answered;
    ``gains_set``: the rate limits the flight software acknowledged (GAINS_SET), for the rate judge."""
    from hil_sim.sil import judge as summary
    t = truth["t_s"]
    n = len(t)
    req = mission.requirements
    b_B = np.asarray(mission.spacecraft.instrument_boresight_B, dtype=float)
    y_N = summary.boresight_N(truth["q_NB"], b_B)
    # only each zone's minimum margin is judged here (and its last boundary drawn): see minimum_only
    zones = (summary.sky_zone_series(mission, truth, y_N, minimum_only=True)
             if mission.flight_software.pointing.zones else [])
    if mission.flight_software.quaternion.zones:
        zones += summary.attitude_zone_series(mission, summary.lifted_quaternions(mission, truth))
    metrics: dict[str, float] = {}
    lows = [(z.name, summary.zone_minimum(z)) for z in zones]  # None: a zone never armed (not judged)
    for name, low in lows:
        if low is not None:
            metrics[f"margin_{name}_deg"] = min(metrics.get(f"margin_{name}_deg", math.inf), low[1])
    for name, low in lows:
        # NaN, not a number that could pass a criterion: the zone was never judged
        metrics.setdefault(f"margin_{name}_deg", math.nan)
    judged = [low[1] for _, low in lows if low is not None]
    metrics["min_margin_deg"] = min(judged, default=math.nan if zones else math.inf)
    # the instrument's exposure: time and depth inside a sky zone with the door not fully closed (always
    # open without a door)
    exposure = summary.instrument_exposure(t, [z for z in zones if z.kind == "sky"], truth.get("door_position"))
    metrics["instrument_exposure_s"] = exposure["exposure_s"]
    metrics["instrument_exposure_depth_deg"] = exposure["depth_deg"]
    err, segments = summary.error_series(mission, truth, y_N)
    spans = summary.settling(mission, t, err, segments)
    if "wheel_torque_Nm" in truth:
        summary.add_torque_variation(spans, t, truth["wheel_torque_Nm"])
        # the roughest commanded slew [N m]
        metrics["torque_variation_Nm"] = max((s.get("torque_variation_Nm", math.nan) for s in spans if s["judged"]),
                                             default=math.nan)
    # the slowest commanded target (inf when one never settled within its span)
    metrics["settling_time_s"] = max((math.inf if s["settling_time_s"] is None else float(s["settling_time_s"])
                                      for s in spans if s["judged"]), default=math.nan)
    metrics["final_error_deg"] = float(err[-1])
    limits = np.array([w.max_speed_rad_s for w in mission.spacecraft.wheels])
    metrics["peak_wheel_speed_fraction"] = float(np.max(np.abs(truth["wheel_speed_rad_s"]) / limits[None, :]))
    metrics["peak_body_rate_fraction"] = summary.peak_body_rate_fraction(mission, truth, gains_set)[0]
    # lockstep: a slip is a tick the flight software never answered with CYCLE_DONE (as the SIL counts)
    metrics["cycle_slips"] = float(cycle_slips)
    expected = list(req.expected_fdir_events)
    metrics["unexpected_fdir_events"] = float(sum(1 for m in fdir_trips if m not in expected))
    metrics["missing_expected_fdir_events"] = float(sum(1 for m in expected if m not in fdir_trips))
    metrics["rejected_commands"] = float(rejected_commands)
    metrics["wheels_lost"] = float(len(wheels_lost(mission, float(t[-1]))))
    # trajectory for the report (decimated)
    step = max(1, int(math.ceil(n / MAX_TRAJECTORY_POINTS)))
    traj: dict[str, np.ndarray] = {"t_s": t[::step], "boresight_N": y_N[::step], "error_deg": err[::step],
                                   "q_NB": truth["q_NB"][::step]}
    if segments and segments[-1].mode == "POINTING":
        traj["target"] = np.asarray(segments[-1].target, dtype=float)
    sky = [z for z in zones if z.kind == "sky" and z.boundary_history]
    for i, z in enumerate(sky):
        traj[f"zone_{i}"] = np.asarray(z.boundary_history[-1][1], dtype=float)
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
        sent = [c["args"] for c in sent_commands
                if c["command"] == entry.command and abs(c["scheduled_t_s"] - entry.t_s) < 1e-9]
        if sent and entry.command == "SET_TARGET" and loc[2] in ("ra_dec_deg", "target_N"):
            v = np.array([sent[0]["c0"], sent[0]["c1"], sent[0]["c2"]], dtype=float)
            if loc[2] == "target_N":
                return (v / np.linalg.norm(v)).tolist()
            return [math.degrees(math.atan2(v[1], v[0])) % 360.0,
                    math.degrees(math.asin(max(-1.0, min(1.0, v[2] / np.linalg.norm(v)))))]
    if loc[:1] == ("faults",):
        # every field a mission's fault may have, so a dispersion that adds faults to a base mission's own
        # (drawn with their delay_s, bit, probability) compares field by field with what was injected
        used = [{"kind": f.kind, "message": f.message, "start_s": f.start_s, "end_s": f.end_s,
                 "delay_s": f.delay_s, "bit": f.bit, "probability": f.probability}
                for f in sim.fault_specs]
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
