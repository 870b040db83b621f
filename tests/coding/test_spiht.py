"""1-D SPIHT against a slow reference written straight from Said & Pearlman's definition."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st

from mocodec.coding.entropy import spiht


class _Budget(Exception):
    pass


def reference_encode(c: np.ndarray, approx: int, budget: int) -> list[int]:
    """SPIHT as the paper states it, with Python sets and lists; slow and plain."""
    n = len(c)

    def children(j):
        if j < approx:
            return [approx + j] if approx + j < n else []
        return [2 * j, 2 * j + 1] if 2 * j < n else []

    def descendants(j):
        out = []
        for k in children(j):
            out += [k] + descendants(k)
        return out

    def grand(j):
        return [d for k in children(j) for d in descendants(k)]

    bits = []

    def emit(b):
        bits.append(int(b))
        if len(bits) == budget:
            raise _Budget

    m = int(np.abs(c).max()) if n else 0
    if m == 0 or budget <= 0:
        return []
    n0 = m.bit_length() - 1
    lip = list(range(min(approx, n)))
    lis = [(j, "A") for j in range(min(approx, n)) if children(j)]
    lsp: list[int] = []
    try:
        for plane in range(n0, -1, -1):
            t = 1 << plane
            old_lsp = list(lsp)
            for j in list(lip):
                emit(abs(c[j]) >= t)
                if abs(c[j]) >= t:
                    emit(c[j] < 0)
                    lip.remove(j)
                    lsp.append(j)
            a = 0
            while a < len(lis):
                j, kind = lis[a]
                if kind == "A":
                    s = any(abs(c[d]) >= t for d in descendants(j))
                    emit(s)
                    if s:
                        for k in children(j):
                            emit(abs(c[k]) >= t)
                            if abs(c[k]) >= t:
                                emit(c[k] < 0)
                                lsp.append(k)
                            else:
                                lip.append(k)
                        if grand(j):
                            lis.append((j, "B"))
                        lis.pop(a)
                        continue
                else:
                    s = any(abs(c[d]) >= t for d in grand(j))
                    emit(s)
                    if s:
                        lis.extend((k, "A") for k in children(j))
                        lis.pop(a)
                        continue
                a += 1
            for j in old_lsp:
                emit((abs(c[j]) >> plane) & 1)
    except _Budget:
        pass
    return bits


signals = st.tuples(
    st.sampled_from([(8, 1), (16, 2), (32, 4), (64, 8), (16, 16), (32, 2)]),
    st.integers(0, 2**32 - 1),
    st.integers(1, 3000),
)


@given(signals)
def test_encoder_matches_the_reference(case):
    (n, approx), seed, budget = case
    rng = np.random.default_rng(seed)
    c = np.round(rng.laplace(0, 40, n) * rng.random(n)).astype(np.int64)
    ours, n0 = spiht.encode(c, approx, budget)
    assert ours.tolist() == reference_encode(c, approx, budget)
    assert n0 == (int(np.abs(c).max()).bit_length() - 1 if np.abs(c).max() else -1)


@given(signals)
def test_decoding_a_whole_stream_is_exact_and_prefixes_decode(case):
    (n, approx), seed, _ = case
    rng = np.random.default_rng(seed)
    c = np.round(rng.laplace(0, 40, n)).astype(np.int64)
    bits, n0 = spiht.encode(c, approx, 1 << 20)
    full, used, plane = spiht.decode(bits, 0, len(bits), n, approx, n0)
    assert used == len(bits) and np.array_equal(full, c) and plane == -1
    errors = []
    for cut in np.linspace(0, len(bits), 6).astype(int):
        prefix, used, plane = spiht.decode(bits, 0, cut, n, approx, n0)
        assert used <= cut
        assert np.abs(prefix - c).max() <= 2.0 ** (plane + 1)  # the promised uncertainty
        errors.append(np.square(prefix - c).sum())
        again, _, _ = spiht.decode(spiht.encode(c, approx, cut)[0], 0, cut, n, approx, n0)
        assert np.array_equal(prefix, again)  # a budget-limited encoding is the prefix
    assert errors[-1] == 0 and errors[0] >= errors[-1]
    assert all(a >= b for a, b in zip(errors, errors[1:]))


def test_all_zero_and_empty_budget():
    bits, n0 = spiht.encode(np.zeros(16, dtype=np.int64), 2, 100)
    assert n0 == -1 and bits.size == 0
    out, used, _ = spiht.decode(bits, 0, 100, 16, 2, n0)
    assert used == 0 and not out.any()
    bits, n0 = spiht.encode(np.arange(16, dtype=np.int64), 2, 0)
    assert bits.size == 0 and n0 == 3


@pytest.mark.parametrize("approx", [1, 4])
def test_streams_concatenate(approx):
    rng = np.random.default_rng(3)
    a, b = (np.round(rng.normal(0, 50, 32)).astype(np.int64) for _ in range(2))
    bits_a, n0a = spiht.encode(a, approx, 90)
    bits_b, n0b = spiht.encode(b, approx, 10**6)
    joined = np.concatenate([bits_a, bits_b])
    da, used, _ = spiht.decode(joined, 0, 90, 32, approx, n0a)
    db, _, _ = spiht.decode(joined, used, 10**6, 32, approx, n0b)
    assert used == len(bits_a) and np.array_equal(db, b)
