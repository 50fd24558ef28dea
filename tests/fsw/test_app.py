"""FlightSoftware application: telecommand handlers, telemetry content, housekeeping, process entry."""
from __future__ import annotations

import ast
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from closed_loop_kit import BusLoop, fsw_config_for
from comms.dictionary import DICTIONARY, FDIR_STATES, MODES
from fsw.telecommand import CommandDispatcher
from comms.telecommand import encode_command
from fsw.telemetry import TelemetrySender
from comms.telemetry import decode_tm_packet

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def loop():
    from hil_sim.world.params import WorldParams
    from hil_sim.world.world import World

    wp = WorldParams()
    cfg = fsw_config_for(wp, initial_mode="SAFE", law={"assumption_check": "inline"},
                         quaternion={"target_q_NB": [1, 0, 0, 0],
                                     "zones": [{"shape": "cone", "name": "x", "center_q": [0, 1, 0, 0], "half_angle_deg": 20.0}]})
    tm = TelemetrySender(DICTIONARY, port=None)
    tc = CommandDispatcher(DICTIONARY, tm, port=None)
    lp = BusLoop(cfg, World(wp, seed=0), telemetry=tm, dispatcher=tc)
    lp.tm, lp.tc = tm, tc
    yield lp
    lp.close()


def _send(lp, name, args=(), seq=[0]):
    seq[0] += 1
    return lp.tc.handle_datagram(encode_command(DICTIONARY, name, args, seq_count=seq[0]))


def _names(lp):
    return [e.name for e in lp.tm.recent_events]


def test_commands_change_mode_gains_target_and_counters(loop) -> None:
    loop.run(3)
    assert _send(loop, "NOOP").accepted
    assert _send(loop, "SET_MODE", {"mode": "QUATERNION"}).accepted
    assert loop.fsw.mode == "QUATERNION" and "MODE_CHANGED" in _names(loop)
    assert _send(loop, "SET_GAINS", {"k1": 0.3, "kappa": 2.0, "eps": 0.0, "rate_limit_deg_s": 0.5}).accepted
    g = loop.fsw.guidance
    assert (g.k1, g.kappa, g.eps_cfg) == (0.3, 2.0, "auto") and g.max_rate_rad_s == pytest.approx(math.radians(0.5))
    # a quaternion target inside the S^3 zone (10 deg from its centre) is refused
    q_bad = [math.sin(math.radians(10)), math.cos(math.radians(10)), 0.0, 0.0]
    res = _send(loop, "SET_TARGET", {"kind": "QUATERNION", "c0": q_bad[0], "c1": q_bad[1], "c2": 0.0, "c3": 0.0})
    assert not res.accepted and "TARGET_REJECTED" in _names(loop)
    q_ok = [math.cos(0.2), 0.0, math.sin(0.2), 0.0]
    assert _send(loop, "SET_TARGET", {"kind": "QUATERNION", "c0": q_ok[0], "c1": 0.0, "c2": q_ok[2], "c3": 0.0}).accepted
    np.testing.assert_allclose(g.q_target, q_ok, atol=1e-12)
    # not a unit vector: validation error
    assert not _send(loop, "SET_TARGET", {"kind": "DIRECTION", "c0": 0.5, "c1": 0.0, "c2": 0.0}).accepted
    loop.fsw.executive.gnc.slips = 7
    assert _send(loop, "RESET_COUNTERS").accepted
    assert loop.fsw.executive.gnc.slips == 0 and loop.tc.counters["accepted"] == 1  # the reset itself
    assert "COUNTERS_RESET" in _names(loop)


def test_gnc_and_housekeeping_telemetry(loop) -> None:
    loop.run(25)
    gnc = loop.tm.latest("GNC")
    assert gnc["cycle"] == 24 and MODES[gnc["mode"]] == "SAFE"
    q = np.array([gnc[f"q_est_NB_{i}"] for i in range(4)])
    truth = loop.world.truth.q_NB
    assert min(np.linalg.norm(q - truth), np.linalg.norm(q + truth)) < 1e-3
    assert gnc["st_valid"] and gnc["imu_valid"] and gnc["exec_time_ms"] > 0
    assert math.isnan(gnc["wheel_speed_rad_s_5"])  # 4 wheels: unused slots are NaN
    hk = loop.tm.latest("HK")
    assert hk["cycles"] >= 20 and hk["bus_rx_ok"] > 100 and hk["bus_crc_errors"] == 0
    assert hk["exec_max_ms_gnc"] >= hk["exec_mean_ms_gnc"] > 0
    assert FDIR_STATES[hk["fdir_imu_stale"]] == "NOMINAL"
    # one GNC packet per cycle, one HK packet per second (3 in 2.5 s: ticks 0, 10, 20)
    assert loop.tm.sequence_count(DICTIONARY.packet("GNC").apid) == 25
    assert loop.tm.sequence_count(DICTIONARY.packet("HK").apid) == 3
    # the bus totals are sums over the driver's per-message E2E counters (now, not at the last HK packet)
    counts, hk_now = loop.fsw.driver.counters, loop.fsw.hk_values()
    assert hk_now["bus_rx_ok"] == sum(c["ok"] + c["ok_some_lost"] for n, c in counts.items() if not n.startswith("_"))
    assert hk_now["bus_alive_errors"] == sum(c["wrong_sequence"] + c["ok_some_lost"]
                                         for n, c in counts.items() if not n.startswith("_"))
    import psutil  # the RSS channel reads /proc itself; psutil is the independent reference
    assert abs(hk["rss_mb"] - psutil.Process().memory_info().rss / 1e6) < 50.0 and hk["rss_mb"] > 10.0


def test_resident_size_is_what_psutil_reports_also_in_a_forked_child() -> None:
    import os

    import psutil

    from fsw.runtime import resident_bytes

    assert abs(resident_bytes() - psutil.Process().memory_info().rss) < 4 << 20
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child must read its own /proc entry, not the descriptor its parent opened
        try:
            block = bytearray(64 << 20)
            block[::4096] = b"1" * len(block[::4096])
            ok = abs(resident_bytes() - psutil.Process().memory_info().rss) < 4 << 20
            os.write(write, b"1" if ok else b"0")
        finally:
            os._exit(0)
    os.waitpid(pid, 0)
    assert os.read(read, 1) == b"1"


def _free_udp_port() -> tuple[socket.socket, int]:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.2)
    return s, s.getsockname()[1]


def test_process_entry_runs_and_stops_when_the_simulator_is_silent(tmp_path) -> None:
    from comms.link_security import downlink_receiver, write_key_file

    rx, port = _free_udp_port()
    key = write_key_file(tmp_path / "link.key")
    cfg = {"flight_software": {"rates": {"lockstep_timeout_s": 0.5}, "law": {"assumption_check": "off"},
                               "tmtc": {"telemetry_port": port, "telecommand_port": 0,
                                        "security": {"key_file": "link.key"}}}}
    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump(cfg))
    proc = subprocess.run([sys.executable, "-m", "fsw", "--config", str(path), "--bus", "virtual:entry", "--lockstep"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    downlink = downlink_receiver(key)  # every packet is signed with the mission's key
    events = []
    while True:
        try:
            data = rx.recv(65536)
        except socket.timeout:
            break
        pkt = decode_tm_packet(DICTIONARY, downlink.unprotect(data)[0])
        if pkt.kind == "event":
            events.append(pkt.event)
    rx.close()
    assert events[0] == "FSW_STARTED" and events[-1] == "FSW_STOPPED"


def test_process_entry_reports_a_bad_config_with_the_key(tmp_path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({"flight_software": {"rates": {"gnc_rate_hz": 500}}}))
    proc = subprocess.run([sys.executable, "-m", "fsw", "--config", str(path), "--bus", "virtual:x"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "flight_software.rates.gnc_rate_hz" in proc.stderr and "bad.yaml" in proc.stderr


def test_realtime_loop_on_the_clock(loop) -> None:
    """Real time on the monotonic clock for 1 s with the simulator silent: cycles on schedule, timing
    measured; the IMU monitor trips once the IMU has been heard from and then goes quiet, never before."""
    n = loop.fsw.run_realtime(duration_s=1.0)
    assert n >= 9
    ex = loop.fsw.executive
    assert len(ex.jitter.recent) == n and ex.gnc.cycles == n
    assert loop.fsw.fdir.stale_counts["IMU"] == 0 and loop.fsw.mode == "SAFE"  # not armed: never heard
    loop.run(3)  # a few lockstep ticks: the IMU is heard
    loop.fsw.run_realtime(duration_s=1.0)
    assert loop.fsw.fdir.stale_counts["IMU"] >= 9
    assert any(e.name == "FDIR_TRIPPED" and e.args["monitor"] == "IMU_STALE" for e in loop.tm.recent_events)


def test_periodic_assumption_check_keeps_to_its_cpu_budget(loop, monkeypatch) -> None:
    """In lockstep the onboard check period passes in a fraction of a host second: after a check that
    took d seconds of CPU, the next periodic one waits d (1/fraction - 1) host seconds, so the background
    check cannot starve the simulator and the flight software of CPU."""
    from fsw.assumption_check import CheckResult

    class StubChecker:
        mode, busy = "process", False

        def __init__(self):
            self.submitted, self.pending = 0, None

        def submit(self, snapshot):
            self.submitted += 1
            self.pending = CheckResult(True, [], float("inf"), None, duration_s=1.0)
            return True

        def poll(self):
            res, self.pending = self.pending, None
            return res

        def close(self):
            pass

    fsw = loop.fsw
    assert _send(loop, "SET_MODE", {"mode": "QUATERNION"}).accepted
    fsw.checker = StubChecker()
    fsw.cfg = fsw.cfg.model_copy(update={"law": fsw.cfg.law.model_copy(update={"check_period_s": 1.0,
                                                                                  "check_max_cpu_fraction": 0.5})})
    now = [1000.0]
    monkeypatch.setattr("fsw.housekeeping.time.monotonic", lambda: now[0])
    loop.run(30)  # 3 onboard seconds: the first check goes, its 1 s result arrives, the budget then binds
    assert fsw.checker.submitted == 1
    now[0] += 0.9  # budget after a 1 s check at 50 %: 1 s of host time
    loop.run(20)
    assert fsw.checker.submitted == 1
    now[0] += 0.2
    loop.run(20)
    assert fsw.checker.submitted == 2


def test_enter_realtime_gets_sched_fifo_or_says_why_not() -> None:
    """In its own process (SCHED_FIFO must not leak into the test run): the policy is FIFO when the host
    grants it, and otherwise the flight software reports that it runs best effort."""
    code = ("import os, gc; from fsw.runtime import enter_realtime; ev = enter_realtime(7); "
            "print(repr(ev)); print(os.sched_getscheduler(0) == os.SCHED_FIFO, gc.get_freeze_count() > 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode == 0, out.stderr
    events_line, state_line = out.stdout.strip().splitlines()[-2:]
    events = ast.literal_eval(events_line)
    fifo, frozen = state_line.split()
    assert frozen == "True"
    names = [name for name, _ in events]
    if fifo == "True":
        assert names[0] == "RT_SCHEDULING" and "priority 7" in events[0][1]
    else:
        assert names == ["RT_SCHEDULING_UNAVAILABLE"]


def test_enter_realtime_without_priority_only_prepares_the_thread() -> None:
    code = ("import os, gc; from fsw.runtime import enter_realtime; "
            "print(enter_realtime(0), os.sched_getscheduler(0) == os.SCHED_OTHER, gc.get_freeze_count() > 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["[]", "True", "True"]


def test_a_cycle_loop_keeps_blas_on_its_own_thread() -> None:
    """OpenBLAS starts one worker thread per CPU at import; a real-time cycle thread must never wait for
    one the host has preempted. Checked in a fresh interpreter: the limit is process-wide."""
    code = ("import numpy, scipy.linalg, threadpoolctl\n"
            "before = [i['num_threads'] for i in threadpoolctl.threadpool_info()]\n"
            "from fsw.runtime import prepare_cycle_thread\n"
            "prepare_cycle_thread()\n"
            "print(before)\n"
            "print([i['num_threads'] for i in threadpoolctl.threadpool_info()])")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "2"}  # as on a 2-CPU host, whatever this host has
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    before, after = (ast.literal_eval(line) for line in out.stdout.strip().splitlines()[-2:])
    assert before and max(before) == 2
    assert after == [1] * len(before)


def test_cycle_loops_freeze_the_start_up_heap_before_the_first_cycle(loop, monkeypatch) -> None:
    """A full GC pass over the start-up heap takes 0.1-0.2 s: it must not land inside a cycle."""
    calls = []
    monkeypatch.setattr("fsw.runtime.freeze_heap", lambda: calls.append("freeze"))
    monkeypatch.setattr(loop.fsw.executive, "run_lockstep", lambda *a, **k: calls.append("cycles") or 0)
    monkeypatch.setattr(loop.fsw.executive, "run_realtime", lambda *a, **k: calls.append("cycles") or 0)
    loop.fsw.run_lockstep(max_ticks=1)
    assert calls == ["freeze", "cycles"]
    calls.clear()
    monkeypatch.setattr("fsw.runtime.enter_realtime", lambda priority: calls.append("freeze") or [])
    loop.fsw.run_realtime(0.1)
    assert calls == ["freeze", "cycles"]


def test_the_warm_up_freezes_the_start_up_heap_before_fsw_started(loop, monkeypatch) -> None:
    """The SIL's simulator starts ticking when FSW_STARTED reaches the ground: a full collection after it
    (0.1-0.2 s, more in the vcan-vm guest) landed inside the lockstep loop's first cycle."""
    calls = []
    monkeypatch.setattr("fsw.runtime.freeze_heap", lambda: calls.append("freeze"))
    monkeypatch.setattr(loop.fsw.checker, "start", lambda: calls.append("worker"))
    loop.fsw._warm_up()
    assert calls == ["freeze", "worker"]


def test_process_entry_refuses_to_run_without_a_private_link_key(tmp_path) -> None:
    """No key named, or a key file others can read: exit 2 with one line naming the file and the fix."""
    from comms.link_security import write_key_file

    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump({"flight_software": {"tmtc": {"telecommand_port": 0}}}))
    proc = subprocess.run([sys.executable, "-m", "fsw", "--config", str(path), "--bus", "virtual:nokey"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "security.key_file" in proc.stderr and "keygen" in proc.stderr
    assert "Traceback" not in proc.stderr
    write_key_file(tmp_path / "open.key")
    os.chmod(tmp_path / "open.key", 0o644)
    proc = subprocess.run([sys.executable, "-m", "fsw", "--config", str(path), "--bus", "virtual:nokey",
                           "--key-file", str(tmp_path / "open.key")], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and "open.key" in proc.stderr and "chmod 600" in proc.stderr


def test_a_burst_of_corrupt_frames_is_a_bus_fault_counted_and_reported_once_a_minute(loop) -> None:
    """Frames that fail their CRC or do not decode in bursts are a bus fault: the bus_corrupt_bursts counter
    and one BUS_CORRUPT event a minute at most (with the frames since the last one). A few stray ones are not."""
    fsw = loop.fsw
    values = lambda crc, dec: {"bus_crc_errors": crc, "bus_decode_errors": dec}  # noqa: E731
    seen = []
    for second, (crc, dec) in enumerate([(2, 0), (3, 0), (40, 5), (80, 5), (81, 5), (200, 9), (0, 0), (30, 0)]):
        fsw.t_s = 30.0 * second  # housekeeping periods 30 s apart: events may come every other one
        v = values(crc, dec)
        fsw.hk.bus_fault_check(v)
        seen.append(v["bus_corrupt_bursts"])
    # bursts: +42 (t 60), +40 (t 90), +123 (t 150), +30 after a counter reset (t 210); +2, +1, +1 are not.
    # Events: at once (t 60), then at t 120 and t 180 with what came since; the last burst waits its minute.
    assert seen == [0, 0, 1, 2, 2, 3, 3, 4]
    events = [e for e in loop.tm.recent_events if e.name == "BUS_CORRUPT"]
    assert [e.args["count"] for e in events] == [42, 40, 123]
    assert not [e for e in loop.tm.recent_events if e.name in ("WHEEL_FAULT", "WHEEL_ISOLATED")]


def test_two_wheels_truly_lost_leave_the_allocation_and_the_rest_give_the_least_squares_torque(loop) -> None:
    """A second wheel truly lost (not only its status) leaves too few for three axes: SAFE, and the dead
    wheel is taken out of the allocation all the same, so the remaining two give the body torque's
    least-squares part (what they can of it) instead of sending a share to a wheel that cannot act."""
    import numpy as np

    from fsw.fdir import FdirAction

    fsw = loop.fsw
    ctl = fsw.control
    assert ctl.n == 4
    fsw.fdir.wheel_fault_reasons[:] = ["drive fault"] * 4
    fsw._execute(FdirAction("isolate_wheel", "WHEEL_FAULT", 0))
    assert ctl.active.tolist() == [False, True, True, True]
    fsw._execute(FdirAction("isolate_wheel", "WHEEL_FAULT", 2))
    assert ctl.active.tolist() == [False, True, False, True] and fsw.guidance.mode == "SAFE"
    torque = np.array([0.01, -0.02, 0.015])
    G = ctl.G[:, [1, 3]]
    tau = ctl.M @ torque
    assert tau[0] == 0.0 and tau[2] == 0.0
    best = np.linalg.lstsq(G, -torque, rcond=None)[0]  # the reaction of the two that are left
    assert np.allclose(tau[[1, 3]], best)
    isolated = [e.args["wheel"] for e in loop.tm.recent_events if e.name == "WHEEL_ISOLATED"]
    assert isolated == [1, 3]
