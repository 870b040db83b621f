"""kinwave-live's prediction, the same arithmetic on both ends: each channel from its last two
decoded frames (order 2 or 1, chosen from their recent misses), clamped to the cells of the
layers below, and quantised; what each layer keeps between packets (:class:`Layer`)."""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from mocodec.codecs.kinwave.body import channel_steps
from mocodec.codecs.kinwave.live.syntax import contexts
from mocodec.codecs.shared.closedloop import depth_end, depth_start
from mocodec.coding.entropy import binarycoder as bc
from mocodec.kernels import kernel
from mocodec.kinematics import channel_plan
from mocodec.skeleton import Skeleton

if TYPE_CHECKING:
    from mocodec.codecs.kinwave.live.codec import KinwaveLiveCodec


ROUNDING = 0.25  # the quantiser's rounding offset (0.5: to the nearest; less: a dead zone)
MISS_DECAY = 0.5  # what a predictor's miss weighs one coded frame later (exact in binary)


@kernel
def predict(targets, history, count, gap, stride, steps, order, trust, lo, hi, out, ints, cell_lo, cell_hi, quantise):
    """Closed-loop prediction of the coded frames ``targets (T, k)``, ``stride`` frames apart,
    from the two last coded frames ``history (2, k)`` (``count`` of them valid, ``gap`` frames
    apart): order 2 a straight line, order 1 the last value, none at the start; the prediction
    is then clamped to ``[lo, hi] (T, k)`` (a layer below says the target lies there). With
    ``quantise`` the integers of the differences at ``steps`` go to ``ints``; else ``ints`` are
    given. ``out`` gets the decoded values and ``cell_lo``, ``cell_hi`` the interval of targets
    that give the same integer (what this layer tells the layer above); the arithmetic is the
    same on both ends."""
    T, k = out.shape
    prev0 = history[0].copy()
    prev1 = history[1].copy()
    n = count
    g = gap
    for t in range(T):
        ratio = stride / g
        for c in range(k):
            if n >= 2 and order[c] == 2:
                pred = prev1[c] + (prev1[c] - prev0[c]) * ratio
            elif n >= 1:
                pred = prev1[c]
            else:
                pred = 0.0
            if trust[c]:
                pred = min(max(pred, lo[t, c]), hi[t, c])
            if quantise:
                x = (targets[t, c] - pred) / steps[c]
                ints[t, c] = np.int64(np.floor(x + ROUNDING)) if x >= 0 else -np.int64(np.floor(-x + ROUNDING))
            i = ints[t, c]
            out[t, c] = pred + i * steps[c]
            low = i - ROUNDING if i > 0 else (i - 1 + ROUNDING if i < 0 else ROUNDING - 1)
            cell_lo[t, c] = pred + low * steps[c]
            cell_hi[t, c] = pred + (low + (1.0 if i != 0 else 2.0 - 2.0 * ROUNDING)) * steps[c]
        for c in range(k):
            prev0[c] = prev1[c]
            prev1[c] = out[t, c]
        n = min(n + 1, 2)
        g = stride


@kernel
def predict_columns(
    channels, targets, history, count, gap, stride, steps, order, trust, lo, hi, ints, decoded, cell_lo, cell_hi
):
    """:func:`predict` (quantising) of the ``channels`` of a packet's coded frames, whose
    ``targets (T, k)`` are given, reading and writing the whole packet's arrays ``(T, C)``
    (``history (2, C)``, ``steps``, ``order``, ``trust (C,)``); returns the decoded ``(T, k)``."""
    T, k = targets.shape
    sub_history = np.empty((2, k))
    sub_steps, sub_order, sub_trust = np.empty(k), np.empty(k, order.dtype), np.empty(k, trust.dtype)
    sub_lo, sub_hi = np.empty((T, k)), np.empty((T, k))
    for i in range(k):
        c = channels[i]
        sub_history[0, i], sub_history[1, i] = history[0, c], history[1, c]
        sub_steps[i], sub_order[i], sub_trust[i] = steps[c], order[c], trust[c]
        for t in range(T):
            sub_lo[t, i], sub_hi[t, i] = lo[t, c], hi[t, c]
    out, sub = np.empty((T, k)), np.zeros((T, k), dtype=np.int64)
    c_lo, c_hi = np.empty((T, k)), np.empty((T, k))
    predict(
        targets,
        sub_history,
        count,
        gap,
        stride,
        sub_steps,
        sub_order,
        sub_trust,
        sub_lo,
        sub_hi,
        out,
        sub,
        c_lo,
        c_hi,
        True,
    )
    for i in range(k):
        c = channels[i]
        for t in range(T):
            ints[t, c], decoded[t, c] = sub[t, i], out[t, i]
            cell_lo[t, c], cell_hi[t, c] = c_lo[t, i], c_hi[t, i]
    return out


@kernel
def predict_tree(loop, history, count, gap, stride, steps, order, trust, lo, hi, ints, decoded, cell_lo, cell_hi):
    """:func:`~mocodec.codecs.shared.closedloop.code_down_tree`'s loop over ``loop``
    (:func:`~mocodec.codecs.shared.closedloop.tree_loop`) with :func:`predict_columns` coding
    each depth, in one compiled call: a packet of a few frames spent most of its time in the
    Python loop's calls per depth and layer. The same floats as that loop."""
    tree = loop.tree
    for d in range(tree.depth_ptr.size - 1):
        targets = depth_start(
            tree, d, loop.start, loop.active, loop.goal, loop.glob, loop.skip, loop.where, loop.goal_positions,
            loop.targeted, loop.plan,
        )  # fmt: skip
        if targets.shape[1] == 0:
            continue
        coded = tree.coded[tree.coded_ptr[d] : tree.coded_ptr[d + 1]].copy()
        out = predict_columns(
            coded, targets, history, count, gap, stride, steps, order, trust, lo, hi, ints, decoded, cell_lo, cell_hi
        )
        depth_end(tree, d, out, loop.glob, loop.where, loop.placing, tree.steps)


@kernel
def update_misses(misses, history, count, gap, stride, coded):
    """After a layer's packet, on both ends: each channel's recent miss of the order-1 and the
    order-2 prediction (``misses (2, C)``) of its decoded coded frames ``coded (T, C)``,
    ``stride`` frames apart, from the last two before them (``history``, ``count`` valid,
    ``gap`` apart), each miss |decoded - prediction| added to the last times MISS_DECAY."""
    T, k = coded.shape
    prev0 = history[0].copy()
    prev1 = history[1].copy()
    n = count
    g = gap
    for t in range(T):
        if n >= 2:
            ratio = stride / g
            for c in range(k):
                line = prev1[c] + (prev1[c] - prev0[c]) * ratio
                misses[0, c] = misses[0, c] * MISS_DECAY + abs(coded[t, c] - prev1[c])
                misses[1, c] = misses[1, c] * MISS_DECAY + abs(coded[t, c] - line)
        for c in range(k):
            prev0[c] = prev1[c]
            prev1[c] = coded[t, c]
        n = min(n + 1, 2)
        g = stride


def fill(previous: np.ndarray, coded: np.ndarray, stride: int) -> np.ndarray:
    """All frames of a packet from its coded ones (every ``stride``-th, the last included) and
    the frame before the packet, by straight lines (the same arithmetic on both ends)."""
    if stride == 1:
        return coded
    out = np.empty((coded.shape[0] * stride, coded.shape[1]))
    starts = np.vstack((previous[None], coded[:-1]))
    for r in range(stride - 1):
        out[r::stride] = starts + (coded - starts) * ((r + 1) / stride)
    out[stride - 1 :: stride] = coded
    return out


@lru_cache(maxsize=64)
def joint_tables(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What every layer of a stream on ``skeleton`` shares (read-only): each joint with channels'
    first channel and count, the guess before the first frame: a translation channel of a joint
    below the root at its offset (a MotionBuilder export repeats every offset), everything else
    zero; and which channels are such translations."""
    joints = [j for j in range(len(skeleton)) if skeleton.joints[j].channels]
    first = np.array([skeleton.channel_offsets[j] for j in joints], dtype=np.int64)
    count = np.array([len(skeleton.joints[j].channels) for j in joints], dtype=np.int64)
    guess = np.zeros(skeleton.num_channels)
    shifts = np.zeros(skeleton.num_channels, dtype=bool)
    plan = channel_plan(skeleton)
    for j in range(1, len(skeleton)):
        for axis, c in enumerate(plan.pos_index[j]):
            if c >= 0:
                guess[c] = plan.offsets[j, axis]
                shifts[c] = True
    tables = (first, count, guess, shifts)
    for table in tables:
        table.setflags(write=False)
    return tables


class Layer:
    """What both ends keep for one layer of a stream: the joints with channels (their first
    channel and count) and the layer's base step codes for its bound, fixed; the arithmetic
    coder's state, the last two coded frames, each channel's recent misses of both predictors,
    the last packet's scale offset and which channels trust the cells of the layers below, from
    its (re)start on, when the last coded frame is the guess: the stream's reference pose, or
    else zero and the offsets (:func:`joint_tables`)."""

    def __init__(self, skeleton: Skeleton, codes: np.ndarray, reference: np.ndarray | None = None):
        self.skeleton = skeleton
        self.first, self.count, self.guess, self.shifts = joint_tables(skeleton)
        if reference is not None:
            self.guess = reference
        self.base_codes = codes
        self._steps: dict[int, np.ndarray] = {}
        self.restart()

    def restart(self) -> None:
        """Start again from nothing (the stream's start, or a refresh)."""
        self.state = bc.new_state(contexts(self.skeleton.num_channels, self.first.size), warm=True)
        self.last_nonzero = np.zeros(self.skeleton.num_channels, dtype=np.int64)
        self.history = np.vstack((np.zeros_like(self.guess), self.guess))  # the last two coded frames
        self.count_history = 1
        self.started = False  # a frame has been coded (strides above 1 need one before them)
        self.gap = 1  # frames between them
        self.offset = 0  # the last packet's scale offset
        self.trust = np.ones(self.skeleton.num_channels, dtype=np.bool_)
        self.misses = np.zeros((2, self.skeleton.num_channels))

    def orders(self) -> np.ndarray:
        """Each channel's predictor for the next packet: 2 (a straight line) where it missed
        the decoded frames less lately than 1 (the last value), else 1."""
        return np.where(self.misses[1] < self.misses[0], 2, 1)

    def steps(self, offset: int) -> np.ndarray:
        """Each channel's step at a scale ``offset`` (1/8 octaves) from the base codes (kept: a
        stream goes back and forth between a few offsets)."""
        if offset not in self._steps:
            codes = np.clip(self.base_codes.astype(np.int64) + offset, 0, 255).astype(np.uint8)
            steps = np.ascontiguousarray(channel_steps(self.skeleton, codes)[:, 0])
            steps.setflags(write=False)
            self._steps[offset] = steps
        return self._steps[offset]


class Cells:
    """Per frame of a packet and channel, the interval the nearest layer below that coded the
    frame puts the target in (everything before the base layer): a layer's prediction is
    clamped to it (:func:`predict`)."""

    def __init__(self, frames: int, channels: int):
        self.lo = np.full((frames, channels), -np.inf)
        self.hi = np.full((frames, channels), np.inf)

    def at(self, stride: int) -> tuple[np.ndarray, np.ndarray]:
        return np.ascontiguousarray(self.lo[stride - 1 :: stride]), np.ascontiguousarray(self.hi[stride - 1 :: stride])

    def update(self, stride: int, lo: np.ndarray, hi: np.ndarray) -> None:
        self.lo[stride - 1 :: stride], self.hi[stride - 1 :: stride] = lo, hi


def reconstruct(layer: Layer, ints: np.ndarray, offset: int, stride: int, cells: Cells):
    """The decoded coded frames ``(T', C)`` of one layer of a packet from its integers, the
    layer's previous coded frames and the cells of the layers below, and this layer's cells:
    the arithmetic of the encoder's :func:`predict`."""
    out = np.empty_like(ints, dtype=np.float64)
    cell_lo, cell_hi = np.empty_like(out), np.empty_like(out)
    predict(
        np.zeros((0, 0)),
        layer.history,
        layer.count_history,
        layer.gap,
        stride,
        layer.steps(offset),
        layer.orders(),
        layer.trust,
        *cells.at(stride),
        out,
        ints,
        cell_lo,
        cell_hi,
        False,
    )
    return out, cell_lo, cell_hi


def advance(layer: Layer, coded: np.ndarray, stride: int, offset: int, cells: Cells) -> None:
    """Both ends after a packet: its last two coded frames are the layer's next history, the
    predictors' misses take them in, and a channel trusts the cells of the layers below while
    its decoded values fall in them."""
    lo, hi = cells.at(stride)
    told = np.isfinite(lo)
    slack = 0.75 * layer.steps(offset)
    inside = (coded >= lo - slack) & (coded <= hi + slack)
    layer.trust = np.where(told.any(axis=0), (inside | ~told).all(axis=0), layer.trust)
    update_misses(layer.misses, layer.history, layer.count_history if layer.started else 0, layer.gap, stride, coded)
    if len(coded) >= 2:
        layer.history, layer.gap = coded[-2:].copy(), stride
    else:
        layer.history = np.vstack((layer.history[1:], coded))
        layer.gap = stride
    layer.count_history = min(layer.count_history + len(coded), 2) if layer.started else min(len(coded), 2)
    layer.started = True
    layer.offset = offset


def stream_layers(codec: KinwaveLiveCodec, skeleton: Skeleton) -> list[Layer]:
    return [Layer(skeleton, codes, codec.reference) for codes in codec.layer_codes(skeleton)]
