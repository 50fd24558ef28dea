"""The E2E CRC of every bus frame: CRC-8 SAE J1850 over the frame's data ID and payload (AUTOSAR E2E
profile 1 style; see comms.bus.e2e for the protection as a whole)."""
from __future__ import annotations

from typing import Iterable

_POLY = 0x1D


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ _POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


CRC_TABLE = _make_table()


def crc8_sae_j1850(data: bytes | bytearray | Iterable[int], crc: int = 0xFF, final_xor: bool = True) -> int:
    """CRC-8 SAE J1850: poly 0x1D, init 0xFF, xor-out 0xFF (check value of b"123456789" is 0x4B).

    ``crc`` is the running register (so a CRC can be computed over pieces); pass ``final_xor=False`` for
    all but the last piece.
    """
    for byte in data:
        crc = CRC_TABLE[(crc ^ byte) & 0xFF]
    return crc ^ 0xFF if final_xor else crc


def e2e_crc(data_id: int, payload_without_crc: bytes | bytearray) -> int:
    """Profile-1 style CRC over the 16-bit data ID (low byte first) and the payload after the CRC byte."""
    reg = crc8_sae_j1850((data_id & 0xFF, (data_id >> 8) & 0xFF), final_xor=False)
    return crc8_sae_j1850(payload_without_crc, crc=reg)
