"""CRC-16 as used by DDCMP: polynomial x^16 + x^15 + x^2 + 1, reflected (0xA001), init 0.

This is the catalogued CRC-16/ARC (check value of ``b"123456789"`` is ``0xBB3D``):
no final XOR, bytes processed least-significant bit first. The CRC is transmitted
low byte first. A property of this CRC that the framing relies on: running it over a
block *followed by its own CRC* (low byte first) gives 0.
"""

from __future__ import annotations

POLY_REFLECTED = 0xA001
CRC_INIT = 0x0000


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ POLY_REFLECTED if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_TABLE = _make_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = CRC_INIT) -> int:
    """CRC-16/ARC of ``data``; pass a previous result as ``crc`` to continue a run.

    Returns an int in [0, 0xFFFF].
    """
    table = _TABLE
    for byte in bytes(data):
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc


def crc16_bitwise(data: bytes | bytearray | memoryview, crc: int = CRC_INIT) -> int:
    """Bit-at-a-time reference implementation (for tests; same result as ``crc16``)."""
    for byte in bytes(data):
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ POLY_REFLECTED if crc & 1 else crc >> 1
    return crc


def crc16_bytes(data: bytes | bytearray | memoryview) -> bytes:
    """The CRC of ``data`` as it goes on the wire: 2 bytes, low byte first."""
    return crc16(data).to_bytes(2, "little")
