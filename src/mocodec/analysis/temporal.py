"""Temporal statistics (000 §5.2.3): autocorrelation, the wide-sense-stationarity check
across time origins (fig. 5-3, 5-4) and the Markov model fit (5-8).

(5-8) is damaged in the OCR ("phi(m) = k-alll" with squares above). We read it as the
autocorrelation of a smooth (second-order) process, phi(m) = A exp(-a m^2): it is flat at lag
0 as the autocorrelation of a differentiable signal must be, and the thesis's constants (a =
2.5e-4 conversational, 0.015 dance, at 30 Hz, fitted for m < 10) give the slow and fast decays
its figures show under this reading. A first-order (exponential) model would have a cusp at 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

THESIS_MARKOV_A = {"conversation": 2.5e-4, "dance": 0.015}  # at 30 Hz


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised autocovariance phi(m) / phi(0) for m = 0..max_lag of each column of ``x``
    ((5-7) with the mean removed), ``(max_lag + 1, columns)``; NaN for constant columns."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    n = x.shape[0]
    max_lag = min(max_lag, n - 1)
    x = x - x.mean(axis=0)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.fft.rfft(x, size, axis=0)
    acov = np.fft.irfft(spec * spec.conj(), size, axis=0)[: max_lag + 1] / n
    with np.errstate(invalid="ignore", divide="ignore"):
        return acov / acov[0]


@dataclass(frozen=True)
class Stationarity:
    origins_s: np.ndarray  # window start times
    means: np.ndarray  # (origins, columns): fig. 5-3
    acfs: np.ndarray  # (origins, lags, columns): fig. 5-4
    mean_drift: np.ndarray  # per column: std of the window means / overall std
    acf_spread: np.ndarray  # per column: largest spread of the window ACFs at any lag


def stationarity(
    x: np.ndarray, fps: float, window_s: float = 10.0, count: int = 6, max_lag_s: float = 1.0
) -> Stationarity:
    """Mean and autocorrelation over ``count`` windows at evenly spaced time origins. Small
    drift and spread support the wide-sense-stationary assumption of §5.2.3. Windows are
    shortened to a third of a short clip so there are always several."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    n = x.shape[0]
    w = max(2, min(n // 3, int(round(window_s * fps))))
    starts = np.unique(np.linspace(0, n - w, count).astype(int))
    lag = max(1, min(w - 1, int(round(max_lag_s * fps))))
    means = np.stack([x[s : s + w].mean(axis=0) for s in starts])
    acfs = np.stack([autocorrelation(x[s : s + w], lag) for s in starts])
    std = x.std(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        drift = means.std(axis=0) / std
    finite = np.isfinite(acfs)  # a window where a DOF is constant has no ACF
    per_lag = np.where(finite, acfs, -np.inf).max(axis=0) - np.where(finite, acfs, np.inf).min(axis=0)
    spread = np.fmax.reduce(np.where(np.isfinite(per_lag), per_lag, np.nan), axis=0)
    return Stationarity(starts / fps, means, acfs, drift, spread)


@dataclass(frozen=True)
class MarkovFit:
    amplitude: float  # A
    decay: float  # a, per squared sample of lag
    rms_error: float  # over the fitted lags

    def model(self, lags: np.ndarray) -> np.ndarray:
        return self.amplitude * np.exp(-self.decay * np.square(lags))

    def decay_at(self, fit_fps: float, fps: float = 30.0) -> float:
        """a for lags counted at ``fps`` when the fit was made at ``fit_fps`` (the thesis's
        constants are at 30 Hz): a lag of m samples at fit_fps is m fps / fit_fps there."""
        return self.decay * (fit_fps / fps) ** 2


def markov_fit(acf: np.ndarray, max_lag: int = 10) -> MarkovFit:
    """Fit phi(m) = A exp(-a m^2) with A = 1 (as the thesis does for a normalised
    autocorrelation) over the lags 0..max_lag-1 where phi is positive: least squares on
    log phi = -a m^2."""
    acf = np.asarray(acf, dtype=np.float64)[:max_lag]
    lags = np.arange(len(acf))
    ok = (acf > 0) & (lags > 0)
    if not ok.any():
        return MarkovFit(1.0, float("nan"), float("nan"))
    m2 = np.square(lags[ok])
    decay = float(-np.sum(m2 * np.log(acf[ok])) / np.sum(m2 * m2))
    fit = MarkovFit(1.0, decay, 0.0)
    return MarkovFit(1.0, decay, float(np.sqrt(np.mean(np.square(fit.model(lags) - acf)))))
