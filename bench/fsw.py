"""Flight-software benchmarks: GNC cycle execution time, real-time jitter, keep-out margin study.

    .venv/bin/python bench/fsw.py                       # all three, 10 min real time (the default)
    .venv/bin/python bench/fsw.py --realtime-s 60 --cycles 3000 --skip-margin

1. cycle: POINTING mode with a star-shaped Sun zone, a Moon cone and an Earth polygon (all moving with the
   onboard ephemeris), lockstep against the hil_sim world (world time excluded). Wall-clock execution
   time of the GNC cycle (p50/p99/max) and its thread CPU time (insensitive to other load on the host).
   Goal: p99 <= 2 ms.
2. realtime: the flight software on the monotonic clock at 10 Hz (executive spin-wait scheduling) with the
   hil_sim simulator paced to real time in a separate process on a UDP-multicast CAN bus. Start jitter
   p50/p99/max and cycle slips. Goal: p99 <= 1 ms, zero slips. ``--rt-priority N`` runs both under
   SCHED_FIFO (rates.realtime_priority), as on a flight computer; without it they share the host's
   time-sharing scheduler with whatever else runs.
3. margin: the same 120 deg slew past the Sun zone as tests/fsw/test_closed_loop.py, with path planning
   off (the law alone rides the zone's edge), for several law.margin_deg: the smallest physical margin of the ideal kinematic loop (the law alone) and of the
   real loop (dynamics, wheels, estimation, 10 Hz). Their difference is the margin the loop consumes.

Prints tables and writes bench/results/fsw.json.
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# This script is bench/fsw.py: keep its directory off the path so ``import fsw`` finds the package.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(ROOT / "tests" / "fsw"))  # closed_loop_kit: world <-> FSW glue shared with the tests

EPOCH = "2030-03-29T12:00:00Z"
SUN_STAR = {"shape": "superellipse", "semi_axes_deg": [25.0, 12.0], "exponent": 0.7, "orientation_deg": 30.0}
MOON_CONE = {"shape": "cone", "half_angle_deg": 12.0}
EARTH_POLY = {"shape": "polygon", "vertices_deg": [[15, 0], [8, 8], [0, 15], [-8, 8], [-15, 0], [-8, -8], [0, -15], [8, -8]]}


def _zones():
    return [{"name": "sun", "body": "sun", "geometry": SUN_STAR},
            {"name": "moon", "body": "moon", "geometry": MOON_CONE},
            {"name": "earth", "body": "earth", "geometry": EARTH_POLY}]


def _world_and_cfg(margin_deg: float = 3.0, seed: int = 11, **sections):
    from closed_loop_kit import attitude_with_boresight, fsw_config_for, slew_geometry
    from hil_sim.world.params import SpacecraftParams, StarTrackerParams, WorldParams
    from hil_sim.world.world import World
    from scipy.spatial.transform import Rotation

    y0, yd, _, _ = slew_geometry(EPOCH.replace("Z", "+00:00"))
    q_BS = np.roll(Rotation.from_rotvec([0.0, math.pi / 2, 0.0]).as_quat(), 1)
    wp = WorldParams(epoch_utc=EPOCH, spacecraft=SpacecraftParams(q_NB0=tuple(attitude_with_boresight(y0))),
                     star_tracker=StarTrackerParams(q_BS=tuple(q_BS)))
    base = dict(initial_mode="POINTING", law={"margin_deg": margin_deg, "k1": 0.1},
                pointing={"boresight_B": [0, 0, 1], "target_N": list(yd), "zones": _zones()})
    base.update(sections)
    return World(wp, seed=seed), fsw_config_for(wp, **base), yd


def _pct(values, q):
    return float(np.percentile(np.asarray(values), q)) if len(values) else float("nan")


# ------------------------------------------------------------------------------------------ 1. cycle
def bench_cycle(cycles: int) -> dict:
    from closed_loop_kit import DirectLoop, RecordingDriver

    from fsw.assembly import build_flight_software
    from comms.dictionary import DICTIONARY
    from fsw.telemetry import TelemetrySender

    world, cfg, _ = _world_and_cfg()
    tm = TelemetrySender(DICTIONARY, port=None)  # packets are built and encoded, not sent
    fsw = build_flight_software(cfg, driver=RecordingDriver(len(cfg.spacecraft.wheels)), telemetry=tm)
    loop = DirectLoop(fsw, world, cfg.gnc_period_s)
    loop.prime()
    wall, cpu = [], []
    orig = fsw.gnc_task

    def timed(inputs, slipped):
        c0 = time.thread_time()
        orig(inputs, slipped)
        cpu.append(1e3 * (time.thread_time() - c0))
        wall.append(fsw.last.exec_time_ms)

    fsw.executive.gnc_task = timed
    for _ in range(cycles):
        loop.step()
    fsw.shutdown()
    return {
        "cycles": cycles, "zones": ["sun superellipse p=0.7", "moon cone", "earth polygon"],
        "wall_ms": {"p50": _pct(wall, 50), "p99": _pct(wall, 99), "max": max(wall)},
        "cpu_ms": {"p50": _pct(cpu, 50), "p99": _pct(cpu, 99), "max": max(cpu)},
        "housekeeping_ms": {"mean": fsw.executive.hk.exec_mean_ms, "max": fsw.executive.hk.exec_max_ms},
        "slips_lockstep": fsw.executive.gnc.slips,
        "goal_p99_ms": 2.0,
    }


# --------------------------------------------------------------------------------------- 2. realtime
def _simulator_process(bus_spec: str, ticks: int, ready, done, rt_priority: int = 0) -> None:
    from comms.bus import Icd, open_bus
    from hil_sim.sil.lockstep import Simulator

    if rt_priority:  # the simulator stands in for hardware, which keeps its own time whatever the host does
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt_priority))

    world, cfg, _ = _world_and_cfg(seed=12)
    bus = open_bus(bus_spec)
    sim = Simulator(world, bus, Icd(), gnc_period_s=cfg.gnc_period_s)
    ready.set()
    stats = sim.run_realtime(ticks)
    done.put({"ticks": stats.ticks, "realtime_overruns": stats.realtime_overruns,
              "cycle_done_late": stats.cycle_done_late, "max_lateness_ms": 1e3 * stats.max_lateness_s})
    bus.shutdown()


def bench_realtime(seconds: float, rt_priority: int = 0) -> dict:
    from fsw.assembly import build_flight_software
    from comms.bus import open_bus

    port = 43000 + os.getpid() % 1000
    spec = f"udp_multicast:239.74.163.{os.getpid() % 200 + 2}:{port}"
    _, cfg, _ = _world_and_cfg()
    ctx = multiprocessing.get_context("fork")
    ready, done = ctx.Event(), ctx.Queue()
    cfg.rates.realtime_priority = rt_priority
    sim = ctx.Process(target=_simulator_process, args=(spec, int(seconds * 10) + 20, ready, done,
                                                       max(0, rt_priority - 1)), daemon=True)
    bus = open_bus(spec)
    sim.start()
    ready.wait(60)
    from comms.dictionary import DICTIONARY
    from fsw.telemetry import TelemetrySender

    fsw = build_flight_software(cfg, bus, telemetry=TelemetrySender(DICTIONARY, port=None))  # events kept, no socket
    n = fsw.run_realtime(seconds)
    ex = fsw.executive
    jitter_ms = 1e3 * np.asarray(ex.jitter.recent)
    sim.join(timeout=30)
    sim_stats = done.get(timeout=5) if not done.empty() else {}
    fsw.shutdown()
    bus.shutdown()
    return {
        "seconds": seconds, "cycles": n, "rate_hz": cfg.rates.gnc_rate_hz, "bus": spec,
        "jitter_ms": {"p50": _pct(jitter_ms, 50), "p99": _pct(jitter_ms, 99), "max": float(jitter_ms.max())},
        "slips": ex.gnc.slips, "exec_ms": {"mean": ex.gnc.exec_mean_ms, "max": ex.gnc.exec_max_ms},
        "final_mode": fsw.mode, "simulator": sim_stats, "rt_priority": rt_priority,
        "rt_events": [e.args.get("reason") for e in getattr(fsw.telemetry, "recent_events", [])
                      if e.name.startswith("RT_SCHEDULING")],
        "warnings": [e.message for e in getattr(fsw.telemetry, "recent_events", [])
                     if e.severity.name in ("WARNING_LO", "WARNING_HI", "FATAL")][:50],
        "goal_p99_ms": 1.0, "goal_slips": 0,
    }


# ----------------------------------------------------------------------------------------- 3. margin
def bench_margin(margins: list[float], seconds: float) -> list[dict]:
    from closed_loop_kit import DirectLoop, RecordingDriver, boresight_N
    from scipy.spatial.transform import Rotation

    from fsw.assembly import build_flight_software
    from fsw.guidance import Guidance
    from gnc import sky_zones

    judges = [sky_zones.SkyZoneBuilder(SUN_STAR), sky_zones.SkyZoneBuilder(MOON_CONE)]

    def signed_deg(zone, y):
        s = float(zone.signed_separation(y))
        return math.copysign(math.degrees(math.acos(1.0 - abs(s))), s)

    rows = []
    b = np.array([0.0, 0.0, 1.0])
    for m in margins:
        # path planning off: the study is about the law at a zone's edge, which a planned path keeps clear of
        sections = dict(pointing={"boresight_B": [0, 0, 1], "zones": [_zones()[0], _zones()[1]], "path": {"enabled": False}})
        world, cfg, yd = _world_and_cfg(margin_deg=m, **sections)
        cfg.pointing.target_N = list(yd)
        # (a) the law alone: perfect kinematics, truth ephemeris frozen at the epoch
        tr = world.truth
        zones = [judges[0].build(tr.sun_N), judges[1].build(tr.moon_N)]
        g = Guidance(cfg)
        q = np.array(world.truth.q_NB)
        kin = 180.0
        for k in range(int(seconds * 10)):
            out = g.step(0.1 * k, 0.1, q, np.zeros(3))
            rot = Rotation.from_quat(np.roll(q, -1)) * Rotation.from_rotvec(out.omega_cmd_BN_B * 0.1)
            q = np.roll(rot.as_quat(), 1)
            kin = min(kin, min(signed_deg(z, boresight_N(q, b)) for z in zones))
        # (b) the real loop
        fsw = build_flight_software(cfg, driver=RecordingDriver(len(cfg.spacecraft.wheels)))
        loop = DirectLoop(fsw, world, cfg.gnc_period_s)
        loop.prime()
        real = 180.0
        for k in range(int(seconds * 10)):
            loop.step()
            if k % 300 == 0:
                zones = [judges[0].build(world.truth.sun_N), judges[1].build(world.truth.moon_N)]
            real = min(real, min(signed_deg(z, boresight_N(world.truth.q_NB, b)) for z in zones))
        rows.append({"margin_deg": m, "kinematic_min_deg": kin, "real_loop_min_deg": real,
                     "consumed_by_loop_deg": kin - real})
        fsw.shutdown()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycles", type=int, default=6000, help="GNC cycles for the execution-time benchmark")
    ap.add_argument("--realtime-s", type=float, default=600.0, help="real-time run length [s] (default 10 min)")
    ap.add_argument("--margins", default="0,1,2,3", help="law margins [deg] for the margin study")
    ap.add_argument("--margin-s", type=float, default=250.0, help="simulated seconds per margin-study slew")
    ap.add_argument("--rt-priority", type=int, default=0,
                    help="real-time run: SCHED_FIFO priority of the flight software (rates.realtime_priority; "
                         "the simulator gets one less); 0 = the host's normal scheduler")
    ap.add_argument("--skip-cycle", action="store_true")
    ap.add_argument("--skip-realtime", action="store_true")
    ap.add_argument("--skip-margin", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "fsw.json"))
    args = ap.parse_args(argv)
    result = {"host": {"python": platform.python_version(), "cpus": os.cpu_count(),
                       "loadavg_start": os.getloadavg()}, "command": " ".join(sys.argv)}
    if not args.skip_cycle:
        r = result["cycle"] = bench_cycle(args.cycles)
        print(f"\nGNC cycle, POINTING with Sun/Moon/Earth zones, {r['cycles']} cycles")
        print(f"{'':12}{'p50 ms':>10}{'p99 ms':>10}{'max ms':>10}")
        for key in ("wall_ms", "cpu_ms"):
            v = r[key]
            print(f"{key:12}{v['p50']:10.3f}{v['p99']:10.3f}{v['max']:10.3f}")
        print(f"goal p99 <= {r['goal_p99_ms']} ms; housekeeping mean {r['housekeeping_ms']['mean']:.3f} ms")
    if not args.skip_realtime:
        r = result["realtime"] = bench_realtime(args.realtime_s, args.rt_priority)
        v = r["jitter_ms"]
        print(f"\nReal time at {r['rate_hz']} Hz for {r['seconds']} s ({r['cycles']} cycles), simulator in another process")
        print(f"{'jitter':12}{'p50 ms':>10}{'p99 ms':>10}{'max ms':>10}{'slips':>8}")
        print(f"{'':12}{v['p50']:10.3f}{v['p99']:10.3f}{v['max']:10.3f}{r['slips']:8d}")
        print(f"goal p99 <= {r['goal_p99_ms']} ms, 0 slips; simulator: {r['simulator']}")
    if not args.skip_margin:
        rows = result["margin"] = bench_margin([float(x) for x in args.margins.split(",")], args.margin_s)
        print("\nKeep-out margin study (120 deg slew past the Sun star zone and Moon cone)")
        print(f"{'margin_deg':>11}{'kinematic min':>15}{'real loop min':>15}{'consumed':>10}")
        for row in rows:
            print(f"{row['margin_deg']:11.1f}{row['kinematic_min_deg']:15.3f}{row['real_loop_min_deg']:15.3f}{row['consumed_by_loop_deg']:10.3f}")
    result["loadavg_end"] = os.getloadavg()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2, default=float))
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
