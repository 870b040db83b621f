"""kinwave-live's bitstream: a packet's head (frame count, scale offset change, stride), the
layers' restart flags, each joint's "any nonzero" flag and its integers, in the contexts of
the binary arithmetic coder; where a layer ends in a packet (:func:`prefix_end`). The
format is described in :mod:`.codec`."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba
import numpy as np

from mocodec.coding.entropy import binarycoder as bc
from mocodec.kernels import kernel

if TYPE_CHECKING:
    from mocodec.codecs.kinwave.live.predict import Layer


DELAY_S = 0.05  # the coding delay a packet may add
ULEN = 6  # unary contexts of an integer's size class
MAX_OFFSET = 127
MAX_LAYERS = 4
DRIFT = 1  # the usual change of the scale offset: a packet under its bound lets the next go coarser


def packet_frames(fps: float) -> int:
    """Frames per packet: as many as fit in DELAY_S (at least one)."""
    return max(int(math.floor(fps * DELAY_S + 1e-9)), 1)


def strides(frames: int) -> list[int]:
    """The strides a full packet of ``frames`` may code its frames at, sparsest first."""
    return [s for s in range(frames, 0, -1) if frames % s == 0]


# per channel: 6 zero flags (the channel's previous integer zero or not x the joint's previous
# channel in this frame: none, zero, nonzero), the sign, ULEN size classes, the mantissas
PER_CHANNEL = 7 + ULEN + bc.MAX_CLASS + 1
HEAD_CONTEXTS = 2 + 3 * PER_CHANNEL  # full flag, frames, offset change, stride


def contexts(channels: int, joints: int) -> int:
    return HEAD_CONTEXTS + joints + channels * PER_CHANNEL


@numba.njit(inline="always")
def _put_head(st, buf, state, frames, full, offset_change, stride):
    per = PER_CHANNEL
    bc.put(st, buf, state, 0, 0 if frames == full else 1)
    if frames != full:
        bc.put_int(st, buf, state, frames, 2, 9, ULEN, 9 + ULEN, 8)
    b = 2 + per
    bc.put_int(st, buf, state, offset_change - DRIFT, b, b + 7, ULEN, b + 7 + ULEN, b + 6)
    b = 2 + 2 * per
    bc.put_int(st, buf, state, _stride_index(frames, stride), b, b + 7, ULEN, b + 7 + ULEN, b + 6)


@numba.njit(inline="always")
def _get_head(st, data, state, full):
    per = PER_CHANNEL
    frames = full
    if bc.get(st, data, state, 0) == 1:
        frames = bc.get_int(st, data, state, 2, 9, ULEN, 9 + ULEN, 8)
    b = 2 + per
    change = DRIFT + bc.get_int(st, data, state, b, b + 7, ULEN, b + 7 + ULEN, b + 6)
    b = 2 + 2 * per
    index = bc.get_int(st, data, state, b, b + 7, ULEN, b + 7 + ULEN, b + 6)
    stride = _stride_at(frames, index) if 1 <= frames <= full else 0  # damaged: refused by the caller
    return frames, change, stride


@numba.njit(inline="always")
def _stride_index(frames, stride):
    """A stride's place among the divisors of ``frames``, sparsest first (the one a still
    avatar's packet codes at is 0, which costs least)."""
    index = 0
    for d in range(frames, stride, -1):
        if frames % d == 0:
            index += 1
    return index


@numba.njit(inline="always")
def _stride_at(frames, index):
    """The inverse of :func:`_stride_index`; 0 if ``frames`` has no such divisor."""
    for d in range(frames, 0, -1):
        if frames % d == 0:
            if index == 0:
                return d
            index -= 1
    return 0


@numba.njit(inline="always")
def _restart_context():
    """The context of a layer's restart flag, 1 in 16, made afresh for each flag (never
    adapted), so that a decoder that lost the stream's contexts, or a relay, reads it."""
    state = np.empty((3, 1), dtype=np.int64)
    state[0, 0] = state[1, 0] = 65536 - 65536 // 16
    state[2, 0] = bc.WARM_DONE
    return state


@kernel
def code_restarts(st, buf, restarts):
    """Each layer's restart flag (0 or 1) at the head of a packet, in the fixed context."""
    for flag in restarts:
        bc.put(st, buf, _restart_context(), 0, flag)


@kernel
def read_restarts(st, data, layers):
    out = np.zeros(layers, dtype=np.int64)
    for k in range(layers):
        out[k] = bc.get(st, data, _restart_context(), 0)
    return out


@kernel
def code_layer(st, buf, ints, frames, full, offset_change, stride, first, count, state, last_nonzero):
    """Arithmetic-code one layer of a packet: its head (:func:`_put_head`), then per joint
    (channels ``first[j]`` to ``first[j] + count[j]``) an "any nonzero" flag, then the integers
    ``(T, C)`` of its coded frames."""
    T, C = ints.shape
    J = first.size
    per = PER_CHANNEL
    _put_head(st, buf, state, frames, full, offset_change, stride)
    H = HEAD_CONTEXTS
    for j in range(J):
        nonzero = 0
        for t in range(T):
            for c in range(first[j], first[j] + count[j]):
                if ints[t, c] != 0:
                    nonzero = 1
        bc.put(st, buf, state, H + j, nonzero)
        if nonzero:
            for t in range(T):
                neighbour = 0
                for c in range(first[j], first[j] + count[j]):
                    base = H + J + c * per
                    z = base + 3 * last_nonzero[c] + neighbour
                    bc.put_int(st, buf, state, ints[t, c], z, base + 7, ULEN, base + 7 + ULEN, base + 6)
                    last_nonzero[c] = 1 if ints[t, c] != 0 else 0
                    neighbour = 1 + last_nonzero[c]
        else:
            for c in range(first[j], first[j] + count[j]):
                last_nonzero[c] = 0


@kernel
def finish(st, buf):
    """:func:`~mocodec.coding.entropy.binarycoder.finish_short`, compiled once and cached."""
    return bc.finish_short(st, buf)


def coder_buffer(layers: list[tuple[Layer, np.ndarray]]) -> np.ndarray:
    """A coder buffer that holds the packet of these layers' integers (head, flags and ends
    included)."""
    return bc.buffer_for(sum(bc.int_decisions(ints) + 2 * layer.first.size for layer, ints in layers) + 64)


@kernel
def decode_head(st, data, full, state):
    frames, change, stride = _get_head(st, data, state, full)
    return frames, change, stride


@kernel
def decode_ints(st, data, frames, first, count, state, last_nonzero, ints):
    J = first.size
    per = PER_CHANNEL
    H = HEAD_CONTEXTS
    for j in range(J):
        if bc.get(st, data, state, H + j) == 1:
            for t in range(frames):
                neighbour = 0
                for c in range(first[j], first[j] + count[j]):
                    base = H + J + c * per
                    z = base + 3 * last_nonzero[c] + neighbour
                    v = bc.get_int(st, data, state, z, base + 7, ULEN, base + 7 + ULEN, base + 6)
                    ints[t, c] = v
                    last_nonzero[c] = 1 if v != 0 else 0
                    neighbour = 1 + last_nonzero[c]
        else:
            for c in range(first[j], first[j] + count[j]):
                last_nonzero[c] = 0
    return st[2]


def prefix_end(data: np.ndarray, read: int, code: int) -> int:
    """The shortest prefix of a packet from which an arithmetic decoder, reading zeros past its
    end, decodes what it decoded from the whole up to where it has read ``read`` bytes of
    ``data`` (the packet after its dropped first byte, :func:`packet_data`) with ``code`` in
    its register: the first ``n`` bytes whose value is at least the coder's interval's low end
    then, ``data[:read]`` less ``code`` (every value from there up to the whole packet's lies in
    that interval). Returns ``n`` less the dropped byte."""
    window = bytes(data[:read]).ljust(read, b"\0")
    low = int.from_bytes(window, "big") - code
    short, long = 1, read  # data[:1] (the zero byte) may fall short, data[:read] does not
    while short < long:
        mid = (short + long) // 2
        if int.from_bytes(window[:mid].ljust(read, b"\0"), "big") >= low:
            long = mid
        else:
            short = mid + 1
    return short - 1


def packet_data(packet: bytes) -> np.ndarray:
    """A packet as the arithmetic decoder reads it: its always-zero first byte put back."""
    return np.frombuffer(b"\0" + bytes(packet), dtype=np.uint8)


def layer_ends(payload: bytes, layers: list[Layer], contexts: list, full: int, refresh: bool) -> list[int]:
    """Where each layer of a packet ends (:func:`prefix_end`), read from its arithmetic code
    alone with each layer's contexts as they were before it (``contexts``: a copy of each
    layer's state and last nonzero flags, consumed): the integers are read, no motion is
    reconstructed."""
    data = packet_data(payload)
    st = bc.start_decoder(data)
    if refresh:
        read_restarts(st, data, len(layers))
    ends = []
    for layer, (state, last_nonzero) in zip(layers, contexts):
        frames, _, stride = decode_head(st, data, full, state)
        ints = np.zeros((frames // stride, last_nonzero.size), dtype=np.int64)
        decode_ints(st, data, frames // stride, layer.first, layer.count, state, last_nonzero, ints)
        ends.append(prefix_end(data, int(st[2]), int(st[0])))
    return ends
