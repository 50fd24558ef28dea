"""Soak: N simulated hours of flight software in lockstep with the hil_sim world, through the bus.

    .venv/bin/python bench/soak.py                 # 24 simulated hours (the goal; ~30 min wall here at SCHED_FIFO)
    .venv/bin/python bench/soak.py --hours 1

Everything runs in one process on a ``virtual`` CAN bus (hil_sim.sil.lockstep.Simulator in-process mode):
every frame is ICD-encoded, E2E-protected and checked. Telemetry goes as real UDP datagrams to a loopback
receiver process that checks the CCSDS sequence counts per APID, so lost packets are counted, not guessed.
The scenario keeps the spacecraft busy: POINTING with Sun (star-shaped), Moon (cone) and Earth (polygon)
zones moving with the ephemeris, a new target telecommanded every 20 simulated minutes (alternating
between two sky directions), housekeeping and assumption checks as in flight.

Reported: quaternion-norm drift of the estimate and of the truth, memory (RSS over time; growth from
10 % of the run until tracing starts, and the tracemalloc top growth over the last part of the run, from
--trace-from + 5 % to the end), cycle slips (lockstep budget: a cycle whose host execution time exceeds
the period), every cycle over 20 ms with the garbage collector's time and the hypervisor's steal time on
the cycle's CPU inside it, lost telemetry packets, bus E2E error counters, FDIR trips, final mode. Goals: no growth,
0 slips, 0 lost. ``--rt-priority N`` runs it under SCHED_FIFO as flight software would run, resting
between steps to stay below the kernel's real-time bandwidth (``--rt-duty``).
Prints a table and writes bench/results/soak.json.
"""
from __future__ import annotations

import argparse
import gc
import json
import math
import multiprocessing
import os
import socket
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(ROOT / "tests" / "fsw"))


class TmReceiver:
    """Counts telemetry datagrams and sequence-count gaps per APID (14-bit counts) in a process of its
    own, as the ground monitor would: a receiver thread in the flight process would take the GIL for
    every datagram, and a host that preempts it there stalls the real-time cycle thread."""

    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.received = 0
        self.lost = 0
        ctx = multiprocessing.get_context("fork")
        self._stop = ctx.Event()
        self._counts, child_end = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=self._run, args=(child_end,), daemon=True)

    def start(self) -> None:
        self._proc.start()
        self.sock.close()  # the child has it

    def _run(self, counts) -> None:
        self.sock.settimeout(0.2)
        last: dict[int, int] = {}
        while not self._stop.is_set():
            try:
                data = self.sock.recv(65536)
            except socket.timeout:
                continue
            if len(data) < 6:
                continue
            apid = ((data[0] & 0x07) << 8) | data[1]
            seq = ((data[2] & 0x3F) << 8) | data[3]
            prev = last.get(apid)
            if prev is not None:
                self.lost += (seq - prev - 1) % 16384
            last[apid] = seq
            self.received += 1
        counts.send((self.received, self.lost))

    def finish(self) -> None:
        """Stop the receiver (after the last datagram has had time to arrive) and collect its counts."""
        self._stop.set()
        if self._counts.poll(5.0):
            self.received, self.lost = self._counts.recv()
        self._proc.join(2)


LONG_CYCLE_MS = 20.0  # a fifth of the 10 Hz budget: worth a look even when it is not a slip


class RtBandwidth:
    """Rests between lockstep steps so that a real-time run stays below the kernel's RT bandwidth."""

    WINDOW_S = 0.02

    def __init__(self, duty: float):
        self.duty = duty
        self.since = time.perf_counter()
        self.rested_s = 0.0

    def between_steps(self) -> None:
        busy = time.perf_counter() - self.since
        if busy >= self.WINDOW_S:
            pause = busy * (1.0 - self.duty) / self.duty
            time.sleep(pause)
            self.rested_s += pause
            self.since = time.perf_counter()


def rss_mb() -> float:
    import psutil

    return psutil.Process().memory_info().rss / 1e6


class GcTimer:
    """The cyclic garbage collector's runs, timed through ``gc.callbacks``: how many per generation, the
    longest, and the collecting time inside the current step (to tell a long cycle that collected)."""

    def __init__(self) -> None:
        self.started = 0.0
        self.in_step_s = 0.0
        self.count = [0, 0, 0]
        self.longest_ms = [0.0, 0.0, 0.0]
        self.total_s = [0.0, 0.0, 0.0]

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self.started = time.perf_counter()
            return
        spent = time.perf_counter() - self.started
        g = info["generation"]
        self.count[g] += 1
        self.total_s[g] += spent
        self.longest_ms[g] = max(self.longest_ms[g], 1e3 * spent)
        self.in_step_s += spent


class StealClock:
    """CPU time the hypervisor took from one CPU (``steal`` in /proc/stat, in ms; 10 ms resolution): a
    real-time thread in a virtual machine cannot stop its virtual CPU from being descheduled, so a long
    cycle with steal time in it was not the flight software's own. ``cpu`` None: all CPUs together."""

    def __init__(self, cpu: int | None) -> None:
        self._fd = os.open("/proc/stat", os.O_RDONLY)
        self._key = b"cpu " if cpu is None else f"\ncpu{cpu} ".encode()
        self._ms_per_tick = 1e3 / os.sysconf("SC_CLK_TCK")

    def ms(self) -> float:
        buf = os.pread(self._fd, 16384, 0)
        i = buf.find(self._key) + len(self._key)
        return int(buf[i:buf.find(b"\n", i)].split()[7]) * self._ms_per_tick

    def close(self) -> None:
        os.close(self._fd)


def _repo_relative(filename: str) -> str:
    """A source file as the repository names it: a result file names no folder of the machine."""
    path = Path(filename).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else path.name


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0, help="simulated hours (default 24)")
    ap.add_argument("--no-tracemalloc", action="store_true", help="skip tracemalloc")
    ap.add_argument("--trace-from", type=float, default=0.85,
                    help="fraction of the run at which tracemalloc starts (it slows the run ~2x while on); the "
                         "growth top compares a snapshot 5 %% of the run later with the end (default 0.85)")
    ap.add_argument("--rt-priority", type=int, default=0,
                    help="run under SCHED_FIFO at this priority (root; 0 = normal scheduling), as flight "
                         "software would: a shared host's other work then cannot stretch a cycle past its period")
    ap.add_argument("--cpu", type=int, default=None,
                    help="pin the cycle thread to this CPU (the telemetry receiver process keeps every CPU, so a "
                         "real-time cycle thread cannot starve it); keeps the run off a CPU that other work needs")
    ap.add_argument("--rt-duty", type=float, default=0.9,
                    help="with --rt-priority: the most of any 20 ms the run may be busy (default 0.9); it rests "
                         "for the rest. Linux stops a real-time task that has used 95 %% of a second "
                         "(sched_rt_runtime_us) for the remainder of it, which would land inside some cycle "
                         "as a slip. A 10 Hz flight loop is ~1 %% busy and never meets that limit; a lockstep "
                         "soak running 60x faster than real time is 100 %% busy and would")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "soak.json"))
    args = ap.parse_args(argv)

    from closed_loop_kit import BusLoop, attitude_with_boresight, fsw_config_for, slew_geometry
    from comms.dictionary import DICTIONARY
    from fsw.telecommand import CommandDispatcher
    from comms.telecommand import encode_command
    from fsw.telemetry import TelemetrySender
    from hil_sim.world.params import SpacecraftParams, StarTrackerParams, WorldParams
    from hil_sim.world.world import World
    from scipy.spatial.transform import Rotation

    epoch = "2030-03-29T12:00:00Z"
    y0, yd, _, _ = slew_geometry(epoch.replace("Z", "+00:00"))
    q_BS = np.roll(Rotation.from_rotvec([0.0, math.pi / 2, 0.0]).as_quat(), 1)
    wp = WorldParams(epoch_utc=epoch, spacecraft=SpacecraftParams(q_NB0=tuple(attitude_with_boresight(y0))),
                     star_tracker=StarTrackerParams(q_BS=tuple(q_BS)))
    zones = [
        {"name": "sun", "body": "sun", "geometry": {"shape": "superellipse", "semi_axes_deg": [25, 12], "exponent": 0.7}},
        {"name": "moon", "body": "moon", "geometry": {"shape": "cone", "half_angle_deg": 12}},
        {"name": "earth", "body": "earth", "geometry": {"shape": "polygon", "vertices_deg": [[15, 0], [8, 8], [0, 15], [-8, 8], [-15, 0], [-8, -8], [0, -15], [8, -8]]}},
    ]
    rx = TmReceiver()
    rx.start()
    cfg = fsw_config_for(wp, initial_mode="POINTING", law={"margin_deg": 3.0},
                         pointing={"target_N": list(yd), "zones": zones},
                         tmtc={"telemetry_port": rx.port})
    tm = TelemetrySender(DICTIONARY, "127.0.0.1", rx.port)
    tc = CommandDispatcher(DICTIONARY, tm, port=None)
    loop = BusLoop(cfg, World(wp, seed=21), telemetry=tm, dispatcher=tc)
    fsw = loop.fsw

    from fsw.runtime import prepare_cycle_thread

    prepare_cycle_thread()  # as the flight software's own cycle loops do before their first cycle
    if args.rt_priority:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt_priority))
    if args.cpu is not None:
        os.sched_setaffinity(0, {args.cpu})  # this thread only: the receiver started above keeps its CPUs
    ticks = int(round(args.hours * 3600 / cfg.gnc_period_s))
    trace_start = int(ticks * args.trace_from)
    trace_snap = min(ticks - 1, trace_start + max(1, ticks // 20))
    targets = [yd, y0]
    tc_every = int(1200 / cfg.gnc_period_s)
    sample_every = max(1, ticks // 200)
    rss, qn_est, qn_truth = [], [], []
    snap_early = None
    t_wall = time.perf_counter()
    seq = 0
    rss_before_trace = None
    notable, last_event = [], None  # warnings and worse, with onboard time (the deque keeps only the latest)
    rest = RtBandwidth(args.rt_duty) if args.rt_priority else None
    long_cycles = []  # GNC cycles longer than LONG_CYCLE_MS: when, whether tracemalloc was on, GC time in it
    gc_timer = GcTimer()
    gc.callbacks.append(gc_timer)
    steal = StealClock(args.cpu)
    steal_start = steal.ms()
    for k in range(ticks):
        if rest is not None:
            rest.between_steps()
        if k == trace_start and not args.no_tracemalloc:
            rss_before_trace = rss_mb()  # RSS growth is judged before tracing adds its own memory
            tracemalloc.start(1)  # one frame: enough to locate growth, ~2x slower instead of ~15x
        gc_timer.in_step_s = 0.0
        stolen_before = steal.ms()
        loop.step()
        task_ms = 1e3 * fsw.executive.gnc.last_exec_s  # the whole GNC task, as slips are judged
        if task_ms > LONG_CYCLE_MS and len(long_cycles) < 100:
            # cycle_ms: the part up to the cycle record; the rest is the telemetry packet's sending
            long_cycles.append({"t_s": round(k * cfg.gnc_period_s, 1), "exec_ms": round(task_ms, 2),
                                "cycle_ms": round(fsw.last.exec_time_ms, 2),
                                "tracing": tracemalloc.is_tracing(), "gc_ms_in_step": round(1e3 * gc_timer.in_step_s, 2),
                                "steal_ms_in_step": steal.ms() - stolen_before})
        if k and k % tc_every == 0:
            seq += 1
            v = targets[seq % 2]
            tc.handle_datagram(encode_command(DICTIONARY, "SET_TARGET", {"kind": "DIRECTION", "c0": v[0], "c1": v[1], "c2": v[2]}, seq_count=seq))
        if k % 50 == 0 and tm.recent_events and tm.recent_events[-1] is not last_event:
            fresh = list(tm.recent_events)
            start = next((i + 1 for i in range(len(fresh) - 1, -1, -1) if fresh[i] is last_event), 0)
            notable += [{"t_s": round(k * cfg.gnc_period_s, 1), "event": e.name, "message": e.message}
                        for e in fresh[start:] if e.severity.name in ("WARNING_LO", "WARNING_HI", "FATAL")]
            last_event = fresh[-1]
        if k % sample_every == 0:
            rss.append((k * cfg.gnc_period_s / 3600, rss_mb()))
            qn_est.append(abs(float(np.linalg.norm(fsw.estimator.q_NB)) - 1.0))
            qn_truth.append(abs(float(np.linalg.norm(loop.world.truth.q_NB)) - 1.0))
        if k == trace_snap and tracemalloc.is_tracing():
            snap_early = tracemalloc.take_snapshot()
        if k % 36000 == 0 and k:
            print(f"  {k * cfg.gnc_period_s / 3600:5.1f} h sim, {time.perf_counter() - t_wall:7.0f} s wall, RSS {rss[-1][1]:.1f} MB", flush=True)
    top = []
    if snap_early is not None:
        snap_end = tracemalloc.take_snapshot()
        for stat in snap_end.compare_to(snap_early, "lineno")[:8]:
            frame = stat.traceback[0]
            top.append({"where": f"{_repo_relative(frame.filename)}:{frame.lineno}", "size_diff_kB": stat.size_diff / 1024, "count_diff": stat.count_diff})
        tracemalloc.stop()
    wall = time.perf_counter() - t_wall
    time.sleep(0.5)
    rx.finish()
    counters = fsw.hk_values()
    rss_first = rss[len(rss) // 10][1] if len(rss) > 10 else rss[0][1]
    rss_last = rss_before_trace if rss_before_trace is not None else rss[-1][1]
    result = {
        "command": " ".join(sys.argv), "simulated_hours": args.hours, "ticks": ticks, "wall_s": wall,
        "quat_norm_drift": {"estimate_max": max(qn_est), "truth_max": max(qn_truth)},
        "rss_mb": {"at_10pct": rss_first, "before_tracing": rss_last, "growth": rss_last - rss_first,
                   "end_with_tracing": rss[-1][1], "series": rss},
        "tracemalloc_window_hours": ([trace_snap * cfg.gnc_period_s / 3600, args.hours] if snap_early is not None else None),
        "rt_priority": args.rt_priority, "cycle_thread_cpu": args.cpu,
        "rt_duty": args.rt_duty if args.rt_priority else None, "rested_s": rest.rested_s if rest else 0.0,
        "tracemalloc_top_growth": top,
        "slips": fsw.executive.gnc.slips,
        "long_cycles": long_cycles,
        "steal_ms": steal.ms() - steal_start,
        "gc": {"collections": gc_timer.count, "longest_ms": gc_timer.longest_ms, "total_s": gc_timer.total_s},
        "exec_ms": {"mean": fsw.executive.gnc.exec_mean_ms, "max": fsw.executive.gnc.exec_max_ms},
        "tm": {"sent": tm.counters["packets_sent"], "send_errors": tm.counters["send_errors"],
               "received": rx.received, "lost_by_sequence_count": rx.lost},
        "bus": {k: counters[k] for k in ("bus_rx_ok", "bus_crc_errors", "bus_alive_errors", "bus_repeated", "bus_decode_errors", "bus_timeouts")},
        "simulator": {"cycle_done_timeouts": loop.sim.stats.cycle_done_timeouts, "ticks": loop.sim.stats.ticks},
        "fdir_trips": fsw.fdir.trips, "final_mode": fsw.mode, "targets_commanded": seq,
        "tc_accepted": tc.counters["accepted"], "tc_rejected": tc.counters["rejected"],
        "loadavg_end": os.getloadavg(),
        "notable_events": notable[:500],
        "fdir_trips_by_monitor": {},
        "events_by_name": {},
    }
    for e in tm.recent_events:
        result["events_by_name"][e.name] = result["events_by_name"].get(e.name, 0) + 1
        if e.name == "FDIR_TRIPPED":
            m = e.args.get("monitor")
            result["fdir_trips_by_monitor"][m] = result["fdir_trips_by_monitor"].get(m, 0) + 1
    loop.close()
    steal.close()
    print(f"\nSoak: {args.hours} simulated hours ({ticks} ticks) in {wall:.0f} s wall")
    rows = [
        ("quaternion norm drift, estimate (max |q|-1)", f"{result['quat_norm_drift']['estimate_max']:.2e}"),
        ("quaternion norm drift, truth (max |q|-1)", f"{result['quat_norm_drift']['truth_max']:.2e}"),
        ("RSS at 10 % / before tracing / growth [MB]", f"{rss_first:.1f} / {rss_last:.1f} / {rss_last - rss_first:+.1f}"),
        ("cycle slips (lockstep budget)", str(result["slips"])),
        ("GNC exec mean / max [ms]", f"{result['exec_ms']['mean']:.3f} / {result['exec_ms']['max']:.1f}"),
        (f"GNC tasks over {LONG_CYCLE_MS:.0f} ms (GC / hypervisor steal; TM send in them) [ms]",
         ", ".join(f"{c['exec_ms']:.0f} ({c['gc_ms_in_step']:.0f}/{c['steal_ms_in_step']:.0f}; TM {c['exec_ms'] - c['cycle_ms']:.0f})"
                   for c in long_cycles[:12]) or "none"),
        ("hypervisor steal on the cycle's CPU over the run [s]", f"{result['steal_ms'] / 1e3:.1f}"),
        ("GC collections gen 0/1/2, longest [ms]",
         "/".join(str(n) for n in gc_timer.count) + ", " + "/".join(f"{m:.1f}" for m in gc_timer.longest_ms)),
        ("TM packets sent / received / lost", f"{result['tm']['sent']} / {rx.received} / {rx.lost}"),
        ("bus CRC / alive / timeouts", f"{counters['bus_crc_errors']} / {counters['bus_alive_errors']} / {counters['bus_timeouts']}"),
        ("FDIR trips, final mode", f"{result['fdir_trips']} {result['fdir_trips_by_monitor']}, {result['final_mode']}"),
        ("warning/fatal events (first 500 kept in JSON)",
         ", ".join(f"{n} {sum(1 for e in notable if e['event'] == n)}" for n in sorted({e['event'] for e in notable})) or "none"),
        ("targets commanded (accepted/rejected)", f"{seq} ({tc.counters['accepted']}/{tc.counters['rejected']})"),
    ]
    width = max(len(r[0]) for r in rows)
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")
    if top:
        print(f"  tracemalloc top growth ({trace_snap * cfg.gnc_period_s / 3600:.1f} h -> end):")
        for t in top[:5]:
            print(f"    {t['size_diff_kB']:+9.1f} kB {t['count_diff']:+7d}  {t['where']}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2, default=float))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
