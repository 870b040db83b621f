"""Bit-level writing and reading, packed by compiled loops.

``BitWriter`` collects (value, width) fields, scalars or whole arrays at once, and packs them
MSB-first in one pass; ``BitReader`` reads fields back, one or an array at a time. Reading past
the end raises :class:`~mocodec.errors.CorruptStreamError`, so a truncated stream never turns
into garbage values.
"""

from __future__ import annotations

import numpy as np

from mocodec.errors import CorruptStreamError
from mocodec.kernels import kernel

MAX_WIDTH = 64


@kernel
def _pack(values, widths, total_bits):
    out = np.zeros((total_bits + 7) // 8, dtype=np.uint8)
    pos = 0
    for k in range(values.size):
        v = values[k]
        for b in range(widths[k] - 1, -1, -1):
            if (v >> np.uint64(b)) & np.uint64(1):
                out[pos >> 3] |= np.uint8(1 << (7 - (pos & 7)))
            pos += 1
    return out


@kernel
def _unpack(data, start, widths):
    out = np.empty(widths.size, dtype=np.uint64)
    pos = start
    for k in range(widths.size):
        v = np.uint64(0)
        for _ in range(widths[k]):
            v = (v << np.uint64(1)) | np.uint64((data[pos >> 3] >> (7 - (pos & 7))) & 1)
            pos += 1
        out[k] = v
    return out


class BitWriter:
    """Append fields of 0..64 bits; ``getvalue()`` packs them (zero-padded to a byte)."""

    def __init__(self):
        self._values: list[np.ndarray] = []
        self._widths: list[np.ndarray] = []
        self.bits = 0

    def write(self, value: int, width: int) -> None:
        self.write_array(np.array([value], dtype=np.uint64), width)

    def write_array(self, values, widths) -> None:
        """Write every value with its width (one width for all, or one per value)."""
        values = np.asarray(values)
        if values.size and (values.min() < 0):
            raise ValueError("BitWriter writes unsigned values; map signed ones first (e.g. zigzag)")
        values = values.astype(np.uint64).ravel()
        widths = np.broadcast_to(np.asarray(widths, dtype=np.int64), values.shape).ravel()
        if widths.size and (widths.min() < 0 or widths.max() > MAX_WIDTH):
            raise ValueError(f"field widths must be 0..{MAX_WIDTH}")
        limit = np.where(widths >= 64, np.uint64(0), np.left_shift(np.uint64(1), widths.astype(np.uint64)))
        if np.any((widths < 64) & (values >= limit)):
            raise ValueError("a value does not fit its field width")
        self._values.append(values)
        self._widths.append(widths.astype(np.uint8))
        self.bits += int(widths.sum())

    def getvalue(self) -> bytes:
        if not self._values:
            return b""
        return _pack(np.concatenate(self._values), np.concatenate(self._widths), self.bits).tobytes()


class BitReader:
    """Read MSB-first fields from ``data``; ``pos`` is the bit position."""

    def __init__(self, data: bytes, pos: int = 0):
        self._data = np.frombuffer(data, dtype=np.uint8)
        self.pos = pos

    @property
    def bits_left(self) -> int:
        return self._data.size * 8 - self.pos

    def read(self, width: int) -> int:
        return int(self.read_array(1, width)[0])

    def read_array(self, count: int, widths) -> np.ndarray:
        """``count`` fields, of one width or of one width each; uint64."""
        widths = np.broadcast_to(np.asarray(widths, dtype=np.int64), (count,))
        if widths.size and (widths.min() < 0 or widths.max() > MAX_WIDTH):
            raise ValueError(f"field widths must be 0..{MAX_WIDTH}")
        need = int(widths.sum())
        if need > self.bits_left:
            raise CorruptStreamError(
                f"stream ends after {self._data.size} bytes: {need} more bits needed at bit {self.pos}"
            )
        out = _unpack(self._data, self.pos, np.ascontiguousarray(widths))
        self.pos += need
        return out


def zigzag(values: np.ndarray) -> np.ndarray:
    """Signed to unsigned: 0, -1, 1, -2, 2 ... -> 0, 1, 2, 3, 4 ... (uint64)."""
    v = np.asarray(values, dtype=np.int64)
    return ((v << 1) ^ (v >> 63)).astype(np.uint64)


def unzigzag(values: np.ndarray) -> np.ndarray:
    """Inverse of :func:`zigzag` (int64)."""
    v = np.asarray(values, dtype=np.uint64)
    return ((v >> np.uint64(1)).astype(np.int64)) ^ -((v & np.uint64(1)).astype(np.int64))
