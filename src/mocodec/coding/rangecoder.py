"""Adaptive arithmetic (range) coding with constriction's range coder.

``encode_symbols`` codes symbols 0..A-1 under a categorical model that adapts to the counts
seen so far. The model is updated between blocks (16 symbols at first, doubling to 2048) so
the coder runs vectorised inside each block; counts start at 1 (every symbol codable) and are
halved when they pass 2^20, so the model follows slow drifts in the statistics. Encoder and
decoder repeat exactly the same updates, so nothing but the coded words is sent.

``encode_ints`` is the general-purpose integer coder built on it: values are zigzag-mapped,
the common ones (below an escape threshold chosen from the data) are range coded, the rare
large ones are sent raw after an escape symbol. It is self-describing.

``constriction`` decodes any words without complaint, so integrity comes from the container's
CRC; the decoders here check every length they are given against the data.
"""

from __future__ import annotations

import struct

import constriction
import numpy as np

from mocodec.coding.bitio import BitReader, BitWriter, unzigzag, zigzag
from mocodec.errors import CorruptStreamError

_MODEL = constriction.stream.model
_QUEUE = constriction.stream.queue
FIRST_BLOCK = 16
LAST_BLOCK = 2048
COUNT_LIMIT = 1 << 20
MAX_ALPHABET = 1 << 16
MAX_THRESHOLD = 4096
MAX_VALUES = 1 << 28


def _blocks(n: int):
    start, size = 0, FIRST_BLOCK
    while start < n:
        yield start, min(n, start + size)
        start += size
        size = min(2 * size, LAST_BLOCK)


def _update(counts: np.ndarray, block: np.ndarray) -> None:
    counts += np.bincount(block, minlength=counts.size)
    if counts.sum() > COUNT_LIMIT:
        counts[:] = (counts + 1) // 2


def encode_symbols(symbols: np.ndarray, alphabet_size: int) -> np.ndarray:
    """Range-code symbols in 0..alphabet_size-1; returns the coded 32-bit words."""
    symbols = np.ascontiguousarray(symbols, dtype=np.int32)
    if not 1 <= alphabet_size <= MAX_ALPHABET:
        raise ValueError(f"alphabet size must be 1..{MAX_ALPHABET}, got {alphabet_size}")
    if symbols.size and (symbols.min() < 0 or symbols.max() >= alphabet_size):
        raise ValueError(f"symbols must be in 0..{alphabet_size - 1}")
    counts = np.ones(alphabet_size, dtype=np.int64)
    encoder = _QUEUE.RangeEncoder()
    for a, b in _blocks(symbols.size):
        encoder.encode(symbols[a:b], _MODEL.Categorical(counts.astype(np.float64), perfect=False))
        _update(counts, symbols[a:b])
    return encoder.get_compressed()


def decode_symbols(words: np.ndarray, count: int, alphabet_size: int) -> np.ndarray:
    """Inverse of :func:`encode_symbols` for ``count`` symbols."""
    if not 1 <= alphabet_size <= MAX_ALPHABET:
        raise CorruptStreamError(f"range coder: alphabet size {alphabet_size} out of range")
    counts = np.ones(alphabet_size, dtype=np.int64)
    decoder = _QUEUE.RangeDecoder(np.ascontiguousarray(words, dtype=np.uint32))
    out = np.empty(count, dtype=np.int32)
    for a, b in _blocks(count):
        out[a:b] = decoder.decode(_MODEL.Categorical(counts.astype(np.float64), perfect=False), b - a)
        _update(counts, out[a:b])
    return out


_HEADER = struct.Struct("<IHII")   # count, escape threshold K, range-coded words, escapes


def escape_threshold(u: np.ndarray) -> int:
    """The power of two K (1..4096) that minimises the estimated size: the entropy of the
    values below K plus the escape symbol, the raw bits of the escaped values, and about 8
    bits for the adaptive model to learn each symbol of the alphabet."""
    n = u.size
    hist = np.bincount(np.minimum(u, MAX_THRESHOLD).astype(np.int64), minlength=MAX_THRESHOLD + 1)
    top = int(u.max()).bit_length()
    best, best_bits = 1, np.inf
    k = 1
    while k <= MAX_THRESHOLD:
        counts = np.append(hist[:k], n - hist[:k].sum()).astype(np.float64)
        c = counts[counts > 0]
        bits = -np.sum(c * np.log2(c / n)) + counts[-1] * top + 8 * k
        if bits < best_bits:
            best, best_bits = k, bits
        k *= 2
    return best


def encode_ints(values: np.ndarray) -> bytes:
    """Any int64 values -> a self-describing byte string."""
    u = zigzag(np.asarray(values, dtype=np.int64).ravel())
    if u.size == 0:
        return _HEADER.pack(0, 1, 0, 0)
    k = escape_threshold(u)
    escaped = u >= k
    symbols = np.where(escaped, k, u).astype(np.int32)
    words = encode_symbols(symbols, k + 1)
    extra = u[escaped] - np.uint64(k)
    w = BitWriter()
    width = int(extra.max()).bit_length() if extra.size else 0
    w.write(width, 7)
    w.write_array(extra, width)
    return _HEADER.pack(u.size, k, words.size, int(escaped.sum())) + words.tobytes() + w.getvalue()


def decode_ints(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_ints`."""
    if len(data) < _HEADER.size:
        raise CorruptStreamError(f"integer stream: {len(data)} bytes, shorter than its {_HEADER.size}-byte header")
    count, k, nwords, nesc = _HEADER.unpack_from(data)
    if count == 0:
        return np.zeros(0, dtype=np.int64)
    end = _HEADER.size + 4 * nwords
    if k < 1 or end > len(data) or nesc > count:
        raise CorruptStreamError(f"integer stream: header (count {count}, threshold {k}, {nwords} words) "
                                 f"does not fit {len(data)} bytes")
    if count > MAX_VALUES:
        raise CorruptStreamError(f"integer stream: {count} values, more than the limit {MAX_VALUES}")
    symbols = decode_symbols(np.frombuffer(data, dtype=np.uint32, count=nwords, offset=_HEADER.size), count, k + 1)
    u = symbols.astype(np.uint64)
    escaped = symbols == k
    if int(escaped.sum()) != nesc:
        raise CorruptStreamError(f"integer stream: {int(escaped.sum())} escapes decoded, header says {nesc}")
    r = BitReader(data[end:])
    width = r.read(7)
    if width > 64:
        raise CorruptStreamError(f"integer stream: escape width {width} > 64")
    u[escaped] = r.read_array(nesc, width) + np.uint64(k)
    return unzigzag(u)
