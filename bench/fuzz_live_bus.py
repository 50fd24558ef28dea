"""Raw junk into the bus of a live SIL run: crashes and healthy wheels isolated.

    .venv/bin/python bench/fuzz_live_bus.py                       # 1e6 datagrams, udp_multicast, this host
    .venv/bin/python bench/fuzz_live_bus.py --count 20000         # a quick look
    vcan-vm -- .venv/bin/python bench/fuzz_live_bus.py --bus socketcan:vcan0   # raw can_frames, in a CAN guest

`bench/fuzz.py` feeds the receivers `can.Message` objects in one process. Here the junk goes where a local
attacker's would: to the bus sockets of a running `keepout sil run` (lockstep, demo-pointing, a day long so it
outlives the attack), as the kernel delivers it to the simulator and the flight software alike.

* udp_multicast: raw datagrams sent to the run's group and port (as found in endpoints.json, or by any local
  user in /proc/net/igmp and /proc/net/udp), a third each: random bytes (not msgpack), msgpack that is not a
  frame, and well-formed frames with the ICD's identifiers and random payloads (about 1 in 256 passes the CRC);
* socketcan: raw ``struct can_frame`` buffers written to a CAN_RAW socket on the run's interface: random
  identifiers (standard, extended, RTR, error flags), lengths and payloads, a third on the ICD's identifiers.

When the count is sent the run is stopped with SIGINT, so it ends `interrupted` and is judged on what it flew.
A crash is a run that ended `crashed: ...` (or never announced its bus); a healthy wheel isolated is a
WHEEL_ISOLATED event (no fault is injected, so every isolation is wrong). Prints a table and writes
bench/results/fuzz_live_bus.json (with the host load).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import msgpack

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from comms.bus import Icd

ICD_IDS = tuple(sorted(m.frame_id for m in Icd().messages.values()))  # every frame of the ICD (the DBC)


def _udp_junk(rnd: random.Random) -> bytes:
    kind = rnd.randrange(3)
    if kind == 0:
        return bytes(rnd.getrandbits(8) for _ in range(rnd.randint(1, 64)))
    if kind == 1:
        return msgpack.packb(rnd.choice([{"arbitration_id": "x"}, [1, 2, 3], {"data": 5}, 7.5,
                                          {"arbitration_id": rnd.choice(ICD_IDS), "data": b"\x00" * 70, "dlc": 70}]))
    data = bytes(rnd.getrandbits(8) for _ in range(8))
    return msgpack.packb({"timestamp": time.time(), "arbitration_id": rnd.choice(ICD_IDS), "is_extended_id": False,
                          "is_remote_frame": False, "is_error_frame": False, "channel": None, "dlc": 8,
                          "data": data, "is_fd": False, "bitrate_switch": False, "error_state_indicator": False},
                         use_bin_type=True)


def _can_junk(rnd: random.Random) -> bytes:
    if rnd.randrange(3) == 0:
        can_id = rnd.choice(ICD_IDS)
    else:
        can_id = rnd.getrandbits(32)  # any flags: EFF, RTR, ERR
    dlc = rnd.randint(0, 8)
    return struct.pack("=IB3x8s", can_id, dlc, bytes(rnd.getrandbits(8) for _ in range(8)))


def _start_run(out: Path, bus: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "cli", "sil", "run", str(ROOT / "config/missions/demo-pointing.yaml"),
           "--bus", bus, "--duration", "86400", "--out", str(out), "--no-progress"]
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _run_dir(out: Path, timeout_s: float = 120.0) -> Path | None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for ep in out.glob("*/endpoints.json"):
            try:
                if "fsw" in json.loads(ep.read_text()).get("pids", {}):
                    return ep.parent
            except ValueError:
                pass
        time.sleep(0.05)
    return None


def attack(bus: str, count: int, rate_per_s: float, seed: int) -> dict:
    rnd = random.Random(seed)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        proc = _start_run(out, bus)
        run_dir = _run_dir(out)
        sent = errors = 0
        started = time.monotonic()
        try:
            if run_dir is not None:
                endpoints = json.loads((run_dir / "endpoints.json").read_text())
                if bus.startswith("udp_multicast"):
                    _, group, port = endpoints["bus"].split(":")
                    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
                    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
                    target, make = (group, int(port)), _udp_junk
                    send = lambda data: sock.sendto(data, target)  # noqa: E731
                else:
                    sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
                    sock.bind((bus.split(":", 1)[1],))
                    make, send = _can_junk, sock.send
                while sent < count and proc.poll() is None:
                    ahead = started + sent / rate_per_s - time.monotonic()
                    if ahead > 0.0:
                        time.sleep(ahead)
                    try:
                        send(make(rnd))
                    except OSError:
                        errors += 1  # the kernel refused it (an invalid can_frame, a full buffer)
                    sent += 1
                sock.close()
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            output, _ = proc.communicate(timeout=600)
        attack_s = time.monotonic() - started
        summary = json.loads((run_dir / "summary.json").read_text()) if run_dir else {"status": "never started"}
        sim = json.loads((run_dir / "simulator.json").read_text()) if run_dir and (run_dir / "simulator.json").exists() else {}
        events = []
        if run_dir and (run_dir / "ground" / "events.jsonl").exists():
            events = [json.loads(line) for line in (run_dir / "ground" / "events.jsonl").read_text().splitlines()]
        hk: dict = {}
        if run_dir and (run_dir / "ground" / "tm_decoded.jsonl").exists():
            with open(run_dir / "ground" / "tm_decoded.jsonl") as f:
                for line in f:
                    if '"HK"' in line:
                        hk = json.loads(line).get("values", hk)
        status = str(summary.get("status", "?"))
        return {"bus": bus.split(":")[0], "sent": sent, "send_errors": errors, "attack_s": round(attack_s, 1),
                "status": status, "crashed": int(status.startswith("crashed") or run_dir is None),
                "healthy_wheels_isolated": sum(1 for e in events if e.get("event") == "WHEEL_ISOLATED"),
                "wheel_faults": sum(1 for e in events if e.get("event") == "WHEEL_FAULT"),
                "simulated_s": summary.get("simulated_s"),
                "bus_decode_errors_sim": sim.get("bus_decode_errors"),
                "bus_decode_errors_fsw": hk.get("bus_decode_errors"),
                "bus_crc_errors_fsw": hk.get("bus_crc_errors"), "exit_code": proc.returncode,
                "output_tail": output[-600:] if status.startswith("crashed") else ""}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bus", default="udp_multicast", help="udp_multicast (default) or socketcan:IFACE")
    p.add_argument("--count", type=int, default=1_000_000, help="datagrams or frames to send (default 1e6)")
    p.add_argument("--rate", type=float, default=20_000.0, help="sent per second (default 20,000)")
    p.add_argument("--seed", type=int, default=20261128)
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "fuzz_live_bus.json")
    args = p.parse_args(argv)
    row = attack(args.bus, args.count, args.rate, args.seed)
    row["host_loadavg_1min"] = os.getloadavg()[0]
    print(f"{'bus':14s} {'sent':>9s} {'s':>6s} {'crashed':>7s} {'isolated':>8s} {'decode err (sim/fsw)':>22s}  status")
    print(f"{row['bus']:14s} {row['sent']:9d} {row['attack_s']:6.1f} {row['crashed']:7d} "
          f"{row['healthy_wheels_isolated']:8d} {str(row['bus_decode_errors_sim']) + ' / ' + str(row['bus_decode_errors_fsw']):>22s}  "
          f"{row['status']}")
    results = json.loads(args.out.read_text()) if args.out.exists() else {}
    results[row["bus"]] = row
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    return 1 if row["crashed"] or row["healthy_wheels_isolated"] else 0


if __name__ == "__main__":
    sys.exit(main())
