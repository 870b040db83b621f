"""Symbols per second of the coding building blocks on 1M Laplace-distributed symbols
(scale 3, like quantised prediction residuals), and their bits per symbol against the entropy.
Run: `.venv/bin/python benchmarks/bench_coding.py`."""

from __future__ import annotations

import time

import numpy as np

from common import options
from mocodec.coding.entropy import huffman, rangecoder, rle
from mocodec.coding.entropy.bitio import BitReader, BitWriter, zigzag
from mocodec.coding.quantisation.quantisers import AdaptiveQuantiser, MuLawQuantiser, UniformQuantiser

N = 1_000_000


def rate(fn, n=N):
    fn()  # compile / warm up
    t0 = time.perf_counter()
    out = fn()
    return n / (time.perf_counter() - t0) / 1e6, out


def main() -> None:
    options(__doc__)
    rng = np.random.default_rng(0)
    x = np.round(rng.laplace(0, 3, N)).astype(np.int64)
    sym = np.clip(x, -32, 31) + 32
    p = np.bincount(zigzag(x).astype(int)) / N
    print(f"{N:,} Laplace symbols, entropy {-np.sum(p[p > 0] * np.log2(p[p > 0])):.3f} bits\n")
    print(f"{'block':<34}{'Msym/s':>8}{'bits/sym':>10}")

    def bits_row(name, enc, dec, n_bits):
        e, data = rate(enc)
        d, _ = rate(lambda: dec(data))
        print(f"{name + ' encode':<34}{e:>8.2f}{n_bits(data):>10.3f}")
        print(f"{name + ' decode':<34}{d:>8.2f}")

    def pack():
        w = BitWriter()
        w.write_array(sym, 6)
        return w.getvalue()

    bits_row("bit I/O (6-bit fields)", pack, lambda d: BitReader(d).read_array(N, 6), lambda d: len(d) * 8 / N)
    bits_row("static Huffman", lambda: huffman.encode_static(sym, 64), huffman.decode_static, lambda d: len(d) * 8 / N)
    small = sym[:100_000]
    e, data = rate(lambda: huffman.encode_adaptive(small, 64), len(small))
    d, _ = rate(lambda: huffman.decode_adaptive(data, 64), len(small))
    print(f"{'adaptive Huffman encode (every sym)':<34}{e:>8.2f}{len(data) * 8 / len(small):>10.3f}")
    print(f"{'adaptive Huffman decode':<34}{d:>8.2f}")
    bits_row(
        "range coder (adaptive ints)",
        lambda: rangecoder.encode_ints(x),
        rangecoder.decode_ints,
        lambda d: len(d) * 8 / N,
    )
    f = rng.laplace(0, 3, N)
    for name, q in (
        ("uniform quantiser 256", UniformQuantiser(-30, 30, 256)),
        ("mu-law quantiser 256", MuLawQuantiser(255, 30, 256)),
    ):
        e, _ = rate(lambda: q.reconstruct(q.quantise(f)))
        print(f"{name + ' (q + r)':<34}{e:>8.2f}")
    aq = AdaptiveQuantiser(16, 1.0, 1e-3, 1e3)
    e, _ = rate(lambda: aq.quantise(f))
    print(f"{'adaptive quantiser 16 (7-7)':<34}{e:>8.2f}")
    zeros = np.where(rng.random(N) < 0.9, 0, x)
    e, runs = rate(lambda: rle.encode_zero_runs(zeros))
    d, _ = rate(lambda: rle.decode_zero_runs(runs))
    print(f"{'zero runs encode / decode':<34}{e:>8.2f}{'':>10}  decode {d:.2f}")


if __name__ == "__main__":
    main()
