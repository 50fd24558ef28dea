"""The housekeeping rate group (1 Hz): the periodic assumption checks, the heartbeat on the bus and the HK
packet (executive timing, bus and telemetry counters, FDIR states, memory), with the bus-fault burst count.

`Housekeeping` reads the flight software's parts through ``fsw`` (`fsw.app.FlightSoftware`) at every call:
a telecommand or a test may replace the configuration or the check worker between two runs.
"""
from __future__ import annotations

import math
import time
from itertools import repeat
from typing import Any

from comms.dictionary import MODES
from fsw import runtime

# A housekeeping period in which at least BUS_BURST_FRAMES frames fail their CRC or do not decode is a burst:
# a bus fault (BUS_CORRUPT, one a minute at most, and the bus_corrupt_bursts counter), not a sensor's or a
# wheel's (those monitors judge their own frames' absence, with their own persistence).
BUS_BURST_FRAMES = 5
BUS_EVENT_PERIOD_S = 60.0
# the E2E classes that housekeeping totals over the received messages
_HK_CLASSES = ("ok", "ok_some_lost", "crc_error", "wrong_sequence", "repeated", "bad_length", "out_of_range", "timeout")
_FDIR_HK_KEYS: dict[str, str] = {}  # FDIR monitor name -> its HK channel (fdir_<monitor>), filled as met


def budget_free_at(duration_s: float, max_cpu_fraction: float) -> float:
    """Host time from which the next periodic assumption check may start, so the background check uses at
    most ``max_cpu_fraction`` of a core. In real time a 0.5 s check every 10 s is 5 %; in lockstep, where
    onboard time runs 20-50x faster than the host clock, the onboard period alone would keep the worker
    busy all the time, stealing the CPU that the simulator and the flight software need."""
    if not math.isfinite(duration_s) or duration_s <= 0.0:
        return -math.inf
    return time.monotonic() + duration_s * (1.0 / max_cpu_fraction - 1.0)


class Housekeeping:
    """The housekeeping rate group of ``fsw``; `run` once per housekeeping period."""

    def __init__(self, fsw: Any) -> None:
        self.fsw = fsw
        self._last_check_t = -math.inf
        self._check_budget_free_at = -math.inf  # host monotonic time from which a periodic check may start
        self._hk_src: dict | None = None  # the driver's counters that _hk_dicts lists
        self._hk_src_len = 0
        self._hk_dicts: list[dict] = []
        # bus-fault bursts (see bus_fault_check): frames failing E2E or decoding seen so far, bursts counted,
        # the frames of the bursts not yet reported and when BUS_CORRUPT was last raised
        self._bus_failed_seen, self._bus_bursts, self._bus_burst_frames = 0, 0, 0
        self._bus_event_t = -math.inf
        self._start_wall = time.monotonic()

    def run(self) -> None:
        """Assumption checks (throttled), heartbeat, HK telemetry."""
        fsw = self.fsw
        self._assumption_checks(fsw)
        fsw.eclipse.update(fsw.t_s)
        try:
            fsw.driver.send_heartbeat(MODES.index(fsw.guidance.mode), fsw.cycle)
        except Exception:  # noqa: BLE001
            fsw.bus_tx_errors += 1
        values = self.values()
        self.bus_fault_check(values)
        rss = runtime.resident_bytes()
        if rss is not None:
            values["rss_mb"] = rss / 1e6
        try:
            fsw.telemetry.send_channels("HK", values, time_s=fsw.t_s)
        except TypeError:
            fsw.telemetry.send_channels("HK", values)

    def _assumption_checks(self, fsw: Any) -> None:
        """Apply a finished check; submit the next one when the zones changed or the period is up (and, with
        a worker process, its CPU budget allows)."""
        gd, checker, law = fsw.guidance, fsw.checker, fsw.cfg.law
        result = checker.poll()
        if result is not None:
            gd.apply_check_result(result)
            self._check_budget_free_at = budget_free_at(result.duration_s, law.check_max_cpu_fraction)
        if gd.mode in ("POINTING", "QUATERNION"):
            due = (fsw.t_s - self._last_check_t >= law.check_period_s
                   and (checker.mode != "process" or time.monotonic() >= self._check_budget_free_at))
            if (gd.checks_dirty or due) and not checker.busy:
                if checker.submit(gd.assumption_snapshot()):
                    gd.mark_checked()
                    self._last_check_t = fsw.t_s
                    if checker.mode == "inline":
                        gd.apply_check_result(checker.poll())

    def _bus_classes(self, counters: dict) -> dict[str, int]:
        """Each E2E class summed over the received messages."""
        if counters is not self._hk_src or len(counters) != self._hk_src_len:
            # the per-message counter dicts live as long as the receiver: list the messages' ones once
            self._hk_src, self._hk_src_len = counters, len(counters)
            self._hk_dicts = [c for name, c in counters.items() if not name.startswith("_")]
        dicts = self._hk_dicts
        # summed in C (map over dict.get): the same integers as a loop
        return {k: sum(map(dict.get, dicts, repeat(k), repeat(0))) for k in _HK_CLASSES}

    def values(self) -> dict:
        """The HK packet's channels, without the burst count and the memory `run` adds."""
        fsw = self.fsw
        ex, driver, fdir = fsw.executive, fsw.driver, fsw.fdir
        counters = driver.counters
        n = self._bus_classes(counters)
        bus = counters.get("_bus", {})
        tm = fsw.telemetry.counters
        values = {
            "uptime_s": time.monotonic() - self._start_wall,
            "hk_mode": fsw.guidance.mode,
            "cycles": fsw.cycle,
            "slips_gnc": ex.gnc.slips,
            "slips_hk": ex.hk.slips,
            "exec_max_ms_gnc": ex.gnc.exec_max_ms,
            "exec_mean_ms_gnc": ex.gnc.exec_mean_ms,
            "exec_max_ms_hk": ex.hk.exec_max_ms,
            "exec_mean_ms_hk": ex.hk.exec_mean_ms,
            "jitter_max_ms": 1e3 * ex.jitter.max_s,
            "bus_rx_ok": n["ok"] + n["ok_some_lost"],
            "bus_crc_errors": n["crc_error"],
            "bus_alive_errors": n["wrong_sequence"] + n["ok_some_lost"],
            "bus_repeated": n["repeated"],
            "bus_decode_errors": n["bad_length"] + n["out_of_range"] + getattr(getattr(driver, "bus", None), "decode_errors", 0),
            "bus_auth_failures": getattr(getattr(driver, "bus", None), "auth_failures", 0),
            "bus_timeouts": n["timeout"],
            "bus_tx_errors": fsw.bus_tx_errors,
            "bus_unknown_ids": bus.get("unknown_id", 0) + bus.get("error_frame", 0),
            "bus_stale_syncs": getattr(driver, "stale_syncs", 0),
            "bus_unexpected_frames": getattr(driver, "unexpected_frames", 0),
            "imu_stale_cycles": fdir.stale_counts["IMU"],
            "st_stale_cycles": fdir.stale_counts["STAR_TRACKER"],
            "tm_packets_sent": tm.get("packets_sent", 0),
            "tm_send_errors": tm.get("send_errors", 0),
            "events_sent": tm.get("events_sent", 0),
            "events_throttled": tm.get("events_throttled", 0),
            "fdir_trips": fdir.trips,
            "wheels_isolated": fsw.control.isolated_mask,
            "mtq_dipole_cmd_Am2": fsw.mtq_command_Am2,
            "h_excess_Nms": fsw.momentum.h_excess_norm_Nms if fsw.momentum is not None else None,
        }
        keys = _FDIR_HK_KEYS
        for mon, state in fdir.states().items():
            key = keys.get(mon)
            if key is None:
                key = keys[mon] = f"fdir_{mon.lower()}"
            values[key] = state
        values.update(fsw.eclipse.values())
        if fsw.dispatcher is not None:
            values.update(fsw.dispatcher.hk_values())
        return values

    def bus_fault_check(self, values: dict) -> None:
        """Count a burst of corrupt frames as a bus fault: `bus_corrupt_bursts`, and BUS_CORRUPT at most every
        BUS_EVENT_PERIOD_S of onboard time with the frames of the bursts since the last one."""
        t_s = self.fsw.t_s
        failed = int(values["bus_crc_errors"]) + int(values["bus_decode_errors"])
        new = failed - self._bus_failed_seen if failed >= self._bus_failed_seen else failed  # (RESET_COUNTERS)
        self._bus_failed_seen = failed
        if new >= BUS_BURST_FRAMES:
            self._bus_bursts += 1
            self._bus_burst_frames += new
        if self._bus_burst_frames and t_s - self._bus_event_t >= BUS_EVENT_PERIOD_S:
            self.fsw.event("BUS_CORRUPT", count=self._bus_burst_frames, bursts=self._bus_bursts)
            self._bus_burst_frames, self._bus_event_t = 0, t_s
        values["bus_corrupt_bursts"] = self._bus_bursts
