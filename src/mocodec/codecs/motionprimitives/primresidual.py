"""Residuals of the motion-primitive coder (001 §5.3.4, §5.4): what a primitive misses, coded
with CDF 9/7 wavelets until the reconstruction is within a joint's threshold, and the root
translation windows.

Segment residuals: the difference (5.7) ``d = p^-1 q`` between a primitive ``p`` and the
segment ``q``, frame by frame, is a rotation near the identity; we code its logarithm (three
numbers per frame, the fourth component of ``d`` follows from them), a 4-level CDF 9/7
transform of each over the 16 normalised frames (periodised: 16 coefficients). Coefficients
are quantised to ``bits`` bits (10 in the thesis: the step is the largest coefficient over
``2^(bits-1) - 1``, sent as a quarter-octave exponent) and all but the largest ``k`` set to
zero, ``k`` the fewest for which every frame is within the bound (5.4) of the segment (found
by bisection). When even all coefficients miss the bound the step is halved.

Translation windows (the three root DOFs, 32 frames in the thesis): each window's samples
minus the last decoded sample before it, less a straight ramp to the window's last sample (so
the periodised transform sees no jump where the window wraps), 4-level CDF 9/7; the smallest
half of the coefficients set to zero, the rest and the ramp's end quantised to ``bits`` bits.
Both ends reconstruct through the same functions on the same integers.
"""

from __future__ import annotations

import numpy as np

from mocodec import rotations
from mocodec.codecs.motionprimitives import quatseg
from mocodec.coding.entropy import coefcoder
from mocodec.coding.quantisation.quantisers import step_exponents, steps
from mocodec.coding.transforms import wavelets

LEVELS = 4
WAVELET = "cdf97"
MODE = "periodization"
NO_RESIDUAL = 1  # exponent sent for a segment coded by its primitive alone
COEFFS = 3 * quatseg.NORMAL_FRAMES
MAX_REFINEMENTS = 6


def pack(coeffs: np.ndarray) -> bytes:
    """Quantised segment coefficients ``(n, 48)`` as bytes: the context-adaptive coefficient
    coder (:mod:`mocodec.coding.entropy.coefcoder`), one channel per rotation-vector component, a block
    of 16 coefficients (4 levels, coarsest first) per segment."""
    n = len(coeffs)
    blocks = np.asarray(coeffs, dtype=np.int64).reshape(n, 3, quatseg.NORMAL_FRAMES).transpose(1, 0, 2).reshape(3, -1)
    return coefcoder.encode(
        np.zeros(3, np.int64), np.zeros((3, 0), np.int64), blocks, np.full(n, quatseg.NORMAL_FRAMES), np.full(n, LEVELS)
    )


def unpack(data: bytes, n: int) -> np.ndarray:
    """Inverse of :func:`pack` for ``n`` segments."""
    blocks = coefcoder.decode(data, 3, 0, np.full(n, quatseg.NORMAL_FRAMES), np.full(n, LEVELS)).coeffs
    return blocks.reshape(3, n, quatseg.NORMAL_FRAMES).transpose(1, 0, 2).reshape(n, COEFFS)


def _segment_matrices() -> tuple[np.ndarray, np.ndarray]:
    return wavelets.matrices(quatseg.NORMAL_FRAMES, WAVELET, LEVELS, MODE)


def _logs(target: np.ndarray, ref: np.ndarray) -> np.ndarray:
    d = rotations.quat_multiply(rotations.quat_conjugate(ref), target)  # (5.7)
    d = np.where(d[..., :1] < 0, -d, d)
    return rotations.quat_log(d)


def _differences(coeffs: np.ndarray) -> np.ndarray:
    """The differences ``exp(S c)`` (5.7) that coefficients ``(n, 48)`` give, ``(n, 16, 4)``."""
    _, synthesis = _segment_matrices()
    v = coeffs.reshape(len(coeffs), 3, -1) @ synthesis.T  # (n, 3, 16)
    return rotations.quat_exp(v.transpose(0, 2, 1))


def _rebuild(ref: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """``ref * exp(S c)`` (5.8) for coefficients ``(n, 48)``."""
    return rotations.quat_multiply(ref, _differences(coeffs))


def fit(target: np.ndarray, ref: np.ndarray, bound: np.ndarray, bits: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(exponents ``(n,)``, quantised coefficients ``(n, 48)``, reconstruction ``(n, 16, 4)``)
    of segments ``target`` from references ``ref``, each within its ``bound`` (5.4)."""
    n = len(target)
    exps = np.full(n, NO_RESIDUAL, dtype=np.int64)
    q = np.zeros((n, COEFFS), dtype=np.int64)
    recon = ref.copy()
    need = np.flatnonzero(quatseg.segment_distance(target, ref) > bound)
    if not need.size:
        return exps, q, recon
    analysis, _ = _segment_matrices()
    c = (_logs(target[need], ref[need]).transpose(0, 2, 1) @ analysis.T).reshape(len(need), -1)
    e = step_exponents(c, bits)
    for _ in range(MAX_REFINEMENTS):
        full = np.round(c / steps(e)[:, None]).astype(np.int64)
        rank = np.empty_like(full)
        np.put_along_axis(
            rank,
            np.argsort(-np.abs(full), axis=1, kind="stable"),
            np.broadcast_to(np.arange(COEFFS), full.shape).copy(),
            axis=1,
        )
        t, r, b = target[need], ref[need], bound[need]

        def within(k):
            kept = np.where(rank < k[:, None], full, 0)
            rebuilt = _rebuild(r, kept * steps(e)[:, None])
            return quatseg.segment_distance(t, rebuilt) <= b, kept, rebuilt

        lo, hi = np.zeros(len(need), dtype=np.int64), np.full(len(need), COEFFS)
        ok, kept, rebuilt = within(hi)
        while np.any(hi[ok] - lo[ok] > 1):
            mid = np.where(ok, (lo + hi) // 2, hi)
            good = within(mid)[0]
            hi, lo = np.where(ok & good, mid, hi), np.where(ok & ~good, mid, lo)
        done = need[ok]
        if done.size:
            _, kept_ok, rebuilt_ok = within(hi)
            exps[done], q[done], recon[done] = e[ok], kept_ok[ok], rebuilt_ok[ok]
        if ok.all():
            break
        exps[need[~ok]], q[need[~ok]], recon[need[~ok]] = e[~ok], kept[~ok], rebuilt[~ok]
        need, c, e = need[~ok], c[~ok], e[~ok] - 4
    return exps, q, recon


def differences(exps: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The decoder's side of :func:`fit`: per segment the rotations ``(n, 16, 4)`` that take
    its reference to the decoded segment (5.8), the identity where no residual was sent; they
    do not depend on the reference, so a decoder finds them all at once."""
    out = np.zeros((len(exps), quatseg.NORMAL_FRAMES, 4))
    out[..., 0] = 1.0
    has = exps != NO_RESIDUAL
    if has.any():
        out[has] = _differences(q[has] * steps(exps[has])[:, None])
    return out


def _window_matrices(frames: int) -> tuple[np.ndarray, np.ndarray]:
    return wavelets.matrices(frames, WAVELET, LEVELS, MODE)


def window_coefficients(frames: int) -> int:
    """Wavelet coefficients of a ``frames``-long translation window (per channel)."""
    return _window_matrices(frames)[0].shape[0]


def _ramp(end: np.ndarray, frames: int) -> np.ndarray:
    return np.outer(np.arange(1, frames + 1) / frames, end)


def fit_window(
    x: np.ndarray, before: np.ndarray, bits: int, keep: float = 0.5
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(exponents ``(C,)``, integers ``(C, 1 + m)`` = ramp end then coefficients, decoded
    window ``(frames, C)``) of a translation window ``x`` following the decoded ``before``."""
    frames = len(x)
    analysis, _ = _window_matrices(frames)
    rel = x - before
    end = rel[-1]
    c = analysis @ (rel - _ramp(end, frames))
    e = step_exponents(np.column_stack((end, c.T)), bits)
    st = steps(e)
    safe = np.where(st > 0, st, 1.0)
    q_end = np.where(st > 0, np.round(end / safe), 0).astype(np.int64)
    c = analysis @ (rel - _ramp(q_end * st, frames))
    kept = max(1, int(np.ceil(keep * len(c))))
    order = np.argsort(-np.abs(c), axis=0, kind="stable")
    mask = np.zeros(c.shape, dtype=bool)
    np.put_along_axis(mask, order[:kept], True, axis=0)
    q_c = np.where(mask & (st > 0), np.round(c / safe), 0).astype(np.int64)
    ints = np.column_stack((q_end, q_c.T))
    return e, ints, rebuild_window(before, e, ints, frames)


def rebuild_window(before: np.ndarray, exps: np.ndarray, ints: np.ndarray, frames: int) -> np.ndarray:
    """The decoder's side of :func:`fit_window`."""
    _, synthesis = _window_matrices(frames)
    st = steps(exps)
    return before + _ramp(ints[:, 0] * st, frames) + synthesis @ (ints[:, 1:] * st[:, None]).T
