"""Waveform measures per DOF and for the whole body (000 §6.1.1-6.1.2, (6-1) to (6-8)).

Every measure compares an original channel array with its approximation, one column per DOF.
Rotation errors are taken modulo 360 degrees (a decoder may return -179 for 181), translation
errors in skeleton units.

Whole-body figures. The thesis reports "the average PSNR for the whole body" (000 §7.1): the
arithmetic mean of the per-DOF PSNR in dB. We do the same, over the DOFs whose original range
R is positive; constant DOFs (R = 0) have no PMSE, are left out of every peak measure and are
counted in ``constant``. A range below ``CONSTANT_RANGE`` (1e-6 degrees or skeleton units, the
printed precision of BVH and AMC files) is float noise in the source file and counts as 0.
A DOF reproduced exactly has an infinite PSNR; it is left out of the mean and counted in
``exact`` (the mean is infinite only when every varying DOF is exact).
``pooled_psnr`` is the alternative that weights every DOF's error alike:
``-10 log10(mean_i PMSE_i)``, dominated by the worst DOFs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec.motion import wrap_degrees

CONSTANT_RANGE = 1e-6


def value_range(original: np.ndarray) -> np.ndarray:
    """R per DOF (column): max - min, with ranges below ``CONSTANT_RANGE`` set to 0."""
    rng = np.ptp(original, axis=0) if original.shape[0] else np.zeros(original.shape[1])
    return np.where(rng > CONSTANT_RANGE, rng, 0.0)


def channel_error(original: np.ndarray, decoded: np.ndarray, rotation_mask: np.ndarray | None = None) -> np.ndarray:
    """``decoded - original`` per sample, ``(frames, channels)``; rotation channels wrapped to
    [-180, 180) so equivalent angles cost nothing."""
    err = np.asarray(decoded, dtype=np.float64) - np.asarray(original, dtype=np.float64)
    if rotation_mask is not None and rotation_mask.any():
        err[:, rotation_mask] = wrap_degrees(err[:, rotation_mask])
    return err


def distance(error: np.ndarray) -> np.ndarray:
    """Instantaneous distance error |e(n)| (6-7)."""
    return np.abs(error)


def squared_distance(error: np.ndarray) -> np.ndarray:
    """Instantaneous squared distance error e(n)^2 (6-8)."""
    return np.square(error)


def to_db(ratio: np.ndarray) -> np.ndarray:
    """-10 log10(ratio), +inf where ratio is 0 and NaN where it is undefined."""
    ratio = np.asarray(ratio, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return -10.0 * np.log10(ratio)


def mean_db(values_db: np.ndarray) -> float:
    """Mean of dB figures over the finite ones; +inf when all are infinite, NaN when none."""
    v = np.asarray(values_db, dtype=np.float64)
    v = v[~np.isnan(v)]
    if v.size == 0:
        return float("nan")
    finite = v[np.isfinite(v)]
    return float(finite.mean()) if finite.size else float("inf")


@dataclass(frozen=True)
class DofErrors:
    """Per-DOF measures (arrays of length ``channels``) and their whole-body summaries."""

    mse: np.ndarray  # (6-1)
    rmse: np.ndarray  # (6-2)
    nmse: np.ndarray  # (6-3), NaN where the original is all zeros
    pmse: np.ndarray  # (6-4), NaN where R = 0
    nsnr: np.ndarray  # (6-5)
    psnr: np.ndarray  # (6-6)
    max_abs: np.ndarray  # max over n of (6-7)
    mean_abs: np.ndarray  # mean over n of (6-7)
    range: np.ndarray  # R, the range of the original

    @property
    def constant(self) -> np.ndarray:
        """DOFs whose original is constant (R = 0): no peak measures."""
        return self.range == 0

    @property
    def exact(self) -> np.ndarray:
        """Varying DOFs reproduced exactly (infinite PSNR)."""
        return (self.range > 0) & (self.mse == 0)

    @property
    def body_psnr(self) -> float:
        """Thesis whole-body PSNR: mean of per-DOF PSNR (dB) over varying, inexact DOFs."""
        return mean_db(self.psnr[self.range > 0])

    @property
    def body_nsnr(self) -> float:
        """Mean of per-DOF NSNR (dB) over varying, inexact DOFs."""
        return mean_db(self.nsnr[self.range > 0])

    @property
    def pooled_psnr(self) -> float:
        """-10 log10 of the mean PMSE over the varying DOFs."""
        p = self.pmse[self.range > 0]
        return float(to_db(p.mean())) if p.size else float("nan")


def dof_errors(original: np.ndarray, decoded: np.ndarray, rotation_mask: np.ndarray | None = None) -> DofErrors:
    """All of (6-1) to (6-8) for ``(frames, channels)`` arrays."""
    if np.shape(original) != np.shape(decoded):
        raise ValueError(f"shapes differ: {np.shape(original)} vs {np.shape(decoded)}")
    return errors_of(np.asarray(original, dtype=np.float64), channel_error(original, decoded, rotation_mask))


def errors_of(original: np.ndarray, err: np.ndarray) -> DofErrors:
    """:func:`dof_errors` from the original and an already computed :func:`channel_error`."""
    if original.shape[0] == 0:
        raise ValueError("no frames to compare")
    sq = squared_distance(err)
    mse = sq.mean(axis=0)
    energy = np.square(original).sum(axis=0)
    rng = value_range(original)
    with np.errstate(divide="ignore", invalid="ignore"):
        nmse = np.where(energy > 0, sq.sum(axis=0) / energy, np.nan)
        pmse = np.where(rng > 0, mse / np.square(rng), np.nan)
    absolute = distance(err)
    return DofErrors(
        mse=mse,
        rmse=np.sqrt(mse),
        nmse=nmse,
        pmse=pmse,
        nsnr=to_db(nmse),
        psnr=to_db(pmse),
        max_abs=absolute.max(axis=0),
        mean_abs=absolute.mean(axis=0),
        range=rng,
    )
