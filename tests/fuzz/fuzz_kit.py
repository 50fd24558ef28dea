"""Fuzz targets and input generators, shared by the hypothesis suite (tests/fuzz) and bench/fuzz.py.

Each target wraps one entry point that must never raise on any input: ``feed(data)`` returns normally
for every input the entry point handles (accepted, or refused and counted) and lets anything else
propagate: that is a crash. Generators take a ``random.Random`` so the bench (millions of inputs,
seeded) and hypothesis (``st.randoms()``, shrinking) drive the same code.

Targets:
  * ``TcTarget``: the flight software's telecommand dispatcher with link security and the real command
    handlers of ``fsw.app.FlightSoftware``;
  * ``CanTarget``: the flight software's bus receiver (``FswBusDriver``: E2E classification, lockstep
    tick assembly, real-time collection) reading frames from a scripted bus;
  * ``TmTarget``: the ground's telemetry path (``GroundMonitor.process``: link security, decoder,
    sequence and limit checks), with and without link security;
  * ``MissionTarget``: the mission loader (``hil_sim.mission.model.load_mission``) on mission files; its
    documented refusal is ``ConfigError``.
"""
from __future__ import annotations

import collections
import json
import math
import random
import struct
from pathlib import Path
from typing import Any

import can

from comms.dictionary import DICTIONARY
from comms.link_security import SPI_TC, SPI_TM, SecurityAssociation, downlink_receiver, uplink_receiver
from comms.telecommand import encode_command, encode_tc_packet

ROOT = Path(__file__).resolve().parents[2]
KEY = bytes(range(100, 132))  # the fuzzer is an insider: it can sign, to reach the code behind the MAC
EVIL_FLOATS = (math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324, -0.0, 0.0, 1.0, -1.0, 2.0**63, 1e-9)
EVIL_INTS = (0, -1, 1, 255, 256, 65535, 65536, 2**31 - 1, 2**31, 2**32, 2**63, -(2**63), 10**30)


def _random_bytes(rng: random.Random, n_max: int) -> bytes:
    return rng.randbytes(rng.randint(0, n_max))


def _mutate(rng: random.Random, data: bytes) -> bytes:
    """Bit flips, byte overwrites, truncation, extension, splices."""
    out = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(5)
        if op == 0 and out:
            i = rng.randrange(len(out))
            out[i] ^= 1 << rng.randrange(8)
        elif op == 1 and out:
            out[rng.randrange(len(out))] = rng.randrange(256)
        elif op == 2 and out:
            del out[rng.randrange(len(out)):]
        elif op == 3:
            out += rng.randbytes(rng.randint(1, 40))
        elif out:
            i, j = sorted(rng.randrange(len(out) + 1) for _ in range(2))
            out[i:j] = rng.randbytes(rng.randint(0, 12))
    return bytes(out)


def _fix_crc(data: bytes) -> bytes:
    """Recompute a space packet's trailing CRC-16 (and length field): what a forger does."""
    from comms.telemetry import crc16_ccitt

    if len(data) < 8:
        return data
    out = bytearray(data)
    out[4:6] = (len(out) - 7).to_bytes(2, "big")
    out[-2:] = crc16_ccitt(bytes(out[:-2])).to_bytes(2, "big")
    return bytes(out)


def _evil_value(rng: random.Random) -> Any:
    return rng.choice((rng.choice(EVIL_FLOATS), rng.choice(EVIL_INTS), rng.uniform(-2, 2), "", "x" * rng.randint(0, 300),
                       None, True, [], {}, [rng.random()] * rng.randint(0, 7), {"a": 1}, "NaN", ".inf", "SAFE"))


# ------------------------------------------------------------------------------------ telecommands
class TcTarget:
    """The flight dispatcher (link security on) with the real FlightSoftware command handlers."""

    def __init__(self) -> None:
        from fsw.app import FlightSoftware
        from fsw.config import parse_fsw_config
        from fsw.telecommand import CommandDispatcher

        resync = DICTIONARY.command("SEC_RESYNC").opcode
        self.dispatcher = CommandDispatcher(DICTIONARY, None, port=None,
                                            security=uplink_receiver(KEY, 64, resync_opcode=resync))
        cfg = parse_fsw_config({"law": {"assumption_check": "off"}})
        self.fsw = FlightSoftware(cfg, driver=None, telemetry=None, dispatcher=self.dispatcher)
        self.signer = SecurityAssociation(KEY, SPI_TC)
        self.sn = 0
        self.sent: collections.deque[bytes] = collections.deque(maxlen=64)
        self.outcomes: collections.Counter[str] = collections.Counter()

    def feed(self, data: bytes) -> None:
        result = self.dispatcher.handle_datagram(data)
        self.outcomes[result.code if not result.completed else "COMPLETED"] += 1
        events = getattr(self.fsw.telemetry, "events", None)
        if events is not None and len(events) > 1000:
            events.clear()  # the stand-in telemetry keeps every event: bound it over millions of inputs

    def close(self) -> None:
        self.fsw.shutdown()

    # ---- inputs ----
    def generate(self, rng: random.Random) -> bytes:
        kind = rng.randrange(8)
        if kind == 0:
            return _random_bytes(rng, 300)
        if kind == 1:  # plain (unsigned) commands: well formed, no MAC
            return self._plain(rng)
        if kind in (2, 3, 4):  # signed, so decoding and the handlers see arbitrary contents
            return self._sign(rng, self._plain(rng) if kind == 2 else self._raw_payload(rng))
        if kind == 5 and self.sent:  # replays and mutations of signed packets
            old = rng.choice(self.sent)
            return old if rng.random() < 0.3 else (_fix_crc(_mutate(rng, old)) if rng.random() < 0.5
                                                   else _mutate(rng, old))
        if kind == 6:  # SNs far ahead, SEC_RESYNC, RESET_COUNTERS
            name = rng.choice(("SEC_RESYNC", "RESET_COUNTERS", "NOOP"))
            jump = rng.choice((0, 1, 62, 63, 64, 65, 10**4, 10**6))
            # the fuzzer's SN follows only what the flight software accepts (a refused jump is forgotten)
            return self._sign(rng, encode_command(DICTIONARY, name, seq_count=rng.randrange(16384)), jump=jump,
                              commit=name == "SEC_RESYNC" or jump < 63)
        return self._sign(rng, _fix_crc(_mutate(rng, self._plain(rng))))

    def _plain(self, rng: random.Random) -> bytes:
        command = rng.choice(DICTIONARY.commands)
        args = {}
        for arg in command.args:
            if arg.enum:
                args[arg.name] = rng.choice(arg.enum)
            elif arg.type in ("F32", "F64"):
                args[arg.name] = rng.choice((rng.uniform(-1.5, 1.5), rng.choice(EVIL_FLOATS)))
            else:
                args[arg.name] = rng.randrange(0, 256)
        try:
            return encode_command(DICTIONARY, command.name, args, seq_count=rng.randrange(16384), check_range=False)
        except (ValueError, OverflowError, struct.error):
            return encode_command(DICTIONARY, "NOOP")

    def _raw_payload(self, rng: random.Random) -> bytes:
        opcode = rng.choice([c.opcode for c in DICTIONARY.commands] + [rng.randrange(65536)])
        payload = opcode.to_bytes(2, "big") + _random_bytes(rng, 80)
        return encode_tc_packet(DICTIONARY.tc_apid if rng.random() < 0.9 else rng.randrange(2048),
                                rng.randrange(16384), payload)

    def _sign(self, rng: random.Random, plain: bytes, jump: int = 0, commit: bool = True) -> bytes:
        if len(plain) < 8:
            return plain
        if self.sn + 1 + jump > 2**32 - 2**24:  # (not reached by a bench run: ~10^4 per resync at most)
            jump = 0
        sn = self.sn + 1 + jump
        if commit:
            self.sn = sn
        secured = self.signer.protect(plain, sn)
        self.sent.append(secured)
        return secured


# ------------------------------------------------------------------------------------ bus frames
class _ScriptedBus(can.BusABC):
    """A bus whose receive queue the fuzzer fills; sends go nowhere."""

    def __init__(self) -> None:
        super().__init__(channel="fuzz")
        self.queue: collections.deque[can.Message] = collections.deque()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return (self.queue.popleft() if self.queue else None), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        return None


class CanTarget:
    """The flight software's bus receiver: ``FswBusDriver`` in lockstep and real-time collection."""

    def __init__(self) -> None:
        from comms.bus import E2ESender, Icd
        from fsw.bus import FswBusDriver

        self.icd = Icd()
        self.bus = _ScriptedBus()
        self.driver = FswBusDriver(self.bus, self.icd, n_wheels=4, clock=lambda: 0.0)
        self.sender = E2ESender(self.icd)
        self.ids = sorted(self.icd.by_id)
        self.names = [m.name for m in self.icd.messages.values()]
        self.tick = 0
        self.pending = 0
        self.frames = 0

    def feed(self, msg: can.Message) -> None:
        """Queue one frame; every few frames run a lockstep or real-time collection over the queue."""
        self.bus.queue.append(msg)
        self.frames += 1
        self.pending += 1
        if self.pending >= 24:
            self.pending = 0
            if self.frames % 5 == 0:
                self.driver.collect_latest()
            else:
                while self.bus.queue:
                    if self.driver.collect_tick(0.0) is None:
                        break
            self.driver.send_wheel_torques(self.tick, [0.01, -0.02, math.nan, 1e9], cycle_done=True)

    @property
    def outcomes(self) -> dict[str, int]:
        """E2E classes of everything received, ticks assembled, stale SYNCs and unexpected frames."""
        out = {k: v for k, v in self.driver.receiver.totals().items() if v}
        out.update(stale_syncs=self.driver.stale_syncs, unexpected_frames=self.driver.unexpected_frames)
        return out

    def close(self) -> None:
        self.bus.shutdown()

    def generate(self, rng: random.Random) -> can.Message:
        kind = rng.randrange(6)
        if kind == 0:  # a SYNC, sometimes replayed or with an absurd frame count
            self.tick += rng.choice((1, 1, 1, 0, -3, 1000))
            values = {"tick": self.tick % 2**32, "frames_following": rng.randrange(256),
                      "period_ms": rng.choice((100, 1, 65535, 0))}
            return self.frame_tm_packet("SYNC", values) or self._random_frame(rng)
        if kind in (1, 2):  # a valid frame of a random message with random (possibly out-of-range) values
            name = rng.choice(self.names)
            spec = self.icd.messages[name]
            values = {s: rng.choice((rng.uniform(*spec.ranges[s]), rng.choice(EVIL_FLOATS[3:]), 0))
                      for s in spec.signals}
            msg = self.frame_tm_packet(name, values)
            if msg is None:
                return self._random_frame(rng)
            if kind == 2:
                msg.data = bytearray(_mutate(rng, bytes(msg.data))[:8])
                msg.dlc = len(msg.data)
            return msg
        return self._random_frame(rng)

    def frame_tm_packet(self, name: str, values: dict) -> can.Message | None:
        """The sender's frame, or None when the ICD refuses the values (the sender checks ranges)."""
        import cantools

        try:
            return self.sender.frame(name, values)
        except (cantools.database.EncodeError, ValueError, OverflowError, KeyError, TypeError):
            return None

    def _random_frame(self, rng: random.Random) -> can.Message:
        extended = rng.random() < 0.1
        frame_id = rng.choice(self.ids) if rng.random() < 0.7 else rng.randrange(2**29 if extended else 2**11)
        data = rng.randbytes(rng.choice((0, 1, 5, 6, 7, 8, 8, 8)))
        return can.Message(arbitration_id=frame_id, data=data, is_extended_id=extended,
                           is_remote_frame=rng.random() < 0.03, is_error_frame=rng.random() < 0.03)


# ------------------------------------------------------------------------------------ telemetry
class TmTarget:
    """The ground's telemetry path: a monitor with link security and one without (the raw decoder)."""

    def __init__(self) -> None:
        from fsw.telemetry import TelemetrySender
        from ground.monitor import GroundMonitor

        self.secured = GroundMonitor(DICTIONARY, port=None, security=downlink_receiver(KEY))
        self.plain = GroundMonitor(DICTIONARY, port=None)
        self.signer = SecurityAssociation(KEY, SPI_TM)
        self.flight = TelemetrySender(DICTIONARY, port=None)
        self.sent: collections.deque[bytes] = collections.deque(maxlen=64)

    def feed(self, data: bytes) -> None:
        self.secured.process(data, 0.0)
        self.plain.process(data, 0.0)

    @property
    def outcomes(self) -> dict[str, int]:
        """What the secured monitor made of its inputs: decoded, decode errors, refusals by reason."""
        stats = self.secured.stats
        return {"decoded": stats.decoded, "decode_errors": stats.decode_errors, **stats.rejected}

    def close(self) -> None:
        self.secured.close()
        self.plain.close()

    def generate(self, rng: random.Random) -> bytes:
        kind = rng.randrange(7)
        if kind == 0:
            return _random_bytes(rng, 700)
        if kind in (1, 2):  # genuine packets (GNC/HK/events) with evil values, signed or not
            plain = self._genuine(rng)
            return self._sign(plain) if kind == 1 else plain
        if kind == 3:  # a signed packet of any APID around arbitrary bytes: the decoder behind the MAC
            header = struct.pack("!BBHH", 0x08 | rng.randrange(8), rng.randrange(256), rng.randrange(65536), 0)
            return self._sign(_fix_crc(header + _random_bytes(rng, 600) + b"\0\0"))
        if kind == 4 and self.sent:
            old = rng.choice(self.sent)
            return old if rng.random() < 0.3 else _fix_crc(_mutate(rng, old))
        if kind == 5:
            return _fix_crc(_mutate(rng, self._genuine(rng)))
        return _mutate(rng, self._sign(self._genuine(rng)))

    def _genuine(self, rng: random.Random) -> bytes:
        if rng.random() < 0.4:
            event = rng.choice(DICTIONARY.events)
            args = {}
            for arg in event.args:
                if arg.enum:
                    args[arg.name] = rng.choice(arg.enum)
                elif arg.type == "STRING":
                    args[arg.name] = rng.choice(("", "x" * rng.randint(0, 200), "\u00e9\u4e2d" * 5))
                elif arg.type in ("F32", "F64"):
                    args[arg.name] = rng.choice(EVIL_FLOATS)
                else:  # integers within every integer type (out of type range is a programming error, raised)
                    args[arg.name] = rng.choice((0, 1, 100))
            sent: list[bytes] = []
            transmit = self.flight._transmit
            self.flight._transmit = lambda raw: sent.append(raw) or raw  # type: ignore[method-assign]
            try:  # the flight sender must take any value (a failure here is a flight bug: not caught)
                self.flight.event(event.name, time_s=rng.choice(EVIL_FLOATS), **args)
            finally:
                self.flight._transmit = transmit  # type: ignore[method-assign]
            if sent:
                return sent[-1]
        packet = rng.choice(DICTIONARY.packets)
        values = {c.name: rng.choice(EVIL_FLOATS) if c.type in ("F32", "F64") else rng.choice(EVIL_INTS)
                  for c in rng.sample(packet.channels, min(len(packet.channels), rng.randint(0, 5)))
                  if c.type != "ENUM"}
        return self.flight.send_channels(packet.name, values, time_s=rng.choice(EVIL_FLOATS))

    def _sign(self, plain: bytes) -> bytes:
        if len(plain) < 8:
            return plain
        secured = self.signer.protect(plain)
        self.sent.append(secured)
        return secured


# ------------------------------------------------------------------------------------ missions
_WHEEL_AXES = ([1, 0, 0], [0, 1, 0], [0, 0, 1])
# A small valid mission (the loader's time grows with the file's size: ~9 us a byte of YAML, so 10^5
# files of the 5 kB demo would take 100 min; this one is ~0.9 kB). Hostile values are put into its leaves.
BASE_MISSION = {
    "schema_version": 1, "name": "fuzz", "epoch_utc": "2026-03-20T12:00:00Z", "duration_s": 60,
    "spacecraft": {"inertia_B_kgm2": [[40, 0, 0], [0, 40, 0], [0, 0, 30]], "instrument_boresight_B": [0, 0, 1],
                   "wheels": [{"axis_B": a, "Js_kgm2": 0.004, "max_torque_Nm": 0.1, "max_speed_rad_s": 600}
                              for a in _WHEEL_AXES]},
    "orbit": {"semi_major_axis_km": 42164},
    "initial_state": {"q_NB": [1, 0, 0, 0], "omega_BN_B_rad_s": [0, 0, 0]},
    "timeline": [{"t_s": 10, "command": "SET_TARGET", "ra_dec_deg": [95, 30]}],
    "flight_software": {"spacecraft": {"inertia_B_kgm2": [[40, 0, 0], [0, 40, 0], [0, 0, 30]],
                                       "wheels": [{"axis_B": a, "max_torque_Nm": 0.1, "max_speed_rad_s": 600,
                                                   "spin_inertia_kgm2": 0.004} for a in _WHEEL_AXES]},
                        "tmtc": {"telecommand_bind_host": "127.0.0.1", "security": {"key_file": "k"}}},
}


class MissionTarget:
    """The mission loader on mission files (written to ``folder``); ConfigError is its documented refusal."""

    def __init__(self, folder: str | Path) -> None:
        self.path = Path(folder) / "mission.yaml"
        self.demo_text = (ROOT / "config" / "missions" / "demo-pointing.yaml").read_text()
        self.base_text = json.dumps(BASE_MISSION)
        self.leaves = list(_leaf_paths(BASE_MISSION))
        self.outcomes: collections.Counter[str] = collections.Counter()

    def feed(self, text: bytes) -> None:
        from hil_sim.mission.model import load_mission
        from hil_sim.mission.loader import ConfigError

        self.path.write_bytes(text)
        try:
            load_mission(self.path)
            self.outcomes["valid"] += 1
        except ConfigError:
            self.outcomes["refused"] += 1

    def close(self) -> None:
        return None

    def generate(self, rng: random.Random) -> bytes:
        r = rng.random()
        if r < 0.55:  # the base mission with a few leaves set to hostile values (or left valid)
            doc = json.loads(self.base_text)
            for _ in range(rng.randint(0, 3)):
                _set(doc, rng.choice(self.leaves), _evil_value(rng))
            if rng.random() < 0.2:
                _set(doc, rng.choice(self.leaves)[:-1] + ("unknown_key",), 1)
            if rng.random() < 0.6:
                # most files keep one or two sections: the validators of what is there all run (pydantic
                # reports every error), at a fraction of the loader's time (proportional to the size)
                keep = set(rng.sample(sorted(doc), rng.randint(1, 2))) | {"schema_version", "name"}
                doc = {k: v for k, v in doc.items() if k in keep}
            return _dump(doc, rng)
        if r < 0.75:  # small documents of random shape
            return _dump(_random_doc(rng, depth=rng.randint(0, 4)), rng)
        if r < 0.83:  # YAML constructs: aliases, tags, deep nesting, odd scalars
            return rng.choice(_YAML_SPECIALS)(rng).encode("utf-8", "surrogatepass")
        if r < 0.92:  # byte mutations of the base mission, and (rarely: 60 ms each) of the demo
            return _mutate(rng, (self.demo_text if rng.random() < 0.03 else self.base_text).encode())
        return _random_bytes(rng, 400)


def _leaf_paths(node: Any, path: tuple = ()) -> Any:
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaf_paths(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _leaf_paths(v, path + (i,))
    else:
        yield path


def _set(doc: Any, path: tuple, value: Any) -> None:
    node = doc
    for key in path[:-1]:
        node = node[key]
    if isinstance(node, (dict, list)):
        try:
            node[path[-1]] = value
        except (IndexError, TypeError):
            pass


def _dump(doc: Any, rng: random.Random) -> bytes:
    """JSON (a YAML subset, compact: the loader's time is proportional to the size) or YAML block style."""
    import yaml

    if rng.random() < 0.85:
        return json.dumps(doc, allow_nan=True, default=str).encode()
    return yaml.safe_dump(doc, default_flow_style=None).encode()


def _random_doc(rng: random.Random, depth: int) -> Any:
    if depth <= 0:
        return _evil_value(rng)
    if rng.random() < 0.6:
        keys = ["name", "duration_s", "spacecraft", "orbit", "initial_state", "flight_software", "timeline",
                "faults", "schema_version", "tmtc", "security", "key_file", "telecommand_bind_host", "x" * 3]
        return {rng.choice(keys): _random_doc(rng, depth - 1) for _ in range(rng.randint(0, 5))}
    return [_random_doc(rng, depth - 1) for _ in range(rng.randint(0, 4))]


def _alias_bomb(levels: int, width: int) -> str:
    """Billion-laughs style: each level lists the previous one ``width`` times (width^levels nodes once
    expanded). 9 levels of 9: ~1.4 s for the loader to refuse (measured), so those are rare here."""
    names = "abcdefghij"[:levels + 1]
    text = "a: &a [" + ",".join(["x"] * width) + "]\n"
    return text + "".join(f"{c}: &{c} [" + ",".join([f"*{p}"] * width) + "]\n" for p, c in zip(names, names[1:]))


_YAML_SPECIALS = (
    lambda rng: _alias_bomb(9 if rng.random() < 0.02 else rng.randint(1, 4), rng.randint(2, 9)),
    lambda rng: "[" * rng.randint(1, 1500) + "]" * rng.randint(0, 1500),
    lambda rng: "{a: " * rng.randint(1, 500) + "1" + "}" * rng.randint(0, 500),
    lambda rng: "!!python/object/apply:os.system ['true']\n",
    lambda rng: "name: !!binary aGVsbG8=\nduration_s: !!float .nan\n",
    lambda rng: "schema_version: 1\nname: x\nduration_s: " + rng.choice(("1e400", "-.inf", ".nan", "0x1p9999", "1_000"))
    + "\n",
    lambda rng: "\ufeff" + "name:\t x\n\t- y\n",
    lambda rng: "key: \"\\ud800\"\n" + "%YAML 1.1\n---\n...\n" * rng.randint(1, 3),
    lambda rng: "<<: *undefined\n",
    lambda rng: "? [a, b]\n: c\n" * rng.randint(1, 20),
    lambda rng: "- " * rng.randint(1, 500) + "x\n",
)
