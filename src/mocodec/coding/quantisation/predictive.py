"""The closed-loop sample coders of 000 §7.2-7.6, for many channels at once (numba).

Both kernels follow fig. 7-4: the encoder predicts each sample from the *decoded* past (the
decoder's own reconstruction), quantises the difference (7-10) and adds the quantised
difference back (7-11), so quantisation errors do not accumulate. The decoder runs the same
loop on the codes, so it reproduces the encoder's reconstruction bit for bit. Both carry
their state between calls (in arrays the caller keeps), so a stream can be coded a packet at
a time and decodes exactly as the whole clip.

* :func:`run_table`: a fixed quantiser given by its normalised decision and reconstruction
  levels (uniform (7-4) or mu-law (7-5), midpoint reconstruction (7-3)) scaled per channel,
  and the first-order predictor ``p = centre + a (y(n-1) - centre)`` (7-12 with p = 1, the
  coefficient from (7-14)). With ``a = 0`` it is direct quantisation about ``centre`` (7.2).
* :func:`run_adaptive`: the feedback adaptive quantiser (7-7), and an order-2 predictor whose
  coefficients are recomputed from the last ``window`` decoded samples by the autocorrelation
  method (7-16 to 7-18) every ``update`` samples: backward adaptation, nothing sent (7.6).
  With ``order = 0`` the prediction is ``centre``: adaptive direct quantisation (7.3).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numba
import numpy as np

from mocodec.errors import CorruptStreamError
from mocodec.kernels import kernel


@kernel
def run_table(x, codes, decode, prev, centre, scale, a, decisions, levels_out):
    """Code (or, with ``decode``, decode) ``x (n, K)`` / ``codes (n, K)``; ``prev (K,)`` is the
    last decoded sample and is advanced. ``decisions`` are the N-1 inner decision levels and
    ``levels_out`` the N reconstruction levels, both for a unit range. Returns the decoded
    samples; ``codes`` (signed, -N/2..N/2-1) are filled when encoding."""
    n, k = codes.shape
    half = levels_out.size // 2
    out = np.empty((n, k))
    for t in range(n):
        for c in range(k):
            p = centre[c] + a[c] * (prev[c] - centre[c])
            if decode:
                i = codes[t, c] + half
            else:
                i = np.searchsorted(decisions, (x[t, c] - p) / scale[c], side="right")
                codes[t, c] = i - half
            y = p + levels_out[i] * scale[c]
            out[t, c] = y
            prev[c] = y
    return out


@numba.njit(inline="always")
def _coefficients(hist, filled, pos, c, order):
    """(mean, a1, a2) of channel c from its last ``filled`` decoded samples in the ring
    ``hist``: the autocorrelation method (7-16 to 7-18) about the window mean."""
    w = hist.shape[0]
    m = 0.0
    for i in range(filled):
        m += hist[(pos - 1 - i) % w, c]
    m /= filled
    r0 = 0.0
    r1 = 0.0
    r2 = 0.0
    for i in range(filled):
        v = hist[(pos - 1 - i) % w, c] - m
        r0 += v * v
        if i + 1 < filled:
            r1 += v * (hist[(pos - 2 - i) % w, c] - m)
        if i + 2 < filled:
            r2 += v * (hist[(pos - 3 - i) % w, c] - m)
    if order == 1:
        return (m, r1 / r0, 0.0) if r0 > 1e-12 else (m, 1.0, 0.0)
    det = r0 * r0 - r1 * r1
    if r0 <= 1e-12 or det <= 1e-9 * r0 * r0:
        return m, 1.0, 0.0  # (near) constant window: repeat the last sample
    return m, (r1 * r0 - r1 * r2) / det, (r0 * r2 - r1 * r1) / det


@kernel
def run_adaptive(x, codes, decode, hist, counters, coef, step, centre, step_lo, step_hi, beta, levels, order, update):
    """Code (or decode) with the adaptive quantiser and predictor. State the caller keeps:
    ``hist (W, K)`` ring of decoded samples, ``counters`` = [write position, samples seen],
    ``coef (K, 3)`` = (mean, a1, a2), ``step (K,)``. Codes are -N/2..N/2-1 (mid-rise)."""
    n, k = codes.shape
    w = hist.shape[0]
    half = levels // 2
    out = np.empty((n, k))
    for t in range(n):
        pos = counters[0]
        seen = counters[1]
        filled = min(seen, w)
        if order > 0 and filled >= 3 and seen % update == 0:
            for c in range(k):
                m, a1, a2 = _coefficients(hist, filled, pos, c, order)
                coef[c, 0] = m
                coef[c, 1] = a1
                coef[c, 2] = a2
        for c in range(k):
            if order == 0 or seen == 0:
                p = centre[c]
            else:
                y1 = hist[(pos - 1) % w, c]
                y2 = hist[(pos - 2) % w, c] if seen >= 2 else y1
                m = coef[c, 0]
                p = m + coef[c, 1] * (y1 - m) + coef[c, 2] * (y2 - m)
            if decode:
                q = codes[t, c]
            else:
                q = int(np.floor((x[t, c] - p) / step[c]))
                q = min(max(q, -half), half - 1)
                codes[t, c] = q
            y = p + (q + 0.5) * step[c]
            out[t, c] = y
            hist[pos, c] = y
            mag = q if q >= 0 else -q - 1
            step[c] = min(max(step[c] * beta[mag], step_lo[c]), step_hi[c])
        counters[0] = (pos + 1) % w
        counters[1] = seen + 1
    return out


_HALF_MAX = 65504.0  # the largest float16
FIRST_STEP_DEG_S = 90.0  # range per second when the first frames show no change to go by


def lag_one(d: np.ndarray, default: float = 1.0) -> np.ndarray:
    """Per column the least-squares coefficient a of d(n) ~ a d(n-1) (7-14): R(1)/R(0), or
    ``default`` where there is nothing to go by (fewer than 3 samples, or d(n-1) all zero)."""
    if len(d) < 3:
        return np.full(d.shape[1], default)
    r0 = (d[:-1] ** 2).sum(axis=0)
    r1 = (d[1:] * d[:-1]).sum(axis=0)
    return np.where(r0 > 0, r1 / np.where(r0 > 0, r0, 1.0), default)


def first_order(values: np.ndarray) -> np.ndarray:
    """Per channel :func:`lag_one` of x(n) - x0, within [0, 1]."""
    return np.clip(lag_one(values - values[:1]), 0.0, 1.0)


def difference_range(values: np.ndarray, fps: float) -> np.ndarray:
    """The largest frame-to-frame change per channel (a default when there is one frame)."""
    if len(values) < 2:
        return np.full(values.shape[1], FIRST_STEP_DEG_S / fps)
    return np.abs(np.diff(values, axis=0)).max(axis=0)


RANGE_FRACTIONS = 2.0 ** -np.arange(5.0)


def best_range(
    values: np.ndarray,
    top: np.ndarray,
    centre: np.ndarray,
    coefficient: np.ndarray,
    decisions: np.ndarray,
    levels_out: np.ndarray,
) -> np.ndarray:
    """Per channel the quantiser range, a fraction (1, 1/2, .. 1/16) of the largest
    frame-to-frame change, whose closed loop codes ``values`` with the least squared error:
    the step a fixed quantiser should have for these data, in the spirit of Max's optimum
    quantiser (7.2) but measured on the coder itself. The largest change alone sets a coarse
    step that every quiet frame pays for as idle noise; too fine a step overloads on fast
    moves, and in a closed loop an overload lasts until the output catches up. ``top`` is the
    largest change (:func:`difference_range`); ``centre`` and ``coefficient`` are the
    predictor's, as the side information carries them."""
    if len(values) < 3:
        return top
    x = np.ascontiguousarray(values)
    codes = np.zeros(x.shape, dtype=np.int64)
    best, best_err = top.copy(), np.full(top.size, np.inf)
    for f in RANGE_FRACTIONS:
        span = np.where(top > 0, top * f, 1.0)
        decoded = run_table(x, codes, False, centre.copy(), centre, span, coefficient, decisions, levels_out)
        err = ((decoded - x) ** 2).sum(axis=0)
        better = err < best_err
        best[better], best_err[better] = span[better], err[better]
    return np.where(top > 0, best, top)


@dataclass
class ChannelParams:
    """Per-channel side information of a waveform coder's first packet: which channels are
    constant (only their value is sent), a centre (float32: the first value, or the middle of
    the range), a scale (float16 rounded up: the quantiser's range or first step) and a predictor
    coefficient (float16). Encoder and decoder both work with the rounded values."""

    constant: np.ndarray  # (C,) bool
    centre: np.ndarray  # (C,)
    scale: np.ndarray  # (C,)
    coefficient: np.ndarray  # (C,)

    def __post_init__(self):
        self.centre = np.asarray(self.centre, dtype=np.float32).astype(np.float64)
        scale = np.clip(np.asarray(self.scale, dtype=np.float64), 2.0**-24, _HALF_MAX)
        half = scale.astype(np.float16)
        half = np.where(half.astype(np.float64) < scale, np.nextafter(half, np.float16(np.inf)), half)
        self.scale = half.astype(np.float64)  # rounded up: a range still covers the data
        self.coefficient = np.asarray(self.coefficient, dtype=np.float16).astype(np.float64)
        self.constant = np.asarray(self.constant, dtype=bool)

    @property
    def active(self) -> np.ndarray:
        return np.flatnonzero(~self.constant)

    def pack(self) -> bytes:
        a = self.active
        return (
            struct.pack("<I", self.constant.size)
            + np.packbits(self.constant).tobytes()
            + self.centre.astype("<f4").tobytes()
            + self.scale[a].astype("<f2").tobytes()
            + self.coefficient[a].astype("<f2").tobytes()
        )

    @classmethod
    def unpack(cls, data: bytes, channels: int) -> ChannelParams:
        (count,) = struct.unpack_from("<I", data)
        if count != channels:
            raise CorruptStreamError(f"header is for {count} channels, the skeleton has {channels}")
        flags = (channels + 7) // 8
        constant = np.unpackbits(np.frombuffer(data, np.uint8, flags, 4))[:channels].astype(bool)
        k = int((~constant).sum())
        if len(data) != 4 + flags + 4 * channels + 4 * k:
            raise CorruptStreamError(f"header of {len(data)} bytes does not fit {channels} channels")
        centre = np.frombuffer(data, "<f4", channels, 4 + flags)
        half = np.frombuffer(data, "<f2", 2 * k, 4 + flags + 4 * channels).astype(np.float64)
        scale, coefficient = np.ones(channels), np.zeros(channels)
        scale[~constant], coefficient[~constant] = half[:k], half[k:]
        if not (np.isfinite(centre).all() and np.isfinite(half).all() and (scale > 0).all()):
            raise CorruptStreamError("header holds non-finite or non-positive parameters")
        return cls(constant, centre, scale, coefficient)


class _SampleCoder:
    """A kernel over all channels with its state: constant channels are their centre and send
    nothing; codes are -N/2..(N-1)/2, one column per active channel."""

    def __init__(self, params: ChannelParams, levels: int):
        self.params, self.levels = params, levels
        self.active = params.active

    def _kernel(self, x: np.ndarray, codes: np.ndarray, decode: bool) -> np.ndarray:
        raise NotImplementedError

    def _run(self, x: np.ndarray, codes: np.ndarray, decode: bool) -> np.ndarray:
        out = np.empty((len(codes), self.params.centre.size))
        out[:] = self.params.centre
        out[:, self.active] = self._kernel(x, codes, decode)
        return out

    def code(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        codes = np.zeros((len(frames), self.active.size), dtype=np.int64)
        return codes, self._run(np.ascontiguousarray(frames[:, self.active]), codes, False)

    def uncode(self, codes: np.ndarray) -> np.ndarray:
        codes = np.clip(codes, -(self.levels // 2), (self.levels - 1) // 2)
        return self._run(np.zeros((len(codes), 0)), np.ascontiguousarray(codes), True)


class TableCoder(_SampleCoder):
    """:func:`run_table`; each active channel starts from its centre."""

    def __init__(self, params: ChannelParams, decisions: np.ndarray, levels_out: np.ndarray):
        super().__init__(params, levels_out.size)
        self.decisions, self.levels_out = decisions, levels_out
        self.prev = params.centre[self.active].copy()

    def _kernel(self, x, codes, decode):
        p, a = self.params, self.active
        return run_table(
            x, codes, decode, self.prev, p.centre[a], p.scale[a], p.coefficient[a], self.decisions, self.levels_out
        )


class AdaptiveCoder(_SampleCoder):
    """:func:`run_adaptive`. ``params.scale`` is each channel's first step; the step stays
    within 2^-10..2^6 of it."""

    def __init__(self, params: ChannelParams, levels: int, order: int, window: int, update: int, beta: np.ndarray):
        super().__init__(params, levels)
        self.order, self.update, self.beta = order, update, beta
        a = self.active
        self.hist = np.zeros((max(window, 3), a.size))
        self.counters = np.zeros(2, dtype=np.int64)
        self.coef = np.tile([0.0, 1.0, 0.0], (a.size, 1))
        self.step = params.scale[a].copy()
        self.step_lo, self.step_hi = self.step * 2.0**-10, self.step * 2.0**6

    def _kernel(self, x, codes, decode):
        return run_adaptive(
            x,
            codes,
            decode,
            self.hist,
            self.counters,
            self.coef,
            self.step,
            self.params.centre[self.active],
            self.step_lo,
            self.step_hi,
            self.beta,
            self.levels,
            self.order,
            self.update,
        )


@kernel
def run_uniform(x, codes, decode, prev, a, step):
    """First-order closed-loop prediction ``p = a y(n-1)`` (7-12) and a uniform mid-tread
    quantiser without overload (its codes are entropy coded, so large ones are rare, not
    forbidden): code (or decode) ``x (n, K)`` / ``codes (n, K)``; ``prev (K,)`` is advanced."""
    n, k = codes.shape
    out = np.empty((n, k))
    for t in range(n):
        for c in range(k):
            p = a[c] * prev[c]
            if not decode:
                codes[t, c] = np.int64(np.round((x[t, c] - p) / step[c]))
            y = p + codes[t, c] * step[c]
            out[t, c] = y
            prev[c] = y
    return out
