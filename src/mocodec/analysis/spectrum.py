"""Frequency content (000 §5.2.4): power spectral densities of the mean-removed DOFs
(autocovariance (5-9), PSD (5-10)), averaged over a group, by Welch's method, by
Blackman-Tukey (the thesis's general method) and by an autoregressive model fitted with the
autocorrelation method (its smooth spectra); and the frequencies that bound the motion: the
one below which 99% of the power lies and the 40 dB and 50 dB cut-offs (the highest
frequency at which the PSD is still within 40 or 50 dB of its peak; the thesis takes 50 dB
suppression as the limit of perceptible motion and finds about 3 Hz for conversation and 6 Hz
for dance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal

from mocodec.analysis.temporal import autocorrelation

AR_ORDER = 12  # the autoregressive spectrum's order


@dataclass(frozen=True)
class Spectrum:
    freqs: np.ndarray  # Hz
    power: np.ndarray  # PSD, units^2 / Hz, averaged over the columns given

    def db(self) -> np.ndarray:
        """The PSD in dB relative to its peak."""
        with np.errstate(divide="ignore"):
            return 10 * np.log10(self.power / self.power.max())


def _centred(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    return x - x.mean(axis=0)


def welch(x: np.ndarray, fps: float, segment_s: float = 8.0) -> Spectrum:
    """Welch PSD averaged over the columns of ``x`` (Hann windows of ``segment_s``, 50% overlap)."""
    x = _centred(x)
    nperseg = max(8, min(x.shape[0], int(round(segment_s * fps))))
    f, p = signal.welch(x, fs=fps, nperseg=nperseg, axis=0, detrend=False)
    return Spectrum(f, p.mean(axis=1))


def blackman_tukey(x: np.ndarray, fps: float, max_lag_s: float = 4.0) -> Spectrum:
    """Blackman-Tukey PSD: the Fourier transform of the autocovariance up to ``max_lag_s``,
    tapered by a Parzen lag window (whose transform is never negative, so neither is the
    estimate, and whose side lobes fall as 1/f^4), averaged over the columns."""
    x = _centred(x)
    n = x.shape[0]
    lags = max(2, min(n - 1, int(round(max_lag_s * fps))))
    acov = autocorrelation(x, lags) * x.var(axis=0)
    acov = np.nan_to_num(acov)
    taper = signal.windows.parzen(2 * lags + 1)[lags:][:, None]
    r = acov * taper
    size = 1 << int(np.ceil(np.log2(4 * lags)))
    sym = np.zeros((size, r.shape[1]))
    sym[: lags + 1] = r
    sym[-lags:] = r[1:][::-1]
    p = np.maximum(np.fft.rfft(sym, axis=0).real, 0.0) * 2.0 / fps
    p[0] /= 2.0
    return Spectrum(np.fft.rfftfreq(size, 1.0 / fps), p.mean(axis=1))


def ar_spectrum(x: np.ndarray, fps: float, order: int = AR_ORDER, points: int = 1024) -> Spectrum:
    """AR(``order``) PSD with coefficients from the autocorrelation (Yule-Walker) method,
    averaged over the columns (constant columns are skipped)."""
    x = _centred(x)
    freqs = np.linspace(0, fps / 2, points)
    z = np.exp(-2j * np.pi * freqs / fps)
    total = np.zeros(points)
    used = 0
    for col in x.T:
        var = col.var()
        if var == 0 or len(col) <= order:
            continue
        r = autocorrelation(col, order)[:, 0] * var
        a = linalg.solve_toeplitz(r[:-1], r[1:])
        noise = r[0] - np.dot(a, r[1:])
        denom = np.abs(1 - np.polyval(np.r_[a[::-1], 0.0], z)) ** 2
        total += max(noise, 0.0) / denom * 2.0 / fps
        used += 1
    return Spectrum(freqs, total / max(used, 1))


def power_frequency(spectrum: Spectrum, fraction: float = 0.99) -> float:
    """The frequency below which ``fraction`` of the power lies."""
    cum = np.cumsum(spectrum.power)
    if cum[-1] <= 0:
        return 0.0
    return float(spectrum.freqs[np.searchsorted(cum, fraction * cum[-1])])


def cutoff_frequency(spectrum: Spectrum, suppression_db: float) -> float:
    """The highest frequency at which the PSD is within ``suppression_db`` of its peak."""
    db = spectrum.db()
    above = np.flatnonzero(db >= -suppression_db)
    return float(spectrum.freqs[above[-1]]) if above.size else 0.0
