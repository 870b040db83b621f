"""Smoothing the seams of independently coded blocks (block-edge smoothing, 000 §7.8.1).

Blocks coded on their own meet with a small step: their coding errors are independent, so the
decoded curve jumps where one block ends and the next begins, and the eye (and the jerk)
catches it. At each seam the step is estimated from both sides (each side's quadratic
extrapolation to the midpoint between the two frames) and removed by two raised-cosine ramps
over ``half_width`` frames each side, half the step from each: smooth motion is left alone,
and a curve without a step is not changed at all.
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from mocodec.kernels import kernel

_EXTRAPOLATE = np.array([0.375, -1.25, 1.875])  # quadratic through 3 frames, half a frame on
_PROBES = np.array([-8, -6, -4, 4, 6, 8], dtype=np.int64)  # frames from a seam its motion's own step is read at
CONTEXT = 11  # frames each side of a seam the estimates read


def smooth_seams(x: np.ndarray, seams, half_width: int, limits: np.ndarray | None = None) -> np.ndarray:
    """``x`` (frames, channels) with the step at every seam spread over 2 ``half_width`` frames.
    The step at a seam (the first frame of the right block) is the difference of each side's
    quadratic extrapolation to the midpoint between the blocks (quadratic, so a smoothly
    accelerating curve shows no step); the motion's own step is the median of the same estimate
    at frames 4 to 8 away from the seam, inside the blocks (noise, sharp moves). Only the part
    of a step beyond four times the motion's own is
    removed, and at most ``limits[k]`` per channel at the k-th seam (what the coder's error can
    explain there), so finely coded or naturally jerky motion keeps its detail. Steps are
    measured on ``x`` as given: seams closer than ``half_width`` plus :data:`CONTEXT` frames
    see each other's input, not each other's output."""
    rows = np.array(np.asarray(x, dtype=np.float64).T, order="C")  # (the kernel's layout: a copy)
    seams = np.asarray(seams, dtype=np.int64)
    bound = np.full((seams.size, rows.shape[0]), np.inf) if limits is None else np.asarray(limits, dtype=np.float64)
    smooth_rows(rows, seams, np.ascontiguousarray(bound), ramp(half_width))
    return np.ascontiguousarray(rows.T)


@lru_cache(maxsize=16)
def ramp(half_width: int) -> np.ndarray:
    """The raised-cosine weights of a ramp over ``half_width`` frames, 1 next to the seam -> 0
    (numpy's cosine, made once: compiled callers take these floats, not their own)."""
    h = max(int(half_width), 1)
    weight = 0.5 * (1 + np.cos(np.pi * (np.arange(h) + 0.5) / h))
    weight.setflags(write=False)
    return weight


@kernel
def smooth_rows(rows, seams, limits, weight):
    """:func:`smooth_seams` in place on ``rows (channels, frames)`` (a compiled caller's layout),
    the step at seam ``seams[k]`` at most ``limits[k, channel]``, the ramp ``weight``
    (:func:`ramp`)."""
    frames = rows.shape[1]
    inside = (seams >= 3) & (seams + 3 <= frames)
    if not inside.any():
        return
    _smooth(rows, seams[inside], np.ascontiguousarray(limits[inside]), weight, _EXTRAPOLATE, _PROBES)


@numba.njit(inline="always")
def _step_at(x, s, col, abc):
    """The step at seam ``s`` in row ``col``: each side's extrapolation ``abc`` to the midpoint."""
    left = abc[0] * x[col, s - 3] + abc[1] * x[col, s - 2] + abc[2] * x[col, s - 1]
    right = abc[0] * x[col, s + 2] + abc[1] * x[col, s + 1] + abc[2] * x[col, s]
    return right - left


@kernel
def _smooth(out, where, bound, weight, abc, probes):
    """:func:`smooth_seams` on the rows ``out (channels, frames)`` in place, seams ``where`` all
    inside: every step measured first, then the ramps added (every seam's left side, then every
    right side; the browser decoder's order and floats, js/src/seams.js)."""
    channels, frames = out.shape
    halves = np.zeros((where.size, channels))
    sizes = np.empty(probes.size)
    for k in range(where.size):
        s = where[k]
        for col in range(channels):
            step = _step_at(out, s, col, abc)
            count = 0
            for m in range(probes.size):
                p = s + probes[m]
                if p >= 3 and p <= frames - 3:
                    size = abs(_step_at(out, p, col, abc))
                    at = count  # insertion: sizes[:count] stay sorted
                    while at > 0 and sizes[at - 1] > size:
                        sizes[at] = sizes[at - 1]
                        at -= 1
                    sizes[at] = size
                    count += 1
            natural = 0.0
            if count:
                natural = (sizes[(count - 1) // 2] + sizes[count // 2]) / 2
            size = max(abs(step) - 4.0 * natural, 0.0)
            size = min(size, bound[k, col])
            halves[k, col] = 0.5 * np.sign(step) * size
    for side in (1.0, -1.0):
        for k in range(where.size):
            for i in range(weight.size):
                row = where[k] - 1 - i if side > 0 else where[k] + i
                if 0 <= row < frames:
                    for col in range(channels):
                        out[col, row] += side * halves[k, col] * weight[i]
