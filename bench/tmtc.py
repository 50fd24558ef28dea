"""Telemetry/telecommand costs and link loss on loopback.

Measures (medians and p99 over many repetitions):
- flight side: GNC packet build+send (``TelemetrySender.send_channels`` with a full GNC cycle's values),
  event build+send, telecommand decode+dispatch;
- ground side: decode of a GNC packet, and the full ``GroundMonitor.process`` with archiving;
- link: a ground monitor in its own process receives bursts of GNC packets sent at fixed rates; the
  sequence-count gap detector reports how many were lost.

Usage: ``.venv/bin/python bench/tmtc.py [--quick]``; prints a table and writes bench/results/tmtc.json.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

import sys

ROOT = Path(__file__).resolve().parents[1]
# bench/fsw.py would shadow the fsw package: drop this folder from the path, as bench/fsw.py does
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(ROOT))

from comms.dictionary import DICTIONARY  # noqa: E402
from ground.monitor import GroundMonitor, run_ground_monitor
from fsw.telecommand import CommandDispatcher
from comms.telecommand import encode_command
from fsw.telemetry import TelemetrySender
from comms.telemetry import decode_tm_packet

RESULTS = Path(__file__).resolve().parent / "results" / "tmtc.json"


def gnc_values(cycle: int) -> dict:
    nan = float("nan")
    return {
        "cycle": cycle, "mode": "POINTING", "safe_phase": "NONE", "q_est_NB": np.array([1.0, 0.0, 0.0, 0.0]),
        "omega_est_BN_B": np.zeros(3), "omega_cmd_BN_B": np.zeros(3), "rate_norm_deg_s": 0.1,
        "bias_est_B": np.zeros(3), "cov_trace": 1e-6, "st_age_s": 0.1, "boresight_N": np.array([0.0, 0.0, 1.0]),
        "target_N": np.array([0.0, 1.0, 0.0]), "q_target_NB": None, "pointing_error_deg": 1.0,
        "att_error_deg": 1.0, "roll_error_deg": 0.0, "active_zone": -1, "zone_count": 3,
        "margin_deg": [10.0, 20.0, 30.0, nan, nan, nan], "margin_min_deg": 10.0, "eps": 0.1, "eps_max": 0.2,
        "kappa": 1.0, "k1": 1.0, "zones_merged": False, "assumptions_ok": True, "torque_cmd_B_Nm": np.zeros(3),
        "torque_scale": 1.0, "wheel_speed_rad_s": [1.0, 2.0, 3.0, 4.0], "wheel_torque_cmd_Nm": [0.0] * 4,
        "sun_N": np.array([1.0, 0.0, 0.0]), "moon_N": np.array([0.0, 0.0, 1.0]), "st_valid": True,
        "imu_valid": True, "st_blind_source": "NONE", "exec_time_ms": 0.5,
    }


def timeit_us(fn, repeats: int) -> dict:
    samples = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        fn(i)
        samples[i] = time.perf_counter() - t0
    samples *= 1e6
    return {"p50_us": float(np.median(samples)), "p99_us": float(np.percentile(samples, 99)),
            "max_us": float(samples.max()), "n": repeats}


def link_loss(rate_hz: float, count: int) -> dict:
    """Send ``count`` GNC packets paced at ``rate_hz`` (0: as fast as possible) to a ground process."""
    ctx = multiprocessing.get_context("spawn")
    ready, stop, port_queue = ctx.Event(), ctx.Event(), ctx.Queue()
    with tempfile.TemporaryDirectory() as archive:
        process = ctx.Process(target=run_ground_monitor, kwargs={
            "archive_dir": archive, "port": 0, "stop_event": stop, "ready": ready, "port_queue": port_queue,
            "duration_s": 120.0, "write_decoded": False})
        process.start()
        ready.wait(30.0)
        port = port_queue.get(timeout=10.0)
        tm = TelemetrySender(DICTIONARY, "127.0.0.1", port)
        t0 = time.perf_counter()
        for cycle in range(count):
            tm.send_channels("GNC", gnc_values(cycle), time_s=cycle * 0.1)
            if rate_hz > 0:
                next_time = t0 + (cycle + 1) / rate_hz
                while time.perf_counter() < next_time:
                    time.sleep(max(0.0, min(0.001, next_time - time.perf_counter())))
        elapsed = time.perf_counter() - t0
        send_errors = tm.counters["send_errors"]
        tm.close()
        time.sleep(1.0)
        stop.set()
        process.join(60.0)
        summary = json.loads((Path(archive) / "ground_summary.json").read_text())
    received = summary["datagrams"]
    return {"rate_hz": rate_hz, "sent": count, "achieved_rate_hz": count / elapsed, "received": received,
            "missing_by_seq_gaps": summary["missing_packets"], "lost": count - received,
            "send_errors": send_errors}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    args = parser.parse_args()
    repeats = 500 if args.quick else 5000

    tm = TelemetrySender(DICTIONARY, port=None)
    raw_gnc = tm.send_channels("GNC", gnc_values(0), time_s=0.0)
    values = gnc_values(0)
    rows = {
        "tm_gnc_build_send": timeit_us(lambda i: tm.send_channels("GNC", values, time_s=i * 0.1), repeats),
        "tm_event_build_send": timeit_us(
            lambda i: tm.event("MODE_CHANGED", time_s=i, from_mode="SAFE", to_mode="POINTING", cause="FDIR"),
            repeats),
        "ground_decode_gnc": timeit_us(lambda i: decode_tm_packet(DICTIONARY, raw_gnc), repeats),
    }
    with tempfile.TemporaryDirectory() as archive:
        with GroundMonitor(DICTIONARY, port=None, archive_dir=archive) as monitor:
            rows["ground_process_archive_gnc"] = timeit_us(lambda i: monitor.process(raw_gnc, float(i)), repeats)
    dispatcher = CommandDispatcher(DICTIONARY, TelemetrySender(DICTIONARY, port=None), port=None)
    dispatcher.register("SET_GAINS", lambda **kw: None)
    tc = encode_command(DICTIONARY, "SET_GAINS", [1.0, 2.0, 0.1, 1.0])
    rows["tc_decode_dispatch"] = timeit_us(lambda i: dispatcher.handle_datagram(tc), repeats)

    link_count = 2000 if args.quick else 10000
    # 500 Hz = a 50 Hz GNC rate group in lockstep at 10x real time; 0 = as fast as the sender can go.
    links = [link_loss(rate, link_count) for rate in (500.0, 0.0)]

    print(f"{'operation':<30} {'p50 [us]':>10} {'p99 [us]':>10} {'max [us]':>10}")
    for name, row in rows.items():
        print(f"{name:<30} {row['p50_us']:>10.1f} {row['p99_us']:>10.1f} {row['max_us']:>10.1f}")
    print()
    print(f"{'link rate [Hz]':<16} {'achieved':>10} {'sent':>8} {'received':>9} {'lost':>6} {'gap-detected':>13}")
    for link in links:
        label = "max" if link["rate_hz"] == 0 else f"{link['rate_hz']:.0f}"
        print(f"{label:<16} {link['achieved_rate_hz']:>10.0f} {link['sent']:>8} {link['received']:>9} "
              f"{link['lost']:>6} {link['missing_by_seq_gaps']:>13}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        "bench": "tmtc", "quick": args.quick, "machine": platform.platform(), "python": platform.python_version(),
        "gnc_packet_bytes": len(raw_gnc), "timings": rows, "link": links,
    }, indent=1) + "\n")
    print(f"\nwrote {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
