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


_EXTRAPOLATE = np.array([0.375, -1.25, 1.875])       # quadratic through 3 frames, half a frame on
_PROBES = (-8, -6, -4, 4, 6, 8)
CONTEXT = 11                                          # frames each side of a seam the estimates read


def seam_steps(x: np.ndarray, seam: int) -> np.ndarray:
    """The step at ``seam`` (first frame of the right block), per column: the difference of
    each side's quadratic extrapolation to the midpoint between the blocks (quadratic, so a
    smoothly accelerating curve shows no step)."""
    left = _EXTRAPOLATE @ x[seam - 3:seam]
    right = _EXTRAPOLATE @ x[seam:seam + 3][::-1]
    return right - left


def natural_steps(x: np.ndarray, seam: int) -> np.ndarray:
    """The same estimate at frames 4 to 8 away from the seam, inside the blocks: how big a
    "step" the motion itself shows here (noise, sharp moves); the median per column."""
    probes = [seam + d for d in _PROBES if 3 <= seam + d <= len(x) - 3]
    if not probes:
        return np.zeros(x.shape[1])
    return np.median(np.abs([seam_steps(x, p) for p in probes]), axis=0)


def smooth_seams(x: np.ndarray, seams, half_width: int, limits: np.ndarray | None = None) -> np.ndarray:
    """``x`` (frames, channels) with the step at every seam spread over 2 ``half_width`` frames.
    Only the part of a step beyond four times the motion's own (:func:`natural_steps`) is
    removed, and at most ``limits[k]`` per channel at the k-th seam (what the coder's error can
    explain there), so finely coded or naturally jerky motion keeps its detail."""
    out = np.array(x, dtype=np.float64, copy=True)
    h = max(int(half_width), 1)
    weight = 0.5 * (1 + np.cos(np.pi * (np.arange(h) + 0.5) / h))        # 1 next to the seam -> 0
    for k, s in enumerate(seams):
        if s < 3 or s + 3 > len(out):
            continue
        step = seam_steps(out, s)
        size = np.maximum(np.abs(step) - 4.0 * natural_steps(out, s), 0.0)
        if limits is not None:
            size = np.minimum(size, limits[k])
        step = np.sign(step) * size
        n_left, n_right = min(h, s), min(h, len(out) - s)
        out[s - n_left:s] += 0.5 * step * weight[:n_left][::-1, None]
        out[s:s + n_right] -= 0.5 * step * weight[:n_right][:, None]
    return out
