"""Budgets for a crowd of avatars: how a viewer's bit rate is shared among the avatars it sees
(001, 6.4 and 6.5), and the ladder that rounds shares so that viewers with nearly equal shares
get the same cut. Plain arithmetic, shared by the scene files (:mod:`mocodec.scene`) and the
relay (:mod:`mocodec.stream.relay`)."""

from __future__ import annotations

import math

import numpy as np

from mocodec.errors import CodecError

#: Shares are rounded down to this many rates per octave (19% apart), so cuts are shared.
LADDER_STEPS = 4


def bandwidth_scores(distances: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """S_C = d_m / d_C (6.4) times the weights, for ``distances`` of shape (characters,) or
    (characters, segments); d_m is the smallest distance (per segment). NaN marks a character
    absent from a segment and scores 0."""
    d = np.asarray(distances, dtype=np.float64)
    absent = np.isnan(d)
    if absent.any():
        if np.any(d[~absent] <= 0):
            raise CodecError("camera distances must be positive")
        scores = np.where(absent, 0.0, np.nanmin(d, axis=0) / np.where(absent, 1.0, d))
    else:  # every character in every column (a relay's crowd, each tick): no NaN to step around
        if not (d > 0).all():
            raise CodecError("camera distances must be positive")
        scores = d.min(axis=0) / d
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        scores = scores * (w[:, None] if scores.ndim == 2 else w)
    return scores


def split_budget(total, scores: np.ndarray) -> np.ndarray:
    """B_k = floor(S_k B / sum S) (6.5). With ``scores`` of shape (characters, columns) and a
    ``total`` per column, each column on its own (a column whose scores are all 0 gets 0)."""
    scores = np.asarray(scores, dtype=np.float64)
    s = scores.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        shares = np.floor(scores * np.asarray(total, dtype=np.float64) / s)
    return np.where(s > 0, shares, 0.0).astype(np.int64)


def viewer_shares(where: np.ndarray, cameras: np.ndarray, budgets: np.ndarray, min_distance: float) -> np.ndarray:
    """``(avatars, viewers)`` bit/s: each viewer's budget split over the avatars at ``where
    (avatars, 3)`` by their distance scores from its camera ``(viewers, 3)`` (6.4, 6.5), a
    distance below ``min_distance`` counting as that; the distances made a coordinate at a time
    (a relay works this out every few ticks)."""
    squared = np.zeros((len(where), len(cameras)))
    for axis in range(3):
        apart = where[:, axis, None] - cameras[None, :, axis]
        squared += apart * apart
    return split_budget(budgets, bandwidth_scores(np.maximum(np.sqrt(squared), min_distance)))


def layers_within(rates: np.ndarray, shares: np.ndarray) -> np.ndarray:
    """``(avatars, viewers)``: how many layers of each avatar fit each viewer's share, at least
    one, given ``rates (avatars, layers)``, the bit/s of each avatar's layers up to each."""
    count = np.zeros(shares.shape, dtype=np.int64)
    for layer in range(rates.shape[1]):
        count += rates[:, layer, None] <= shares
    return np.maximum(count, 1)


def on_ladder(bits_per_second: float) -> float:
    """A share rounded down to a ladder of LADDER_STEPS rates per octave, so viewers with
    nearly equal shares share one cut packet."""
    if bits_per_second < 1:
        return 0.0
    return 2.0 ** (math.floor(math.log2(bits_per_second) * LADDER_STEPS) / LADDER_STEPS)
