"""Segment animation (000 §8.3): the motion between non-uniform samples.

``hermite`` joins the samples by Hermite cubics (8-5, 8-6) whose end slopes come from the
neighbouring samples (8-7, 8-8). The thesis writes the slope at sample m as
``D(m) = s (th(m) - th(m-1)) + (1 - s) (th(m+1) - th(m))``, ``s = r(m+1) / (r(m) + r(m+1))``,
with r the lags; that is the mean of the two neighbouring per-frame slopes times the harmonic
mean of the two lags. Used as the tangent of both segments it is right only when the lags are
equal; here each segment scales that per-frame slope by its own lag, which is the thesis's
value for equal lags and keeps the first derivative equal on both sides of a sample (the
continuity 8.3.1 asks for) when they differ. The end samples take their one segment's slope.

``raised_cosine`` joins samples where the motion rests (gesture samples) by (8-9, 8-10), whose
slope is zero at both ends. ``blend_start`` eases a decoded segment in from the previous
segment's last frame with the same weight (fig. 8-5, 8.5).

Sample values of angles are unwrapped first (:func:`unwrap_degrees`) so interpolation never
turns the long way round.
"""

from __future__ import annotations

import numpy as np


def unwrap_degrees(values: np.ndarray) -> np.ndarray:
    """``values (S, K)`` with each column shifted by turns to follow its previous row."""
    return np.unwrap(np.asarray(values, dtype=np.float64), period=360.0, axis=0)


def turned_to(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``values`` (one row, or a sequence of rows) shifted by whole turns per angle so that
    their first row lies within half a turn of ``reference``."""
    start = values[0] if values.ndim == 2 else values
    return values + 360.0 * np.round((reference - start) / 360.0)


def _segment_of(times: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, its segment (between sample k and k + 1) and its position t in [0, 1)."""
    f = np.arange(n)
    k = np.clip(np.searchsorted(times, f, side="right") - 1, 0, len(times) - 2)
    return k, (f - times[k]) / (times[k + 1] - times[k])


def hermite(times: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Hermite interpolation (8-5 to 8-8) of samples ``values (S, K)`` at frames ``times``."""
    if len(times) < 2:
        return np.repeat(values[:1], n, axis=0)
    lags = np.diff(times).astype(np.float64)[:, None]
    slope = np.diff(values, axis=0) / lags
    per_frame = np.concatenate([slope[:1], (slope[:-1] + slope[1:]) / 2, slope[-1:]])
    k, t = _segment_of(times, n)
    t = t[:, None]
    r = lags[k]
    p0, p1 = values[k], values[k + 1]
    d0, d1 = per_frame[k] * r, per_frame[k + 1] * r
    a2 = 3 * (p1 - p0) - 2 * d0 - d1
    a3 = 2 * (p0 - p1) + d0 + d1
    return p0 + t * (d0 + t * (a2 + t * a3))


def cosine_weight(t: np.ndarray) -> np.ndarray:
    """(8-9): 1 at t = 0 falling to 0 at t = 1, flat at both ends."""
    return (1.0 + np.cos(np.pi * t)) / 2


def raised_cosine(times: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """(8-10): raised-cosine interpolation of samples ``values (S, K)`` at frames ``times``."""
    if len(times) < 2:
        return np.repeat(values[:1], n, axis=0)
    k, t = _segment_of(times, n)
    w = cosine_weight(t)[:, None]
    return w * values[k] + (1 - w) * values[k + 1]


def blend_start(segment: np.ndarray, previous: np.ndarray, frames: int) -> np.ndarray:
    """``segment (L, K)`` eased in over its first ``frames`` frames from ``previous (K,)``, the
    last frame before it (fig. 8-5)."""
    m = min(frames, len(segment))
    if m <= 0:
        return segment
    w = cosine_weight(np.arange(1, m + 1) / (frames + 1))[:, None]
    out = segment.copy()
    out[:m] = w * previous + (1 - w) * segment[:m]
    return out


def stretch(sequence: np.ndarray, length: int) -> np.ndarray:
    """``sequence (N, K)`` linearly resampled to ``length`` frames, both ends kept."""
    n = len(sequence)
    if n == length:
        return sequence.copy()
    if n == 1 or length == 1:
        return np.repeat(sequence[:1], length, axis=0)
    pos = np.linspace(0.0, n - 1, length)
    i = np.minimum(pos.astype(np.int64), n - 2)
    frac = (pos - i)[:, None]
    return (1 - frac) * sequence[i] + frac * sequence[i + 1]
