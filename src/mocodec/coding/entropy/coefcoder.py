"""Context-adaptive binary arithmetic coding of quantised wavelet coefficients and knots.

The binary range coder and the binarisation of integers are :mod:`mocodec.coding.entropy.binarycoder`'s
(zero flag, size class in unary, mantissa, sign). Contexts (kinwave.md, "what mattered" 2):

* zero flag: subband (approximation, then detail bands counted from the finest), local
  activity (``2|v[i-1]| + |v[i-2]|`` in the same band, four classes) and the parent
  coefficient's magnitude (the coefficient one level coarser at ``i // 2``, three classes);
* size-class unary bits: subband, activity and position in the unary code;
* sign: subband (revision 2: and the signs of the previous value and of the parent);
* revision 2 codes the approximation band of a block as differences from its previous value
  (neighbours 32 frames apart are alike), the first value and the rest in contexts of their own,
  and its contexts warm up (:func:`~mocodec.coding.entropy.binarycoder.new_state`; short clips
  gain most, as they spend a larger share learning);
* per channel: a "constant" flag; per segment block: an "all zero" flag, in the context of the
  previous block of the same channel; knots: their own set of the above.

A payload's layout (segments, their padded lengths and wavelet levels) is known to both ends,
so only the decisions are sent. The decoder mirrors the encoder decision for decision; on
damaged input it produces garbage of the right shape (callers check a CRC first) and never
reads outside its buffer.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numba
import numpy as np

from mocodec.coding.entropy.binarycoder import (
    MAX_CLASS,
    buffer_for,
    encoder_start,
    finish_s,
    get_int_s,
    get_s,
    int_decisions,
    new_state,
    put_int_s,
    put_s,
    start_decoder_s,
)
from mocodec.kernels import kernel

# context layout
_BANDS = 6  # approximation, detail 1 (finest) .. detail 5+ (coarser)
_ACT = 4
_PAR = 3
_UNARY = 8
_Z0 = 0  # zero flags: band x activity x parent
_U0 = _Z0 + _BANDS * _ACT * _PAR  # unary: band x activity x position
_M0 = _U0 + _BANDS * _ACT * _UNARY  # top mantissa bit: class
_S0 = _M0 + MAX_CLASS  # sign: band
_KZ = _S0 + _BANDS  # knots: zero flag (first knot, later knots)
_KU = _KZ + 2  # knots: unary position (x2)
_KM = _KU + 2 * 24  # knots: top mantissa bit per class
_KS = _KM + MAX_CLASS  # knots: sign
_CONST = _KS + 2  # channel is constant
_BLOCK = _CONST + 1  # block has a nonzero coefficient (prev block: 0/1)
_S2 = _BLOCK + 2  # revision 2 signs: band x previous sign x parent sign
_SIDE = _S2 + _BANDS * 9  # side integers: zero flag, unary positions, sign
_SIDE_UNARY = 8
_CONTEXTS = _SIDE + 2 + _SIDE_UNARY


@numba.njit(inline="always")
def _activity(a, b):
    s = 2 * (a if a >= 0 else -a) + (b if b >= 0 else -b)
    return 0 if s == 0 else (1 if s <= 2 else (2 if s <= 6 else 3))


@numba.njit(inline="always")
def _sign_class(v):
    return 0 if v == 0 else (1 if v > 0 else 2)


@numba.njit(inline="always")
def _parent_class(v):
    m = v if v >= 0 else -v
    return 0 if m == 0 else (1 if m <= 2 else 2)


# ----- payloads -----------------------------------------------------------------------------
@kernel
def _encode(side, const, knots, coeffs, seg_pad, seg_lev, rev2, buf):
    low, rng, cache, size, pos = encoder_start()
    state = new_state(_CONTEXTS, rev2)  # revision 2: contexts warm up
    for v in side:
        low, rng, cache, size, pos = put_int_s(
            low, rng, cache, size, pos, buf, state, v, _SIDE, _SIDE + 2, _SIDE_UNARY, _KM, _SIDE + 1
        )
    for c in range(const.size):
        low, rng, cache, size, pos = put_s(low, rng, cache, size, pos, buf, state, _CONST, const[c])
        prev = 0
        nk = min(1, knots.shape[1]) if const[c] else knots.shape[1]  # (a layout of no frames has no knot)
        for i in range(nk):
            first = 1 if i == 0 else 0
            delta, zctx, uctx, sctx = knots[c, i] - prev, _KZ + 1 - first, _KU + 24 * (1 - first), _KS + 1 - first
            low, rng, cache, size, pos = put_int_s(
                low, rng, cache, size, pos, buf, state, delta, zctx, uctx, 24, _KM, sctx
            )
            prev = knots[c, i]
        if const[c]:
            continue
        off = 0
        last_nz = 0
        for s in range(seg_pad.size):
            n = seg_pad[s]
            if n == 0:
                continue
            nz = 0
            for i in range(off, off + n):
                if coeffs[c, i] != 0:
                    nz = 1
                    break
            low, rng, cache, size, pos = put_s(low, rng, cache, size, pos, buf, state, _BLOCK + last_nz, nz)
            last_nz = nz
            if nz:
                L = seg_lev[s]
                start = off
                blen = n >> L
                prev_v = 0
                for b in range(L + 1):
                    band = 0 if b == 0 else min(L - b + 1, _BANDS - 1)
                    p1 = 0
                    p2 = 0
                    for i in range(blen):
                        v = coeffs[c, start + i]
                        pv = 0
                        if b == 0:
                            par = 1 if rev2 and i > 0 else 0
                            if rev2:  # the difference from the previous value
                                u = v - prev_v
                                prev_v = v
                                v = u
                        else:
                            pv = coeffs[c, off + i] if b == 1 else coeffs[c, start - (blen >> 1) + (i >> 1)]
                            par = _parent_class(pv)
                        act = _activity(p1, p2)
                        sctx = _S2 + (band * 3 + _sign_class(p1)) * 3 + _sign_class(pv) if rev2 else _S0 + band
                        zctx, uctx = _Z0 + (band * _ACT + act) * _PAR + par, _U0 + (band * _ACT + act) * _UNARY
                        low, rng, cache, size, pos = put_int_s(
                            low, rng, cache, size, pos, buf, state, v, zctx, uctx, _UNARY, _M0, sctx
                        )
                        p2 = p1
                        p1 = v
                    start += blen
                    if b > 0:
                        blen <<= 1
            off += n
    return finish_s(low, cache, size, pos, buf)


@kernel
def _decode(data, side, channels, num_knots, num_coeffs, seg_pad, seg_lev, rev2, const, knots, coeffs):
    code, rng, pos = start_decoder_s(data)
    state = new_state(_CONTEXTS, rev2)  # revision 2: contexts warm up
    for i in range(side.size):
        side[i], code, rng, pos = get_int_s(code, rng, pos, data, state, _SIDE, _SIDE + 2, _SIDE_UNARY, _KM, _SIDE + 1)
    for c in range(channels):
        const[c], code, rng, pos = get_s(code, rng, pos, data, state, _CONST)
        prev = 0
        nk = min(1, num_knots) if const[c] else num_knots  # (a layout of no frames has no knot)
        for i in range(nk):
            first = 1 if i == 0 else 0
            delta, code, rng, pos = get_int_s(
                code, rng, pos, data, state, _KZ + 1 - first, _KU + 24 * (1 - first), 24, _KM, _KS + 1 - first
            )
            prev += delta
            knots[c, i] = prev
        if const[c]:
            continue
        off = 0
        last_nz = 0
        for s in range(seg_pad.size):
            n = seg_pad[s]
            if n == 0:
                continue
            nz, code, rng, pos = get_s(code, rng, pos, data, state, _BLOCK + last_nz)
            last_nz = nz
            if nz:
                L = seg_lev[s]
                start = off
                blen = n >> L
                prev_v = 0
                for b in range(L + 1):
                    band = 0 if b == 0 else min(L - b + 1, _BANDS - 1)
                    p1 = 0
                    p2 = 0
                    for i in range(blen):
                        pv = 0
                        if b == 0:
                            par = 1 if rev2 and i > 0 else 0
                        else:
                            pv = coeffs[c, off + i] if b == 1 else coeffs[c, start - (blen >> 1) + (i >> 1)]
                            par = _parent_class(pv)
                        act = _activity(p1, p2)
                        sctx = _S2 + (band * 3 + _sign_class(p1)) * 3 + _sign_class(pv) if rev2 else _S0 + band
                        v, code, rng, pos = get_int_s(
                            code,
                            rng,
                            pos,
                            data,
                            state,
                            _Z0 + (band * _ACT + act) * _PAR + par,
                            _U0 + (band * _ACT + act) * _UNARY,
                            _UNARY,
                            _M0,
                            sctx,
                        )
                        p2 = p1
                        p1 = v
                        if b == 0 and rev2:
                            prev_v += v
                            v = prev_v
                        coeffs[c, start + i] = v
                    start += blen
                    if b > 0:
                        blen <<= 1
            off += n
    return pos


def _approx_differences(coeffs: np.ndarray, seg_pad: np.ndarray, seg_lev: np.ndarray) -> np.ndarray:
    """The values :func:`encode` codes in place of the approximation bands after their first."""
    offsets = np.concatenate([[0], np.cumsum(seg_pad)[:-1]]).astype(np.int64)
    parts = [
        np.diff(coeffs[:, o : o + (n >> lev)], axis=1).ravel() for o, n, lev in zip(offsets, seg_pad, seg_lev) if n
    ]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def _differences(sequences) -> np.ndarray:
    """Every sequence as differences from its previous value (the first from 0), end to end."""
    parts = [np.diff(np.asarray(q, dtype=np.int64), prepend=0) for q in sequences]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def encode(
    const: np.ndarray,
    knots: np.ndarray,
    coeffs: np.ndarray,
    seg_pad: np.ndarray,
    seg_lev: np.ndarray,
    revision: int = 1,
    side: tuple = (),
) -> bytes:
    """Bytes for ``const (C,)`` flags, ``knots (C, K)`` and ``coeffs (C, N)`` integers laid out
    as segments of ``seg_pad`` coefficients (0: no block) with ``seg_lev`` wavelet levels,
    after the ``side`` sequences of integers (a caller's parameters, such as kinwave's step
    codes: each coded as differences, in contexts of their own).
    ``revision`` 2 codes each block's approximation band as differences from the previous value
    and a sign in the context of the previous value's and the parent's signs (kinwave's gain:
    docs/kinwave.md)."""
    const = np.ascontiguousarray(const, dtype=np.int64)
    side_values = _differences(side)
    knots, coeffs, seg_pad, seg_lev, buf = _prepared(knots, coeffs, seg_pad, seg_lev, revision, side_values, const.size)
    n = _encode(side_values, const, knots, coeffs, seg_pad, seg_lev, revision >= 2, buf)
    return buf[:n].tobytes()


def _prepared(knots, coeffs, seg_pad, seg_lev, revision: int, side_values: np.ndarray, rows: int) -> tuple:
    """The coder's arrays as int64, and an output buffer large enough for ``rows`` channels of
    them (or any of their groups) after ``side_values``."""
    knots = np.ascontiguousarray(knots, dtype=np.int64)
    coeffs = np.ascontiguousarray(coeffs, dtype=np.int64)
    seg_pad, seg_lev = np.asarray(seg_pad, dtype=np.int64), np.asarray(seg_lev, dtype=np.int64)
    values = [side_values, coeffs.ravel(), knots[:, :1].ravel(), np.diff(knots, axis=1).ravel()]
    if revision >= 2:
        values.append(_approx_differences(coeffs, seg_pad, seg_lev))
    buf = buffer_for(rows + int_decisions(np.concatenate(values)) + 2 * len(seg_pad) * rows)
    return knots, coeffs, seg_pad, seg_lev, buf


def group_sizes(
    knots: np.ndarray, coeffs: np.ndarray, seg_pad: np.ndarray, seg_lev: np.ndarray, rows: int, revision: int = 1
) -> np.ndarray:
    """The bytes :func:`encode` gives every ``rows`` consecutive rows of ``knots`` and
    ``coeffs`` coded on their own (no constant flags set, no side sequences), in one call: a
    choice that codes many small groups (kinwave's coding forms) without a call per group."""
    knots, coeffs, seg_pad, seg_lev, buf = _prepared(
        knots, coeffs, seg_pad, seg_lev, revision, np.zeros(0, dtype=np.int64), rows
    )
    return _group_sizes(knots, coeffs, seg_pad, seg_lev, rows, revision >= 2, buf)


@kernel
def _group_sizes(knots, coeffs, seg_pad, seg_lev, rows, rev2, buf):
    groups = knots.shape[0] // rows
    out = np.empty(groups, dtype=np.int64)
    side, const = np.zeros(0, dtype=np.int64), np.zeros(rows, dtype=np.int64)
    for g in range(groups):
        a = g * rows
        out[g] = _encode(side, const, knots[a : a + rows], coeffs[a : a + rows], seg_pad, seg_lev, rev2, buf)
    return out


@dataclass(frozen=True)
class Decoded:
    const: np.ndarray
    knots: np.ndarray
    coeffs: np.ndarray
    side: tuple  # the side sequences
    used: int  # bytes read
    terms: tuple  # each side sequence's differences as coded (a caller that sent running sums reads its values here)


def decode(
    data: bytes,
    channels: int,
    num_knots: int,
    seg_pad: np.ndarray,
    seg_lev: np.ndarray,
    revision: int = 1,
    side_sizes: tuple = (),
) -> Decoded:
    """Inverse of :func:`encode`, given the lengths of the side sequences."""
    seg_pad = np.asarray(seg_pad, dtype=np.int64)
    n = int(seg_pad.sum())
    const = np.zeros(channels, dtype=np.int64)
    knots = np.zeros((channels, num_knots), dtype=np.int64)
    coeffs = np.zeros((channels, n), dtype=np.int64)
    side = np.zeros(sum(side_sizes), dtype=np.int64)
    used = _decode(
        np.frombuffer(data, dtype=np.uint8),
        side,
        channels,
        num_knots,
        n,
        seg_pad,
        np.asarray(seg_lev, dtype=np.int64),
        revision >= 2,
        const,
        knots,
        coeffs,
    )
    running = np.concatenate(([0], np.cumsum(side)))  # each sequence's sums: one running sum, less its start
    starts = [0, *itertools.accumulate(side_sizes)]
    sequences = tuple(running[a + 1 : b + 1] - running[a] for a, b in zip(starts, starts[1:]))
    terms = tuple(side[a:b] for a, b in zip(starts, starts[1:]))
    return Decoded(const, knots, coeffs, sequences, int(used), terms)


def warm() -> None:
    """Compile (or load) this coder's kernels on a tiny input, with the argument types its
    callers pass: ``mocodec warmup`` runs it in a second process while the first compiles
    the rest of a codec (the coder's kernels are among the largest)."""
    knots, coeffs = np.zeros((3, 2), dtype=np.int64), np.zeros((3, 16), dtype=np.int64)
    knots[:, 1], coeffs[:, ::3] = 5, -2
    layout = (np.array([16]), np.array([2]))
    group_sizes(knots, coeffs, *layout, 3, revision=2)
    data = encode(np.zeros(3, dtype=np.int64), knots, coeffs, *layout, revision=2, side=(np.arange(2),))
    decode(data, 3, 2, *layout, revision=2, side_sizes=(2,))
