"""Length-prefixed parts: the framing codecs use to put several streams in one body."""

from __future__ import annotations

import struct

from mocodec.errors import CorruptStreamError

_U32 = struct.Struct("<I")


def join_parts(parts) -> bytes:
    """Each part as a little-endian u32 length and its bytes."""
    return b"".join(_U32.pack(len(p)) + p for p in parts)


def split_parts(data: bytes, count: int | None, what: str, start: int = 0) -> list[bytes]:
    """The parts of :func:`join_parts` from ``data[start:]``: exactly ``count`` of them, or as
    many as there are when ``count`` is None. Lengths are checked against the data."""
    parts: list[bytes] = []
    pos = start
    while (count is None and pos < len(data)) or (count is not None and len(parts) < count):
        if pos + 4 > len(data):
            raise CorruptStreamError(f"{what}: part {len(parts)} header at byte {pos} is missing")
        (size,) = _U32.unpack_from(data, pos)
        if pos + 4 + size > len(data):
            raise CorruptStreamError(f"{what}: a {size}-byte part at byte {pos} overruns the end ({len(data)} bytes)")
        parts.append(data[pos + 4 : pos + 4 + size])
        pos += 4 + size
    return parts
