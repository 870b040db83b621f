"""Unsigned varints (LEB128: 7 bits a byte, low bits first, the top bit set on every byte but
the last), as the compact skeleton and the .moc framing write small integers."""

from __future__ import annotations

import numpy as np


def pack(v: int) -> bytes:
    out = bytearray()
    while True:
        out.append((v & 0x7F) | (0x80 if v > 0x7F else 0))
        v >>= 7
        if not v:
            return bytes(out)


def unpack(data: bytes | memoryview, pos: int, max_bytes: int = 10) -> tuple[int, int]:
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


#: The longest varint the array forms read and write (values below 2^28).
ARRAY_MAX_BYTES = 4


def pack_array(values: np.ndarray) -> bytes:
    """The varints of ``values`` (integers from 0 to 2^28 - 1) back to back, written in bulk."""
    v = np.asarray(values, dtype=np.int64)
    if v.size and (v.min() < 0 or v.max() >= 1 << (7 * ARRAY_MAX_BYTES)):
        raise ValueError(f"a value outside 0 to 2^{7 * ARRAY_MAX_BYTES} - 1")
    size = np.ones(v.shape, dtype=np.int64)
    for k in range(1, ARRAY_MAX_BYTES):
        size += v >= 1 << (7 * k)
    starts = np.cumsum(size) - size
    out = np.empty(int(size.sum()), dtype=np.uint8)
    for k in range(ARRAY_MAX_BYTES):
        here = size > k
        more = (size[here] > k + 1).astype(np.int64) << 7
        out[starts[here] + k] = ((v[here] >> (7 * k)) & 0x7F) | more
    return out.tobytes()


def unpack_array(data: bytes | memoryview, pos: int, count: int) -> tuple[np.ndarray, int]:
    """(values, next position) of ``count`` varints from ``pos``, read in bulk; ValueError if
    the data ends inside them or one is longer than ARRAY_MAX_BYTES bytes."""
    window = np.frombuffer(data, dtype=np.uint8, count=min(len(data) - pos, ARRAY_MAX_BYTES * count), offset=pos)
    ends = np.flatnonzero(window < 0x80)[:count]  # each varint's last byte
    if ends.size < count:
        if pos + window.size == len(data):
            raise ValueError(f"ends inside a number of the {count} from byte {pos}")
        raise ValueError(f"a number longer than {ARRAY_MAX_BYTES} bytes among the {count} from byte {pos}")
    starts = np.concatenate(([0], ends[:-1] + 1))
    size = ends - starts + 1
    if size.size and size.max() > ARRAY_MAX_BYTES:
        raise ValueError(f"a number longer than {ARRAY_MAX_BYTES} bytes at byte {pos + int(starts[size.argmax()])}")
    values = np.zeros(count, dtype=np.int64)
    for k in range(ARRAY_MAX_BYTES):
        here = size > k
        values[here] |= (window[starts[here] + k].astype(np.int64) & 0x7F) << (7 * k)
    return values, pos + (int(ends[-1]) + 1 if count else 0)
