"""Huffman coding (000 §7.4): static, with the code table in the stream, and adaptive.

Static: code lengths from the symbol counts (the two least probable nodes merged until one
remains), canonical codes, and the table written as (symbol, length) pairs of the used
symbols, so a stream decodes on its own. Adaptive (the thesis's variant): both ends start
from equal counts (equal-length codes) and, after every ``rebuild_every`` symbols, rebuild the
code from the counts seen so far; nothing but the codes is sent.

Decoding is canonical and table driven, in compiled loops; every read is bounds-checked, so
truncated or damaged input raises :class:`~mocodec.errors.CorruptStreamError`.
"""

from __future__ import annotations

import heapq

import numpy as np

from mocodec.coding.entropy.bitio import BitReader, BitWriter
from mocodec.errors import CorruptStreamError
from mocodec.kernels import kernel

MAX_CODE_LENGTH = 48
MAX_ALPHABET = 1 << 20


def code_lengths(counts: np.ndarray) -> np.ndarray:
    """Huffman code length of every symbol (0 for unused ones; 1 if only one is used)."""
    counts = np.asarray(counts, dtype=np.int64)
    used = np.flatnonzero(counts > 0)
    lengths = np.zeros(counts.size, dtype=np.int64)
    if used.size == 1:
        lengths[used] = 1
    if used.size <= 1:
        return lengths
    heap: list[tuple[int, int, tuple[int, ...]]] = [(int(counts[s]), int(s), (int(s),)) for s in used]
    heapq.heapify(heap)
    while len(heap) > 1:
        c1, k1, s1 = heapq.heappop(heap)
        c2, k2, s2 = heapq.heappop(heap)
        for s in s1 + s2:
            lengths[s] += 1
        heapq.heappush(heap, (c1 + c2, min(k1, k2), s1 + s2))
    if lengths.max() > MAX_CODE_LENGTH:  # only for pathological (Fibonacci-like) counts
        return code_lengths(np.where(counts > 0, (counts + 1) // 2, 0))
    return lengths


@kernel
def _canonical(lengths):
    """Canonical codes for the lengths, and the decoding tables: per length the first code,
    the index of its first symbol in ``order`` and how many symbols have it."""
    max_len = 0
    for v in lengths:
        max_len = max(max_len, v)
    count = np.zeros(max_len + 2, dtype=np.int64)
    for v in lengths:
        if v > 0:
            count[v] += 1
    first = np.zeros(max_len + 2, dtype=np.int64)
    start = np.zeros(max_len + 2, dtype=np.int64)
    code = 0
    index = 0
    for n in range(1, max_len + 1):
        code = (code + count[n - 1]) << 1 if n > 1 else 0
        first[n] = code
        start[n] = index
        index += count[n]
    order = np.empty(index, dtype=np.int64)
    codes = np.zeros(lengths.size, dtype=np.int64)
    nxt = first.copy()
    fill = start.copy()
    for n in range(1, max_len + 1):
        for s in range(lengths.size):
            if lengths[s] == n:
                codes[s] = nxt[n]
                nxt[n] += 1
                order[fill[n]] = s
                fill[n] += 1
    return codes, first, start, count, order


@kernel
def _decode_one(data, pos, end, first, start, count, order):
    code = 0
    for n in range(1, first.size - 1):
        if pos >= end:
            return -1, pos
        code = (code << 1) | ((data[pos >> 3] >> (7 - (pos & 7))) & 1)
        pos += 1
        if code - first[n] < count[n] and code >= first[n]:
            return order[start[n] + code - first[n]], pos
    return -2, pos


@kernel
def _decode_static(data, pos, n, first, start, count, order):
    out = np.empty(n, dtype=np.int64)
    end = data.size * 8
    for k in range(n):
        s, pos = _decode_one(data, pos, end, first, start, count, order)
        if s < 0:
            return out[:k], pos, s
        out[k] = s
    return out, pos, 0


def _width(n: int) -> int:
    return max(1, int(n - 1).bit_length())


def encode_static(symbols: np.ndarray, alphabet_size: int) -> bytes:
    """Symbols 0..alphabet_size-1 -> table + count + codes."""
    symbols = np.asarray(symbols, dtype=np.int64)
    _check(symbols, alphabet_size)
    counts = np.bincount(symbols, minlength=alphabet_size)
    lengths = code_lengths(counts)
    codes = _canonical(lengths)[0]
    used = np.flatnonzero(lengths)
    w = BitWriter()
    w.write(alphabet_size, 32)
    w.write(used.size, 32)
    w.write_array(used, _width(alphabet_size))
    w.write_array(lengths[used], 6)
    w.write(symbols.size, 40)
    w.write_array(codes[symbols], lengths[symbols])
    return w.getvalue()


def decode_static(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_static`."""
    r = BitReader(data)
    alphabet = r.read(32)
    if not 0 < alphabet <= MAX_ALPHABET:
        raise CorruptStreamError(f"Huffman table: alphabet size {alphabet} out of range")
    used_n = r.read(32)
    if used_n > alphabet:
        raise CorruptStreamError(f"Huffman table: {used_n} used symbols in an alphabet of {alphabet}")
    used = r.read_array(used_n, _width(alphabet)).astype(np.int64)
    lens = r.read_array(used_n, 6).astype(np.int64)
    if used.size and (used.max() >= alphabet or np.unique(used).size != used.size or lens.min() < 1):
        raise CorruptStreamError("Huffman table: invalid symbols or lengths")
    if used.size and np.sum(2.0**-lens) > 1.0 + 1e-12:
        raise CorruptStreamError("Huffman table: code lengths violate the Kraft inequality")
    lengths = np.zeros(alphabet, dtype=np.int64)
    lengths[used] = lens
    n = r.read(40)
    if n and not used.size:
        raise CorruptStreamError("Huffman stream: symbols but no code table")
    if n > r.bits_left:
        raise CorruptStreamError(f"Huffman stream: {n} symbols cannot fit in {r.bits_left} bits")
    _, first, start, count, order = _canonical(lengths)
    out, _, status = _decode_static(np.frombuffer(data, dtype=np.uint8), r.pos, n, first, start, count, order)
    if status:
        raise CorruptStreamError(
            f"Huffman stream: {'truncated' if status == -1 else 'invalid code'} at symbol {out.size} of {n}"
        )
    return out


def _check(symbols: np.ndarray, alphabet_size: int) -> None:
    if not 0 < alphabet_size <= MAX_ALPHABET:
        raise ValueError(f"alphabet size must be 1..{MAX_ALPHABET}, got {alphabet_size}")
    if symbols.size and (symbols.min() < 0 or symbols.max() >= alphabet_size):
        raise ValueError(f"symbols must be in 0..{alphabet_size - 1}")


@kernel
def _adaptive_lengths(counts):
    """Huffman code lengths of all symbols (counts all positive) by the two-queue method."""
    n = counts.size
    if n == 1:
        return np.ones(1, dtype=np.int64)
    order = np.argsort(counts, kind="mergesort")
    weight = np.empty(2 * n - 1, dtype=np.int64)
    parent = np.empty(2 * n - 1, dtype=np.int64)
    for k in range(n):
        weight[k] = counts[order[k]]
    leaf, node, nxt = 0, n, n
    for _ in range(n - 1):
        pick = np.empty(2, dtype=np.int64)
        for t in range(2):
            if leaf < n and (node >= nxt or weight[leaf] <= weight[node]):
                pick[t] = leaf
                leaf += 1
            else:
                pick[t] = node
                node += 1
        weight[nxt] = weight[pick[0]] + weight[pick[1]]
        parent[pick[0]] = nxt
        parent[pick[1]] = nxt
        nxt += 1
    depth = np.zeros(2 * n - 1, dtype=np.int64)
    for k in range(2 * n - 3, -1, -1):
        depth[k] = depth[parent[k]] + 1
    lengths = np.empty(n, dtype=np.int64)
    for k in range(n):
        lengths[order[k]] = depth[k]
    return lengths


@kernel
def _adaptive_encode(symbols, alphabet, rebuild_every):
    counts = np.ones(alphabet, dtype=np.int64)
    lengths = _adaptive_lengths(counts)
    codes, _, _, _, _ = _canonical(lengths)
    out_codes = np.empty(symbols.size, dtype=np.uint64)
    out_lens = np.empty(symbols.size, dtype=np.uint8)
    for k in range(symbols.size):
        if k and k % rebuild_every == 0:
            lengths = _adaptive_lengths(counts)
            codes, _, _, _, _ = _canonical(lengths)
        s = symbols[k]
        out_codes[k] = codes[s]
        out_lens[k] = lengths[s]
        counts[s] += 1
    return out_codes, out_lens


@kernel
def _adaptive_decode(data, pos, n, alphabet, rebuild_every):
    counts = np.ones(alphabet, dtype=np.int64)
    _, first, start, count, order = _canonical(_adaptive_lengths(counts))
    out = np.empty(n, dtype=np.int64)
    end = data.size * 8
    for k in range(n):
        if k and k % rebuild_every == 0:
            _, first, start, count, order = _canonical(_adaptive_lengths(counts))
        s, pos = _decode_one(data, pos, end, first, start, count, order)
        if s < 0:
            return out[:k], s
        out[k] = s
        counts[s] += 1
    return out, 0


def encode_adaptive(symbols: np.ndarray, alphabet_size: int, rebuild_every: int = 1) -> bytes:
    """Adaptive Huffman: count + codes only; the code is rebuilt every ``rebuild_every`` symbols."""
    symbols = np.ascontiguousarray(symbols, dtype=np.int64)
    _check(symbols, alphabet_size)
    if rebuild_every < 1:
        raise ValueError("rebuild_every must be at least 1")
    codes, lens = _adaptive_encode(symbols, alphabet_size, rebuild_every)
    w = BitWriter()
    w.write(symbols.size, 40)
    w.write_array(codes, lens)
    return w.getvalue()


def decode_adaptive(data: bytes, alphabet_size: int, rebuild_every: int = 1) -> np.ndarray:
    r = BitReader(data)
    n = r.read(40)
    if n > r.bits_left:
        raise CorruptStreamError(f"adaptive Huffman stream: {n} symbols cannot fit in {r.bits_left} bits")
    out, status = _adaptive_decode(np.frombuffer(data, dtype=np.uint8), r.pos, n, alphabet_size, rebuild_every)
    if status:
        raise CorruptStreamError(
            f"adaptive Huffman stream: {'truncated' if status == -1 else 'invalid code'} at symbol {out.size} of {n}"
        )
    return out
