"""Subband split of short blocks for the time-frequency coders of 000 §7.8.2 (figs. 7-17, 7-18).

A block of N frames (a power of two) is split by ``levels`` steps of the CDF 5/3 lifting
wavelet into ``levels + 1`` bands, laid out coarsest first: [approximation, details of the
coarsest level, ..., finest details]. The 5/3 filters are symmetric, so the block's ends are
mirrored (whole-sample symmetric extension) and the split stays critically sampled: N
coefficients, no wrap from the end of a block to its start (which periodised filters would
add at every block edge), and exact reconstruction. PyWavelets offers symmetric extension only
with extra coefficients, hence these few lines of lifting.

At 30 Hz a 16-frame block split three times gives bands of 0-1.9, 1.9-3.75, 3.75-7.5 and
7.5-15 Hz: the four bands of the visual MSE (fig. 6-1, edges 1, 3 and 7 Hz), so each band can
be given its VMSE weight (:func:`visual_weights`).
"""

from __future__ import annotations

import math

import numpy as np


def _lift(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One 5/3 analysis step along axis 1 of ``(blocks, n, K)``: (low, high), n/2 each."""
    even, odd = x[:, 0::2], x[:, 1::2]
    even_next = np.concatenate((even[:, 1:], even[:, -1:]), axis=1)  # x[n] mirrored to x[n-2]
    high = odd - 0.5 * (even + even_next)
    high_prev = np.concatenate((high[:, :1], high[:, :-1]), axis=1)  # d[-1] mirrored to d[0]
    return even + 0.25 * (high_prev + high), high


def _unlift(low: np.ndarray, high: np.ndarray) -> np.ndarray:
    high_prev = np.concatenate((high[:, :1], high[:, :-1]), axis=1)
    even = low - 0.25 * (high_prev + high)
    even_next = np.concatenate((even[:, 1:], even[:, -1:]), axis=1)
    out = np.empty((low.shape[0], 2 * low.shape[1], *low.shape[2:]))
    out[:, 0::2], out[:, 1::2] = even, high + 0.5 * (even + even_next)
    return out


def check(n: int, levels: int) -> None:
    if n < 1 or n & (n - 1) or not 0 <= levels <= int(math.log2(n)):
        raise ValueError(f"a {n}-frame block cannot be split {levels} times (N must be a power of two >= 2^levels)")


def forward(blocks: np.ndarray, levels: int) -> np.ndarray:
    """Coefficients of ``(blocks, N, K)`` along N, coarsest band first."""
    check(blocks.shape[1], levels)
    low, highs = np.asarray(blocks, dtype=np.float64), []
    for _ in range(levels):
        low, high = _lift(low)
        highs.append(high)
    return np.concatenate([low, *highs[::-1]], axis=1)


def inverse(coeffs: np.ndarray, levels: int) -> np.ndarray:
    n = coeffs.shape[1]
    check(n, levels)
    size = n >> levels
    low = coeffs[:, :size]
    for _ in range(levels):
        low = _unlift(low, coeffs[:, size : 2 * size])
        size *= 2
    return low


def band_bounds(n: int, levels: int) -> list[tuple[int, int]]:
    """(start, stop) of each band along N, coarsest first."""
    check(n, levels)
    edges = [0, n >> levels] + [n >> k for k in range(levels - 1, -1, -1)]
    return list(zip(edges[:-1], edges[1:]))


def synthesis_gains(n: int, levels: int) -> np.ndarray:
    """Per band the RMS norm of the signal a unit coefficient rebuilds: how much an error in
    that band's coefficients weighs in the signal (1 for an orthonormal split; the 5/3 split
    is not quite, and its bands differ)."""
    eye = np.eye(n)[:, :, None]  # one block per coefficient
    energy = (inverse(eye, levels) ** 2).sum(axis=1)[:, 0]
    return np.array([math.sqrt(energy[a:b].mean()) for a, b in band_bounds(n, levels)])


def band_centres_hz(n: int, levels: int, fps: float) -> np.ndarray:
    """The (geometric) centre frequency of each band; the approximation's is half its top."""
    top = fps / 2.0
    details = [top / 2.0 ** (k + 0.5) for k in range(levels - 1, -1, -1)]
    return np.array([top / 2.0**levels / 2.0, *details])


def visual_weights(n: int, levels: int, fps: float, edges_hz, weights) -> np.ndarray:
    """Per band the weight (6-15) of the visual band (fig. 6-1: ``edges_hz``, ``weights``)
    that holds the band's centre."""
    index = np.searchsorted(np.asarray(edges_hz), band_centres_hz(n, levels, fps))
    return np.asarray(weights, dtype=np.float64)[index]


def visual_levels(n: int, fps: float, first_edge_hz: float) -> int:
    """The fewest splits whose approximation band ends below twice the first visual edge (1.9
    Hz at 30 and 120 Hz for the VMSE's 1 Hz), so the bands follow the visual ones; at most
    log2(N)."""
    levels = 0
    while fps / 2.0 ** (levels + 1) >= 2.0 * first_edge_hz:
        levels += 1
    return min(levels, int(math.log2(n)))
