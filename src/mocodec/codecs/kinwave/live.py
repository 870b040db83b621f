"""``kinwave-live``: kinwave's low-delay mode for live avatars (docs/streaming.md).

A packet codes ``packet_frames`` frames (at most 50 ms: 6 at 120 fps, 1 at 30 fps) as soon as
they are in, with the pose representation of offline kinwave:

1. Joints are coded parents first, each against its parent's *decoded* orientation
   (:func:`~mocodec.codecs.shared.closedloop.code_down_tree`), so a joint's orientation error is
   its own quantisation error and errors do not pile up along the chains. A translation below
   the root that moves restores its joint's position from its parent's decoded one; one that
   stands still is coded as it is (:meth:`_LiveEncoder._retarget`).
2. Each channel is predicted from its last two decoded frames (order 2, a straight line, or
   order 1, the last value) and the difference is quantised with its joint's step: the decoded
   angle is within half a step of its target on every frame, whatever came before. Both ends
   choose the order per channel from the decoded frames alone (:func:`_update_misses`: the
   one that missed them less lately), so the choice costs no bits.
3. The steps' shape per joint is the convex allocation of :mod:`.kinalloc` for the max joint
   error; one scale offset per packet (1/8 octave) multiplies it. The encoder decodes each
   packet bit-exactly and checks the max joint (or shell) error of every frame against
   ``max_error_cm``; a packet over it is coded again finer, and a packet well under it lets the
   next start coarser.
4. The integers go through the context-adaptive binary arithmetic coder of
   :mod:`mocodec.coding.entropy.binarycoder`: per joint a flag "all zero in this packet", per
   channel and frame an integer whose zero flag is in the context of the channel's previous
   integer. The contexts carry over from packet to packet (a codec stream's packets depend on
   each other; the live stream restarts the codec at each keyframe, docs/streaming.md).
5. **Layers** (knob ``layers``): the stream may carry up to four layers, base first, each at
   ``layer_ratio`` (2) times the bound of the next (``layers=3`` at 1 cm: 4, 2 and 1 cm). Each
   layer is coded as above with its own history, steps and contexts, and closed-loop on the
   layers below: its prediction is clamped to the interval the nearest layer below that coded
   the frame puts the target in (the quantiser cell of that layer's integer), for the channels
   whose decoded values fell in those cells in the last packet (both ends judge this alike,
   nothing is sent). Its bound is checked on the decoding of it and the layers below.

A packet is one arithmetic-coded stream (:func:`~mocodec.coding.entropy.binarycoder.finish_short`,
its always-zero first byte left out): with ``refresh_s``, each layer's restart flag in a fixed
context; then per layer, base first, whether the packet is short (and its frame count), the
change of the scale offset, the stride, then per joint its "any nonzero" flag and its
integers. The layers are not delimited: a decoder of the whole packet finds where each ends,
the shortest prefix that decodes it and those below as the whole does (:func:`prefix_end`),
which the sender gives the relay as the packet's cut table; a relay serves a viewer the lowest
layers by cutting there, and says how many it cut off in the packet's frame.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numba
import numpy as np

from mocodec.codecs.base import Codec, Coded, Knob, QualityKnob, StreamDecoder, StreamEncoder, continuous_frames
from mocodec.codecs.kinwave import kinalloc
from mocodec.codecs.kinwave.encoder import bone_skeleton
from mocodec.codecs.kinwave.payload import channel_steps, code_channels, rotation_joints, step_codes, step_groups
from mocodec.codecs.registry import register
from mocodec.codecs.shared import closedloop
from mocodec.coding.entropy import binarycoder as bc
from mocodec.errors import CodecError, CorruptStreamError, OutOfStepError
from mocodec.formats import varint
from mocodec.kinematics import channel_plan, forward_kinematics
from mocodec.metrics.pose import worst_error
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

DELAY_S = 0.05  # the coding delay a packet may add
ULEN = 6  # unary contexts of an integer's size class
MAX_RETRIES = 12  # codings of one packet, each 1/2 octave finer, before it is refused
SPARSE_RETRIES = 3  # ... at a stride above 1, before that stride is given up
FINER = 4  # 1/8 octaves a packet over its bound goes finer at each retry
COARSER_BELOW = 0.9  # a packet under this share of the bound lets the next start a code coarser
MAX_OFFSET = 127
MAX_LAYERS = 4
MAX_REFERENCE = 1e9  # the largest reference value a stream header may give
ROUNDING = 0.25  # the quantiser's rounding offset (0.5: to the nearest; less: a dead zone)
MISS_DECAY = 0.5  # what a predictor's miss weighs one coded frame later (exact in binary)
DRIFT = 1  # the usual change of the scale offset: a packet under its bound lets the next go coarser
STILL_CM = 1e-3  # a translation that moves less than this in a packet stands still


def packet_frames(fps: float) -> int:
    """Frames per packet: as many as fit in DELAY_S (at least one)."""
    return max(int(math.floor(fps * DELAY_S + 1e-9)), 1)


@numba.njit(cache=True)
def _predict(targets, history, count, gap, stride, steps, order, trust, lo, hi, out, ints, cell_lo, cell_hi, quantise):
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


@numba.njit(cache=True)
def _predict_columns(
    channels, targets, history, count, gap, stride, steps, order, trust, lo, hi, ints, decoded, cell_lo, cell_hi
):
    """:func:`_predict` (quantising) of the ``channels`` of a packet's coded frames, whose
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
    _predict(
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


@numba.njit(cache=True)
def _update_misses(misses, history, count, gap, stride, coded):
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


def _fill(previous: np.ndarray, coded: np.ndarray, stride: int) -> np.ndarray:
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


def strides(frames: int) -> list[int]:
    """The strides a full packet of ``frames`` may code its frames at, sparsest first."""
    return [s for s in range(frames, 0, -1) if frames % s == 0]


# per channel: 6 zero flags (the channel's previous integer zero or not x the joint's previous
# channel in this frame: none, zero, nonzero), the sign, ULEN size classes, the mantissas
PER_CHANNEL = 7 + ULEN + bc.MAX_CLASS + 1
_HEAD_CONTEXTS = 2 + 3 * PER_CHANNEL  # full flag, frames, offset change, stride


def _contexts(channels: int, joints: int) -> int:
    return _HEAD_CONTEXTS + joints + channels * PER_CHANNEL


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


@numba.njit(cache=True)
def _code_restarts(st, buf, restarts):
    """Each layer's restart flag (0 or 1) at the head of a packet, in the fixed context."""
    for flag in restarts:
        bc.put(st, buf, _restart_context(), 0, flag)


@numba.njit(cache=True)
def _read_restarts(st, data, layers):
    out = np.zeros(layers, dtype=np.int64)
    for k in range(layers):
        out[k] = bc.get(st, data, _restart_context(), 0)
    return out


@numba.njit(cache=True)
def _code_layer(st, buf, ints, frames, full, offset_change, stride, first, count, state, last_nonzero):
    """Arithmetic-code one layer of a packet: its head (:func:`_put_head`), then per joint
    (channels ``first[j]`` to ``first[j] + count[j]``) an "any nonzero" flag, then the integers
    ``(T, C)`` of its coded frames."""
    T, C = ints.shape
    J = first.size
    per = PER_CHANNEL
    _put_head(st, buf, state, frames, full, offset_change, stride)
    H = _HEAD_CONTEXTS
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


@numba.njit(cache=True)
def _finish(st, buf):
    """:func:`~mocodec.coding.entropy.binarycoder.finish_short`, compiled once and cached."""
    return bc.finish_short(st, buf)


def _buffer(layers: list[tuple[_Layer, np.ndarray]]) -> np.ndarray:
    """A coder buffer that holds the packet of these layers' integers (head, flags and ends
    included)."""
    return bc.buffer_for(sum(bc.int_decisions(ints) + 2 * layer.first.size for layer, ints in layers) + 64)


@numba.njit(cache=True)
def _decode_head(st, data, full, state):
    frames, change, stride = _get_head(st, data, state, full)
    return frames, change, stride


@numba.njit(cache=True)
def _decode_ints(st, data, frames, first, count, state, last_nonzero, ints):
    J = first.size
    per = PER_CHANNEL
    H = _HEAD_CONTEXTS
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


@lru_cache(maxsize=64)
def _joint_tables(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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


class _Layer:
    """What both ends keep for one layer of a stream: the joints with channels (their first
    channel and count) and the layer's base step codes for its bound, fixed; the arithmetic
    coder's state, the last two coded frames, each channel's recent misses of both predictors,
    the last packet's scale offset and which channels trust the cells of the layers below, from
    its (re)start on, when the last coded frame is the guess: the stream's reference pose, or
    else zero and the offsets (:func:`_joint_tables`)."""

    def __init__(self, skeleton: Skeleton, codes: np.ndarray, reference: np.ndarray | None = None):
        self.skeleton = skeleton
        self.first, self.count, self.guess, self.shifts = _joint_tables(skeleton)
        if reference is not None:
            self.guess = reference
        self.base_codes = codes
        self._steps: dict[int, np.ndarray] = {}
        self.restart()

    def restart(self) -> None:
        """Start again from nothing (the stream's start, or a refresh)."""
        self.state = bc.new_state(_contexts(self.skeleton.num_channels, self.first.size), warm=True)
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


class _Cells:
    """Per frame of a packet and channel, the interval the nearest layer below that coded the
    frame puts the target in (everything before the base layer): a layer's prediction is
    clamped to it (:func:`_predict`)."""

    def __init__(self, frames: int, channels: int):
        self.lo = np.full((frames, channels), -np.inf)
        self.hi = np.full((frames, channels), np.inf)

    def at(self, stride: int) -> tuple[np.ndarray, np.ndarray]:
        return np.ascontiguousarray(self.lo[stride - 1 :: stride]), np.ascontiguousarray(self.hi[stride - 1 :: stride])

    def update(self, stride: int, lo: np.ndarray, hi: np.ndarray) -> None:
        self.lo[stride - 1 :: stride], self.hi[stride - 1 :: stride] = lo, hi


def layer_bounds(max_error_cm: float, layers: int, ratio: float = 2.0) -> list[float]:
    """The bounds of a stream's layers, base first: each ``ratio`` times the next, the last
    ``max_error_cm``."""
    return [max_error_cm * ratio ** (layers - 1 - k) for k in range(layers)]


def prefix_end(data: np.ndarray, read: int, code: int) -> int:
    """The shortest prefix of a packet from which an arithmetic decoder, reading zeros past its
    end, decodes what it decoded from the whole up to where it has read ``read`` bytes of
    ``data`` (the packet after its dropped first byte, :func:`_packet_data`) with ``code`` in
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


def base_codes(skeleton: Skeleton, bound_cm: float, measure: str) -> np.ndarray:
    """The step codes (one per rotation joint, then the translations) whose modelled max error
    is ``bound_cm`` (:func:`.kinalloc.steps`, closed loop): where a stream's scale starts."""
    counts = [0] * len(skeleton)
    translations = 0
    for g in step_groups(skeleton):
        if g.rotation:
            counts[g.joint] = g.channels.size
        else:
            translations += g.channels.size
    rot, trans = kinalloc.steps(skeleton, tuple(counts), translations, "shell" if measure == "shell" else "joint", True)
    rot = np.where(np.isfinite(rot), rot, np.nanmin(rot) if np.isfinite(rot).any() else 1.0)
    steps = np.append(rot[rotation_joints(skeleton)], trans if translations else [])
    return step_codes(np.asarray(steps) * bound_cm)


@register
class KinwaveLiveCodec(Codec):
    id = "kinwave-live"
    packet_number = 10
    description = (
        "kinwave for live avatars: closed-loop prediction down the kinematic tree, packets of at most "
        "50 ms, context-adaptive arithmetic coding across packets, guaranteed max error on every frame, "
        "layers a relay drops by cutting"
    )
    knobs = (
        Knob("max_error_cm", float, 1.0, "error bound in cm, held on every decoded frame", 1e-3, 1000.0),
        Knob(
            "error_measure",
            str,
            "joint",
            "joint: max joint position error; shell: points 3 cm off every bone",
            choices=("joint", "shell"),
        ),
        Knob(
            "layers",
            int,
            1,
            "layers of the stream, each at layer_ratio times the bound of the next (3: 4, 2 and 1 cm at "
            "max_error_cm 1)",
            1,
            MAX_LAYERS,
        ),
        Knob(
            "layer_ratio",
            float,
            2.0,
            "each layer's bound over the next one's: a coarser base costs the full stream less "
            "(2 layers at 32: 32 and 1 cm, about 1.1x one layer at 1 cm; at 2, about 1.4x)",
            1.0,
            1000.0,
        ),
        Knob(
            "refresh_s",
            float,
            0.0,
            "seconds between restarts of each layer inside the codec stream, the layers' restarts "
            "spread over that time (0: none; the live stream's keyframes restart the whole stream)",
            0.0,
            60.0,
        ),
    )
    quality = QualityKnob("max_error_cm", higher_is_better=False, log_scale=True)
    # 2: the predictor orders are no longer sent (both ends choose them, _update_misses);
    # 3: the head codes a still packet's usual values as zeros (full flag, drift, stride index)
    revision = 3
    reference: np.ndarray | None = None  # the stream's reference pose (for_stream)
    codes: np.ndarray | None = None  # the stream's base step codes per layer (for_stream)

    def delay_frames(self) -> int:
        return 0  # plus the packet's own frames: packet_frames(fps) - 1 at most

    def bound_knobs(self, target: str, value: float) -> dict | None:
        """Its bound holds on every decoded frame of the full stream (the finest layer)."""
        return {"max_error_cm": value} if target == "max_error_cm" else None

    @property
    def layers(self) -> int:
        return self.config["layers"]

    @property
    def layer_bounds(self) -> list[float]:
        """Each layer's bound in cm, base first."""
        return layer_bounds(self.config["max_error_cm"], self.config["layers"], self.config["layer_ratio"])

    def layer_starts(self, payload: bytes) -> list[bool]:
        layers = self.config["layers"]
        if not self.config["refresh_s"]:
            return [False] * layers
        data = _packet_data(payload)
        return [bool(flag) for flag in _read_restarts(bc.start_decoder(data), data, layers)]

    def restart_frames(self, fps: float) -> tuple[int, list[int]]:
        """(period, phase of each layer) in frames of the layers' restarts inside a codec stream:
        layer k restarts in the packet that holds a frame ``f`` with ``f % period == phase[k]``
        (0: never)."""
        if not self.config["refresh_s"]:
            return 0, []
        period = max(int(round(self.config["refresh_s"] * fps)), packet_frames(fps))
        layers = self.config["layers"]
        return period, [k * period // layers for k in range(layers)]

    def packet_frames(self, fps: float) -> int:
        return packet_frames(fps)

    def decoder_tables(self, skeleton: Skeleton, primer: np.ndarray | None = None) -> dict:
        """Each layer's base step codes (:func:`base_codes`, base layer first): the convex
        allocation's result, which a decoder elsewhere cannot recompute exactly; and with a
        ``primer``, its first frame as the stream's *reference pose* (to 1e-4 of a degree or a
        skeleton unit), from which every codec stream of the live stream predicts its first
        frame (:meth:`for_stream`): a keyframe then codes how the pose moved since, not the
        pose. The allocation's levers are then the motion's own bones (the offsets plus the
        reference's translations below the root, :func:`.encoder.bone_skeleton`: a skeleton
        that keeps its bones in position channels has zero offsets)."""
        measure = self.config["error_measure"]
        levers = skeleton
        tables: dict = {}
        if primer is not None and len(primer):
            tables["reference"] = [round(float(v), 4) for v in primer[0]]
            levers = bone_skeleton(skeleton, np.array(tables["reference"])[:, None], _joint_tables(skeleton)[3])
        tables["base_codes"] = [base_codes(levers, b, measure).tolist() for b in self.layer_bounds]
        return tables

    def for_stream(self, skeleton: Skeleton, tables: dict) -> KinwaveLiveCodec:
        """This codec with a live stream header's base step codes and reference pose
        (:meth:`decoder_tables`), where it gives them: CorruptStreamError for codes that are
        not a list per layer of one integer 0-255 per step, or a reference that is not a
        finite value per channel within MAX_REFERENCE."""
        if not isinstance(tables, dict) or not ("base_codes" in tables or "reference" in tables):
            return self
        bound = type(self)(**self.config)
        if "base_codes" in tables:
            bound.codes = _checked_codes(tables["base_codes"], skeleton, len(self.layer_bounds))
        if "reference" in tables:
            bound.reference = _checked_reference(tables["reference"], skeleton)
        return bound

    def layer_codes(self, skeleton: Skeleton) -> list[np.ndarray]:
        """Each layer's base step codes: a stream header's (:meth:`for_stream`), else those of
        the skeleton's offsets."""
        if self.codes is not None:
            return list(self.codes)
        return [base_codes(skeleton, b, self.config["error_measure"]) for b in self.layer_bounds]

    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return _LiveEncoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return _LiveDecoder(self, skeleton, fps)

    def _encode(self, motion: Motion) -> bytes:
        """A clip is its stream: every packet after its length (a varint)."""
        enc = self.encoder(motion.skeleton, motion.fps)
        return b"".join(varint.pack(len(p)) + p for p in enc.push(motion.channels) + enc.flush())

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        dec = self.decoder(skeleton, fps)
        out, pos = [], 0
        while pos < len(body):
            try:
                size, pos = varint.unpack(body, pos, 4)
            except ValueError as e:
                raise CorruptStreamError(f"kinwave-live body: a packet length: {e}") from None
            if pos + size > len(body):
                raise CorruptStreamError(f"kinwave-live body: a {size}-byte packet at byte {pos} runs past the end")
            out.append(dec.push(body[pos : pos + size]))
            pos += size
        return np.concatenate(out) if out else np.zeros((0, skeleton.num_channels))


def _checked_codes(codes: object, skeleton: Skeleton, layers: int) -> np.ndarray:
    count = len(code_channels(skeleton))
    if not (
        isinstance(codes, list)
        and len(codes) == layers
        and all(
            isinstance(row, list)
            and len(row) == count
            and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255 for v in row)
            for row in codes
        )
    ):
        raise CorruptStreamError(
            f"kinwave-live stream header: base_codes must be {layers} lists of {count} step codes 0-255"
        )
    return np.array(codes, dtype=np.int64)


def _checked_reference(reference: object, skeleton: Skeleton) -> np.ndarray:
    if (
        not isinstance(reference, list)
        or len(reference) != skeleton.num_channels
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in reference)
    ):
        raise CorruptStreamError(
            f"kinwave-live stream header: the reference pose must be {skeleton.num_channels} numbers"
        )
    values = np.array(reference, dtype=np.float64)
    if not (np.isfinite(values).all() and np.abs(values).max(initial=0.0) <= MAX_REFERENCE):
        raise CorruptStreamError(f"kinwave-live stream header: a reference value beyond {MAX_REFERENCE:g}")
    return values


def _layers(codec: KinwaveLiveCodec, skeleton: Skeleton) -> list[_Layer]:
    return [_Layer(skeleton, codes, codec.reference) for codes in codec.layer_codes(skeleton)]


def _packet_data(packet: bytes) -> np.ndarray:
    """A packet as the arithmetic decoder reads it: its always-zero first byte put back."""
    return np.frombuffer(b"\0" + bytes(packet), dtype=np.uint8)


def _reconstruct(layer: _Layer, ints: np.ndarray, offset: int, stride: int, cells: _Cells):
    """The decoded coded frames ``(T', C)`` of one layer of a packet from its integers, the
    layer's previous coded frames and the cells of the layers below, and this layer's cells:
    the arithmetic of the encoder's :func:`_predict`."""
    out = np.empty_like(ints, dtype=np.float64)
    cell_lo, cell_hi = np.empty_like(out), np.empty_like(out)
    _predict(
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


def _advance(layer: _Layer, coded: np.ndarray, stride: int, offset: int, cells: _Cells) -> None:
    """Both ends after a packet: its last two coded frames are the layer's next history, the
    predictors' misses take them in, and a channel trusts the cells of the layers below while
    its decoded values fall in them."""
    lo, hi = cells.at(stride)
    told = np.isfinite(lo)
    slack = 0.75 * layer.steps(offset)
    inside = (coded >= lo - slack) & (coded <= hi + slack)
    layer.trust = np.where(told.any(axis=0), (inside | ~told).all(axis=0), layer.trust)
    _update_misses(layer.misses, layer.history, layer.count_history if layer.started else 0, layer.gap, stride, coded)
    if len(coded) >= 2:
        layer.history, layer.gap = coded[-2:].copy(), stride
    else:
        layer.history = np.vstack((layer.history[1:], coded))
        layer.gap = stride
    layer.count_history = min(layer.count_history + len(coded), 2) if layer.started else min(len(coded), 2)
    layer.started = True
    layer.offset = offset


def layer_ends(payload: bytes, layers: list[_Layer], contexts: list, full: int, refresh: bool) -> list[int]:
    """Where each layer of a packet ends (:func:`prefix_end`), read from its arithmetic code
    alone with each layer's contexts as they were before it (``contexts``: a copy of each
    layer's state and last nonzero flags, consumed): the integers are read, no motion is
    reconstructed."""
    data = _packet_data(payload)
    st = bc.start_decoder(data)
    if refresh:
        _read_restarts(st, data, len(layers))
    ends = []
    for layer, (state, last_nonzero) in zip(layers, contexts):
        frames, _, stride = _decode_head(st, data, full, state)
        ints = np.zeros((frames // stride, last_nonzero.size), dtype=np.int64)
        _decode_ints(st, data, frames // stride, layer.first, layer.count, state, last_nonzero, ints)
        ends.append(prefix_end(data, int(st[2]), int(st[0])))
    return ends


class _LiveEncoder(StreamEncoder):
    def __init__(self, codec: KinwaveLiveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.layers = _layers(codec, skeleton)
        self.bounds = codec.layer_bounds
        self.size = packet_frames(fps)
        self.pending = np.zeros((0, skeleton.num_channels))
        self.previous: np.ndarray | None = None  # the last continuous frame
        self.offsets = [0] * len(self.layers)  # where each layer's next packet starts
        self.cm = 100.0 / skeleton.units_per_metre
        self.period, self.phases = codec.restart_frames(fps)
        self.frame = 0  # the first frame of the next packet
        self.last_values: np.ndarray | None = None  # the last packet's last original frame
        self.cut = len(self.layers) > 1  # a relay may cut its packets by layers

    def follow(self, previous: StreamEncoder) -> None:
        """Each layer's scale offset goes on from where the last stream left it (a restart codes
        it in full), rather than finding its way back from the allocation's a packet at a time."""
        if isinstance(previous, _LiveEncoder) and len(previous.offsets) == len(self.offsets):
            self.offsets = list(previous.offsets)

    def code(self, frames: np.ndarray) -> list[Coded]:
        cont = continuous_frames(self.codec.id, self.skeleton, self.fps, frames, self.previous)
        if len(cont):
            self.previous = cont[-1]
            self.pending = np.vstack((self.pending, cont))
        out = []
        while len(self.pending) >= self.size:
            out.append(self._packet(self.pending[: self.size]))
            self.pending = self.pending[self.size :]
        return out

    def finish(self) -> list[Coded]:
        if not len(self.pending):
            return []
        packet = self._packet(self.pending)
        self.pending = self.pending[:0]
        return [packet]

    def _code(self, layer: _Layer, values, goal, retarget, offset: int, stride: int, cells: _Cells):
        """The integers, decoded coded frames and cells of one layer of a packet at ``offset``
        and ``stride`` (every ``stride``-th frame coded, down the tree), and all its decoded
        frames; ``goal`` is the packet's original positions and orientations (forward
        kinematics, once), ``retarget`` the channels the closed loop sets (:meth:`_retarget`)."""
        steps = layer.steps(offset)
        order = layer.orders()
        coded = np.ascontiguousarray(values[stride - 1 :: stride])
        ints = np.zeros(coded.shape, dtype=np.int64)
        decoded, cell_lo, cell_hi = np.zeros(coded.shape), np.zeros(coded.shape), np.zeros(coded.shape)
        lo, hi = cells.at(stride)
        pos, quats = (np.ascontiguousarray(g[stride - 1 :: stride]) for g in goal)

        history, trust = np.ascontiguousarray(layer.history), np.ascontiguousarray(layer.trust)
        lo, hi = np.ascontiguousarray(lo), np.ascontiguousarray(hi)

        def code(channels: np.ndarray, targets: np.ndarray) -> np.ndarray:
            return _predict_columns(
                channels,
                np.ascontiguousarray(targets),
                history,
                layer.count_history,
                layer.gap,
                stride,
                steps,
                order,
                trust,
                lo,
                hi,
                ints,
                decoded,
                cell_lo,
                cell_hi,
            )

        closedloop.code_down_tree(self.skeleton, coded, retarget, quats, code, True, pos)
        return ints, decoded, (cell_lo, cell_hi), _fill(layer.history[1], decoded, stride)

    def _error(self, goal: tuple[np.ndarray, np.ndarray], decoded: np.ndarray) -> float:
        p0, q0 = goal
        p1, q1 = forward_kinematics(self.skeleton, decoded)
        return worst_error(self.skeleton, p0 * self.cm, q0, p1 * self.cm, q1, self.codec.config["error_measure"])

    def _fit(self, k: int, values, goal, retarget, stride: int, retries: int, cells: _Cells):
        """(integers, coded frames, cells, offset, worst error) of layer ``k`` of the packet at
        ``stride``, from the layer's current offset and finer until its bound holds, or None."""
        offset = self.offsets[k]
        for tried in range(retries if stride > 1 else MAX_OFFSET):
            ints, coded, coded_cells, frames = self._code(self.layers[k], values, goal, retarget, offset, stride, cells)
            worst = self._error(goal, frames)
            if worst <= self.bounds[k]:
                return ints, coded, coded_cells, offset, worst
            if offset <= -MAX_OFFSET:
                return None
            # 1/2 octave finer a try; past ``retries`` (a scale that quiet motion let drift far
            # coarser), twice as far each time
            offset = max(offset - FINER * 2 ** max(tried + 1 - retries, 0), -MAX_OFFSET)
        return None

    def _trial_size(self, layer: _Layer, ints: np.ndarray, frames: int, change: int, stride: int) -> int:
        """The bytes layer ``layer``'s part of a packet would take coded on its own (its
        contexts left as they are): what a stride is chosen by."""
        buf, st = _buffer([(layer, ints)]), bc.encoder_state()
        state, last = layer.state.copy(), layer.last_nonzero.copy()
        _code_layer(st, buf, ints, frames, self.size, change, stride, layer.first, layer.count, state, last)
        return int(_finish(st, buf))

    def _retarget(self, values: np.ndarray) -> np.ndarray:
        """The channels whose targets the closed loop sets: every one but the translations below
        the root that stand still through this packet (and since the last). A translation the
        motion moves (the body's root under a dummy root) restores its joint's position from its
        parent's decoded one; one that stands still (a MotionBuilder export's six channels on
        every joint repeat the offsets) is coded as it is, nearly for free, rather than made to
        carry its parents' quantisation errors in every frame."""
        since = values[0] if self.last_values is None else self.last_values
        moved = np.abs(values - since).max(axis=0) > STILL_CM / self.cm
        return ~self.layers[0].shifts | moved

    def _packet(self, values: np.ndarray) -> Coded:
        """One packet of every layer, with where each layer but the top one ends in it (read
        back from the arithmetic code, :func:`layer_ends`) and whether the base restarts."""
        goal = forward_kinematics(self.skeleton, values)
        retarget = self._retarget(values)
        cells = _Cells(len(values), values.shape[1])
        restarts = [self._restart_flag(k, len(values)) for k in range(len(self.layers))]
        coded = [self._layer_packet(k, values, goal, retarget, cells, restarts[k]) for k in range(len(self.layers))]
        self.frame += len(values)
        self.last_values = values[-1]
        contexts = [(layer.state.copy(), layer.last_nonzero.copy()) for layer in self.layers] if self.cut else []
        buf, st = _buffer([(layer, ints) for layer, (ints, *_) in zip(self.layers, coded)]), bc.encoder_state()
        if self.period:
            _code_restarts(st, buf, np.array(restarts, dtype=np.int64))
        for layer, (ints, change, stride) in zip(self.layers, coded):
            first, count, state, last = layer.first, layer.count, layer.state, layer.last_nonzero
            _code_layer(st, buf, ints, len(values), self.size, change, stride, first, count, state, last)
        payload = buf[1 : _finish(st, buf)].tobytes()  # the first byte is always 0
        ends = layer_ends(payload, self.layers, contexts, self.size, bool(self.period))[:-1] if self.cut else []
        return Coded(payload, len(values), tuple(ends), bool(restarts[0]))

    def _restart_flag(self, k: int, frames: int) -> int:
        """1 if layer ``k`` restarts in the packet of ``frames`` frames starting at
        ``self.frame`` (never without refresh, nor in the stream's first: every layer starts
        there), else 0."""
        if not self.period:
            return 0
        first = (self.phases[k] - self.frame) % self.period  # the packet's first restart frame
        return int(self.frame > 0 and first < frames)

    def _layer_packet(self, k: int, values: np.ndarray, goal, retarget, cells: _Cells, restart: int):
        """Layer ``k`` of a packet, (integers, scale offset change, stride) to code: the
        cheapest stride that holds its bound on every frame, predicted within the cells of the
        layers below; the cells become its own. A layer that restarts here starts again from
        nothing: its history, contexts and scale offset."""
        layer = self.layers[k]
        if restart:
            layer.restart()
        sparse = layer.started and len(values) == self.size
        best = None
        for stride in strides(len(values)) if sparse else [1]:
            fit = self._fit(k, values, goal, retarget, stride, MAX_RETRIES if stride == 1 else SPARSE_RETRIES, cells)
            if fit is None:
                continue
            ints, coded, coded_cells, offset, worst = fit
            size = self._trial_size(layer, ints, len(values), offset - layer.offset, stride)
            if best is None or size < best[0]:
                best = (size, stride, ints, coded, coded_cells, offset, worst)
        if best is None:
            raise CodecError(f"kinwave-live cannot hold {self.bounds[k]:g} cm on a packet")
        _, stride, ints, coded, coded_cells, offset, worst = best
        self.offsets[k] = min(offset + DRIFT, MAX_OFFSET) if worst < COARSER_BELOW * self.bounds[k] else offset
        change = offset - layer.offset
        _advance(layer, coded, stride, offset, cells)
        cells.update(stride, *coded_cells)
        return ints, change, stride


class _LiveDecoder(StreamDecoder):
    """Decodes every layer a packet carries that it is in step with: a layer the packet lacks
    (a relay dropped it) or that followed a loss is out of step until it restarts (a packet
    whose head says so, with ``refresh_s``, or the next codec stream), and so are the
    layers above it, whose predictions lean on it."""

    def __init__(self, codec: KinwaveLiveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton = codec, skeleton
        self.layers = _layers(codec, skeleton)
        self.layer_in_step = [True] * len(self.layers)
        self.refresh = bool(codec.config["refresh_s"])
        self.size = packet_frames(fps)
        self.data = _packet_data(b"")  # the last packet, and where the decoder stood after each layer of it
        self.read: list[tuple[int, int]] = []

    @property
    def in_step(self) -> bool:
        return self.layer_in_step[0]

    @property
    def layers_in_step(self) -> int:
        """How many layers the next packet can decode (those below an out-of-step one)."""
        return self.layer_in_step.index(False) if False in self.layer_in_step else len(self.layers)

    def lost(self) -> bool:
        self.layer_in_step = [False] * len(self.layers)
        return self.refresh

    def push_layers(self, packet: bytes, layers: int) -> np.ndarray:
        """The frames of ``packet``, which carries its stream's ``layers`` lowest layers (a
        relay's cut is said by the packet's frame, :attr:`mocodec.stream.packets.Packet.dropped`)."""
        return self.push(packet, layers)

    def push(self, packet: bytes, layers: int | None = None) -> np.ndarray:
        """The frames of ``packet``, which carries its stream's ``layers`` lowest layers (None: all)."""
        count = len(self.layers) if layers is None else layers
        if not 1 <= count <= len(self.layers):
            raise CorruptStreamError(f"kinwave-live packet: {count} layers of a stream of {len(self.layers)}")
        data = _packet_data(packet)
        st = bc.start_decoder(data)
        restarts = (
            _read_restarts(st, data, len(self.layers)) if self.refresh else np.zeros(len(self.layers), dtype=np.int64)
        )
        self.data, self.read = data, []
        cells = out = None
        below = True  # every layer below this one decoded this packet
        for k in range(len(self.layers)):
            if below and k < count and restarts[k]:
                self.layers[k].restart()
                self.layer_in_step[k] = True
            below = below and k < count and self.layer_in_step[k]
            if not below:
                self.layer_in_step[k] = False
                continue
            try:
                out, cells = self._layer(self.layers[k], st, data, cells)
            except CorruptStreamError:
                self.layer_in_step[k:] = [False] * (len(self.layers) - k)
                raise
            self.read.append((int(st[2]), int(st[0])))
        if out is None:
            raise OutOfStepError("kinwave-live: waiting for the base layer to restart")
        return out

    @property
    def layer_ends(self) -> list[int]:
        """Where each layer the last packet pushed decoded ends in it: the shortest prefix that
        decodes that layer and those below as the whole packet does (:func:`prefix_end`); the
        sender's cut table, by which a relay drops the top layers without decoding."""
        return [prefix_end(self.data, read, code) for read, code in self.read]

    def _layer(self, layer: _Layer, st: np.ndarray, data: np.ndarray, cells: _Cells | None):
        frames, change, stride = _decode_head(st, data, self.size, layer.state)
        offset = layer.offset + change
        if not (
            1 <= frames <= self.size
            and abs(offset) <= MAX_OFFSET
            and 1 <= stride <= frames
            and frames % stride == 0
            and (stride == 1 or layer.started)
            and (cells is None or cells.lo.shape[0] == frames)
        ):
            raise CorruptStreamError(
                f"kinwave-live packet: {frames} frames at stride {stride} and scale offset "
                f"{offset} (the data is damaged)"
            )
        cells = cells or _Cells(frames, self.skeleton.num_channels)
        coded_frames = frames // stride
        ints = np.zeros((coded_frames, self.skeleton.num_channels), dtype=np.int64)
        _decode_ints(st, data, coded_frames, layer.first, layer.count, layer.state, layer.last_nonzero, ints)
        if np.abs(ints).max(initial=0) >= 1 << 40:
            raise CorruptStreamError("kinwave-live packet: an integer out of range (the data is damaged)")
        coded, cell_lo, cell_hi = _reconstruct(layer, ints, offset, stride, cells)
        out = _fill(layer.history[1], coded, stride)
        _advance(layer, coded, stride, offset, cells)
        cells.update(stride, cell_lo, cell_hi)
        return out, cells
