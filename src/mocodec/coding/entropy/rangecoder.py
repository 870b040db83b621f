"""Adaptive arithmetic (range) coding with constriction's range coder.

``encode_symbols`` codes symbols 0..A-1 under a categorical model that adapts to the counts
seen so far. The model is updated between blocks (16 symbols at first, doubling to 2048) so
the coder runs vectorised inside each block; counts start at 1 (every symbol codable) and are
halved when they pass 2^20, so the model follows slow drifts in the statistics. Encoder and
decoder repeat exactly the same updates, so nothing but the coded words is sent.

``encode_ints`` is the general-purpose integer coder built on it: values are zigzag-mapped,
split into a magnitude class (range coded) and the low bits below it (sent raw). It is
self-describing.

``constriction`` decodes any words without complaint, so integrity comes from the container's
CRC; the decoders here check every length they are given against the data.
"""

from __future__ import annotations

import struct

import constriction
import numpy as np

from mocodec import limits
from mocodec.coding.entropy.bitio import BitReader, BitWriter, unzigzag, zigzag
from mocodec.errors import CodecError, CorruptStreamError

_MODEL = constriction.stream.model
_QUEUE = constriction.stream.queue
FIRST_BLOCK = 16
LAST_BLOCK = 2048
COUNT_LIMIT = 1 << 20
MAX_ALPHABET = 1 << 16
MAX_VALUES = limits.MAX_DECODED_VALUES  # values one integer stream may declare


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


_HEADER = struct.Struct("<II")  # count, range-coded words
DIRECT = 16  # zigzag values below this are symbols of their own
ALPHABET = DIRECT + 2 * (64 - 4)  # then two symbols per octave up to 2^64


def int_symbols(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(symbol, raw bits, raw width) of zigzagged values: small values are their own symbol;
    a larger value with bit length b is symbol 16 + 2 (b - 5) + (its second-highest bit),
    followed by its b - 2 lower bits raw. Like JPEG's magnitude categories, this keeps the
    alphabet small and costs within a fraction of a bit of the entropy for Laplace data."""
    u = np.asarray(u, dtype=np.uint64)
    big = u >= DIRECT
    length = np.zeros(u.shape, dtype=np.int64)
    length[big] = np.floor(np.log2(u[big].astype(np.float64))).astype(np.int64) + 1
    # log2 of a float can be off by one next to a power of two: fix exactly
    length[big] += (u[big] >> length[big].astype(np.uint64)) > 0
    length[big] -= (u[big] >> (length[big] - 1).astype(np.uint64)) == 0
    width = np.maximum(length - 2, 0)
    second = np.where(big, (u >> np.maximum(length - 2, 0).astype(np.uint64)) & np.uint64(1), 0).astype(np.int64)
    symbols = np.where(big, DIRECT + 2 * (length - 5) + second, u.astype(np.int64))
    raw = np.where(big, u & ((np.uint64(1) << width.astype(np.uint64)) - np.uint64(1)), 0).astype(np.uint64)
    return symbols.astype(np.int32), raw, np.where(big, width, 0)


def _from_symbols(symbols: np.ndarray, reader: BitReader) -> np.ndarray:
    symbols = symbols.astype(np.int64)
    big = symbols >= DIRECT
    length = np.where(big, (symbols - DIRECT) // 2 + 5, 0)
    second = np.where(big, (symbols - DIRECT) % 2, 0).astype(np.uint64)
    width = np.where(big, length - 2, 0)
    raw = reader.read_array(symbols.size, width)
    top = (np.uint64(2) | second) << width.astype(np.uint64)
    return np.where(big, top | raw, symbols.astype(np.uint64))


def encode_ints(values: np.ndarray) -> bytes:
    """Any int64 values -> a self-describing byte string: the magnitude classes range coded
    adaptively, the bits below them raw."""
    u = zigzag(np.asarray(values, dtype=np.int64).ravel())
    if u.size > MAX_VALUES:
        raise CodecError(f"integer stream: {u.size} values, more than a decoder accepts ({MAX_VALUES})")
    symbols, raw, width = int_symbols(u)
    words = encode_symbols(symbols, ALPHABET)
    w = BitWriter()
    w.write_array(raw, width)
    return _HEADER.pack(u.size, words.size) + words.tobytes() + w.getvalue()


def decode_ints(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_ints`."""
    if len(data) < _HEADER.size:
        raise CorruptStreamError(f"integer stream: {len(data)} bytes, shorter than its {_HEADER.size}-byte header")
    count, nwords = _HEADER.unpack_from(data)
    end = _HEADER.size + 4 * nwords
    if end > len(data):
        raise CorruptStreamError(f"integer stream: {nwords} coded words do not fit {len(data)} bytes")
    if count > MAX_VALUES:
        raise CorruptStreamError(f"integer stream: {count} values, more than the limit {MAX_VALUES}")
    if count == 0:
        return np.zeros(0, dtype=np.int64)
    symbols = decode_symbols(np.frombuffer(data, dtype=np.uint32, count=nwords, offset=_HEADER.size), count, ALPHABET)
    return unzigzag(_from_symbols(symbols, BitReader(data[end:])))
