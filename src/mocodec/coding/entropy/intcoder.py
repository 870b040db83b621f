"""Context-adaptive coding of a frames x channels array of small integers (the codes of the
waveform coders of 000 ch. 7: quantiser indices, differences, update flags).

Values are coded frame by frame (so a stream packet holds whole frames), each with the binary
decisions of :func:`mocodec.coding.entropy.binarycoder.put_int`. Every channel has its own adaptive
contexts, in the context of its previous value's size (zero, small, large), so a quiet
channel's codes cost little whatever its neighbours do; the top mantissa bit's contexts are
shared.

The codes of a quantiser with N levels are better coded as such (``Model(channels,
levels=N)``): each is a path down a binary tree of its ``ceil(log2 N)`` bits, every node an
adaptive context of its own per channel and per quarter of the range the channel's previous
code fell in, so the coder learns each channel's whole distribution at a fixed number of
decisions per value (better for ``quant`` and ``adpcm``; ``dpcm``'s differences, peaked at
zero, do better the first way: docs/codecs.md).

Either plays the part of the thesis's statistical coder (7.4) as a "black box" after each
coder, adaptive like its adaptive Huffman coder but within a fraction of a bit of the entropy.
"""

from __future__ import annotations

import numba
import numpy as np

from mocodec.coding.entropy.binarycoder import (
    MAX_CLASS,
    buffer_for,
    encoder_state,
    finish,
    get,
    get_even,
    get_int,
    int_decisions,
    new_state,
    put,
    put_even,
    put_int,
    start_decoder,
)
from mocodec.kernels import kernel

_ACT = 3  # previous value: zero, |v| <= 2, larger
_UNARY = 8
_PER_CHANNEL = _ACT * (1 + _UNARY) + 2  # zero flags, unary positions, sign (after >= 0 / < 0)
_TREE_BITS = 8
_PREV_BITS = 2  # bounded codes: the previous code's quarter of the range
_PREV_SETS = 1 << _PREV_BITS


@numba.njit(inline="always")
def _act(prev):
    m = prev if prev >= 0 else -prev
    return 0 if m == 0 else (1 if m <= 2 else 2)


@numba.njit(inline="always")
def _contexts(c, prev):
    base = MAX_CLASS + c * _PER_CHANNEL
    a = _act(prev)
    return base + a, base + _ACT + a * _UNARY, base + _ACT * (1 + _UNARY) + (1 if prev < 0 else 0)


class Model:
    """The adaptive state of one coded array: probabilities and each channel's previous
    value. A stream keeps one per part, so packets go on learning where the last one stopped
    (and so depend on it, as the coders' own state does).

    ``levels`` > 0 declares the values bounded, ``-levels//2 <= v < levels - levels//2`` (a
    quantiser's codes): each is then coded as ``v + levels//2`` down a binary tree, its top 8
    bits in adaptive contexts (per channel and quarter of the range of the previous code), the
    rest at probability 1/2."""

    def __init__(self, channels: int, levels: int = 0):
        self.channels, self.levels = channels, levels
        self.bits = int(levels - 1).bit_length() if levels > 1 else 0
        self.tree_bits = min(self.bits, _TREE_BITS)
        per_channel = (_PREV_SETS << self.tree_bits) if levels else _PER_CHANNEL
        size = MAX_CLASS + channels * per_channel
        self.state = new_state(size)
        self.prev = np.zeros(channels, dtype=np.int64)

    def copy(self) -> Model:
        other = Model(self.channels, self.levels)
        other.state[:], other.prev[:] = self.state, self.prev
        return other


@kernel
def _encode(values, buf, state, prev):
    frames, channels = values.shape
    st = encoder_state()
    for t in range(frames):
        for c in range(channels):
            z, u, s = _contexts(c, prev[c])
            v = values[t, c]
            put_int(st, buf, state, v, z, u, _UNARY, 0, s)
            prev[c] = v
    return finish(st, buf)


@kernel
def _decode(data, frames, channels, out, state, prev):
    st = start_decoder(data)
    for t in range(frames):
        for c in range(channels):
            z, u, s = _contexts(c, prev[c])
            v = get_int(st, data, state, z, u, _UNARY, 0, s)
            out[t, c] = v
            prev[c] = v
    return st[2]


@numba.njit(inline="always")
def _tree_base(c, prev_u, shift, size):
    """The first context of channel c's tree for a previous code ``prev_u`` (0..levels-1)."""
    return MAX_CLASS + (c * _PREV_SETS + (prev_u >> shift)) * size


@kernel
def _encode_tree(values, buf, state, prev, half, bits, tree_bits):
    frames, channels = values.shape
    st = encoder_state()
    size = 1 << tree_bits
    shift = max(bits - _PREV_BITS, 0)
    for t in range(frames):
        for c in range(channels):
            u = values[t, c] + half
            base = _tree_base(c, prev[c] + half, shift, size)
            node = 1
            for i in range(bits - 1, bits - 1 - tree_bits, -1):
                b = (u >> i) & 1
                put(st, buf, state, base + node, b)
                node = 2 * node + b
            for i in range(bits - 1 - tree_bits, -1, -1):
                put_even(st, buf, (u >> i) & 1)
            prev[c] = u - half
    return finish(st, buf)


@kernel
def _decode_tree(data, out, state, prev, half, bits, tree_bits):
    frames, channels = out.shape
    st = start_decoder(data)
    size = 1 << tree_bits
    shift = max(bits - _PREV_BITS, 0)
    for t in range(frames):
        for c in range(channels):
            base = _tree_base(c, prev[c] + half, shift, size)
            node = 1
            for _ in range(tree_bits):
                node = 2 * node + get(st, data, state, base + node)
            u = node - size
            for _ in range(bits - tree_bits):
                u = 2 * u + get_even(st, data)
            out[t, c] = u - half
            prev[c] = u - half
    return st[2]


def _model(model: Model | None, channels: int) -> Model:
    if model is None:
        return Model(channels)
    if model.channels != channels:
        raise ValueError(f"a model for {model.channels} channels cannot code {channels}")
    return model


def encode(values: np.ndarray, model: Model | None = None) -> bytes:
    """The bytes of a ``(frames, channels)`` integer array (the shape is not stored); a given
    ``model`` is continued and updated (ValueError for values outside a bounded model's levels)."""
    values = np.ascontiguousarray(values, dtype=np.int64)
    if values.ndim != 2:
        raise ValueError(f"intcoder codes a (frames, channels) array, got shape {values.shape}")
    m = _model(model, values.shape[1])
    if m.levels:
        half = m.levels // 2
        if values.size and (values.min() < -half or values.max() >= m.levels - half):
            raise ValueError(f"values outside the {m.levels} levels the model codes")
        buf = buffer_for(values.size * m.bits)
        return buf[: _encode_tree(values, buf, m.state, m.prev, half, m.bits, m.tree_bits)].tobytes()
    buf = buffer_for(int_decisions(values))
    return buf[: _encode(values, buf, m.state, m.prev)].tobytes()


def decode(data: bytes, frames: int, channels: int, model: Model | None = None) -> np.ndarray:
    """Inverse of :func:`encode` for a ``(frames, channels)`` array (with the same model
    state). Damaged data decodes to garbage of the right shape (callers check a CRC first)."""
    m = _model(model, channels)
    out = np.zeros((frames, channels), dtype=np.int64)
    if m.levels:
        _decode_tree(np.frombuffer(data, dtype=np.uint8), out, m.state, m.prev, m.levels // 2, m.bits, m.tree_bits)
        return out
    _decode(np.frombuffer(data, dtype=np.uint8), frames, channels, out, m.state, m.prev)
    return out
