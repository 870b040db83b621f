"""Channels as a piecewise-linear trend through knots plus a wavelet-coded residual.

A payload of T frames is cut into segments of W frames (after up to two one-frame keyframe
segments, for a bind pose or T-pose at the start of many clips: kinwave.md 6). Knots sit at every segment start
and on the last frame; the trend joins them linearly, so it is continuous across seams, and
the residual of a segment is close to zero at both of its ends, which is what a periodised
transform needs (kinwave.md 4: detrend, zero-pad to a multiple of 2^levels, periodise). Each
segment's residual is transformed on its own (CDF 9/7 by default), so segments are the unit
of streaming delay.

This module lays the segments and knots out (:func:`layout`) and gives compiled coders the
layout as flat arrays (:func:`flat`, :func:`reaches`); encoder and decoder reconstruct through
the same kernels on the same integers, so the encoder knows the decoder's output bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from mocodec.coding.transforms import wavelets

KEYFRAME_QUANTUM = 0.5
LEADS = 4  # the leads a layout may take (0 to 3: a grid of four frames, two dyadic levels)
EDGE = 4  # detail coefficients at either end of a band that the periodised transform's wrap reaches
LEAD_GAIN = 0.9  # a grid phase is taken when its details cost at most this share of the dearest phase's


@dataclass(frozen=True, eq=False)
class Layout:
    frames: int
    wavelet: str
    starts: np.ndarray  # (S,) first frame of each segment
    lengths: np.ndarray  # (S,) frames in each segment
    leads: np.ndarray  # (S,) zeros before each segment's frames in its block
    padded: np.ndarray  # (S,) coefficients of each segment's block (0: no block)
    levels: np.ndarray  # (S,) wavelet levels of each block
    knot_frames: np.ndarray  # (K,)
    left: np.ndarray  # (T,) knot index before each frame
    frac: np.ndarray  # (T,) position between knot `left` and the next one
    knot_quantum: np.ndarray  # (K,) knot step relative to the channel's step

    @property
    def num_knots(self) -> int:
        return int(self.knot_frames.size)

    @property
    def num_coeffs(self) -> int:
        return int(self.padded.sum())


def first_window(frames: int, keyframes: int) -> int:
    """The frame a payload's windows start on: after its keyframes, of which a payload keeps
    at least one frame for the windows (none for a single frame)."""
    return min(int(keyframes), frames - 1) if frames > 1 else 0


@lru_cache(maxsize=256)
def layout(frames: int, window: int, levels: int, keyframes: int, wavelet: str = "cdf97", lead: int = 0) -> Layout:
    """The segments and knots of a ``frames``-long payload (``window`` a power of two), its
    first ``keyframes`` frames (a bind pose, a T-pose) one-frame segments of their own. With a
    ``lead``, the first window is ``lead`` frames shorter and its block starts with that many
    zeros, so every block's dyadic grid falls ``lead`` frames earlier in the motion (where a
    clip resampled from a lower rate has its smooth samples: :func:`grid_phase`)."""
    first = first_window(frames, keyframes)
    windows = list(range(first, max(frames, 1), window))
    if lead and frames > first + 1:
        windows = [first] + list(range(first + window - lead, frames, window))
        if len(windows) > 1 and frames - windows[-1] <= lead:
            windows.pop()  # the last window takes the few frames the lead left over
    starts = np.array(list(range(first)) + windows, dtype=np.int64)
    if frames == 0:
        starts = np.zeros(0, dtype=np.int64)
    lengths = np.diff(np.append(starts, frames))
    leads = np.where((np.arange(starts.size) == first) & (lengths >= 2), lead, 0).astype(np.int64)
    spans = lengths + leads
    seg_levels = np.array([0 if n < 2 else min(levels, int(np.log2(n))) for n in spans], dtype=np.int64)
    unit = 1 << seg_levels
    padded = np.where(lengths < 2, 0, -(-spans // unit) * unit)
    knots = starts.copy()
    if frames > 0 and frames - 1 != starts[-1]:
        knots = np.append(knots, frames - 1)
    left = np.zeros(frames, dtype=np.int64)
    frac = np.zeros(frames)
    for s, (a, n) in enumerate(zip(starts, lengths)):
        end = knots[s + 1] if s + 1 < knots.size else a
        left[a : a + n] = s
        if end > a:
            frac[a : a + n] = np.arange(n) / (end - a)
    # a keyframe has no residual to correct its knot: it gets an twice finer step
    quantum = np.ones(knots.size)
    quantum[:first] = KEYFRAME_QUANTUM
    padded = padded.astype(np.int64)
    return Layout(
        frames,
        wavelet,
        starts,
        lengths,
        leads,
        padded,
        seg_levels,
        knots,
        left,
        frac,
        quantum,
    )


def grid_phase(scaled: np.ndarray, wavelet: str, skip: int = 0) -> int | None:
    """The frame (mod LEADS) where a block's dyadic grid makes the two finest bands of ``scaled
    (channels, T)`` (the channels in quantiser steps; the first ``skip`` frames, which may jump,
    left out) cheapest, summed as log2(1 + |detail|) (about the bits a coefficient costs) away
    from the ends; None unless it saves more than 1 - LEAD_GAIN against the dearest. A clip
    resampled from a lower rate (CMU's cgspeed BVH files: 120 fps with the smoothness of 30)
    has every fourth frame on the original grid, and a block aligned elsewhere pays for the
    interpolation in its finest bands (docs/kinwave.md)."""
    usable = (scaled.shape[1] - skip - (LEADS - 1)) // LEADS * LEADS
    if usable < 16 * LEADS or not scaled.shape[0]:
        return None
    inner = np.r_[usable // 4 + EDGE : usable // 2 - EDGE, usable // 2 + EDGE : usable - EDGE]
    costs = np.zeros(LEADS)
    for phase in range(LEADS):
        at = skip + (phase - skip) % LEADS
        coeffs = wavelets.forward(scaled[:, at : at + usable], wavelet, 2)
        costs[phase] = np.log2(1.0 + np.abs(coeffs[:, inner])).sum()
    best = int(np.argmin(costs))
    return best if costs[best] < LEAD_GAIN * costs.max() else None


class Flat(NamedTuple):
    """A :class:`Layout` as the arrays compiled kernels take (:func:`flat`)."""

    knot_frames: np.ndarray
    left: np.ndarray
    frac: np.ndarray
    knot_quantum: np.ndarray
    starts: np.ndarray
    lengths: np.ndarray
    leads: np.ndarray
    padded: np.ndarray
    levels: np.ndarray
    offsets: np.ndarray  # (S,) each segment's first coefficient


@lru_cache(maxsize=256)
def flat(lay: Layout) -> Flat:
    """``lay`` as flat arrays for compiled kernels."""
    offsets = np.concatenate([[0], np.cumsum(lay.padded)[:-1]]).astype(np.int64)
    return Flat(
        lay.knot_frames,
        lay.left,
        lay.frac,
        lay.knot_quantum,
        lay.starts,
        lay.lengths,
        lay.leads,
        lay.padded,
        lay.levels,
        offsets,
    )


@lru_cache(maxsize=256)
def reaches(lay: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which coefficients each frame's error reaches (:func:`_reach_lists`), for compiled
    kernels: per frame of each block shape (one copy per shape), where its list starts and
    ends in the second array (``(frames + 1,)`` per shape, end to end), the lists, and
    where each segment's block shape starts in the first array (-1: no block)."""
    ptrs: list[np.ndarray] = []
    lists: list[np.ndarray] = []
    at = np.full(lay.starts.size, -1, dtype=np.int64)
    first: dict[tuple[int, int], int] = {}
    rows = listed = 0
    for s in np.flatnonzero(lay.padded):
        key = (int(lay.padded[s]), int(lay.levels[s]))
        if key not in first:
            ptr, coefficients = _reach_lists(*key, lay.wavelet)
            ptrs.append(ptr + listed)
            lists.append(coefficients)
            first[key], rows, listed = rows, rows + ptr.size, listed + coefficients.size
        at[s] = first[key]
    ptr = np.concatenate(ptrs) if ptrs else np.zeros(0, dtype=np.int64)
    reached = np.concatenate(lists) if lists else np.zeros(0, dtype=np.int64)
    for table in (ptr, reached, at):
        table.setflags(write=False)  # (shared by the passes of a layout)
    return ptr, reached, at


@lru_cache(maxsize=64)
def _reach_lists(n: int, levels: int, wavelet: str) -> tuple[np.ndarray, np.ndarray]:
    """Per frame of a block, the coefficients whose synthesis functions carry at least 5% of
    their peak there: where its list starts and ends in the second array (``(n + 1,)``), and
    the lists, each in order. A periodized band's functions are one function shifted round
    the block by the band's stride, so each band's first one is synthesised and the others'
    frames are its frames shifted (no table of every frame and coefficient)."""
    bands = wavelets.band_lengths(n, wavelet, levels)
    firsts = np.concatenate([[0], np.cumsum(bands)[:-1]])
    impulses = np.zeros((len(bands), int(sum(bands))))
    impulses[np.arange(len(bands)), firsts] = 1.0
    first = np.abs(wavelets.inverse(impulses, n, wavelet, levels))
    first = first > 0.05 * first.max(axis=1, keepdims=True)
    frames, coefficients = [], []
    for band, (at, length) in enumerate(zip(firsts, bands)):
        support, shifts = np.flatnonzero(first[band]), np.arange(length)
        frames.append(((support[:, None] + shifts * (n // length)) % n).ravel())
        coefficients.append(np.broadcast_to(at + shifts, (support.size, length)).ravel())
    frame, coefficient = np.concatenate(frames), np.concatenate(coefficients)
    order = np.lexsort((coefficient, frame))
    ptr = np.searchsorted(frame[order], np.arange(n + 1)).astype(np.int64)
    return ptr, coefficient[order].astype(np.int64)
