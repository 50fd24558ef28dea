"""The ground archive: file names, the raw record format, and readers for plots, summaries and replay.

A run's archive directory holds ``tm_raw.bin`` (records of ``rx_time_s`` float64 + ``length`` u32 +
packet bytes, big-endian; written before decoding so nothing is lost), ``tm_decoded.jsonl``,
``events.jsonl``, ``limits.jsonl`` (every YELLOW/RED limit transition) and ``ground_summary.json``.
With link security ``tm_raw.bin`` holds the authenticated packets in their plain form (security header
and MAC checked and taken off) and ``tm_rejected.bin`` (same record format) the datagrams that failed
authentication or anti-replay, as received.
"""
from __future__ import annotations

import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Sequence

from comms.dictionary import DICTIONARY, TelemetryDictionary

if TYPE_CHECKING:
    from comms.telemetry import DecodedTm

RAW_RECORD = struct.Struct("!dI")  # rx time (s, UNIX), packet length (bytes)
RAW_ARCHIVE = "tm_raw.bin"
DECODED_ARCHIVE = "tm_decoded.jsonl"
EVENTS_ARCHIVE = "events.jsonl"
LIMITS_ARCHIVE = "limits.jsonl"  # every yellow/red limit transition seen by the ground
SUMMARY_FILE = "ground_summary.json"
REJECTED_ARCHIVE = "tm_rejected.bin"  # datagrams refused by the link security, never decoded as telemetry


def read_raw_archive(path: str | Path) -> Iterator[tuple[float, bytes]]:
    """Yield (rx_time_s, packet bytes) from a ``tm_raw.bin`` archive; stops at a torn final record."""
    for rx_time_s, data, _ in raw_records(path):
        yield rx_time_s, data


def raw_records(path: str | Path, offset: int = 0) -> Iterator[tuple[float, bytes, int]]:
    """Yield (rx_time_s, packet bytes, file offset after the record) from ``offset`` on; stops at a torn
    final record, so a reader of a growing archive resumes from the last offset it got."""
    with open(path, "rb") as stream:
        stream.seek(offset)
        while True:
            head = stream.read(RAW_RECORD.size)
            if len(head) < RAW_RECORD.size:
                return
            rx_time_s, length = RAW_RECORD.unpack(head)
            data = stream.read(length)
            if len(data) < length:
                return
            offset += RAW_RECORD.size + length
            yield rx_time_s, data, offset


def decode_archive(archive_dir: str | Path, dictionary: TelemetryDictionary = DICTIONARY
                   ) -> Iterator[tuple[float, DecodedTm | None, bytes]]:
    """Yield (rx_time_s, decoded packet or None if undecodable, raw bytes) from a raw archive."""
    from comms.telemetry import TelemetryDecodeError, decode_tm_packet

    for rx_time_s, raw in read_raw_archive(Path(archive_dir) / RAW_ARCHIVE):
        try:
            yield rx_time_s, decode_tm_packet(dictionary, raw), raw
        except (TelemetryDecodeError, ValueError):
            yield rx_time_s, None, raw


def read_channels(archive_dir: str | Path, packet_name: str = "GNC",
                  dictionary: TelemetryDictionary = DICTIONARY) -> dict[str, Any]:
    """Time series of one packet's channels from the raw archive, as numpy arrays keyed by channel.

    Also holds ``time_s`` (onboard), ``rx_time_s`` (ground) and ``seq``. Enum channels are arrays of
    names. For plots and summaries in the SIL run folder.
    """
    return read_packets(archive_dir, (packet_name,), dictionary)[packet_name]


def read_packets(archive_dir: str | Path, packet_names: Sequence[str],
                 dictionary: TelemetryDictionary = DICTIONARY) -> dict[str, dict[str, Any]]:
    """Several packets' time series (each as `read_channels` gives it) from one pass over the raw archive:
    a day's archive is gigabytes, and every packet in it is decoded whichever are kept."""
    import numpy as np

    columns: dict[str, dict[str, list[Any]]] = {}
    for name in packet_names:
        columns[name] = {key: [] for key in ("time_s", "rx_time_s", "seq")}
        columns[name].update({c.name: [] for c in dictionary.packet(name).channels})
    for rx_time_s, decoded, _ in decode_archive(archive_dir, dictionary):
        kept = columns.get(decoded.packet) if decoded is not None else None
        if kept is None:
            continue
        kept["time_s"].append(decoded.time_s)
        kept["rx_time_s"].append(rx_time_s)
        kept["seq"].append(decoded.seq_count)
        for name, value in decoded.values.items():
            kept[name].append(value)
    return {packet: {name: np.asarray(values) for name, values in cols.items()} for packet, cols in columns.items()}


def read_events(archive_dir: str | Path, dictionary: TelemetryDictionary = DICTIONARY) -> list[dict[str, Any]]:
    """Every event in the raw archive, decoded (dicts as in ``events.jsonl``)."""
    events = []
    for rx_time_s, decoded, _ in decode_archive(archive_dir, dictionary):
        if decoded is not None and decoded.kind == "event":
            record = decoded.to_json_dict()
            record["rx_time_s"] = rx_time_s
            events.append(record)
    return events
