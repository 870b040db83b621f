"""Fixed-length blocks of frames for the block coders of 000 §7.8 (dct, subband): cutting a
signal into blocks, and the decoder's block-edge smoothing of §7.8.1, streamed.

Blocks coded on their own meet with a small step (their errors are independent); the decoder
replaces the two samples either side of every block edge by [1 2 1] / 4 of their neighbours,
which trades a little MSE for the periodic jerk of the edges. Streamed, the newest frame of a
packet waits for the next packet, whose first frame it is smoothed with.
"""

from __future__ import annotations

import numpy as np


def split(x: np.ndarray, n: int) -> np.ndarray:
    """``x (frames, K)`` as ``(blocks, n, K)``, the last block padded with its last frame."""
    m = -(-len(x) // n)
    padded = np.vstack((x, np.repeat(x[-1:], m * n - len(x), axis=0))) if m * n > len(x) else x
    return padded.reshape(m, n, x.shape[1])


def smooth_edges(values: np.ndarray, edges: list[int]) -> np.ndarray:
    """The samples either side of each edge (an edge at i lies between i - 1 and i) replaced
    by [1 2 1] / 4 of their neighbours, from the unsmoothed values."""
    out = values.copy()
    for i in edges:
        if 2 <= i <= len(values) - 2:
            out[i - 1] = (values[i - 2] + 2 * values[i - 1] + values[i]) / 4
            out[i] = (values[i - 1] + 2 * values[i] + values[i + 1]) / 4
    return out


class EdgeSmoother:
    """:func:`smooth_edges` over a stream of decoded packets of whole ``n``-frame blocks: each
    packet's newest frame is held back until the next packet (or the end) shows what follows it,
    so a clip decoded at once and the same clip streamed give the same frames."""

    def __init__(self, n: int):
        self.n = n
        self.tail: np.ndarray | None = None  # the last two unsmoothed frames (the last one not yet out)

    def push(self, frames: np.ndarray, last: bool) -> np.ndarray:
        held = 0 if self.tail is None else len(self.tail)
        seq = frames if self.tail is None else np.vstack((self.tail, frames))
        edges = [held + i for i in range(0 if held else self.n, len(frames), self.n)]
        out = smooth_edges(seq, edges)
        start = 1 if held == 2 else 0
        if last:
            self.tail = None
            return out[start:]
        self.tail = seq[-2:] if len(seq) >= 2 else seq
        return out[start : len(seq) - 1]
