"""Smoothing the seams of independently coded blocks (block-edge smoothing, 000 §7.8.1).

Blocks coded on their own meet with a small step: their coding errors are independent, so the
decoded curve jumps where one block ends and the next begins, and the eye (and the jerk)
catches it. At each seam the step is estimated from both sides (each side's quadratic
extrapolation to the midpoint between the two frames) and removed by two raised-cosine ramps
over ``half_width`` frames each side, half the step from each: smooth motion is left alone,
and a curve without a step is not changed at all.
"""

from __future__ import annotations

import numpy as np

_EXTRAPOLATE = np.array([0.375, -1.25, 1.875])  # quadratic through 3 frames, half a frame on
_PROBES = (-8, -6, -4, 4, 6, 8)
CONTEXT = 11  # frames each side of a seam the estimates read


def seam_steps(x: np.ndarray, seams) -> np.ndarray:
    """The step at each of ``seams`` (first frame of the right block), per column
    ``(seams, columns)``: the difference of each side's quadratic extrapolation to the midpoint
    between the blocks (quadratic, so a smoothly accelerating curve shows no step). Elementwise,
    so a column's floats do not depend on the other columns."""
    s = np.asarray(seams)
    a, b, c = _EXTRAPOLATE
    left = a * x[s - 3] + b * x[s - 2] + c * x[s - 1]
    right = a * x[s + 2] + b * x[s + 1] + c * x[s]
    return right - left


def natural_steps(x: np.ndarray, seams) -> np.ndarray:
    """The same estimate at frames 4 to 8 away from each seam, inside the blocks: how big a
    "step" the motion itself shows there (noise, sharp moves); the median per seam and column
    over the probes that fit in ``x`` (0 where none does)."""
    probes = np.asarray(seams)[:, None] + np.array(_PROBES)[None, :]
    fits = (probes >= 3) & (probes <= len(x) - 3)
    sizes = np.abs(seam_steps(x, np.where(fits, probes, 3).ravel())).reshape(*probes.shape, -1)
    sizes[~fits] = np.inf  # sorted after every probe that fits
    sizes.sort(axis=1)
    count = fits.sum(axis=1)
    rows = np.arange(len(count))
    low = sizes[rows, np.maximum(count - 1, 0) // 2]  # the middle one, or the two middle ones
    high = sizes[rows, np.minimum(count // 2, sizes.shape[1] - 1)]
    return np.where((count > 0)[:, None], (low + high) / 2, 0.0)


def smooth_seams(x: np.ndarray, seams, half_width: int, limits: np.ndarray | None = None) -> np.ndarray:
    """``x`` (frames, channels) with the step at every seam spread over 2 ``half_width`` frames.
    Only the part of a step beyond four times the motion's own (:func:`natural_steps`) is
    removed, and at most ``limits[k]`` per channel at the k-th seam (what the coder's error can
    explain there), so finely coded or naturally jerky motion keeps its detail. Steps are
    measured on ``x`` as given: seams closer than ``half_width`` plus :data:`CONTEXT` frames
    see each other's input, not each other's output."""
    out = np.array(x, dtype=np.float64, copy=True)
    seams = np.asarray(seams, dtype=np.int64)
    inside = (seams >= 3) & (seams + 3 <= len(out))
    if not inside.any():
        return out
    where = seams[inside]
    step = seam_steps(out, where)
    size = np.maximum(np.abs(step) - 4.0 * natural_steps(out, where), 0.0)
    if limits is not None:
        size = np.minimum(size, np.asarray(limits)[inside])
    half = 0.5 * np.sign(step) * size  # (seams, channels)
    h = max(int(half_width), 1)
    weight = 0.5 * (1 + np.cos(np.pi * (np.arange(h) + 0.5) / h))  # 1 next to the seam -> 0
    for side, rows in ((1.0, where[:, None] - 1 - np.arange(h)), (-1.0, where[:, None] + np.arange(h))):
        ok = (rows >= 0) & (rows < len(out))
        k, i = np.nonzero(ok)
        np.add.at(out, rows[k, i], side * half[k] * weight[i][:, None])
    return out
