"""GroundMonitor's batched receive (recvmmsg) and chunked raw archive give what a recv per datagram and a
buffered file gave: every datagram, whole, in order, once; the archive on disk after flush and close."""
from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from ground import monitor as monitor_module
from ground.archive import RAW_ARCHIVE, read_raw_archive
from ground.monitor import GroundMonitor


def _send_all(port: int, datagrams: list[bytes]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for data in datagrams:
            tx.sendto(data, ("127.0.0.1", port))


def _poll_until(monitor: GroundMonitor, n: int) -> None:
    deadline = time.monotonic() + 5.0
    while monitor.stats.datagrams < n and time.monotonic() < deadline:
        monitor.poll(0.05)


def _datagrams() -> list[bytes]:
    # not telemetry: archived raw (then counted as decode errors) exactly as received; sizes from 1 byte to
    # near the UDP maximum, more than one recvmmsg batch in total
    sizes = [1, 7, 300, 4096, 65000] + [17 + i for i in range(3 * monitor_module.RECV_BATCH)]
    return [bytes([i % 251]) * size for i, size in enumerate(sizes)]


@pytest.mark.parametrize("batched", [True, False])
def test_every_datagram_archived_whole_in_order(tmp_path: Path, batched: bool) -> None:
    monitor = GroundMonitor(port=0, host="127.0.0.1", archive_dir=tmp_path)
    if not batched:
        monitor._batch = None  # the per-datagram recv path (platforms without recvmmsg)
    assert (monitor._batch is not None) == batched  # (Linux: recvmmsg through ctypes)
    sent = _datagrams()
    _send_all(monitor.address[1], sent)
    _poll_until(monitor, len(sent))
    monitor.close()
    archived = [raw for _, raw in read_raw_archive(tmp_path / RAW_ARCHIVE)]
    assert archived == sent
    assert monitor.stats.datagrams == len(sent)


def test_poll_stops_at_max_packets_per_poll(tmp_path: Path) -> None:
    monitor = GroundMonitor(port=0, host="127.0.0.1", archive_dir=None)
    monitor.max_packets_per_poll = 5
    sent = _datagrams()[:40]
    _send_all(monitor.address[1], sent)
    time.sleep(0.2)
    assert monitor.poll(0.5) == 5
    _poll_until(monitor, len(sent))
    assert monitor.stats.datagrams == len(sent)
    monitor.close()


def test_chunked_archive_reaches_the_file_on_flush_and_when_full(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(monitor_module, "ARCHIVE_CHUNK_BYTES", 100)
    path = tmp_path / "a.bin"
    path.write_bytes(b"old")  # appends, as the buffered file did
    writer = monitor_module._ChunkedWriter(path)
    writer.write(b"x" * 60)
    assert path.read_bytes() == b"old"  # held until a flush or a full piece
    writer.write(b"y" * 60)
    assert path.read_bytes() == b"old" + b"x" * 60 + b"y" * 60
    writer.write(b"z")
    writer.flush()
    assert path.read_bytes().endswith(b"z")
    writer.write(b"end")
    writer.close()
    assert path.read_bytes() == b"old" + b"x" * 60 + b"y" * 60 + b"zend"
