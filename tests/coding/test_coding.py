"""Coding building blocks: round trips on arbitrary input (hypothesis), known answers, and
clean errors on damaged streams."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra import numpy as hnp

from mocodec.coding.entropy import huffman, rangecoder, rle
from mocodec.coding.entropy.bitio import BitReader, BitWriter, unzigzag, zigzag
from mocodec.coding.quantisation.quantisers import AdaptiveQuantiser, MuLawQuantiser, UniformQuantiser, multipliers
from mocodec.errors import CorruptStreamError

small_ints = hnp.arrays(np.int64, st.integers(0, 300), elements=st.integers(-50, 50))
any_ints = hnp.arrays(np.int64, st.integers(0, 200), elements=st.integers(-(2**62), 2**62))


# ----- bit I/O ----------------------------------------------------------------------------
@given(st.lists(st.tuples(st.integers(0, 64), st.integers(0, 2**64 - 1)), max_size=60))
def test_bit_fields_round_trip(fields):
    fields = [(w, v & ((1 << w) - 1) if w < 64 else v) for w, v in fields]
    w = BitWriter()
    for width, value in fields:
        w.write(value, width)
    data = w.getvalue()
    assert len(data) == (sum(f[0] for f in fields) + 7) // 8
    r = BitReader(data)
    assert [r.read(width) for width, _ in fields] == [v for _, v in fields]


def test_bits_are_msb_first_and_reads_past_the_end_fail():
    w = BitWriter()
    w.write(0b101, 3)
    w.write_array([1, 1], 1)
    assert w.getvalue() == bytes([0b10111000])
    r = BitReader(b"\xff")
    r.read(6)
    with pytest.raises(CorruptStreamError, match="more bits"):
        r.read(3)
    with pytest.raises(ValueError):
        BitWriter().write(8, 3)
    with pytest.raises(ValueError):
        BitWriter().write_array([-1], 4)


@given(any_ints)
def test_zigzag_round_trip(x):
    assert (unzigzag(zigzag(x)) == x).all()
    assert zigzag(np.array([0, -1, 1, -2, 2])).tolist() == [0, 1, 2, 3, 4]


# ----- quantisers (7-3) to (7-7) -----------------------------------------------------------
def test_uniform_quantiser_levels_and_midpoints():
    q = UniformQuantiser(-10.0, 10.0, 8)
    assert q.decision_levels().tolist() == [-10, -7.5, -5, -2.5, 0, 2.5, 5, 7.5, 10]
    assert q.reconstruct(q.quantise([-10.0, -9.9, 0.1, 9.99, 99.0])).tolist() == [-8.75, -8.75, 1.25, 8.75, 8.75]


@given(hnp.arrays(np.float64, st.integers(1, 100), elements=st.floats(-10, 10)), st.sampled_from([4, 16, 64, 256]))
def test_uniform_error_is_at_most_half_a_step(x, levels):
    q = UniformQuantiser(-10.0, 10.0, levels)
    assert np.abs(q.reconstruct(q.quantise(x)) - x).max() <= q.step / 2 + 1e-12


def test_mu_law_levels_follow_7_5():
    q = MuLawQuantiser(mu=255.0, limit=10.0, levels=8)
    d = q.decision_levels()
    assert d[0] == 0 and d[-1] == pytest.approx(10.0)
    assert d[1] == pytest.approx(10 * (256**0.25 - 1) / 255)  # i = 1 of N/2 = 4
    assert np.all(np.diff(d, 2) > 0)  # levels widen outwards
    codes = q.quantise([-12.0, -0.01, 0.01, 12.0])
    assert codes.tolist() == [0, 3, 4, 7]
    r = q.reconstruct(codes)
    assert r[1] == -r[2] and r[0] == -r[3]


@given(hnp.arrays(np.float64, st.integers(1, 200), elements=st.floats(-1e3, 1e3)), st.sampled_from([4, 8, 16, 32]))
def test_adaptive_quantiser_decoder_follows_the_encoder(x, levels):
    q = AdaptiveQuantiser(levels, step=1.0, step_min=1e-3, step_max=1e3)
    codes, recon = q.quantise(x)
    assert codes.min() >= -levels // 2 and codes.max() < levels // 2
    assert np.array_equal(q.reconstruct(codes), recon)


def test_adaptive_step_grows_on_large_codes_and_shrinks_on_small():
    q = AdaptiveQuantiser(8, step=1.0, step_min=1e-3, step_max=1e3)
    _, big = q.quantise(np.full(10, 500.0))
    assert big[-1] > 100  # tracked the jump
    codes, small = q.quantise(np.full(40, 0.001))
    assert np.all(np.abs(codes) <= 1) and abs(small[-1]) < 0.01
    assert multipliers(8).tolist() == [0.9, 0.9, 1.25, 1.75]  # Jayant's 3-bit table


# ----- entropy coders ----------------------------------------------------------------------
@given(small_ints)
def test_static_huffman_round_trip(x):
    sym = x + 50
    assert np.array_equal(huffman.decode_static(huffman.encode_static(sym, 101)), sym)


@settings(max_examples=40)
@given(small_ints, st.sampled_from([1, 3, 64]))
def test_adaptive_huffman_round_trip(x, every):
    sym = x + 50
    assert np.array_equal(huffman.decode_adaptive(huffman.encode_adaptive(sym, 101, every), 101, every), sym)


def test_huffman_known_code_lengths_and_efficiency():
    assert huffman.code_lengths(np.array([5, 0, 1, 1, 2])).tolist() == [1, 0, 3, 3, 2]
    x = np.clip(np.round(np.random.default_rng(0).laplace(0, 3, 50000)), -32, 31).astype(int) + 32
    p = np.bincount(x) / x.size
    entropy = -np.sum(p[p > 0] * np.log2(p[p > 0]))
    for data in (huffman.encode_static(x, 64), huffman.encode_adaptive(x, 64)):
        assert entropy <= len(data) * 8 / x.size < entropy + 0.1


@given(any_ints)
def test_range_coded_ints_round_trip(x):
    assert np.array_equal(rangecoder.decode_ints(rangecoder.encode_ints(x)), x)


def test_range_coder_is_near_the_entropy():
    x = np.round(np.random.default_rng(1).laplace(0, 3, 200000)).astype(int)
    u = zigzag(x).astype(int)
    p = np.bincount(u) / u.size
    entropy = -np.sum(p[p > 0] * np.log2(p[p > 0]))
    bits = len(rangecoder.encode_ints(x)) * 8 / x.size
    assert entropy <= bits < entropy * 1.02


@given(st.binary(max_size=200))
def test_damaged_streams_raise_only_our_error(data):
    for decode in (huffman.decode_static, rangecoder.decode_ints, lambda d: huffman.decode_adaptive(d, 16)):
        try:
            decode(data)
        except CorruptStreamError:
            pass


def test_truncated_streams_are_caught():
    x = np.arange(-100, 100)
    for data, decode in (
        (huffman.encode_static(x + 100, 200), huffman.decode_static),
        (rangecoder.encode_ints(x), rangecoder.decode_ints),
    ):
        for cut in range(len(data) - 1):
            try:
                out = decode(data[:cut])
            except CorruptStreamError:
                continue
            assert not np.array_equal(out, x if decode is rangecoder.decode_ints else x + 100)


# ----- zero runs ----------------------------------------------------------------------------
@given(hnp.arrays(np.int64, st.integers(0, 200), elements=st.sampled_from([0, 0, 0, 0, 1, -3, 7])))
def test_zero_runs_round_trip(x):
    runs = rle.encode_zero_runs(x)
    assert runs.length == x.size and np.all(runs.values != 0)
    assert np.array_equal(rle.decode_zero_runs(runs), x)


@pytest.mark.parametrize("wavelet", ["cdf97", "haar", "db4"])
def test_a_blocks_reach_is_its_synthesis_matrix_thresholded(wavelet):
    """Which coefficients reach each frame (at least 5% of their synthesis function's peak):
    the rolled first function of every band gives what the whole synthesis matrix gives, and
    the lists the kernels read hold the same."""
    from mocodec.coding.transforms import trendwave, wavelets

    for n, levels in ((16, 1), (96, 3), (192, 3), (256, 4)):
        lay = trendwave.layout(n, n, levels, 0, wavelet)  # one block of n frames
        assert lay.padded.tolist() == [n]
        synthesis = np.abs(wavelets.matrices(n, wavelet, levels)[1])
        expected = (synthesis > 0.05 * synthesis.max(axis=0)).astype(np.uint8)
        ptr, reached, at = trendwave.reaches(lay)  # per frame, the list of its coefficients
        table = np.zeros((n, n), dtype=np.uint8)
        for frame in range(n):
            table[frame, reached[ptr[frame] : ptr[frame + 1]]] = 1
        assert at.tolist() == [0] and ptr.size == n + 1 and np.array_equal(table, expected)
