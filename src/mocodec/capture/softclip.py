"""Soft clipping of joint limits and of acos arguments (003 §4.4.5, (4-39), (4-40)).

Linear up to x1 = x_c - margin, a parabola from x1 to x2 = x_c + margin whose slope goes from 1
to 0, constant x_c beyond: y = a x^2 + b x + c with d = 4 (x_c - x1), a = -1/d, b = 1 + 2 x1/d,
c = -x1^2/d. The lower edge is the mirror image.
"""

from __future__ import annotations

import numpy as np


def soft_clip_upper(x: np.ndarray, clip: float | np.ndarray, margin: float | np.ndarray) -> np.ndarray:
    """(4-39) at the upper edge ``clip``: ``x`` eased into the limit over ``margin`` each side."""
    x = np.asarray(x, dtype=np.float64)
    clip = np.asarray(clip, dtype=np.float64)
    margin = np.asarray(margin, dtype=np.float64)
    x1 = clip - margin
    d = 4.0 * margin
    safe_d = np.where(d > 0, d, 1.0)
    curve = -(x**2) / safe_d + (1.0 + 2.0 * x1 / safe_d) * x - x1**2 / safe_d  # (4-40)
    return np.where(x <= x1, x, np.where(x >= clip + margin, clip, np.where(d > 0, curve, clip)))


def soft_clip(x: np.ndarray, low, high, margin) -> np.ndarray:
    """``x`` softly held inside [low, high] (infinite limits leave it as it is)."""
    x = np.asarray(x, dtype=np.float64)
    low, high = np.broadcast_arrays(np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64))
    m = np.minimum(np.asarray(margin, dtype=np.float64), np.where(np.isfinite(high - low), (high - low) / 4, np.inf))
    hi = np.where(np.isfinite(high), soft_clip_upper(x, np.where(np.isfinite(high), high, 0.0), m), x)
    return np.where(np.isfinite(low), -soft_clip_upper(-hi, np.where(np.isfinite(low), -low, 0.0), m), hi)
