"""Multi-level periodised wavelet transforms of many rows in compiled loops, with PyWavelets'
floats: every sum adds its terms in the order PyWavelets' C code does (``wavedec`` and
``waverec``, mode ``periodization``), so a coder that switches to these kernels keeps its bytes.

A level's analysis output ``o`` of an even-length signal ``x`` (N samples, filter of F taps)
sums ``filter[f] * x[(i - f) mod N]`` at ``i = F/2 + 2o``, over f ascending; where i >= N the
terms that wrap past the end come first, f from i - N down to 0, then the rest ascending. A
level's synthesis adds the approximation's terms (reconstruction low-pass filter) and then the
details' (high-pass) to each output sample, each filter's taps split into even and odd ones,
in the same orders; a filter whose half length is even (D4) has its output one sample later.
"""

from __future__ import annotations

import numba
import numpy as np

from mocodec.kernels import kernel


@numba.njit(inline="always")
def analysis_sum(x, n, i, h):
    """One output of a level's analysis: ``h`` over ``x[:n]`` at ``i`` in PyWavelets' order."""
    taps = h.size
    total = 0.0
    if taps - 1 <= i < n:  # no wrap: the common case, without the modulo
        for f in range(taps):
            total += h[f] * x[np.uintp(i - f)]  # (unsigned: no check for a negative index)
        return total
    f0 = 0
    if i >= n:
        for f in range(i - n, -1, -1):
            total += h[f] * x[(i - f) % n]
        f0 = i - n + 1
    for f in range(f0, taps):
        total += h[f] * x[(i - f) % n]
    return total


@numba.njit(inline="always")
def synthesis_add(x, n, h, out):
    """Add one band ``x[:n]`` upsampled through ``h`` to ``out[:2n]`` in PyWavelets' order (a
    filter whose half length is even puts every pair one sample later, the last pair's odd
    sample at 0)."""
    half = h.size // 2
    start = h.size // 4
    shift = 1 - half % 2
    size = 2 * n
    for i in range(start, n + start):
        o = 2 * (i - start) + shift
        if half - 1 <= i < n:  # no wrap (nor of the output: i < n)
            sum_even, sum_odd = out[np.uintp(o)], out[np.uintp(o + 1)]  # (summed in registers)
            for g in range(half):
                v = x[np.uintp(i - g)]
                sum_even += h[2 * g] * v
                sum_odd += h[2 * g + 1] * v
            out[np.uintp(o)], out[np.uintp(o + 1)] = sum_even, sum_odd
            continue
        even, odd = o % size, (o + 1) % size
        g0 = 0
        if i >= n:
            for g in range(i - n, -1, -1):
                v = x[(i - g) % n]
                out[even] += h[2 * g] * v
                out[odd] += h[2 * g + 1] * v
            g0 = i - n + 1
        for g in range(g0, half):
            v = x[(i - g) % n]
            out[even] += h[2 * g] * v
            out[odd] += h[2 * g + 1] * v


@kernel
def forward_one(x, n, levels, lo, hi, out, a, b):
    """Coefficients of ``x[:n]`` (n a multiple of 2^levels) into ``out[:n]``, coarsest band
    first: [approximation, coarsest details, ..., finest details]; ``a`` and ``b`` are scratch
    of n values (``x`` may be ``out``)."""
    for t in range(n):
        a[t] = x[t]
    m = n
    for _ in range(levels):
        half = m // 2
        for o in range(half):
            i = lo.size // 2 + 2 * o
            b[o] = analysis_sum(a, m, i, lo)
            out[np.uintp(half + o)] = analysis_sum(a, m, i, hi)
        for o in range(half):
            a[o] = b[o]
        m = half
    for t in range(m):
        out[t] = a[t]


@kernel
def inverse_one(c, n, levels, lo, hi, out, a, b):
    """Inverse of :func:`forward_one`: the signal of ``c[:n]`` into ``out[:n]``; ``a`` and ``b``
    are scratch of n values (``c`` may not be ``out``)."""
    m = n >> levels
    for t in range(m):
        a[t] = c[t]
    for _ in range(levels):
        for t in range(2 * m):
            b[t] = 0.0
        synthesis_add(a, m, lo, b)
        synthesis_add(c[m:], m, hi, b)
        m *= 2
        for t in range(m):
            a[t] = b[t]
    for t in range(n):
        out[t] = a[t]


@kernel
def forward_rows(x, levels, lo, hi):
    """:func:`forward_one` of every row of ``x (rows, n)``."""
    rows, n = x.shape
    out = np.empty((rows, n))
    a, b = np.empty(n), np.empty(n)
    for r in range(rows):
        forward_one(x[r], n, levels, lo, hi, out[r], a, b)
    return out


@kernel
def inverse_rows(c, levels, lo, hi):
    """:func:`inverse_one` of every row of ``c (rows, n)``."""
    rows, n = c.shape
    out = np.empty((rows, n))
    a, b = np.empty(n), np.empty(n)
    for r in range(rows):
        inverse_one(c[r], n, levels, lo, hi, out[r], a, b)
    return out
