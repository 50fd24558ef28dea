"""The interface control document: config/icd/keepout.dbc, loaded with cantools.

All frames on the bus are built and read here, with strict range checks. The E2E fields (``E2E_CRC``,
``E2E_Counter``) are ordinary DBC signals: the payload is packed with the CRC signal zero, the CRC is
computed over bytes 1.., then written into byte 0.

Packing goes through a per-message codec (:class:`_MessageCodec`) compiled from the DBC's signal
definitions at load time: cantools' generic encode/decode costs ~20 us per frame, which a campaign run
pays 20+ times per GNC tick. The codec repeats cantools' arithmetic exactly (same rounding, same scaling
expressions, same dict order and value types); tests/fsw/test_bus_icd.py checks it bit-exact against
cantools for every message of the DBC. Layouts it does not handle (big-endian or float signals,
multiplexing) and values it cannot pack go through cantools unchanged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Mapping

import can
import cantools
import numpy as np
from keepout_config import config_path

from comms.bus.crc import CRC_TABLE as _CRC_TABLE
from comms.bus.crc import crc8_sae_j1850, e2e_crc
from comms.bus.burst import FrameBurst
from comms.bus.burst import data_frame as _data_frame
from comms.bus.kernels import MAX_DLC, CodecTable, encode_burst

DEFAULT_DBC_PATH = config_path("icd", "keepout.dbc")

E2E_CRC_SIGNAL = "E2E_CRC"
E2E_COUNTER_SIGNAL = "E2E_Counter"
SECOC_ATTRIBUTE = "SecOCAuthenticator"
SECOC_LAYOUT = [("frame_id", 0, 11), ("freshness_lsb", 11, 21), ("mac", 32, 32)]  # comms.bus.secoc's frame
# RWn_STATUS.fault's bits (the DBC's comment on the signal; tests/fsw/test_bus_icd.py reads it)
WHEEL_FAULT_OVERSPEED, WHEEL_FAULT_CMD_TIMEOUT, WHEEL_FAULT_DRIVE = 1, 2, 4


class IcdError(ValueError):
    """The DBC file violates a rule the bus relies on (named file, message and rule)."""


@dataclass(frozen=True)
class MessageSpec:
    """One ICD frame: identity, size, timing and E2E parameters (from the DBC attributes)."""

    name: str
    frame_id: int
    dlc: int
    senders: tuple[str, ...]
    cycle_time_s: float
    timeout_s: float
    data_id: int
    max_delta_counter: int
    signals: tuple[str, ...]  # application signals (without the E2E ones)
    ranges: Mapping[str, tuple[float, float]]
    db_message: Any  # cantools Message
    # ranges widened by half an LSB: the DBC limits are physical values the raw grid may not hit exactly
    accept_bounds: Mapping[str, tuple[float, float]] = None  # type: ignore[assignment]
    codec: _MessageCodec | None = None  # None: cantools packs this message
    crc_seed: int = 0  # CRC-8 register after the data ID bytes (the part of every frame's CRC that is fixed)


class _MessageCodec:
    """Encoder/decoder of one message with only little-endian integer signals (see the module docstring).

    Scaling per conversion class, as cantools does it: identity ``round(v)`` / ``raw``; linear
    ``round((v - offset) / scale)`` / ``raw * scale + offset``; other conversions (integer-linear:
    cantools divides exactly when it can) call cantools' own conversion object. The four functions are
    generated as Python source from the signal table (one straight-line function per message: a frame
    costs a few microseconds, and a loop over a signal table would double that).
    """

    def __init__(self, message: Any, accept_bounds: Mapping[str, tuple[float, float]], crc_seed: int) -> None:
        self.length = message.length
        ns: dict[str, Any] = {"_T": _CRC_TABLE}

        def crc_lines(buf: str) -> list[str]:  # the CRC register over bytes 1.. of ``buf``, unrolled, into c
            return ([f"    c = _T[{crc_seed} ^ {buf}[1]]"]
                    + [f"    c = _T[c ^ {buf}[{k}]]" for k in range(2, message.length)])

        app = [s for s in message.signals if s.name not in (E2E_CRC_SIGNAL, E2E_COUNTER_SIGNAL)]
        pack = [f"def encode(signals, counter):",
                f"    if len(signals) != {len(app)}:",
                "        return None",
                "    word = (counter & 15) << 8",
                "    try:"]
        unpack = ["def unpack(data):", "    w = int.from_bytes(data, 'little')"]
        checked = ["def unpack_checked(data):", "    w = int.from_bytes(data, 'little')"]
        for i, sig in enumerate(message.signals):
            conv = sig.conversion
            if type(conv).__name__ == "NamedSignalConversion":
                conv = conv._conversion  # numbers only (decode_choices=False): its numeric conversion
            kind = type(conv).__name__
            ns[f"scale{i}"], ns[f"offset{i}"], ns[f"conv{i}"] = conv.scale, conv.offset, conv
            ns[f"alo{i}"], ns[f"ahi{i}"] = accept_bounds[sig.name]
            mask, half = (1 << sig.length) - 1, 1 << (sig.length - 1)
            read = [f"    r = (w >> {sig.start}) & {mask}"]
            if sig.is_signed:
                read.append(f"    if r & {half}:\n        r -= {1 << sig.length}")
            if kind == "IdentityConversion":
                read.append(f"    v{i} = r")
            elif kind == "LinearConversion":
                read.append(f"    v{i} = r * scale{i} + offset{i}")
            else:
                read.append(f"    v{i} = conv{i}.raw_to_scaled(r, False)")
            unpack += read
            checked += read + [f"    if not (alo{i} <= v{i} <= ahi{i}):", "        return None"]
            if sig.name not in (E2E_CRC_SIGNAL, E2E_COUNTER_SIGNAL):
                ns[f"vmin{i}"] = sig.minimum if sig.minimum is not None else -math.inf
                ns[f"vmax{i}"] = sig.maximum if sig.maximum is not None else math.inf
                lo = -half if sig.is_signed else 0
                hi = half - 1 if sig.is_signed else mask
                raw = {"IdentityConversion": "round(v)", "LinearConversion": f"round((v - offset{i}) / scale{i})"}.get(
                    kind, f"conv{i}.numeric_scaled_to_raw(v)")
                pack += [f"        v = signals[{sig.name!r}]",
                         f"        if not (vmin{i} <= v <= vmax{i}) or not isinstance(v, (int, float)):",
                         "            return None",
                         f"        r = {raw}",
                         f"        if not ({lo} <= r <= {hi}):",
                         "            return None",
                         f"        word |= (r & {mask}) << {sig.start}"]
        pack += ["    except (KeyError, TypeError):", "        return None",
                 f"    data = bytearray(word.to_bytes({message.length}, 'little'))"]
        pack += crc_lines("data")
        pack += ["    data[0] = c ^ 255", "    return data"]
        result = "    return {" + ", ".join(f"{s.name!r}: v{i}" for i, s in enumerate(message.signals)) + "}"
        unpack.append(result)
        checked.append(result)
        crc = ["def crc(data):", *crc_lines("data"), "    return c ^ 255"]
        exec(compile("\n".join(pack + unpack + checked + crc) + "\n", f"<codec {message.name}>", "exec"), ns)
        self.encode = ns["encode"]
        self.encode.__doc__ = """(signals, counter) -> the frame's bytes with alive counter ``counter`` and
        its E2E CRC in byte 0 (one generated function: packing, bytes and CRC were three calls); None when
        anything is off (a value missing, outside its DBC range, not a plain number, or its raw value not
        fitting its bits; an unknown signal): the caller then takes the checked cantools path, which
        raises the error that names it."""
        self.unpack = ns["unpack"]  # (data) -> {signal: value} as cantools decodes it (scaling, no choices)
        self.unpack_checked = ns["unpack_checked"]  # the same, None if a value is outside accept_bounds
        self.crc = ns["crc"]  # (frame bytes) -> E2E CRC over bytes 1.. (= e2e_crc(data_id, data[1:]))

    @staticmethod
    def supports(message: Any) -> bool:
        names = {s.name: s for s in message.signals}
        crc, counter = names.get(E2E_CRC_SIGNAL), names.get(E2E_COUNTER_SIGNAL)
        if crc is None or counter is None or (crc.start, crc.length, counter.start, counter.length) != (0, 8, 8, 4):
            return False
        return (not message.is_multiplexed() and 2 <= message.length <= 8 and all(
            s.byte_order == "little_endian" and not s.is_float and not s.conversion.is_float
            for s in message.signals))


def _codec_table(specs: list[MessageSpec]) -> CodecTable:
    """The kernels' signal table (see comms.bus.kernels) of ``specs``, message index = list position.
    Messages the per-frame generated codec does not handle are left out of ``index_of_id``."""
    n_slots = max(len(s.db_message.signals) for s in specs)
    shape = (len(specs), n_slots)
    ints = {k: np.zeros(shape, dtype=np.int64) for k in ("start", "length")}
    floats = {k: np.zeros(shape) for k in ("scale", "offset", "vmin", "vmax", "alo", "ahi")}
    signed = np.zeros(shape, dtype=np.bool_)
    index_of_id = np.full(2048, -1, dtype=np.int64)
    for m, spec in enumerate(specs):
        by_name = {s.name: s for s in spec.db_message.signals}
        ordered = [by_name[E2E_CRC_SIGNAL], by_name[E2E_COUNTER_SIGNAL]] + [by_name[n] for n in spec.signals]
        kinds = {type(getattr(s.conversion, "_conversion", s.conversion)).__name__ for s in ordered}
        if spec.codec is None or not kinds <= _TABLE_CONVERSIONS:
            continue
        index_of_id[spec.frame_id] = m
        for k, sig in enumerate(ordered):
            ints["start"][m, k], ints["length"][m, k], signed[m, k] = sig.start, sig.length, sig.is_signed
            floats["scale"][m, k], floats["offset"][m, k] = float(sig.scale), float(sig.offset)
            floats["vmin"][m, k], floats["vmax"][m, k] = spec.ranges[sig.name]
            floats["alo"][m, k], floats["ahi"][m, k] = spec.accept_bounds[sig.name]
    return CodecTable(index_of_id=index_of_id,
                      dlc=np.array([s.dlc for s in specs], dtype=np.int64),
                      seed=np.array([s.crc_seed for s in specs], dtype=np.int64),
                      nsig=np.array([2 + len(s.signals) for s in specs], dtype=np.int64),
                      signed=signed, crc_table=np.array(_CRC_TABLE, dtype=np.int64),
                      max_delta=np.array([s.max_delta_counter for s in specs], dtype=np.int64), **ints, **floats)


# cantools conversions the kernels repeat exactly (LinearIntegerConversion: integer scale and offset,
# whose exact-division path gives the same raw values as the float one for the values a frame can hold)
_TABLE_CONVERSIONS = {"IdentityConversion", "LinearConversion", "LinearIntegerConversion"}


def _attribute(message: Any, name: str, default: Any) -> Any:
    attrs = message.dbc.attributes if message.dbc is not None else {}
    if name in attrs:
        return attrs[name].value
    return default


class Icd:
    """The bus ICD. ``Icd()`` loads the project's DBC; ``Icd(path)`` another one.

    Checks at load time that every message carries the E2E signals at the fixed positions (CRC in byte 0,
    counter in bits 8..11), has a unique E2EDataID and a positive cycle time, and fits classic CAN.
    """

    def __init__(self, dbc_path: str | Path | None = None) -> None:
        self.path = Path(dbc_path) if dbc_path is not None else DEFAULT_DBC_PATH
        if not self.path.is_file():
            raise IcdError(f"ICD file {self.path} not found (expected a DBC file, e.g. {DEFAULT_DBC_PATH})")
        try:
            self.db = cantools.database.load_file(str(self.path), strict=True)
        except (cantools.database.UnsupportedDatabaseFormatError, ValueError) as exc:
            raise IcdError(f"ICD file {self.path} is not a valid DBC: {exc}") from exc
        self.messages: dict[str, MessageSpec] = {}
        self.by_id: dict[int, MessageSpec] = {}
        seen_ids: dict[int, str] = {}
        # SecOC authenticator frames (comms.bus.secoc) belong to the layer below E2E: node -> frame id
        self.authenticators: dict[str, int] = {}
        for message in self.db.messages:
            if int(_attribute(message, SECOC_ATTRIBUTE, 0)):
                self._authenticator(message)
                continue
            spec = self._spec(message)
            if spec.data_id in seen_ids:
                raise IcdError(
                    f"{self.path}: message {spec.name} reuses E2EDataID {spec.data_id} of {seen_ids[spec.data_id]}"
                )
            seen_ids[spec.data_id] = spec.name
            self.messages[spec.name] = spec
            self.by_id[spec.frame_id] = spec
        self.nodes: tuple[str, ...] = tuple(node.name for node in self.db.nodes)
        # message index m of the compiled kernels (comms.bus.kernels), in DBC order
        self.message_names: tuple[str, ...] = tuple(self.messages)
        self.message_index: dict[str, int] = {name: m for m, name in enumerate(self.message_names)}
        self.table = _codec_table(list(self.messages.values()))

    def column(self, name: str, signal: str) -> int:
        """Slot of ``signal`` in the kernels' value rows of message ``name`` (E2E_CRC 0, E2E_Counter 1,
        then the application signals in DBC order)."""
        spec = self.spec(name)
        if signal == E2E_CRC_SIGNAL:
            return 0
        if signal == E2E_COUNTER_SIGNAL:
            return 1
        return 2 + spec.signals.index(signal)

    def _authenticator(self, message: Any) -> None:
        where = f"{self.path}: message {message.name}"
        layout = [(s.name, s.start, s.length) for s in message.signals]
        if message.is_extended_frame or message.length != 8 or layout != SECOC_LAYOUT or len(message.senders) != 1:
            raise IcdError(f"{where}: a SecOC authenticator is an 8-byte classic frame with one sender and "
                           f"the signals {SECOC_LAYOUT} (name, start bit, length)")
        node = message.senders[0]
        if node in self.authenticators:
            raise IcdError(f"{where}: node {node} has a second SecOC authenticator")
        self.authenticators[node] = message.frame_id

    def _spec(self, message: Any) -> MessageSpec:
        where = f"{self.path}: message {message.name}"
        if message.is_extended_frame or message.length > 8:
            raise IcdError(f"{where}: must be a classic CAN 2.0A frame (11-bit id, <= 8 bytes)")
        names = {s.name: s for s in message.signals}
        crc, counter = names.get(E2E_CRC_SIGNAL), names.get(E2E_COUNTER_SIGNAL)
        if crc is None or (crc.start, crc.length, crc.byte_order) != (0, 8, "little_endian"):
            raise IcdError(f"{where}: needs signal {E2E_CRC_SIGNAL} at bits 0..7 (byte 0), little endian")
        if counter is None or (counter.start, counter.length, counter.byte_order) != (8, 4, "little_endian"):
            raise IcdError(f"{where}: needs signal {E2E_COUNTER_SIGNAL} at bits 8..11, little endian")
        cycle_ms = message.cycle_time or 0
        if cycle_ms <= 0:
            raise IcdError(f"{where}: GenMsgCycleTime must be set (> 0 ms)")
        data_id = int(_attribute(message, "E2EDataID", 0))
        if data_id <= 0:
            raise IcdError(f"{where}: E2EDataID attribute must be set (1..65535)")
        timeout_ms = int(_attribute(message, "E2ETimeoutMs", 3 * cycle_ms)) or 3 * cycle_ms
        seed = crc8_sae_j1850((data_id & 0xFF, (data_id >> 8) & 0xFF), final_xor=False)
        ranges, accept = {}, {}
        for s in message.signals:
            lo = s.minimum if s.minimum is not None else -math.inf
            hi = s.maximum if s.maximum is not None else math.inf
            ranges[s.name] = (lo, hi)
            slack = 0.5 * abs(s.scale)
            accept[s.name] = (lo - slack, hi + slack)
        return MessageSpec(
            name=message.name,
            frame_id=message.frame_id,
            dlc=message.length,
            senders=tuple(message.senders),
            cycle_time_s=cycle_ms / 1000.0,
            timeout_s=timeout_ms / 1000.0,
            data_id=data_id,
            max_delta_counter=int(_attribute(message, "E2EMaxDeltaCounter", 2)),
            signals=tuple(s.name for s in message.signals if s.name not in (E2E_CRC_SIGNAL, E2E_COUNTER_SIGNAL)),
            ranges=ranges,
            db_message=message,
            accept_bounds=accept,
            codec=_MessageCodec(message, accept, seed) if _MessageCodec.supports(message) else None,
            crc_seed=seed,
        )

    # ------------------------------------------------------------------------------- queries
    def spec(self, name: str) -> MessageSpec:
        try:
            return self.messages[name]
        except KeyError:
            raise KeyError(f"message {name!r} is not in the ICD {self.path}; known: {sorted(self.messages)}") from None

    def ids_sent_by(self, *nodes: str) -> frozenset[int]:
        """Frame ids whose DBC sender is one of ``nodes``."""
        return frozenset(m.frame_id for m in self.messages.values() if set(m.senders) & set(nodes))

    def names_sent_by(self, *nodes: str) -> tuple[str, ...]:
        return tuple(m.name for m in self.messages.values() if set(m.senders) & set(nodes))

    def signal_range(self, name: str, signal: str) -> tuple[float, float]:
        return self.spec(name).ranges[signal]

    def resolution(self, name: str, signal: str) -> float:
        """Scale factor (LSB size) of a signal, in its DBC unit."""
        return float(self.spec(name).db_message.get_signal_by_name(signal).scale)

    # ---------------------------------------------------------------------------- encode/decode
    def encode(self, name: str, signals: Mapping[str, float], counter: int) -> can.Message:
        """Build the frame ``name`` with alive counter ``counter`` (0..15) and its E2E CRC.

        Raises ``cantools`` EncodeError naming the signal when a value is outside its DBC range, NaN, or
        missing: a sender bug must not be silently clipped onto the bus.
        """
        spec = self.messages.get(name) or self.spec(name)
        data = spec.codec.encode(signals, counter) if spec.codec is not None else None
        if data is not None:  # the compiled codec checked the ranges itself
            return _data_frame(spec.frame_id, data)
        else:
            values = dict(signals)
            values[E2E_COUNTER_SIGNAL] = counter & 0x0F
            values[E2E_CRC_SIGNAL] = 0
            self._check_ranges(spec, values)
            message = spec.db_message
            payload = message.encode(values, scaling=True, padding=False, strict=False)
            values[E2E_CRC_SIGNAL] = e2e_crc(spec.data_id, payload[1:])
            data = message.encode(values, scaling=True, padding=False, strict=False)
        return can.Message(arbitration_id=spec.frame_id, data=data, is_extended_id=False, is_fd=False)

    @staticmethod
    def _check_ranges(spec: MessageSpec, values: Mapping[str, float]) -> None:
        """The DBC's [min|max] of every signal, enforced before encoding (cantools' strict mode does the
        same; this precomputed check is cheaper and names the message, signal and allowed range)."""
        for signal, (lo, hi) in spec.ranges.items():
            try:
                value = values[signal]
            except KeyError:
                raise cantools.database.EncodeError(
                    f"message {spec.name}: signal {signal!r} missing; needs {sorted(spec.ranges)}") from None
            if not lo <= value <= hi:  # also rejects NaN
                raise cantools.database.EncodeError(
                    f"message {spec.name}: signal {signal!r} = {value!r} outside its ICD range [{lo}, {hi}]")
        if len(values) != len(spec.ranges):
            unknown = sorted(set(values) - set(spec.ranges))
            raise cantools.database.EncodeError(f"message {spec.name}: unknown signal(s) {unknown}")

    def decode_checked(self, spec: MessageSpec, data: bytes) -> dict[str, float] | None:
        """Decode ``data``; None if the length is wrong or a signal is out of range."""
        if spec.codec is not None and len(data) == spec.dlc:
            return spec.codec.unpack_checked(data)
        else:
            try:
                values = spec.db_message.decode(data, decode_choices=False, scaling=True, allow_truncated=False,
                                                allow_excess=False)
            except (cantools.database.DecodeError, ValueError, KeyError):
                return None
        bounds = spec.accept_bounds
        for signal, value in values.items():
            lo, hi = bounds[signal]
            if not (lo <= value <= hi):
                return None
        return values

    def decode(self, msg: can.Message) -> tuple[str, dict[str, float]]:
        """Decode a frame without E2E checks (tools, logs). Raises KeyError for an unknown id."""
        spec = self.by_id.get(msg.arbitration_id)
        if spec is None:
            raise KeyError(f"frame id 0x{msg.arbitration_id:03X} is not in the ICD {self.path}")
        return spec.name, spec.db_message.decode(bytes(msg.data), decode_choices=False)


class E2ESender:
    """Keeps one alive counter per message and builds protected frames through an :class:`Icd`:
    one at a time (``frame``) or a whole burst in one compiled call (``burst``)."""

    def __init__(self, icd: Icd) -> None:
        self.icd = icd
        # alive counters and sent counts by message index (the kernels'), rows of one array (one argument)
        self._cs = np.zeros((2, len(icd.message_names)), dtype=np.int64)
        self._counter, self._sent = self._cs[0], self._cs[1]
        self._fast = {name: (spec.codec, spec.frame_id, icd.message_index[name])
                      for name, spec in icd.messages.items() if spec.codec}
        self._ids = np.array([icd.messages[n].frame_id for n in icd.message_names], dtype=np.int64)
        self._dlc = icd.table.dlc
        t = icd.table
        # kernels.encode_burst with this sender's counters and the table bound (a burst passes its rows only)
        self._encode = partial(encode_burst, self._cs, t.packed_i, t.sig_f)

    @property
    def counters(self) -> dict[str, int]:
        """The next alive counter of each message."""
        return dict(zip(self.icd.message_names, self._counter.tolist()))

    @property
    def sent(self) -> dict[str, int]:
        """Frames built per message."""
        return dict(zip(self.icd.message_names, self._sent.tolist()))

    def frame(self, name: str, signals: Mapping[str, float]) -> can.Message:
        codec, frame_id, m = self._fast.get(name, (None, 0, -1))
        if m < 0:
            m = self.icd.message_index[name]
        counter = int(self._counter[m])
        data = codec.encode(signals, counter) if codec is not None else None
        # Icd.encode's own steps, one call less per frame; anything the codec refuses takes its checked path
        msg = _data_frame(frame_id, data) if data is not None else self.icd.encode(name, signals, counter)
        self._counter[m] = (counter + 1) & 0x0F
        self._sent[m] += 1
        return msg

    def burst(self, idx: np.ndarray, values: np.ndarray, out: np.ndarray | None = None, done: int = 0) -> FrameBurst:
        """The frames of messages ``idx`` (message indices, ``Icd.message_index``) with the application
        values of row i in slots 2.. of ``values[i]`` (``Icd.column``), in order, as one burst: the same
        bytes and counters as ``frame`` called row by row. A row the compiled codec refuses (a value out
        of its DBC range, NaN) goes through ``frame``, which raises the error that names it. ``out`` with
        ``done``: its first ``done`` rows are encoded already (by a compiled caller that stopped there)."""
        n = len(idx)
        if out is None:
            out = np.zeros((n, MAX_DLC), dtype=np.uint8)
        if done == 0 and n:  # the whole burst, without slicing (the usual call: every row encodes)
            done = self._encode(idx, values, out)
        while done < n:
            done += self._encode(idx[done:], values[done:], out[done:])
            if done < n:
                name = self.icd.message_names[idx[done]]
                spec = self.icd.messages[name]
                row = values[done].tolist()
                msg = self.frame(name, {sig: row[2 + j] for j, sig in enumerate(spec.signals)})
                out[done, :len(msg.data)] = np.frombuffer(bytes(msg.data), dtype=np.uint8)
                done += 1
        return FrameBurst(self._ids[idx], out, self._dlc[idx])
