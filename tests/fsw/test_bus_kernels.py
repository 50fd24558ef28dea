"""The compiled burst codec (comms.bus.kernels) against the per-frame codec: same bytes, same classification."""
from __future__ import annotations

import can
import numpy as np
import pytest

from comms.bus import E2EReceiver, E2ESender, Icd
from comms.bus.burst import FrameBurst
from comms.bus.transport import open_bus, recv_burst, send_burst
from reference.bus import ReferenceReceiver, encode_frame


@pytest.fixture(scope="module")
def icd() -> Icd:
    return Icd()


def _random_rows(icd: Icd, rng: np.random.Generator, n: int) -> tuple[list[str], list[dict], np.ndarray]:
    width = icd.table.start.shape[1]
    names = [icd.message_names[k] for k in rng.integers(0, len(icd.message_names), n)]
    values, dicts = np.zeros((n, width)), []
    for i, name in enumerate(names):
        spec, d = icd.spec(name), {}
        for sig in spec.signals:
            lo, hi = (max(b, -1e6) if j == 0 else min(b, 1e6) for j, b in enumerate(spec.ranges[sig]))
            v = float(rng.uniform(lo, hi))
            if spec.db_message.get_signal_by_name(sig).scale == 1:
                v = float(round(v))
            d[sig] = v
            values[i, icd.column(name, sig)] = v
        dicts.append(d)
    return names, dicts, values


def test_burst_encode_is_bit_exact_with_frame_by_frame(icd: Icd) -> None:
    rng = np.random.default_rng(1)
    batch, single = E2ESender(icd), E2ESender(icd)
    for _ in range(500):
        names, dicts, values = _random_rows(icd, rng, 6)
        burst = batch.burst(np.array([icd.message_index[n] for n in names]), values)
        for ref, got in zip((single.frame(n, d) for n, d in zip(names, dicts)), burst.messages()):
            assert (got.arbitration_id, bytes(got.data)) == (ref.arbitration_id, bytes(ref.data))
    assert batch.counters == single.counters and batch.sent == single.sent


def test_burst_encode_refuses_out_of_range_values_naming_the_signal(icd: Icd) -> None:
    sender = E2ESender(icd)
    values = np.zeros((1, icd.table.start.shape[1]))
    values[0, icd.column("RW1_CMD", "torque_cmd")] = 5.0
    with pytest.raises(Exception, match="torque_cmd"):
        sender.burst(np.array([icd.message_index["RW1_CMD"]]), values)
    assert sender.counters["RW1_CMD"] == 0  # nothing sent, the counter did not move


def _damaged_frames(icd: Icd, rng: np.random.Generator, sender: E2ESender) -> list[can.Message]:
    msgs = []
    for name, d, _ in zip(*_random_rows(icd, rng, 8)):
        data = bytearray(sender.frame(name, d).data)
        fid = icd.spec(name).frame_id
        r = rng.random()
        if r < 0.1:
            data[rng.integers(len(data))] ^= 1 << int(rng.integers(8))     # crc_error
        elif r < 0.15:
            data = data[:-1]                                                # bad_length
        elif r < 0.2 and name == "SYNC":
            data[6] &= 0x0F                                                  # period_ms 0: out_of_range
            data[7] = 0
            data[0] = sender.icd.spec("SYNC").codec.crc(data)
        elif r < 0.25:
            fid = int(rng.integers(0, 0x800))                               # unknown id or own echo
        msgs.append(can.Message(arbitration_id=fid, data=data, is_extended_id=bool(rng.random() < 0.03)))
        if rng.random() < 0.1:
            msgs.append(msgs[-1])                                            # repeated
        if rng.random() < 0.05:
            msgs.pop(-2 if len(msgs) > 1 else -1)                            # lost: sequence gaps
    return msgs


def test_burst_classification_follows_the_rules_frame_by_frame(icd: Icd) -> None:
    rng = np.random.default_rng(2)
    sender, own = E2ESender(icd), icd.ids_sent_by("FSW")
    burst_rx, one_rx, ref = E2EReceiver(icd, ignore_ids=own), E2EReceiver(icd, ignore_ids=own), ReferenceReceiver(icd, own)
    for tick in range(1500):
        t = 0.05 * tick
        if tick % 7 == 0:
            assert burst_rx.check_timeouts(t) == one_rx.check_timeouts(t) == ref.check_timeouts(t)
        msgs = _damaged_frames(icd, rng, sender)
        checked = burst_rx.check(FrameBurst.from_messages(msgs))
        # the whole burst in compiled calls (bursts of one or two frames take the Python path)
        assert burst_rx.classify_until(checked, t) == len(msgs)
        for i, msg in enumerate(msgs):
            expected, got, one = ref.classify(msg, t), burst_rx.frame_at(checked, i), one_rx.classify(msg, t)
            if expected is None:
                assert got is None and one is None
                continue
            name, status, counter, values = expected
            assert (got.name, got.status, got.counter) == (name, status, counter) == (one.name, one.status, one.counter)
            if values is not None:
                slots = ("E2E_CRC", "E2E_Counter", *icd.spec(name).signals)
                assert got.row[:len(slots)] == [values[k] for k in slots]
                assert one.signals == values
    assert burst_rx.counters == one_rx.counters
    for (name, cls), n in ref.counts.items():
        assert burst_rx.counters["_bus" if name is None else name][cls] == n, (name, cls)
    assert sum(len(c.fallback) for c in [checked]) < len(msgs)  # the kernel judged most of them
    totals = burst_rx.totals()
    for cls in ("ok", "ok_some_lost", "repeated", "wrong_sequence", "crc_error", "bad_length", "out_of_range",
                "timeout", "unknown_id", "own_echo"):
        assert totals[cls] > 0, cls  # every class was exercised


def test_light_virtual_bus_carries_bursts_and_plain_readers_see_the_same_frames(icd: Icd) -> None:
    rng = np.random.default_rng(3)
    names, _, values = _random_rows(icd, rng, 5)
    burst = E2ESender(icd).burst(np.array([icd.message_index[n] for n in names]), values)
    tx, rx_burst = open_bus("virtual:kernels-test", light=True), open_bus("virtual:kernels-test", light=True)
    rx_plain = can.Bus(interface="virtual", channel="kernels-test")
    try:
        tx.send(can.Message(arbitration_id=0x7FF, data=b"\x01", is_extended_id=False))
        assert send_burst(tx, burst) == 5
        got = recv_burst(rx_burst, 0.0)
        assert got.ids.tolist() == [0x7FF] + burst.ids.tolist()
        assert [bytes(m.data) for m in got.messages()[1:]] == [bytes(m.data) for m in burst.messages()]
        assert recv_burst(rx_burst, 0.0) is None
        plain = [rx_plain.recv(0.5) for _ in range(6)]
        assert [(m.arbitration_id, bytes(m.data)) for m in plain[1:]] == \
            [(m.arbitration_id, bytes(m.data)) for m in burst.messages()]
        # a LightVirtualBus read frame by frame hands a queued burst out frame by frame
        send_burst(tx, burst)
        assert [bytes(rx_burst.recv(0.0).data) for _ in range(5)] == [bytes(m.data) for m in burst.messages()]
        assert rx_burst.recv(0.0) is None
    finally:
        for bus in (tx, rx_burst, rx_plain):
            bus.shutdown()


def test_encode_burst_matches_cantools_frame_by_frame(icd: Icd) -> None:
    """kernels.encode_burst (E2ESender's: counters/sent as one array, the table packed) gives the bytes
    cantools packs frame by frame (tests/reference), the counters and sent counts of the rows it encoded,
    and stops at the first row cantools refuses (out of range or NaN)."""
    from comms.bus.kernels import encode_burst

    rng = np.random.default_rng(7)
    table, m = icd.table, len(icd.message_names)
    cs = np.zeros((2, m), dtype=np.int64)
    counters, sent = [0] * m, [0] * m
    refused = 0
    for trial in range(200):
        names, dicts, values = _random_rows(icd, rng, 5)
        idx = np.array([icd.message_index[n] for n in names], dtype=np.int64)
        if trial % 5 == 0:  # a refused row: out of range or NaN
            i = int(rng.integers(5))
            spec = icd.spec(names[i])
            if spec.signals:
                sig = spec.signals[int(rng.integers(len(spec.signals)))]
                dicts[i][sig] = values[i, icd.column(names[i], sig)] = [np.nan, 1e12, -1e12][trial % 3]
        out = np.zeros((5, 8), dtype=np.uint8)
        got = encode_burst(cs, table.packed_i, table.sig_f, idx, values, out)
        want = []
        for name, d in zip(names, dicts):
            frame = encode_frame(icd, name, d, counters[icd.message_index[name]])
            if frame is None:
                break
            want.append(frame)
            counters[icd.message_index[name]] = (counters[icd.message_index[name]] + 1) & 15
            sent[icd.message_index[name]] += 1
        refused += got < 5
        assert got == len(want)
        assert [bytes(out[i, :len(w)]) for i, w in enumerate(want)] == want
        assert cs.tolist() == [counters, sent]
    assert refused >= 30
