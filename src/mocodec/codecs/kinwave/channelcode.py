"""kinwave's rows in compiled loops: the quantisation of channels to knots and dead-zone wavelet
coefficients, their reconstruction (trend, wavelet synthesis, seam smoothing), the encoder's
plain rounding where a frame misses its target far, and a tree depth's whole coding with its
coding forms, world-axis translations and isolated frames (docs/kinwave.md). Each row is coded alone,
with the same floats as the numpy expressions these loops replace term for term, so the bytes
of every body are what they were; the wavelets are :mod:`.periodized`'s (PyWavelets' floats).
"""

from __future__ import annotations

import numba
import numpy as np

from mocodec.codecs.shared import rotvec
from mocodec.coding.transforms import periodized, seams, trendwave, wavelets
from mocodec.kernels import kernel


@numba.njit(inline="always")
def _trend_row(values, left, frac, out):
    """The piecewise-linear trend through knot ``values`` at every frame: the value of the knot
    before it, moved along the line to the next one by its ``frac``.
    (Computed indices are cast to unsigned here and below: numba then skips its check for a
    negative one in the per-sample loops.)"""
    last = values.size - 1
    for t in range(left.size):
        a = values[np.uintp(left[t])]
        b = values[np.uintp(min(left[t] + 1, last))]
        out[t] = a + (b - a) * frac[t]


@numba.njit(inline="always")
def constant_knot(row, base, quantum):
    """A constant row's knot from its values ``row``: the first one's nearest multiple of
    ``quantum`` (its step's constant fraction) about ``base`` (a row of no frames: 0)."""
    first = row[0] if row.size else base
    return np.int64(np.rint((first - base) / quantum))


@numba.njit(inline="always")
def constant_value(knot, base, quantum):
    """What a constant row decodes to at every frame (its trend is the value, its
    coefficients 0 and its seams without a step)."""
    return base + knot * quantum


@kernel
def _reconstruct(knots, coeffs, const, step, fraction, base, knot_f, coeff_f, seam_f, seam_limit, lay, lo, hi, weight):
    """Decoded rows ``(k, T)`` from their integers (:func:`reconstruct`)."""
    knot_frames, left, frac, knot_quantum, starts, lengths, leads, padded, levels, offsets = lay
    rows, frames = knots.shape[0], left.size
    widest = max(padded.max(), 1) if padded.size else 1
    out = np.empty((rows, frames))
    values = np.empty(knot_frames.size)
    trend = np.empty(frames)
    block, signal, a, b = np.empty(widest), np.empty(widest), np.empty(widest), np.empty(widest)
    for r in range(rows):
        if const[r]:
            if frames:
                out[r, :] = constant_value(knots[r, 0], base[r], step[r] * fraction[r])
            continue
        for k in range(knot_frames.size):
            values[k] = knots[r, k] * (step[r] * knot_quantum[k] * knot_f[k])
        _trend_row(values, left, frac, trend)
        residual = np.zeros(frames)
        for s in range(starts.size):
            n = padded[s]
            if n == 0:
                continue
            o = offsets[s]
            for i in range(n):
                at = np.uintp(o + i)
                block[i] = coeffs[r, at] * (step[r] * coeff_f[at])
            periodized.inverse_one(block, n, levels[s], lo, hi, signal, a, b)
            for t in range(lengths[s]):
                residual[np.uintp(starts[s] + t)] = signal[np.uintp(leads[s] + t)]
        for t in range(frames):
            out[r, t] = trend[t] + residual[t]
    if starts.size > 1:
        limits = np.empty((starts.size - 1, rows))
        for s in range(starts.size - 1):
            for r in range(rows):
                limits[s, r] = seam_limit * seam_f[s] * step[r]
        seams.smooth_rows(out, starts[1:], limits, weight)
    return out


@kernel
def _quantise(target, const, step, fraction, base, knot_f, coeff_f, lay, lo, hi, deadzone):
    """Knots, dead-zone coefficients and the coefficients in steps of ``target (k, T)``
    (:func:`quantise`)."""
    knot_frames, left, frac, knot_quantum, starts, lengths, leads, padded, levels, offsets = lay
    rows, frames = target.shape
    K, N = knot_frames.size, int(padded.sum())
    widest = max(padded.max(), 1) if padded.size else 1
    k_int = np.empty((rows, K), dtype=np.int64)
    c_int = np.zeros((rows, N), dtype=np.int64)
    scaled = np.zeros((rows, N))
    values = np.empty(K)
    trend = np.empty(frames)
    block, coeffs, a, b = np.empty(widest), np.empty(widest), np.empty(widest), np.empty(widest)
    for r in range(rows):
        if const[r]:  # (a body of no frames has nothing to read: knot 0, decoded as no frame)
            k_int[r, :] = constant_knot(target[r], base[r], step[r] * fraction[r])
            continue
        for k in range(K):
            quantum = step[r] * knot_quantum[k] * knot_f[k]
            k_int[r, k] = np.int64(np.rint(target[r, knot_frames[k]] / quantum))
            values[k] = k_int[r, k] * quantum
        _trend_row(values, left, frac, trend)
        for s in range(starts.size):
            n = padded[s]
            if n == 0:
                continue
            block[:n] = 0.0
            for t in range(lengths[s]):
                f = np.uintp(starts[s] + t)
                block[np.uintp(leads[s] + t)] = target[r, f] - trend[f]
            periodized.forward_one(block, n, levels[s], lo, hi, coeffs, a, b)
            o = offsets[s]
            for i in range(n):
                at = np.uintp(o + i)
                c = coeffs[i] / (step[r] * coeff_f[at])
                scaled[r, at] = c
                v = np.int64(np.floor(abs(c) + deadzone))
                c_int[r, at] = v if c > 0 else (-v if c < 0 else 0)
    return k_int, c_int, scaled


@kernel
def _round_far(target, out, const, step, knot_f, far_steps, scaled, coeffs, lay, reach_ptr, reached, reach_at):
    """Round to the nearest integer, in place in ``coeffs``, the coefficients whose synthesis
    reaches a frame where ``out`` misses ``target`` by more than ``far_steps`` of the frame's
    step (``reach_ptr``, ``reached``, ``reach_at``: :func:`trendwave.reaches`' lists; ``scaled``:
    the coefficients in steps before rounding). Returns ``(k,)`` bool: the rows that changed."""
    knot_frames, left, frac, knot_quantum, starts, lengths, leads, padded, levels, offsets = lay
    rows = target.shape[0]
    marked = np.zeros(int(padded.sum()), dtype=np.bool_)
    changed = np.zeros(rows, dtype=np.bool_)
    for r in range(rows):
        if const[r]:
            continue
        marked[:] = False
        for s in range(starts.size):
            n = padded[s]
            if n == 0:
                continue
            at, o = reach_at[s], offsets[s]
            for t in range(lengths[s]):
                f = starts[s] + t
                if abs(out[r, f] - target[r, f]) > far_steps * step[r] * knot_f[left[f]]:
                    row = at + leads[s] + t
                    for j in range(reach_ptr[row], reach_ptr[row + 1]):
                        marked[o + reached[j]] = True
        for i in range(marked.size):
            if marked[i]:
                c = scaled[r, i]
                v = np.int64(np.floor(abs(c) + 0.5))
                nearest = v if c > 0 else (-v if c < 0 else 0)
                if nearest != coeffs[r, i]:
                    coeffs[r, i] = nearest
                    changed[r] = True
    return changed


@kernel
def _code_rows(target, const, step, fraction, base, factors, seam_limit, lay, dec, rec, weight, deadzone, far, reach):
    """:func:`_quantise`, :func:`_reconstruct` and, with ``far`` > 0, :func:`_round_far` and
    the changed rows reconstructed again, in one call (:func:`code_depth`)."""
    knot_f, coeff_f, seam_f = factors
    k_int, c_int, scaled = _quantise(
        target, const, step, fraction, base, knot_f, coeff_f, lay, dec[0], dec[1], deadzone
    )
    out = _reconstruct(
        k_int, c_int, const, step, fraction, base, knot_f, coeff_f, seam_f, seam_limit, lay, rec[0], rec[1], weight
    )
    if far <= 0.0:
        return k_int, c_int, out
    changed = np.flatnonzero(_round_far(target, out, const, step, knot_f, far, scaled, c_int, lay, *reach))
    if changed.size:
        again = _reconstruct(
            k_int[changed], c_int[changed], const[changed], step[changed], fraction[changed], base[changed],
            knot_f, coeff_f, seam_f, seam_limit, lay, rec[0], rec[1], weight,
        )  # fmt: skip
        for i in range(changed.size):
            out[changed[i]] = again[i]
    return k_int, c_int, out


def _row_steps(const, step, fraction, base) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each row's constant flag, step, and constant's fraction and base, as the contiguous,
    writable arrays the kernels are compiled for (a read-only one, such as a cached plan's,
    would compile them a second time)."""
    return (
        np.require(const, np.bool_, ("C", "W")),
        np.require(step, np.float64, ("C", "W")),
        np.require(fraction, np.float64, ("C", "W")),
        np.require(base, np.float64, ("C", "W")),
    )


def reconstruct(
    knots: np.ndarray,
    coeffs: np.ndarray,
    const: np.ndarray,
    step: np.ndarray,
    fraction: np.ndarray,
    base: np.ndarray,
    lay: trendwave.Layout,
    factors: tuple[np.ndarray, np.ndarray, np.ndarray],
    seam_limit: float,
    half_width: int,
) -> np.ndarray:
    """Rows ``(k, T)`` from their integers, steps ``step (k,)``, the segments' step ``factors``
    (knots, coefficients, seams), a constant row its first knot in ``fraction`` of its step about
    ``base``; each seam's step smoothed over ``half_width`` frames, at most ``seam_limit`` of the
    finer side's step."""
    knot_f, coeff_f, seam_f = factors
    const, step, fraction, base = _row_steps(const, step, fraction, base)
    return _reconstruct(
        np.ascontiguousarray(knots, dtype=np.int64),
        np.ascontiguousarray(coeffs, dtype=np.int64),
        const,
        step,
        fraction,
        base,
        knot_f,
        coeff_f,
        np.asarray(seam_f, dtype=np.float64),
        float(seam_limit),
        tuple(trendwave.flat(lay)),
        *wavelets.filters(lay.wavelet, "rec"),
        seams.ramp(half_width),
    )


def quantise(
    target: np.ndarray,
    const: np.ndarray,
    step: np.ndarray,
    fraction: np.ndarray,
    base: np.ndarray,
    lay: trendwave.Layout,
    factors: tuple[np.ndarray, np.ndarray, np.ndarray],
    deadzone: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Knots and dead-zone quantised coefficients of ``target (k, T)`` (arguments as
    :func:`reconstruct`'s), and the coefficients in steps before rounding."""
    knot_f, coeff_f, _ = factors
    const, step, fraction, base = _row_steps(const, step, fraction, base)
    return _quantise(
        np.ascontiguousarray(target, dtype=np.float64),
        const,
        step,
        fraction,
        base,
        knot_f,
        coeff_f,
        tuple(trendwave.flat(lay)),
        *wavelets.filters(lay.wavelet, "dec"),
        float(deadzone),
    )


@numba.njit(inline="always")
def _turn_rows(values, rows, turn, sign):
    """Translation rows ``values[rows]`` (three) turned in place by the unit quaternion
    ``turn`` (``sign`` -1: its inverse), as :func:`rotvec.turn_vectors` turns them."""
    a, b, c = rows[0], rows[1], rows[2]
    for t in range(values.shape[1]):
        values[a, t], values[b, t], values[c, t] = rotvec.rotate_vector(
            turn[0], sign * turn[1], sign * turn[2], sign * turn[3], values[a, t], values[b, t], values[c, t]
        )


@kernel
def depth_kernel(
    values, cols, quats, forms, moved_rows, moved_turns, iso, const, step, fraction, base, factors, coder, every_frame
):
    """:func:`code_depth` (``forms``: :meth:`rotvec.FormSet.kernel_arguments`), for compiled
    callers; also returns the decoded rotations ``(T, n, 4)`` of the joints in coding forms
    (:func:`rotvec.quats_of_forms`). Without ``every_frame`` their rows go back to the file's
    Euler angles at frame 0 only (what the rows' orientations above are taken from; a caller
    that composes the joints' orientations from their rotations needs no more)."""
    vector, means, form_axes, world, turns, file_axes = forms
    seam_limit, lay, dec, rec, weight, deadzone, far, reach = coder
    n, rows, frames = cols.size // 3, values.shape[0], values.shape[1]
    if n:
        coded = rotvec.forms_of_quats(quats, vector, means, form_axes, world, turns)
        for e in range(n):
            for m in range(3):
                for t in range(frames):
                    values[cols[3 * e + m], t] = coded[t, e, m]
    for i in range(moved_rows.shape[0]):
        _turn_rows(values, moved_rows[i], moved_turns[i], 1.0)
    wanted = np.empty((rows, iso.size))
    between = np.empty((rows, iso.size))  # the wavelet sees the neighbours' mean there
    for r in range(rows):
        for i in range(iso.size):
            wanted[r, i] = values[r, iso[i]]
            between[r, i] = (values[r, iso[i] - 1] + values[r, iso[i] + 1]) / 2.0
    for r in range(rows):
        for i in range(iso.size):
            values[r, iso[i]] = between[r, i]
    k_int, c_int, out = _code_rows(
        values, const, step, fraction, base, factors, seam_limit, lay, dec, rec, weight, deadzone, far, reach
    )
    patch = np.zeros((rows, iso.size), dtype=np.int64)
    for r in range(rows):
        quantum = step[r] * trendwave.KEYFRAME_QUANTUM
        for i in range(iso.size):
            if not const[r]:  # (a constant row takes no patch)
                patch[r, i] = np.int64(np.rint((wanted[r, i] - out[r, iso[i]]) / quantum))
            out[r, iso[i]] += patch[r, i] * quantum
    for i in range(moved_rows.shape[0]):
        _turn_rows(out, moved_rows[i], moved_turns[i], -1.0)
    decoded = np.empty((frames, n, 4))
    if n:
        back = np.empty((frames, n, 3))
        for e in range(n):
            for m in range(3):
                for t in range(frames):
                    back[t, e, m] = out[cols[3 * e + m], t]
        decoded = rotvec.quats_of_forms(back, form_axes, vector, means, world, turns)
        written = frames if every_frame else min(frames, 1)
        euler = rotvec.euler_of_quats(decoded[:written], file_axes)
        for e in range(n):
            for m in range(3):
                for t in range(written):
                    out[cols[3 * e + m], t] = euler[t, e, m]
    return k_int, c_int, out, patch, decoded


NO_FORMS = rotvec.FormSet((), np.zeros(0, dtype=np.int64), np.zeros((0, 4)))  # a depth without coding forms


def code_depth(
    target: np.ndarray,
    const: np.ndarray,
    step: np.ndarray,
    fraction: np.ndarray,
    base: np.ndarray,
    lay: trendwave.Layout,
    factors: tuple[np.ndarray, np.ndarray, np.ndarray],
    deadzone: float,
    seam_limit: float,
    half_width: int,
    far_steps: float,
    forms: tuple[np.ndarray, np.ndarray, rotvec.FormSet, np.ndarray | None] | None = None,
    moved: tuple[np.ndarray, np.ndarray] | None = None,
    isolated: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A tree depth's rows ``target (k, T)`` (file-order angles and translations) coded in one
    compiled call: :func:`quantise` (arguments as its), :func:`reconstruct`, and with
    ``far_steps`` > 0 the coefficients :func:`_round_far` rounds to the nearest integer and
    their rows reconstructed again. ``forms``: ``(cols, quats (T, n, 4), form_set, pre)``, the
    three-angle joints whose rows are ``cols`` (three each) go in their coding forms from their
    rotations (:class:`rotvec.FormSet`, WORLD turns ``pre``) and back; ``moved``: ``(rows (m,
    3), turns (m, 4))``, translations on the world's axes; ``isolated`` frames are coded as
    their neighbours' mean and a patch each. Returns knots, coefficients, the reconstruction
    ``(k, T)`` in the file's angles and axes with the patches applied, and the patches ``(k,
    isolated)``; the same floats as each step one call at a time. (The encoder's compiled pass,
    :mod:`.treepass`, calls :func:`depth_kernel` itself; this is its entry from Python.)"""
    no_forms = (np.zeros(0, dtype=np.int64), np.zeros((target.shape[1], 0, 4)), NO_FORMS, None)
    cols, quats, form_set, pre = forms or no_forms
    moved_rows, moved_turns = moved or (np.zeros((0, 3), dtype=np.int64), np.zeros((0, 4)))
    const, step, fraction, base = _row_steps(const, step, fraction, base)
    return depth_kernel(
        np.array(target, dtype=np.float64, order="C"),
        cols,
        np.ascontiguousarray(quats, dtype=np.float64),
        form_set.kernel_arguments(pre),
        moved_rows,
        np.ascontiguousarray(moved_turns, dtype=np.float64),
        np.zeros(0, dtype=np.int64) if isolated is None else isolated,
        const,
        step,
        fraction,
        base,
        (factors[0], factors[1], np.asarray(factors[2], dtype=np.float64)),
        coder_arguments(lay, deadzone, seam_limit, half_width, far_steps),
        True,
    )[:4]


def coder_arguments(lay: trendwave.Layout, deadzone: float, seam_limit: float, half_width: int, far_steps: float):
    """What :func:`depth_kernel` takes of the layout and the coder's settings, in its order:
    the seam limit, the flat layout, the analysis and synthesis filters, the seams' ramp, the
    dead zone, the far rounding's steps and the coefficients' reach."""
    return (
        float(seam_limit),
        tuple(trendwave.flat(lay)),
        wavelets.filters(lay.wavelet, "dec"),
        wavelets.filters(lay.wavelet, "rec"),
        seams.ramp(half_width),
        float(deadzone),
        float(far_steps),
        trendwave.reaches(lay),
    )
