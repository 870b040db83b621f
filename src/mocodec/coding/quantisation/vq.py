"""Vector quantisation for 000 §7.9: the LBG codebook design with diameter splitting, and the
closed-loop coding kernels of the spatial and temporal coders.

:func:`lbg` starts from the centroid of the training set and splits one region at a time,
the widest, in two through its diameter (its two points furthest apart: the one furthest from
the centroid and the one furthest from that), with Lloyd's iterations (nearest-neighbour cells
(7-26), centroids) over all cells whenever the size reaches a power of two, until the codebook
has the size asked for; the codebooks met on the way (16, 32, ...) are kept, so one training
gives every size. Euclidean distance, as the thesis uses. Nothing random: the same data give the same
codebook.

The kernels code vectors either directly (``predictive`` false: the vector itself is
quantised, as the thesis does) or in a closed loop (the vector minus a prediction from the
decoded past: the last decoded sample of a channel for temporal vectors, the last decoded
frame of a group for spatial ones), so errors do not accumulate (fig. 7-4).
"""

from __future__ import annotations

import numba
import numpy as np

from mocodec.kernels import kernel

_CHUNK = 8192
LLOYD_ITERATIONS = 8


def nearest(data: np.ndarray, book: np.ndarray) -> np.ndarray:
    """Index of the nearest code vector (7-26) of every row of ``data``."""
    out = np.empty(len(data), dtype=np.int64)
    norms = (book**2).sum(axis=1)
    for a in range(0, len(data), _CHUNK):
        chunk = data[a : a + _CHUNK]
        out[a : a + _CHUNK] = np.argmin(norms[None, :] - 2.0 * chunk @ book.T, axis=1)
    return out


def _lloyd(data: np.ndarray, book: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """Lloyd's iterations; an empty cell keeps its code vector. Returns (book, cell of each row)."""
    for _ in range(iterations):
        cell = nearest(data, book)
        counts = np.bincount(cell, minlength=len(book))
        sums = np.zeros_like(book)
        np.add.at(sums, cell, data)
        book = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], book)
    return book, nearest(data, book)


def _diameter(members: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, float]:
    """Which members lie nearer the diameter's far end than its near end, and the diameter:
    its ends are the member furthest from the centroid and the member furthest from that."""
    if len(members) < 2:
        return np.zeros(len(members), dtype=bool), 0.0
    a = members[np.argmax(((members - centre) ** 2).sum(axis=1))]
    to_a = ((members - a) ** 2).sum(axis=1)
    b = members[np.argmax(to_a)]
    return to_a < ((members - b) ** 2).sum(axis=1), float(np.sqrt(to_a.max()))


class _Cells:
    """The training rows of every code vector, and each cell's diameter split."""

    def __init__(self, data: np.ndarray, book: np.ndarray, cell: np.ndarray):
        self.data, self.book = data, book
        order = np.argsort(cell, kind="stable")
        bounds = np.concatenate([[0], np.cumsum(np.bincount(cell, minlength=len(book)))])
        self.rows = [order[bounds[k] : bounds[k + 1]] for k in range(len(book))]
        self.splits = [_diameter(data[r], book[k]) for k, r in enumerate(self.rows)]

    def split_widest(self) -> bool:
        """Cut the cell of largest diameter in two (False when no cell holds two distinct points)."""
        k = int(np.argmax([d for _, d in self.splits]))
        side, width = self.splits[k]
        if width <= 0 or side.all() or not side.any():
            return False
        rows = self.rows[k]
        halves = [rows[side], rows[~side]]
        centres = [self.data[h].mean(axis=0) for h in halves]
        self.book = np.vstack([self.book, centres[1]])
        self.book[k] = centres[0]
        self.rows[k : k + 1] = [halves[0]]
        self.rows.append(halves[1])
        self.splits[k] = _diameter(self.data[halves[0]], centres[0])
        self.splits.append(_diameter(self.data[halves[1]], centres[1]))
        return True


def lbg(data: np.ndarray, sizes: list[int], iterations: int = LLOYD_ITERATIONS) -> dict[int, np.ndarray]:
    """Codebooks of the asked ``sizes`` for the rows of ``data``: one cell split at a time (the
    widest), Lloyd's iterations over all cells at every power of two and at each asked size.
    Each codebook is sorted by how often the training rows use its entries (most used first:
    small indices are cheap to code)."""
    data = np.asarray(data, dtype=np.float64)
    cells = _Cells(data, data.mean(axis=0, keepdims=True), np.zeros(len(data), dtype=np.int64))
    out: dict[int, np.ndarray] = {}
    for size in sorted(sizes):
        while len(cells.book) < size and cells.split_widest():
            n = len(cells.book)
            if n & (n - 1) == 0 or n == size:
                cells = _Cells(data, *_lloyd(data, cells.book, iterations))
        use = np.bincount(nearest(data, cells.book), minlength=len(cells.book))
        out[size] = cells.book[np.argsort(-use, kind="stable")]
    return out


@numba.njit(inline="always")
def _closest(v, book, rows):
    """Index of the nearest of the first ``rows`` entries of ``book`` to ``v``."""
    best, best_d = 0, np.inf
    for k in range(rows):
        d = 0.0
        for j in range(v.size):
            e = v[j] - book[k, j]
            d += e * e
            if d >= best_d:
                break
        if d < best_d:
            best, best_d = k, d
    return best


@kernel
def run_temporal(x, codes, decode, predictive, prev, book):
    """Temporal VQ (7.9.2) of ``x (blocks, L, K)``: per block and channel the vector of its L
    samples, minus the channel's last decoded sample (``predictive``; else the vector itself);
    ``codes (blocks, K)``; ``prev (K,)`` advanced. Returns the decoded ``(blocks, L, K)``."""
    m, k = codes.shape
    length = book.shape[1]
    out = np.empty((m, length, k))
    v = np.empty(length)
    for b in range(m):
        for c in range(k):
            base = prev[c] if predictive else 0.0
            if decode:
                i = codes[b, c]
            else:
                for j in range(length):
                    v[j] = x[b, j, c] - base
                i = _closest(v, book, book.shape[0])
                codes[b, c] = i
            for j in range(length):
                out[b, j, c] = base + book[i, j]
            prev[c] = out[b, length - 1, c]
    return out


@kernel
def run_spatial(x, codes, decode, predictive, prev, columns, starts, books, book_starts):
    """Spatial VQ (7.9.1) of ``x (n, C)``: per frame and group g the vector of its channels
    ``columns[starts[g]:starts[g + 1]]``, minus their last decoded values (``predictive``; else
    the vector itself), against the group's rows ``book_starts[g]:book_starts[g + 1]`` of
    ``books``; ``codes (n, G)``; ``prev (C,)`` advanced. Returns the decoded ``(n, C)``."""
    n, groups = codes.shape
    out = np.empty(x.shape if not decode else (n, prev.size))
    v = np.empty(books.shape[1])
    for t in range(n):
        for g in range(groups):
            cols = columns[starts[g] : starts[g + 1]]
            book = books[book_starts[g] : book_starts[g + 1], : cols.size]
            if decode:
                i = codes[t, g]
            else:
                for j in range(cols.size):
                    c = cols[j]
                    v[j] = x[t, c] - (prev[c] if predictive else 0.0)
                i = _closest(v[: cols.size], book, book.shape[0])
                codes[t, g] = i
            for j in range(cols.size):
                c = cols[j]
                y = (prev[c] if predictive else 0.0) + book[i, j]
                out[t, c] = y
                prev[c] = y
    return out
