"""Multi-level 1-D wavelet transforms of many channels at once (PyWavelets).

``periodization`` makes a segment of N frames give about N coefficients (exactly N when N is
divisible by 2^levels), which is what bit-plane coders (001 ch. 6) need; but it joins the end
of a segment to its start, so a motion that ends elsewhere than it began (any walk) gets a jump
that costs coefficients at every scale. ``symmetric`` mirrors the ends instead: a few more
coefficients, no jump; coders that send only their largest coefficients prefer it. Names:
``db2`` is Daubechies D4 (4 taps), ``bior4.4`` is CDF 9/7. Coefficients of a channel are laid
out coarsest first: [approximation, details of the coarsest level, ..., finest details].
"""

from __future__ import annotations

import warnings
from functools import lru_cache

import numpy as np
import pywt

from mocodec.coding.transforms import periodized

WAVELETS = {"d4": "db2", "cdf97": "bior4.4", "haar": "haar"}


@lru_cache(maxsize=16)
def _wavelet(name: str) -> pywt.Wavelet:
    """PyWavelets' wavelet of one of our names (or its own), made once: a transform given the
    object skips the lookup a name costs on every call."""
    return pywt.Wavelet(WAVELETS.get(name, name))


@lru_cache(maxsize=16)
def filters(wavelet: str, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """A wavelet's low- and high-pass filters, ``dec`` (analysis) or ``rec`` (synthesis), as
    PyWavelets has them (:mod:`.periodized`'s kernels take them)."""
    w = _wavelet(wavelet)
    lo, hi = (w.dec_lo, w.dec_hi) if kind == "dec" else (w.rec_lo, w.rec_hi)
    out = np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64)
    for f in out:
        f.setflags(write=False)
    return out


def _compiled(x: np.ndarray, levels: int, wavelet: str, mode: str) -> bool:
    """Whether :mod:`.periodized`'s kernels transform ``x (rows, n)`` with PyWavelets' floats: a
    periodised transform of rows whose length is a multiple of 2^levels."""
    return mode == "periodization" and x.ndim == 2 and x.shape[-1] % (1 << levels) == 0


def max_levels(frames: int, wavelet: str) -> int:
    """The deepest decomposition PyWavelets does without boundary warnings (0 for tiny segments)."""
    return pywt.dwt_max_level(frames, _wavelet(wavelet).dec_len)


@lru_cache(maxsize=1024)
def band_lengths(frames: int, wavelet: str, levels: int, mode: str = "periodization") -> tuple[int, ...]:
    """Lengths of the bands of a ``frames``-long signal, coarsest first."""
    taps = _wavelet(wavelet).dec_len
    lengths, n = [], frames
    for _ in range(levels):
        n = pywt.dwt_coeff_len(n, taps, mode)
        lengths.append(n)
    return (lengths[-1], *lengths[::-1]) if levels else (frames,)


def forward(x: np.ndarray, wavelet: str, levels: int, mode: str = "periodization") -> np.ndarray:
    """Wavelet coefficients of every row of ``x`` ``(channels, frames)``, concatenated."""
    x = np.asarray(x, dtype=np.float64)
    if levels == 0:
        return x.copy()
    if _compiled(x, levels, wavelet, mode):
        return periodized.forward_rows(np.ascontiguousarray(x), levels, *filters(wavelet, "dec"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # deep levels on short segments
        bands = pywt.wavedec(x, _wavelet(wavelet), mode=mode, level=levels, axis=-1)
    return np.concatenate(bands, axis=-1)


def inverse(coeffs: np.ndarray, frames: int, wavelet: str, levels: int, mode: str = "periodization") -> np.ndarray:
    """Inverse of :func:`forward` for signals of ``frames`` samples."""
    coeffs = np.asarray(coeffs, dtype=np.float64)
    if levels == 0:
        return coeffs.copy()
    if coeffs.shape[-1] == frames and _compiled(coeffs, levels, wavelet, mode):
        return periodized.inverse_rows(np.ascontiguousarray(coeffs), levels, *filters(wavelet, "rec"))
    bounds = np.cumsum(band_lengths(frames, wavelet, levels, mode))[:-1]
    bands = np.split(coeffs, bounds, axis=-1)
    out = pywt.waverec(bands, _wavelet(wavelet), mode=mode, axis=-1)
    return out[..., :frames]


@lru_cache(maxsize=64)
def matrices(frames: int, wavelet: str, levels: int, mode: str = "periodization") -> tuple[np.ndarray, np.ndarray]:
    """(analysis ``(m, frames)``, synthesis ``(frames, m)``) matrices of the transform, so that
    coefficients are ``A @ x`` and the signal ``S @ c``: short segments of many channels
    transform as one matrix product."""
    analysis = forward(np.eye(frames), wavelet, levels, mode).T
    synthesis = inverse(np.eye(analysis.shape[0]), frames, wavelet, levels, mode).T
    analysis.setflags(write=False)
    synthesis.setflags(write=False)
    return analysis, synthesis
