"""Run-length coding of zero runs (001 §3.2 step 8: thresholded wavelet coefficients are
mostly zero). A sequence becomes (runs, values): ``runs[k]`` zeros come before the k-th
non-zero value; ``tail`` zeros end the sequence."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ZeroRuns:
    runs: np.ndarray  # zeros before each non-zero value
    values: np.ndarray  # the non-zero values in order
    tail: int  # zeros after the last non-zero value

    @property
    def length(self) -> int:
        return int(self.runs.sum()) + self.values.size + self.tail


def encode_zero_runs(x: np.ndarray) -> ZeroRuns:
    x = np.asarray(x).ravel()
    nz = np.flatnonzero(x)
    runs = np.diff(np.r_[-1, nz]) - 1
    tail = x.size - (int(nz[-1]) + 1 if nz.size else 0)
    return ZeroRuns(runs.astype(np.int64), x[nz], int(tail))


def decode_zero_runs(runs: ZeroRuns) -> np.ndarray:
    if runs.runs.size != runs.values.size or (runs.runs.size and runs.runs.min() < 0) or runs.tail < 0:
        raise ValueError("zero runs: runs and values must pair up and be non-negative")
    if np.any(runs.values == 0):
        raise ValueError("zero runs: a run value is zero")
    out = np.zeros(runs.length, dtype=runs.values.dtype if runs.values.size else np.int64)
    out[np.cumsum(runs.runs + 1) - 1] = runs.values
    return out
