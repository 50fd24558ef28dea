"""Plain-Python references of the bus stages (test oracles; the product never imports tests/).

Each is written from the rules in the stage's docstrings, frame by frame, with cantools where a frame is
decoded or encoded: what the compiled kernels of comms.bus.kernels, fsw.bus.driver and hil_sim.devices must
reproduce bit for bit.
"""
from __future__ import annotations

import can
import cantools

from comms.bus import E2EReceiver, Icd, e2e_crc


class ReferenceReceiver:
    """The receiver's rules written out plainly in Python (comms.bus.e2e's docstrings), frame by frame, with
    cantools decoding: what the compiled classification must reproduce."""

    def __init__(self, icd: Icd, ignore: frozenset[int]) -> None:
        self.icd, self.ignore = icd, ignore
        self.last: dict[str, int | None] = {n: None for n in icd.messages}
        self.last_ok = {n: 0.0 for n in icd.messages}
        self.timed_out = {n: False for n in icd.messages}
        self.counts: dict[tuple[str | None, str], int] = {}

    def _count(self, name: str | None, cls: str) -> str:
        self.counts[name, cls] = self.counts.get((name, cls), 0) + 1
        return cls

    def classify(self, msg: can.Message, t: float) -> tuple | None:
        fid = msg.arbitration_id
        if fid in self.ignore and not msg.is_extended_id:
            self._count(None, "own_echo")
            return None
        spec = None if msg.is_extended_id else self.icd.by_id.get(fid)
        if spec is None:
            return (None, self._count(None, "unknown_id"), None, None)
        data = bytes(msg.data)
        if len(data) != spec.dlc:
            return (spec.name, self._count(spec.name, "bad_length"), None, None)
        if e2e_crc(spec.data_id, data[1:]) != data[0]:
            return (spec.name, self._count(spec.name, "crc_error"), None, None)
        values = spec.db_message.decode(data, decode_choices=False)
        if any(not lo <= values[k] <= hi for k, (lo, hi) in spec.accept_bounds.items()):
            return (spec.name, self._count(spec.name, "out_of_range"), None, None)
        counter, last = values["E2E_Counter"], self.last[spec.name]
        if last is None or self.timed_out[spec.name]:
            self.last[spec.name], cls = counter, "ok"
        else:
            delta = (counter - last) % 16
            if delta == 0:
                cls = "repeated"
            elif delta >= 13:
                cls = "wrong_sequence"
            else:
                self.last[spec.name] = counter
                cls = "ok" if delta == 1 else "ok_some_lost" if delta <= spec.max_delta_counter else "wrong_sequence"
        self._count(spec.name, cls)
        if cls in ("ok", "ok_some_lost"):
            self.last_ok[spec.name], self.timed_out[spec.name] = t, False
            return (spec.name, cls, counter, values)
        return (spec.name, cls, counter, None)

    def check_timeouts(self, t: float) -> list[str]:
        stale = []
        for name in self.icd.messages:
            if self.icd.spec(name).frame_id in self.ignore:
                continue
            if t - self.last_ok[name] > self.icd.spec(name).timeout_s + 1e-9:
                if not self.timed_out[name]:
                    self.timed_out[name] = True
                    self._count(name, "timeout")
                stale.append(name)
        return stale


class ReferenceDriver:
    """FswBusDriver.collect_tick(0) frame by frame, on E2EReceiver.classify (the Python path)."""

    def __init__(self, icd: Icd, n_wheels: int) -> None:
        own = icd.ids_sent_by("FSW")
        watch = icd.names_sent_by("SIM", "IMU", "STR", *[f"RW{i}" for i in range(1, n_wheels + 1)])
        self.rx = E2EReceiver(icd, ignore_ids=own, watch=watch)
        self.icd, self.n = icd, n_wheels
        self.device = frozenset(icd.by_id) - own - {icd.spec("SYNC").frame_id}
        self.sync, self.imu = icd.spec("SYNC").frame_id, icd.spec("IMU_RATE").frame_id
        self.st = {icd.spec(n).frame_id: n for n in ("ST_QUAT_A", "ST_QUAT_B")}
        self.wheel = {icd.spec(f"RW{i}_STATUS").frame_id: i - 1 for i in range(1, n_wheels + 1)}
        self.queue: list = []
        self.last_tick = None
        self.t_tick = self.period_s = 0.0
        self.pending = None
        self.halves: dict = {}
        self.supervised = False
        self.stale = self.unexpected = self.incomplete = 0

    def _next(self):
        return self.queue.pop(0) if self.queue else None

    def collect_tick(self):
        sync, self.pending = self.pending, None
        while sync is None:
            msg = self._next()
            if msg is None:
                return None
            f = self.rx.classify(msg, self.t_tick)
            if f is None or not f.delivered:
                continue
            if f.frame_id == self.sync:
                if self.last_tick is not None and int(f.signals["tick"]) <= self.last_tick:
                    self.stale += 1
                else:
                    sync = f.signals
            elif f.frame_id in self.device:
                self.unexpected += 1
        tick = int(sync["tick"])
        self.period_s = float(sync["period_ms"]) / 1000.0
        t = self.t_tick = tick * self.period_s
        if not self.supervised:
            self.rx.reset_clock(t)
            self.supervised = True
        expected = int(sync["frames_following"])
        received = 0
        imu, st, wheels = [], None, [None] * self.n
        while received < expected:
            msg = self._next()
            if msg is None:
                break
            f = self.rx.classify(msg, t)
            fid = -1 if f is None else f.frame_id
            if f is not None and f.delivered:
                s = f.signals
                if fid == self.sync:
                    if int(s["tick"]) <= tick:
                        self.stale += 1
                    else:
                        self.pending = s
                        break
                    continue
                if fid not in self.device:
                    continue
                received += 1
                if fid == self.imu:
                    imu.append(([s["omega_x"], s["omega_y"], s["omega_z"]], bool(s["saturated"])))
                elif fid in self.st:
                    self.halves[self.st[fid]] = s
                    a, b = self.halves.get("ST_QUAT_A"), self.halves.get("ST_QUAT_B")
                    if a is not None and b is not None and int(a["sample_seq"]) == int(b["sample_seq"]):
                        st = ([a["q_w"], a["q_x"], b["q_y"], b["q_z"]], bool(a["valid"]), int(a["blind_source"]),
                              t - float(b["age_ms"]) / 1000.0)
                        self.halves.clear()
                elif fid in self.wheel:
                    wheels[self.wheel[fid]] = (s["speed"], s["torque"], s["current"], s["temp"], int(s["fault"]), t)
        if received < expected:
            self.incomplete += 1
        self.rx.check_timeouts(t)
        self.last_tick = tick
        n = len(imu)
        samples = [(w, sat, t - (n - 1 - i) * self.period_s / n) for i, (w, sat) in enumerate(imu)]
        return (tick, t, self.period_s, samples, st, wheels, expected, received)


def reference_rows_due(pending: list, t_s: float) -> tuple[list, list, list]:
    """The list-based ``Devices.rows_due`` of before the array queue (sorted by due time, stable)."""
    cut = t_s + 1e-9
    due = [p for p in pending if p.due_s <= cut]
    rest = [p for p in pending if p.due_s > cut]
    due.sort(key=lambda p: p.due_s)
    return [p.m for p in due], [p.values(t_s) for p in due], rest


def encode_frame(icd: Icd, name: str, signals: dict, counter: int) -> bytes | None:
    """Frame ``name``'s bytes by cantools (strict: every value inside its DBC range) with alive counter
    ``counter`` and its E2E CRC over bytes 1..; None where cantools refuses a value."""
    spec = icd.spec(name)
    values = dict(signals, E2E_Counter=counter & 0x0F, E2E_CRC=0)
    if any(not lo <= values[k] <= hi for k, (lo, hi) in spec.ranges.items()):
        return None
    try:
        payload = spec.db_message.encode(values, scaling=True, padding=False, strict=True)
    except (cantools.database.EncodeError, ValueError, OverflowError):
        return None
    values["E2E_CRC"] = e2e_crc(spec.data_id, payload[1:])
    return bytes(spec.db_message.encode(values, scaling=True, padding=False, strict=True))
