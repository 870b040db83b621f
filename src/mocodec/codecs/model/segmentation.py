"""Non-uniform sampling of a group's motion (000 §8.2): posture and gesture segmentation.

Both return the sample frames (the first and last frame always among them) and, per sample,
the frame at which a causal encoder knows it: what sets the coding delay (8.1).

Posture segmentation (8.2.1) samples the group's monotone distance (8-1), the running sum of
the absolute changes of its DOFs, every ``d`` units (degrees, or centimetres for a
translation): often in busy motion, rarely in calm motion. A sample is known the frame the
sum crosses its level. Beyond the thesis, a lag limit adds a sample wherever none came for
``max_lag`` frames: a group at rest sends no samples, and its decoder would otherwise wait
until it moves again (for a hand that never moves, the whole clip).

Gesture segmentation (8.2.2) samples where the group comes (almost) to rest. The speed (8-2)
is the length of the vector of its DOFs' first derivatives, estimated by a third-order
least-squares fit over seven samples at 30 Hz (a Savitzky-Golay differentiator; at other rates
the same 233 ms); the acceleration (8-3) is the derivative of that speed, estimated the same
way. A threshold (8-4), ``beta`` times the speed low-pass filtered by a causal Hann window of
``window`` seconds, marks windows of interest where the speed is below it; the zero crossings
of the acceleration inside them are the candidate samples. Candidates closer than
``min_length`` to the last sample are dropped. A segment longer than ``max_length`` is
segmented again with ``beta`` raised by :data:`BETA_STEP`, up to :data:`BETA_LIMIT`, after
which it is cut evenly (the thesis leaves such segments "as they are, or subdivided by other
means"). A gesture sample is known when its window of interest closes (the speed rises above
the threshold again), half a differentiator window later; a cut of an overlong segment, when
the segment reaches its maximum length.

Defaults are the thesis's Appendix III parameters at 30 Hz (nWin 20, beta 0.75, nMin 5,
nMax 60 samples) in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

FIT_SECONDS = 7 / 30  # the seven-sample, third-order fit at 30 Hz
BETA_STEP = 0.25
BETA_LIMIT = 3.0


@dataclass(frozen=True)
class GestureParams:
    """The gesture segmentation parameters (Appendix III: nWin, beta, nMin, nMax), in seconds."""

    beta: float = 0.75
    window: float = 20 / 30
    min_length: float = 5 / 30
    max_length: float = 2.0

    def frames(self, fps: float) -> tuple[int, int, int]:
        """(filter length, shortest and longest segment) in frames at ``fps``."""
        short = max(1, round(self.min_length * fps))
        return max(1, round(self.window * fps)), short, max(short + 1, round(self.max_length * fps))


@dataclass(frozen=True)
class Samples:
    frames: np.ndarray  # (S,) increasing sample frames, first 0 and last n - 1
    known: np.ndarray  # (S,) the frame at which the encoder has decided each sample


def posture_samples(x: np.ndarray, d: float, max_lag: int = 0) -> Samples:
    """Samples of ``x (frames, K)`` every ``d`` of the distance (8-1), and (with ``max_lag``)
    at least every ``max_lag`` frames, so a group at rest does not hold up its decoder."""
    n = len(x)
    if n < 2:
        return Samples(np.zeros(1, np.int64), np.zeros(1, np.int64))
    s = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(x, axis=0)).sum(axis=1))])
    level = np.floor(s / d)
    inner = np.flatnonzero(level[1:-1] > level[:-2]) + 1
    frames = np.concatenate([[0], inner, [n - 1]]).astype(np.int64)
    if max_lag > 0:
        gaps = np.diff(frames)
        extra = (
            [np.arange(a + max_lag, b, max_lag) for a, b in zip(frames[:-1], frames[1:]) if b - a > max_lag]
            if (gaps > max_lag).any()
            else []
        )
        frames = np.sort(np.concatenate([frames, *extra])).astype(np.int64)
    return Samples(frames, frames.copy())


def fit_window(fps: float) -> int:
    """Odd length (frames) of the least-squares differentiator at ``fps``."""
    return max(5, 2 * round(FIT_SECONDS * fps / 2) + 1)


def speed_acceleration(x: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """The group's scalar speed (8-2) and acceleration (8-3), per frame (units/s, units/s^2)."""
    win = fit_window(fps)
    if len(x) < win:
        return np.zeros(len(x)), np.zeros(len(x))
    rate = signal.savgol_filter(x, win, 3, deriv=1, delta=1.0 / fps, axis=0)
    speed = np.sqrt(np.square(rate).sum(axis=1))
    return speed, signal.savgol_filter(speed, win, 3, deriv=1, delta=1.0 / fps)


def _threshold(speed: np.ndarray, length: int) -> np.ndarray:
    """(8-4) without beta: the speed through a causal, unit-gain Hann low-pass of ``length``."""
    h = np.hanning(length + 2)[1:-1]
    return signal.lfilter(h / h.sum(), [1.0], speed)


def gesture_samples(x: np.ndarray, fps: float, params: GestureParams = GestureParams()) -> Samples:
    """Samples of ``x (frames, K)`` where the group's motion comes to rest (8.2.2)."""
    n = len(x)
    if n < 2:
        return Samples(np.zeros(1, np.int64), np.zeros(1, np.int64))
    speed, accel = speed_acceleration(x, fps)
    win, short, longest = params.frames(fps)
    smooth = _threshold(speed, win)
    half = fit_window(fps) // 2
    cross = np.flatnonzero(np.sign(accel[:-1]) != np.sign(accel[1:]))
    cross = np.where(np.abs(accel[cross + 1]) < np.abs(accel[cross]), cross + 1, cross)
    frames, known = [0], [0]

    def candidates(beta: float, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        below = speed < beta * smooth
        c = cross[(cross > lo) & (cross < hi)]
        c = c[below[c]]
        if not c.size:
            return c, c
        # a window of interest closes at the first frame after it with the speed above threshold
        above = np.flatnonzero(~below)
        at = np.searchsorted(above, c)
        closes = np.where(at < above.size, above[np.minimum(at, above.size - 1)], n - 1)
        return c, np.minimum(closes + half, n - 1)

    def segment(lo: int, hi: int, beta: float) -> None:
        """Samples strictly between the samples ``lo`` and ``hi`` (appended in order)."""
        c, when = candidates(beta, lo, hi)
        chosen, last = [], lo
        for f, k in zip(c.tolist(), when.tolist()):
            if f - last >= short and hi - f >= short:
                chosen.append((f, k))
                last = f
        edges = [(lo, 0)] + chosen + [(hi, 0)]
        for (a, _), (b, kb) in zip(edges[:-1], edges[1:]):
            if b - a > longest:
                if beta + BETA_STEP <= BETA_LIMIT:
                    segment(a, b, beta + BETA_STEP)
                else:
                    pieces = -(-(b - a) // longest)
                    for p in range(1, pieces):
                        f = a + round(p * (b - a) / pieces)
                        frames.append(f)
                        known.append(min(a + longest + half, n - 1))
            if b != hi:
                frames.append(b)
                known.append(kb)

    segment(0, n - 1, params.beta)
    frames.append(n - 1)
    known.append(n - 1)
    return Samples(np.array(frames, np.int64), np.array(known, np.int64))


def frame_delays(samples: Samples, n: int, lookahead: int) -> np.ndarray:
    """Per frame, how many frames after it its segment can be decoded: frame f in the segment
    ending at sample m waits until sample m + ``lookahead`` is known (Hermite interpolation
    needs the sample after the segment's end (8-7): lookahead 1; the others: 0)."""
    f = np.arange(n)
    end = np.minimum(np.searchsorted(samples.frames, f, side="left"), len(samples.frames) - 1)
    needed = np.minimum(end + lookahead, len(samples.frames) - 1)
    return np.maximum(samples.known[needed] - f, 0)
