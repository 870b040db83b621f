"""The visual mean square error (000 §6.2.2, (6-15) to (6-17)).

The error signal is split by a filter bank into the bands 0-1, 1-3, 3-7 and 7 Hz-Nyquist (fig.
6-1), each band is weighted (a = 0.25, 0.5, 1, 2.25: slow drift is forgiven, jitter is
punished) and the weighted sum is squared and averaged (6-15):

    VMSE = 1/N sum_n ( sum_m a_m e_m(n) )^2,   VPMSE = VMSE / R^2,   VPSNR = -10 log10(VPMSE).

The bank is complementary and zero-phase: zero-phase low-pass filters L_f (Butterworth run
forward and backward with ``sosfiltfilt``) at the inner edges give the bands
``L_1 e, L_3 e - L_1 e, L_7 e - L_3 e, e - L_7 e``, which sum to the error exactly. So with all
weights 1 the VMSE *is* the MSE, and no band is shifted in time. Band edges are in Hz, so any
frame rate works; edges at or above Nyquist are dropped (their bands are empty).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import signal

from mocodec.metrics.waveform import mean_db, to_db

BAND_EDGES_HZ = (1.0, 3.0, 7.0)
BAND_WEIGHTS = (0.25, 0.5, 1.0, 2.25)
FILTER_ORDER = 4


@lru_cache(maxsize=64)
def _lowpass(cutoff_hz: float, fps: float, order: int) -> np.ndarray:
    return signal.butter(order, cutoff_hz, fs=fps, output="sos")


def _zero_phase_lowpass(x: np.ndarray, cutoff_hz: float, fps: float, order: int) -> np.ndarray:
    """Zero-phase low-pass along axis 0. The odd extension at each end is one period of the
    cut-off long (at least scipy's default), so the slow filters settle before the data."""
    n = x.shape[0]
    if n < 2:
        return x.copy()
    sos = _lowpass(cutoff_hz, fps, order)
    padlen = min(max(3 * (2 * len(sos) + 1), round(fps / cutoff_hz)), n - 1)
    return signal.sosfiltfilt(sos, x, axis=0, padlen=padlen)


def band_split(error: np.ndarray, fps: float, edges_hz=BAND_EDGES_HZ, order: int = FILTER_ORDER) -> list[np.ndarray]:
    """The error split into ``len(edges) + 1`` zero-phase bands that sum to it exactly.

    Edges at or above the Nyquist frequency give empty (all-zero) bands."""
    error = np.asarray(error, dtype=np.float64)
    if list(edges_hz) != sorted(edges_hz) or min(edges_hz, default=1.0) <= 0:
        raise ValueError(f"band edges must be positive and increasing, got {edges_hz}")
    nyquist = fps / 2.0
    bands, below = [], np.zeros_like(error)
    for edge in edges_hz:
        low = _zero_phase_lowpass(error, edge, fps, order) if edge < nyquist else error
        bands.append(low - below)
        below = low
    bands.append(error - below)
    return bands


def weighted_error(
    error: np.ndarray, fps: float, weights=BAND_WEIGHTS, edges_hz=BAND_EDGES_HZ, order: int = FILTER_ORDER
) -> np.ndarray:
    """sum_m a_m e_m(n), the inner sum of (6-15), ``(frames, channels)``."""
    if len(weights) != len(edges_hz) + 1:
        raise ValueError(f"{len(edges_hz) + 1} bands need as many weights, got {len(weights)}")
    bands = band_split(error, fps, edges_hz, order)
    out = weights[0] * bands[0]
    for a, band in zip(weights[1:], bands[1:]):
        out += a * band
    return out


@dataclass(frozen=True)
class VisualErrors:
    vmse: np.ndarray  # (6-15) per DOF
    vpmse: np.ndarray  # (6-16), NaN where R = 0
    vpsnr: np.ndarray  # (6-17)

    @property
    def body_vmse(self) -> float:
        """The VMSE of the figure: the sum over DOFs (000 §6.2.2)."""
        return float(self.vmse.sum())

    @property
    def body_vpsnr(self) -> float:
        """Mean of per-DOF VPSNR (dB) over varying, inexact DOFs, like the body PSNR."""
        return mean_db(self.vpsnr)


def visual_errors(
    error: np.ndarray, value_range: np.ndarray, fps: float, weights=BAND_WEIGHTS, edges_hz=BAND_EDGES_HZ
) -> VisualErrors:
    """VMSE, VPMSE, VPSNR per DOF of an error array ``(frames, channels)``; ``value_range`` is R
    of the original per DOF."""
    vmse = np.square(weighted_error(error, fps, weights, edges_hz)).mean(axis=0)
    rng = np.asarray(value_range, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        vpmse = np.where(rng > 0, vmse / np.square(rng), np.nan)
    return VisualErrors(vmse=vmse, vpmse=vpmse, vpsnr=to_db(vpmse))
