"""Scalar quantisers of 000 §7.2-7.3.

- :class:`UniformQuantiser`: N levels between the limits theta_L and theta_U, decision levels
  d_i = theta_L + i (theta_U - theta_L) / N (7-4), reconstruction at the midpoints (7-3).
- :class:`MuLawQuantiser`: bipolar mu-law, positive-half decision levels
  d_i = theta_MAX ((1 + mu)^(i / (N/2)) - 1) / mu, the inverse of the mu-law compressor
  log(1 + mu |x| / theta_MAX) / log(1 + mu) read off (7-5), mirrored for negative inputs,
  midpoint reconstruction (7-3); indices found by binary search as in the thesis.
- :class:`AdaptiveQuantiser`: the feedback quantiser (7-7), Delta(n) = beta(c(n-1)) Delta(n-1),
  a uniform mid-rise quantiser whose step follows the previous code through a multiplier
  table. The thesis's table is heuristic and not printed; we use Jayant's multipliers for
  2- to 4-bit adaptive quantisers (small codes shrink the step, large ones grow it), and
  geometric interpolation for other sizes. The decoder tracks the step from the codes alone.

Indices are int64 in 0..N-1 (the adaptive quantiser's are signed, -N/2..N/2-1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec.kernels import kernel

NO_STEP = -(1 << 20)  # step exponent of a row with nothing to quantise
FINEST_STEP = -40  # 2^(-40/4) = 0.001 degree (or unit): rows that vary less
# than this (float noise in unused channels) quantise to zero

JAYANT = {
    4: (0.8, 1.6),
    8: (0.9, 0.9, 1.25, 1.75),
    16: (0.9, 0.9, 0.9, 0.9, 1.2, 1.6, 2.0, 2.4),
}


def _check_levels(levels: int) -> int:
    if int(levels) != levels or levels < 2:
        raise ValueError(f"a quantiser needs at least 2 levels, got {levels}")
    return int(levels)


@dataclass(frozen=True)
class UniformQuantiser:
    low: float
    high: float
    levels: int

    def __post_init__(self):
        _check_levels(self.levels)
        if not self.high > self.low:
            raise ValueError(f"quantiser limits must increase, got {self.low}..{self.high}")

    @property
    def step(self) -> float:
        return (self.high - self.low) / self.levels

    def decision_levels(self) -> np.ndarray:
        """d_0..d_N (7-4)."""
        return self.low + np.arange(self.levels + 1) * self.step

    def quantise(self, x: np.ndarray) -> np.ndarray:
        i = np.floor((np.asarray(x, dtype=np.float64) - self.low) / self.step)
        return np.clip(i, 0, self.levels - 1).astype(np.int64)

    def reconstruct(self, index: np.ndarray) -> np.ndarray:
        """r_i = (d_i + d_(i+1)) / 2 (7-3)."""
        return self.low + (np.asarray(index, dtype=np.float64) + 0.5) * self.step

    def table(self) -> tuple[np.ndarray, np.ndarray]:
        """(the N-1 inner decision levels, the N reconstruction levels), for table-driven
        quantisers (:func:`mocodec.coding.quantisation.predictive.run_table`)."""
        return self.decision_levels()[1:-1], self.reconstruct(np.arange(self.levels))


@dataclass(frozen=True)
class MuLawQuantiser:
    mu: float
    limit: float  # theta_MAX: inputs beyond +-limit land in the outer levels
    levels: int  # N, even: N/2 levels each side of zero

    def __post_init__(self):
        _check_levels(self.levels)
        if self.levels % 2:
            raise ValueError(f"a bipolar mu-law quantiser needs an even number of levels, got {self.levels}")
        if not self.mu > 0 or not self.limit > 0:
            raise ValueError("mu and the limit must be positive")

    def decision_levels(self) -> np.ndarray:
        """Positive-half decision levels d_0 = 0 .. d_(N/2) = limit (7-5)."""
        half = self.levels // 2
        return self.limit * ((1.0 + self.mu) ** (np.arange(half + 1) / half) - 1.0) / self.mu

    def quantise(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        half = self.levels // 2
        mag = np.clip(np.searchsorted(self.decision_levels(), np.abs(x), side="right") - 1, 0, half - 1)
        return np.where(x >= 0, half + mag, half - 1 - mag).astype(np.int64)

    def reconstruct(self, index: np.ndarray) -> np.ndarray:
        d = self.decision_levels()
        mid = 0.5 * (d[:-1] + d[1:])
        index = np.asarray(index, dtype=np.int64)
        half = self.levels // 2
        return np.where(
            index >= half, mid[np.clip(index - half, 0, half - 1)], -mid[np.clip(half - 1 - index, 0, half - 1)]
        )

    def table(self) -> tuple[np.ndarray, np.ndarray]:
        """(the N-1 inner decision levels, the N reconstruction levels), mirrored about 0."""
        d = self.decision_levels()[:-1]
        return np.r_[-d[:0:-1], d], self.reconstruct(np.arange(self.levels))


def even_levels(levels: int) -> int:
    """The level count of a bipolar (mu-law) or mid-rise adaptive quantiser: N rounded up to
    even, as these need N/2 levels each side of zero."""
    return max(2, levels + levels % 2)


def table(law: str, levels: int, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """The normalised table (inner decision levels, reconstruction levels) over [-1, 1] of a
    ``uniform`` quantiser with N levels or a ``mulaw`` one with N rounded up to even."""
    if law == "uniform":
        return UniformQuantiser(-1.0, 1.0, levels).table()
    return MuLawQuantiser(mu, 1.0, even_levels(levels)).table()


def multipliers(levels: int) -> np.ndarray:
    """beta for each code magnitude 0..N/2-1 (7-7): Jayant's table for 4, 8 and 16 levels,
    otherwise from 0.85 up to 2.4 geometrically (for 2 levels: shrink 0.9 / grow 1.5 is
    impossible with one magnitude, so a 2-level quantiser does not adapt)."""
    levels = _check_levels(levels)
    if levels in JAYANT:
        return np.array(JAYANT[levels])
    half = levels // 2
    if half == 1:
        return np.ones(1)
    low = half // 2
    return np.r_[np.full(low, 0.9), np.geomspace(1.1, 2.4, half - low)]


@kernel
def _adaptive(x, levels, step0, step_min, step_max, beta, decode_codes):
    """Shared loop: quantise x (or, with decode_codes, only follow the given codes)."""
    n = decode_codes.size if decode_codes.size else x.size
    half = levels // 2
    codes = np.empty(n, dtype=np.int64)
    out = np.empty(n)
    step = step0
    for k in range(n):
        if decode_codes.size:
            c = decode_codes[k]
        else:
            c = int(np.floor(x[k] / step))
            c = min(max(c, -half), half - 1)
        codes[k] = c
        out[k] = (c + 0.5) * step
        mag = c if c >= 0 else -c - 1
        step = min(max(step * beta[mag], step_min), step_max)
    return codes, out


@dataclass(frozen=True)
class AdaptiveQuantiser:
    """Feedback-adaptive uniform mid-rise quantiser (7-7) for zero-mean inputs (differences,
    prediction errors). Codes are -N/2..N/2-1; the step starts at ``step`` and stays within
    [step_min, step_max]."""

    levels: int
    step: float
    step_min: float
    step_max: float

    def __post_init__(self):
        _check_levels(self.levels)
        if self.levels % 2:
            raise ValueError(f"the adaptive quantiser needs an even number of levels, got {self.levels}")
        if not 0 < self.step_min <= self.step <= self.step_max:
            raise ValueError("need 0 < step_min <= step <= step_max")

    def quantise(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(codes, reconstruction) of a sequence, the step adapting as it goes."""
        return _adaptive(
            np.ascontiguousarray(x, dtype=np.float64),
            self.levels,
            self.step,
            self.step_min,
            self.step_max,
            multipliers(self.levels),
            np.zeros(0, dtype=np.int64),
        )

    def reconstruct(self, codes: np.ndarray) -> np.ndarray:
        codes = np.ascontiguousarray(codes, dtype=np.int64)
        if codes.size and (codes.min() < -(self.levels // 2) or codes.max() >= self.levels // 2):
            raise ValueError(f"adaptive quantiser codes must be in -{self.levels // 2}..{self.levels // 2 - 1}")
        if codes.size == 0:
            return np.zeros(0)
        return _adaptive(
            np.zeros(0), self.levels, self.step, self.step_min, self.step_max, multipliers(self.levels), codes
        )[1]


def step_exponents(kept: np.ndarray, qp: int) -> np.ndarray:
    """Quarter-octave exponent e of each row's step 2^(e/4) >= max|kept| / (2^(QP-1) - 1)."""
    peak = np.abs(kept).max(axis=1)
    with np.errstate(divide="ignore"):
        e = np.ceil(4 * np.log2(peak / (2 ** (qp - 1) - 1)))
    return np.where(peak > 0, np.maximum(e, FINEST_STEP), NO_STEP).astype(np.int64)


def steps(exponents: np.ndarray) -> np.ndarray:
    return np.where(exponents == NO_STEP, 0.0, 2.0 ** (exponents / 4.0))
