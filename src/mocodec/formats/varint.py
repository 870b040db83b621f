"""Unsigned varints (LEB128: 7 bits a byte, low bits first, the top bit set on every byte but
the last), as the compact skeleton and the .moc framing write small integers."""

from __future__ import annotations


def pack(v: int) -> bytes:
    out = bytearray()
    while True:
        out.append((v & 0x7F) | (0x80 if v > 0x7F else 0))
        v >>= 7
        if not v:
            return bytes(out)


def unpack(data: bytes, pos: int, max_bytes: int = 10) -> tuple[int, int]:
    """(value, next position) of the varint at ``pos``; ValueError if the data ends inside
    it or it runs past ``max_bytes``."""
    v = shift = 0
    for k in range(max_bytes):
        if pos + k >= len(data):
            raise ValueError(f"ends inside a number at byte {pos + k}")
        b = data[pos + k]
        v |= (b & 0x7F) << shift
        if not b & 0x80:
            return v, pos + k + 1
        shift += 7
    raise ValueError(f"bad number at byte {pos}")
