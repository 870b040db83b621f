"""``kinwave``: the project's own error-bounded, skeleton-aware wavelet codec (kinwave.md).

Per payload of T frames:

1. Angles are made continuous (:meth:`Motion.continuous`); channels constant to 1e-6 are
   collapsed to one knot (1/8 of a step; a translation about its joint's offset); leading
   frames that jump away (a bind pose, a T-pose) may be coded as one-frame segments
   (keyframes) where a trial pass says it is cheaper; an isolated frame far from both its
   neighbours (a glitch) is coded apart as a patch on the neighbours' mean. Each three-angle joint is coded in the
   form that costs least (:mod:`mocodec.codecs.shared.rotvec`: its Euler angles, a rotation vector
   about its mean rotation, Euler angles in another order), so the file's Euler order, a
   gimbal lock or a rotated dummy root above it do not change what is coded.
2. Joints are coded parents first. Each joint's angles are the *closed-loop* target: the
   angles that restore its original global orientation on top of its parent's decoded one
   (:mod:`mocodec.codecs.shared.closedloop`), so errors do not pile up along chains. The root's
   translations (in cm) are coded as they are; a translated joint below the root restores its
   original position from its parent's decoded one.
3. Every channel becomes knots at segment starts plus a wavelet-coded residual per segment of
   ``window`` frames (:mod:`mocodec.coding.transforms.trendwave`: CDF 9/7, ``levels`` deep, periodised),
   quantised with a dead zone by its joint's step, and the integers go through the
   context-adaptive binary arithmetic coder of :mod:`mocodec.coding.entropy.coefcoder`. Segments
   share their knots but their residuals' errors are independent, so the decoded curve steps
   where they meet; the reconstruction (on both ends) spreads each seam's step over 8 frames
   each side (:func:`mocodec.coding.transforms.seams.smooth_seams`, at most one step of the channel's
   quantiser): jerk at the seams falls 5-14x and, as the step was error, the files shrink.
4. Steps: the shape per joint comes from the convex allocation of
   :mod:`mocodec.codecs.kinwave.kinalloc` for the chosen error measure; one scale multiplies it. With
   ``max_error_cm`` the scale is predicted from the model and corrected by a secant in log-log
   space on the *decoded* output (the encoder reconstructs through the decoder's own
   functions), so the bound holds on what the decoder will produce, verified on the final bytes;
   with ``bits_per_second`` the same search aims at the payload's byte budget within 2%.
5. Under a max-error bound a first pass corrects the model's step per joint by the slack it
   measured at the points the joint moves (the model overstates quiet joints' errors), and a
   payload of 4 segments or more gets time-adaptive steps: each segment a step offset of its
   own (1/8 octave), searched on its own worst error, so quiet stretches are not coded as
   finely as the busiest one needs.

Payload body: u8 format (1), u8 flags (bits 0 and 5: one or two leading keyframes, bits 1-2
wavelet, bit 3 segment offsets, bit 4 coding forms, bit 6 mean rotations, bit 7 isolated
frames), u8 log2 window, u8 levels, u16 channels (a payload for another skeleton is refused),
with bit 7 a u8 count of isolated frames (glitches coded apart: their positions and one patch
per channel follow in the stream's side sequences), then the arithmetic-coded
stream (:mod:`mocodec.coding.entropy.coefcoder`, revision 2), which opens with one step code per joint
with rotation channels and one for translations (step = 2^(code/8 - 20) degrees or cm), with
bit 3 one step offset per segment, with bit 4 a coding form per three-angle joint
(:mod:`mocodec.codecs.shared.rotvec`) and with bit 6 three mean-rotation integers per such joint.
docs/formats.md gives the layout byte by byte.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from mocodec import rotations
from mocodec.codecs.base import Codec, Knob, QualityKnob, StreamDecoder, StreamEncoder
from mocodec.codecs.kinwave import kinalloc
from mocodec.codecs.registry import register
from mocodec.codecs.shared import closedloop, rotvec
from mocodec.coding.entropy import coefcoder
from mocodec.coding.transforms import seams, trendwave
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.formats import varint
from mocodec.kinematics import channel_plan, forward_kinematics
from mocodec.metrics.pose import bone_joints, shell_errors
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

FORMAT = 1  # the payload format (docs/formats.md), pinned by the golden fixtures
CODER_REVISION = 2  # the coefficient coder's revision (coefcoder: differences in the approximation band)
_HEAD = struct.Struct("<BBBBH")  # format, flags, log2 window, levels, channels
FLAG_OFFSETS = 8  # flags bit 3: a signed step offset per segment follows the step codes
FLAG_FORMS = 16  # flags bit 4: per 3-angle joint its coding form (rotvec: 0 the file's Euler angles,
# 1 a rotation vector, 2-7 Euler angles in a Tait-Bryan order, 8-15 those forms of
# the rotation turned by the constant joints above, rotvec.WORLD; formats 1-2: 0, 1)
FLAG_MEANS = 64  # flags bit 6: three integers per 3-angle joint, a vector joint's mean rotation
MEAN_QUANTUM = 2.0  # degrees: a vector joint's mean rotation, as a rotation vector in these steps
MEAN_LEAST = 20.0  # degrees: a mean rotation smaller than this is left at the identity
FLAG_ISOLATED = 128  # flags bit 7: a byte n after the header; n isolated frames coded apart (format 3)
MAX_ISOLATED = 32  # isolated frames a payload codes apart at most
FLAG_KEYFRAME = 1  # flags bit 0: frame 0 is a keyframe (a one-frame segment)
FLAG_SECOND_KEYFRAME = 32  # flags bit 5 (with bit 0): frame 1 is one too
WAVELET_IDS = ("cdf97", "d4", "haar")
CONSTANT = 1e-6  # a channel whose range is below this is one knot
CONST_FRACTION = 1.0 / 8.0  # format 3: a constant channel's quantum, in steps of its joint
MAX_PASSES = 8  # secant passes before falling back to halving
JOINT_FEEDBACK = 1.0  # share of a joint's measured slack (in octaves) its steps take on
SLACK_PASSES = 2  # rounds in which a max bound's final pass gives its slack away (_use_slack)
SEGMENT_SLACK_BELOW = 0.9  # ... with time-adaptive steps only when its worst error is under this share
ACCEPT = 0.95  # a max-error bound is met well enough at 95-100% of it (0.9: 1-1.6% larger files)
MEAN_ACCEPT = 0.97  # a mean-error bound (smooth in the scale: 1.9% fewer bytes than at 0.9 for
# 1.3 more passes)
SEGMENT_PASSES = 2  # passes of the per-segment search before the combination is fixed
MARGIN = 0.95  # a segment whose error was this close to the bound goes a code finer when combined
SEGMENT_ACCEPT = 0.8  # a segment's worst error is near enough to the bound at this share of it
ADAPTIVE_SEGMENTS = 4  # time-adaptive steps from this many segments on (at W = 128 on fewer they
# measured 1.6% larger than one scale, from 4 on 3% smaller, from 8 on 9%)
RATE_TOLERANCE = 0.02
JUMP_CM = 10.0  # a leading frame jumping less than this is not tried as a keyframe
TRIAL_FRAMES = 1024  # frames the choice of forms codes each form of every joint on
GIMBAL_MARGIN = 15.0  # degrees from an Euler order's lock within which a joint goes as a vector
COARSEST_BAND_S = 0.25  # seconds between the coarsest band's samples (the automatic levels)
SEAM_HALF_WIDTH = 8  # frames each side of a seam over which its step is spread
SEAM_LIMIT = 1.0  # the largest step removed, in quantiser steps of the channel


def _code(step: float) -> int:
    return int(np.clip(np.round((math.log2(step) + 20.0) * 8.0), 0, 255))


def _step(code: int) -> float:
    return 2.0 ** (code / 8.0 - 20.0)


@dataclass(frozen=True)
class _Group:
    """Channels coded together with one step: a joint's rotation steps, or its translations."""

    joint: int
    rotation: bool
    channels: np.ndarray  # channel indices (rotation: in rotation-order steps)
    axes: np.ndarray  # rotation axes of the steps


@lru_cache(maxsize=64)
def _groups(skeleton: Skeleton) -> tuple[_Group, ...]:
    plan = channel_plan(skeleton)
    out = []
    for j in range(len(skeleton)):
        pos = plan.pos_index[j][plan.pos_index[j] >= 0]
        if pos.size:
            out.append(_Group(j, False, pos, np.zeros(0, dtype=np.int64)))
        k = int((plan.rot_index[j] >= 0).sum())
        if k:
            out.append(_Group(j, True, plan.rot_index[j, :k].copy(), plan.rot_axis[j, :k].copy()))
    return tuple(out)


def _group_step(g: _Group, codes: np.ndarray, skeleton: Skeleton) -> float:
    """A group's quantiser step from the payload's step codes (one per rotation joint, then
    the translation code in cm): degrees, or skeleton units for translations."""
    if g.rotation:
        return _step(codes[_rotation_joints(skeleton).index(g.joint)])
    return _step(codes[-1]) * skeleton.units_per_metre / 100.0


@lru_cache(maxsize=64)
def _influence(skeleton: Skeleton, measure: str) -> np.ndarray:
    """``(codes, points)``: which of the points a max bound measures each step code moves (a
    rotation joint: the joints below it, and with ``shell`` its own bone's shell; the
    translations: all)."""
    n = len(skeleton)
    below = np.zeros((n, n), dtype=bool)
    for p in range(n):
        j = skeleton.parents[p]
        while j >= 0:
            below[j, p] = True
            j = skeleton.parents[j]
    if measure == "shell":
        points = bone_joints(skeleton)
        below = below[:, points] | (np.arange(n)[:, None] == points[None, :])
    rows = [below[j] for j in _rotation_joints(skeleton)]
    if _has_translation(skeleton):
        rows.append(np.ones(below.shape[1], dtype=bool))
    return np.array(rows)


def _rotation_joints(skeleton: Skeleton) -> list[int]:
    return [g.joint for g in _groups(skeleton) if g.rotation]


def _has_translation(skeleton: Skeleton) -> bool:
    return any(not g.rotation for g in _groups(skeleton))


@lru_cache(maxsize=64)
def _three_angle_groups(skeleton: Skeleton) -> tuple[tuple[np.ndarray, str], ...]:
    """``(channels, order)`` of every joint with three rotation channels (in rotation order):
    the joints that may be coded as rotation vectors."""
    return tuple(
        (g.channels, "".join("XYZ"[a] for a in g.axes))
        for g in _groups(skeleton)
        if g.rotation and g.channels.size == 3
    )


def _parent_orientations(skeleton: Skeleton, frame: np.ndarray) -> np.ndarray:
    """``(joints, 4)``: each joint's parent's orientation ``G_p`` in one frame of channels
    ``frame (C,)`` (the identity for the root)."""
    _, quats = forward_kinematics(skeleton, frame[None])
    parents = skeleton.parents
    return np.where((parents >= 0)[:, None], quats[0, np.maximum(parents, 0)], np.array([1.0, 0.0, 0.0, 0.0]))


def _parent_turns(skeleton: Skeleton, parents: np.ndarray) -> np.ndarray:
    """``(n, 4)``: per three-angle joint, ``conj(C) G_p C``, its parent's orientation
    (``parents``, :func:`_parent_orientations`) seen through the joint's own pre-rotation ``C``:
    the turn a WORLD form (:mod:`mocodec.codecs.shared.rotvec`) puts on the joint's rotation ``M``,
    since ``G = G_p C M C^-1 = C (conj(C) G_p C M) C^-1``. Encoder and decoder compute it from
    the same decoded constants, so it is the same floats on both ends."""
    joints = np.array([skeleton.channel_joints[g[0]] for g, _ in _three_angle_groups(skeleton)], dtype=np.int64)
    out = parents[joints]
    axis = np.array([skeleton.joints[j].has_axis for j in joints], dtype=bool)
    if axis.any():
        c = rotations.matrix_to_quat(skeleton.axis_matrices)[joints[axis]]
        out[axis] = rotations.quat_multiply(rotations.quat_conjugate(c), rotations.quat_multiply(out[axis], c))
    return out


def _still_rotations(skeleton: Skeleton, const: np.ndarray) -> np.ndarray:
    """``(joints,)``: whether a joint and every joint above it hold constant rotations
    (``const (C,)`` per channel)."""
    plan = channel_plan(skeleton)
    still = np.ones(len(skeleton), dtype=bool)
    for j in range(len(skeleton)):
        p = skeleton.parents[j]
        still[j] = bool(const[plan.rot_index[j][plan.rot_index[j] >= 0]].all()) and (p < 0 or still[p])
    return still


def _world_translations(skeleton: Skeleton, const: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """``(joint, its X, Y, Z position channels)`` of every non-root joint whose three
    translations all move and whose ancestors' rotations are all constant (the body's root
    under a dummy root): they are coded on the world's axes, ``G_p t`` with ``G_p`` from the
    decoded constants, so a dummy's turn does not tilt their quantisation grid (under no turn
    ``G_p`` is the identity and nothing changes). Implied by the constant flags: no side data."""
    if not const.size:
        return []
    plan, still, out = channel_plan(skeleton), _still_rotations(skeleton, const), []
    for j in range(1, len(skeleton)):
        pos = plan.pos_index[j]
        if still[skeleton.parents[j]] and (pos >= 0).all() and not const[pos].any():
            out.append((j, pos.copy()))
    return out


def _on_axes(rows: np.ndarray, turn: np.ndarray, inverse: bool = False) -> np.ndarray:
    """Translation rows ``(3, T)`` turned by the unit quaternion ``turn`` (its inverse)."""
    q = rotations.quat_conjugate(turn) if inverse else turn
    return rotations.quat_rotate(np.broadcast_to(q, (rows.shape[1], 4)), rows.T).T


def _factors(offsets: np.ndarray, lay: trendwave.Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step factors of the segments' offsets (1/8 octave each) at every knot (a knot takes its
    segment's; the end knot the last segment's), every coefficient, and every seam (the finer
    of its two sides)."""
    f = 2.0 ** (np.asarray(offsets, dtype=np.float64) / 8.0)
    last = max(lay.starts.size - 1, 0)
    knot = f[np.minimum(np.arange(lay.num_knots), last)] if f.size else np.ones(lay.num_knots)
    return knot, np.repeat(f, lay.padded), np.minimum(f[:-1], f[1:])


@dataclass(frozen=True)
class _Constants:
    """How constant channels are coded: one knot, ``fraction`` of the joint's step, about
    ``base (C,)``. Format 3: a constant's error is the same in every frame and is not noise
    that the closed loop averages out (a dummy root's rotation turns the whole body), so its
    quantum is 8 times finer than the step, and a constant translation is coded as its
    difference from the joint's offset on the decoder's skeleton (a MotionBuilder export
    repeats every offset in its position channels: these cost one decision each)."""

    fraction: float
    base: np.ndarray


def _constants(skeleton: Skeleton) -> _Constants:
    base = np.zeros(skeleton.num_channels)
    plan = channel_plan(skeleton)
    for j in range(len(skeleton)):
        for axis, c in enumerate(plan.pos_index[j]):
            if c >= 0:
                base[c] = plan.offsets[j, axis]
    return _Constants(CONST_FRACTION, base)


def _reconstruct(
    knots: np.ndarray,
    coeffs: np.ndarray,
    const: np.ndarray,
    step: np.ndarray,
    lay: trendwave.Layout,
    factors: tuple[np.ndarray, np.ndarray, np.ndarray],
    constants: _Constants,
) -> np.ndarray:
    """Decoded channels ``(k, T)`` from their integers, steps ``(k, 1)`` and the segments'
    step :func:`_factors`: the same arithmetic on both ends (the encoder calls it a tree depth
    at a time, the decoder for all channels at once; each row's floats are the same either
    way). A constant channel is its first knot as :class:`_Constants` says (``base`` of these
    rows)."""
    knot_f, coeff_f, seam_f = factors
    values = knots * (step * lay.knot_quantum * knot_f)
    values[const] = constants.base[const, None] + knots[const, :1] * (step[const] * constants.fraction)
    out = trendwave.trend(values, lay) + trendwave.synthesise(coeffs * (step * coeff_f), lay)
    limits = SEAM_LIMIT * seam_f[:, None] * step[:, 0]
    return seams.smooth_seams(out.T, lay.starts[1:], SEAM_HALF_WIDTH, limits).T


def _levels_for(fps: float) -> int:
    """Wavelet levels whose coarsest band samples every ~1/4 s (COARSEST_BAND_S): the depth
    that was best at 120 fps (5) keeps its meaning at other rates; at 30 fps 3 levels made
    Bandai Namco files 2-4% smaller than 5."""
    return int(np.clip(round(math.log2(max(fps, 1.0) * COARSEST_BAND_S)), 1, 10))


def _frame_moves(positions_cm: np.ndarray) -> np.ndarray:
    """``(T - 1,)`` cm: how far the farthest-moving joint goes from each frame to the next."""
    return np.linalg.norm(np.diff(positions_cm, axis=0), axis=2).max(axis=1)


def _jumps_at_start(positions_cm: np.ndarray) -> bool:
    """Whether the first or second frame jumps far from the next one: twice the clip's own
    largest frame-to-frame motion after them, and at least JUMP_CM (a bind pose, a T-pose, or
    both, lead the clip; a walk's first step does not)."""
    if len(positions_cm) < 8:
        return False
    moves = _frame_moves(positions_cm)
    return bool(moves[:2].max() > max(2.0 * np.percentile(moves[2:], 99) + 1.0, JUMP_CM))


@dataclass
class _Pass:
    steps: np.ndarray  # u8 codes: rotation joints, then translation
    const: np.ndarray
    knots: np.ndarray
    coeffs: np.ndarray
    decoded: np.ndarray  # (C, T)
    offsets: np.ndarray  # i8 per segment: its steps are 2^(offset/8) times the joints'
    patches: np.ndarray  # (C, isolated frames): each isolated frame's correction (_patch)


@register
class KinwaveCodec(Codec):
    id = "kinwave"
    description = (
        "project codec: closed-loop wavelet coding down the kinematic tree, convex step allocation, "
        "context-adaptive arithmetic coding, guaranteed error bound (kinwave.md)"
    )
    knobs = (
        Knob("max_error_cm", float, 0.5, "error bound in cm, held on the decoded output", 1e-4, 1000.0),
        Knob(
            "error_measure",
            str,
            "joint",
            "what the bound limits: shell = points 3 cm off every bone (worst), "
            "joint = max joint position error, mean = mean joint position error",
            choices=kinalloc.MODES,
        ),
        Knob("bits_per_second", float, 0.0, "code to this bit rate instead of an error bound (0: off)", 0.0, 1e9),
        Knob(
            "window",
            int,
            256,
            "segment length in frames (a power of two): the streaming delay (128 halves it, "
            "for 2-6% more bytes at a mean-error bound)",
            8,
            4096,
        ),
        Knob(
            "levels",
            int,
            0,
            "wavelet levels per segment (0: by the frame rate, the coarsest band about 1/4 s "
            "apart: 5 at 120 fps, 4 at 60, 3 at 30 and 24)",
            0,
            10,
        ),
        Knob("wavelet", str, "cdf97", "segment transform", choices=WAVELET_IDS),
        Knob("deadzone", float, 0.4, "rounding offset of the dead-zone quantiser (0.5: plain rounding)", 0.0, 0.5),
        Knob("closed_loop", bool, True, "code each joint against its parent's decoded orientation"),
        Knob(
            "allocation",
            str,
            "convex",
            "per-joint steps: convex program, or one step for every angle",
            choices=("convex", "uniform"),
        ),
        Knob(
            "joint_feedback",
            bool,
            True,
            "under a max-error bound, correct each joint's step by the slack a first "
            "pass measured at the points it moves",
        ),
        Knob(
            "segment_steps",
            bool,
            True,
            "under a max-error bound, give each segment its own step offset (time-"
            "adaptive steps, from 4 segments on): quiet stretches get coarser steps",
        ),
        Knob(
            "rotation_vectors",
            bool,
            True,
            "code each 3-angle joint in the form that costs least: its Euler "
            "angles, a rotation vector about its mean rotation, or Euler angles in another order (off: the file's "
            "Euler angles always; ASF skeletons under a max bound: the root and joints near gimbal lock only)",
        ),
        Knob(
            "keyframes",
            bool,
            True,
            "code the first one or two frames on their own where they jump far from the "
            "rest (a bind pose or T-pose in frame 0), so they do not cost the wavelet",
        ),
    )
    quality = QualityKnob("max_error_cm", higher_is_better=False, log_scale=True)
    streaming = True

    def __init__(self, **knobs):
        super().__init__(**knobs)
        w = self.config["window"]
        if w & (w - 1):
            raise CodecError(f"codec kinwave: window must be a power of two, got {w}")

    @property
    def delay_frames(self) -> int:  # type: ignore[override]
        return self.config["window"]

    def target_knobs(self, target: str, value: float, motion: Motion, overhead_bytes: int = 0) -> dict | None:
        """Knobs that make the encoder itself meet a rate-control target (:mod:`ratecontrol`)."""
        if target == "max_error_cm":
            measure = self.config["error_measure"]
            return {
                "max_error_cm": value,
                "bits_per_second": 0.0,
                "error_measure": "joint" if measure == "mean" else measure,
            }
        if target == "mean_error_cm":
            return {"max_error_cm": value, "bits_per_second": 0.0, "error_measure": "mean"}
        if target in ("ratio", "bitrate"):
            bits = motion.raw_bits / value if target == "ratio" else value * motion.duration
            return {"bits_per_second": max((bits - 8 * overhead_bytes) / max(motion.duration, 1e-9), 1.0)}
        return None

    # ----- encoding -----------------------------------------------------------------------
    def _encode(self, motion: Motion) -> bytes:
        return _Encoder(self, motion).run()

    def _encode_for(self, motion: Motion, output_skeleton: Skeleton) -> bytes:
        return _Encoder(self, motion, output_skeleton).run()

    # ----- decoding -----------------------------------------------------------------------
    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        rot_joints = _rotation_joints(skeleton)
        trans = _has_translation(skeleton)
        num_codes = len(rot_joints) + trans
        if len(body) < _HEAD.size:
            raise CorruptStreamError(
                f"kinwave payload of {len(body)} bytes is shorter than its {_HEAD.size}-byte header"
            )
        version, flags, log_w, levels, channels = _HEAD.unpack_from(body)
        if version != FORMAT:
            raise CorruptStreamError(f"kinwave payload format {version}, this mocodec reads {FORMAT}")
        if channels != skeleton.num_channels:
            raise CorruptStreamError(
                f"kinwave payload has {channels} channels, the skeleton {skeleton.num_channels}: wrong skeleton?"
            )
        if log_w > 16 or not 1 <= levels <= 10 or (flags >> 1) & 3 >= len(WAVELET_IDS):
            raise CorruptStreamError(f"kinwave payload header is damaged (window 2^{log_w}, levels {levels})")
        keyframes = int(bool(flags & FLAG_KEYFRAME)) * (2 if flags & FLAG_SECOND_KEYFRAME else 1)
        lay = trendwave.layout(frames, 1 << log_w, levels, keyframes, WAVELET_IDS[(flags >> 1) & 3])
        num_offsets = lay.starts.size if flags & FLAG_OFFSETS else 0
        num_vectors = len(_three_angle_groups(skeleton)) if flags & FLAG_FORMS else 0
        num_means = 3 * num_vectors if flags & FLAG_MEANS else 0
        start, num_isolated = _HEAD.size, 0
        if flags & FLAG_ISOLATED:
            if len(body) <= start or not 1 <= body[start] <= MAX_ISOLATED:
                raise CorruptStreamError(f"kinwave payload's isolated frame count at byte {start} is damaged")
            start, num_isolated = start + 1, body[start]
        coded = coefcoder.decode(
            body[start:],
            skeleton.num_channels,
            lay.num_knots,
            lay.padded,
            lay.levels,
            CODER_REVISION,
            (num_codes, num_offsets, num_vectors, num_means, num_isolated, num_isolated * skeleton.num_channels),
        )
        codes, offsets, forms, running, isolated, patched = coded.side
        means = np.diff(running, prepend=0).reshape(-1, 3)
        patches = np.diff(patched, prepend=0).reshape(skeleton.num_channels, num_isolated)
        if num_isolated and not (1 <= isolated[0] and (np.diff(isolated) > 1).all() and isolated[-1] < frames - 1):
            raise CorruptStreamError("kinwave payload's isolated frames are damaged")
        if (
            (codes.size and not 0 <= codes.min() <= codes.max() <= 255)
            or np.abs(offsets).max(initial=0) > 128
            or not rotvec.valid_forms(forms)
            or np.abs(means).max(initial=0) * MEAN_QUANTUM > 360.0
        ):
            raise CorruptStreamError("kinwave payload's step codes are damaged")
        if not num_offsets:
            offsets = np.zeros(lay.starts.size, dtype=np.int8)
        if not frames:
            return np.zeros((0, skeleton.num_channels))
        return _decoded(
            skeleton,
            codes,
            offsets,
            coded.const,
            coded.knots,
            coded.coeffs,
            lay,
            forms,
            _constants(skeleton),
            means,
            (isolated, patches),
        ).T

    # ----- streaming ------------------------------------------------------------------------
    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return _SegmentEncoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return _SegmentDecoder(self, skeleton, fps)


def _decoded(
    skeleton: Skeleton,
    codes: np.ndarray,
    offsets: np.ndarray,
    const: np.ndarray,
    knots: np.ndarray,
    coeffs: np.ndarray,
    lay: trendwave.Layout,
    forms: np.ndarray,
    constants: _Constants,
    means: np.ndarray,
    isolated: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """Channels ``(C, T)`` from the integers, in one reconstruction of all channels; the
    joints coded in another form (``forms``, one per three-angle joint, :mod:`rotvec`; ``means``
    a row of integers per such joint, or none; a WORLD form's turn from the decoded constants
    above it, :func:`_parent_turns`) back to the file's Euler angles; translations coded on the
    world's axes back on their parent's (:func:`_world_translations`); ``isolated`` frames and
    their patches (:func:`_patch`)."""
    steps = _channel_steps(skeleton, codes)
    out = _reconstruct(knots, coeffs, const == 1, steps, lay, _factors(offsets, lay), constants)
    _patch(out, steps, *isolated)
    moved = _world_translations(skeleton, const == 1)
    world = bool(len(forms)) and bool((forms >= rotvec.WORLD).any())
    parents = (
        _parent_orientations(skeleton, out[:, 0]) if moved or world else np.zeros((0, 4))
    )  # (the caller has frames)
    for j, pos in moved:
        out[pos] = _on_axes(out[pos], parents[j], inverse=True)
    groups = _three_angle_groups(skeleton)
    coded = np.flatnonzero(forms) if len(forms) else np.zeros(0, dtype=np.int64)
    if coded.size:
        rows = np.concatenate([groups[k][0] for k in coded])
        turns = rotvec.mean_quats(means[coded] if len(means) else np.zeros((coded.size, 3)), MEAN_QUANTUM)
        pre = _parent_turns(skeleton, parents)[coded] if world else None
        out[rows] = rotvec.from_forms(out[rows], tuple(groups[k][1] for k in coded), forms[coded], turns, pre)
    return out


def _patch(out: np.ndarray, steps: np.ndarray, frames: np.ndarray, patches: np.ndarray) -> None:
    """Isolated frames coded apart: the decoded rows ``out (k, T)`` at ``frames`` move by their
    ``patches (k, n)`` in quanta of KEYFRAME_QUANTUM steps (the same arithmetic on both ends)."""
    if len(frames):
        out[:, frames] += patches * (steps * trendwave.KEYFRAME_QUANTUM)


def _isolated_frames(positions_cm: np.ndarray, skip: int) -> np.ndarray:
    """Frames (after the first ``skip``) that jump far from both neighbours while the
    neighbours are close to each other: a glitch, coded apart so it does not cost the wavelet
    (one 25-degree spike made a CMU walk 60-68% larger)."""
    frames = len(positions_cm)
    if frames < 8:
        return np.zeros(0, dtype=np.int64)
    moves = _frame_moves(positions_cm)
    usual = np.percentile(moves, 90)
    across = np.linalg.norm(positions_cm[2:] - positions_cm[:-2], axis=2).max(axis=1)
    far = 4.0 * usual + 1.0
    t = np.arange(1, frames - 1)
    found = t[(moves[:-1] > far) & (moves[1:] > far) & (across <= 2.0 * usual + 1.0) & (t >= max(skip, 1))]
    keep: list[int] = []
    for f in found:  # neither neighbour of an isolated frame is one
        if not keep or f > keep[-1] + 1:
            keep.append(int(f))
    return np.array(keep[:MAX_ISOLATED], dtype=np.int64)


def _bone_skeleton(skeleton: Skeleton, values: np.ndarray, const: np.ndarray) -> Skeleton:
    """The skeleton with each non-root joint's constant translation channels (``values (C, T)``)
    added to its offset: the bones the motion really has, whose lengths are the allocation's
    levers (a MotionBuilder export keeps every bone in position channels)."""
    plan = channel_plan(skeleton)
    joints = list(skeleton.joints)
    for j in range(1, len(joints)):
        held = [(k, c) for k, c in enumerate(plan.pos_index[j]) if c >= 0 and const[c]]
        if held and values.shape[1]:
            offset = list(joints[j].offset)
            for k, c in held:
                offset[k] += float(values[c, 0])
            joints[j] = replace(joints[j], offset=tuple(offset))
    if joints == list(skeleton.joints):
        return skeleton
    return Skeleton(tuple(joints), skeleton.units_per_metre, skeleton.name)


def _channel_steps(skeleton: Skeleton, codes: np.ndarray) -> np.ndarray:
    """``(C, 1)``: every channel's quantiser step from the payload's step codes."""
    steps = np.empty((skeleton.num_channels, 1))
    for g in _groups(skeleton):
        steps[g.channels] = _group_step(g, codes, skeleton)
    return steps


class _Encoder:
    """One payload: the passes of the scale search and the final bytes."""

    def __init__(self, codec: KinwaveCodec, motion: Motion, output_skeleton: Skeleton | None = None):
        self.cfg = codec.config
        self.skeleton = sk = motion.skeleton
        self.output_skeleton = output_skeleton or sk  # the decoder's: errors are measured on its joints
        self.constants = _constants(self.output_skeleton)
        self.motion = motion.continuous() if motion.num_frames else motion
        self.values = self.motion.channels.T.copy()  # (C, T)
        self.frames = motion.num_frames
        pos, quat = forward_kinematics(sk, self.motion.channels)
        self.cm = 100.0 / sk.units_per_metre
        self.positions = pos * self.cm
        self.quats = quat
        self.const = (np.ptp(self.values, axis=1) <= CONSTANT) if self.frames else np.ones(sk.num_channels, bool)
        self._set_layout(0)
        self.first_pass: _Pass | None = None
        self.isolated = _isolated_frames(self.positions, 2) if self.cfg["keyframes"] else np.zeros(0, np.int64)
        self.rot_joints = _rotation_joints(sk)
        self.trans = _has_translation(sk)
        self.shape_rot, self.shape_trans = self._shape()
        self.joint_offsets = np.zeros(len(self.rot_joints) + self.trans, dtype=np.int64)
        self.means = np.zeros((len(_three_angle_groups(sk)), 3), dtype=np.int64)
        self.turns, self.turned = self._turns()
        self.forms = self._choose_forms() if self.cfg["rotation_vectors"] else np.zeros(0, dtype=np.int64)
        self._constant_in_forms()
        self.world_translations = _world_translations(sk, self.const)
        if self.cfg["keyframes"] and _jumps_at_start(self.positions):
            self._choose_keyframes()

    def _turns(self) -> tuple[np.ndarray, np.ndarray]:
        """Per three-angle joint, the turn a WORLD form would take off (:func:`_parent_turns`,
        exact) and whether it may: every joint above it holds a constant rotation, and together
        they turn it (a dummy root's constant rotation)."""
        groups = _three_angle_groups(self.skeleton)
        if not self.frames or not groups:
            return np.tile([1.0, 0.0, 0.0, 0.0], (len(groups), 1)), np.zeros(len(groups), dtype=bool)
        sk = self.skeleton
        still = _still_rotations(sk, self.const)
        parents = sk.parents[[sk.channel_joints[g[0]] for g, _ in groups]]
        above = np.where(parents >= 0, still[np.maximum(parents, 0)], False)
        turns = _parent_turns(sk, _parent_orientations(sk, self.values[:, 0]))
        return turns, above & (np.abs(turns[:, 0]) < 1.0 - 1e-12)

    def _set_layout(self, keyframes: int) -> None:
        """Segments and knots with ``keyframes`` leading one-frame segments, and the header."""
        self.keyframes = keyframes
        levels = self.cfg["levels"] or _levels_for(self.motion.fps)
        self.lay = trendwave.layout(self.frames, self.cfg["window"], levels, keyframes, self.cfg["wavelet"])
        flags = (FLAG_KEYFRAME if keyframes else 0) | (FLAG_SECOND_KEYFRAME if keyframes == 2 else 0)
        self.header = _HEAD.pack(
            FORMAT,
            flags | WAVELET_IDS.index(self.cfg["wavelet"]) << 1,
            int(math.log2(self.cfg["window"])),
            levels,
            self.skeleton.num_channels,
        )

    def _choose_keyframes(self) -> None:
        """Leading frames that jump away (a bind pose, a T-pose) cost the wavelet a jump, but
        as keyframes a finely quantised pose each; which is cheaper depends on the pose and the
        bound (a CMU T-pose at max shell 0.1 cm cost 16% more as a keyframe, a bind pose before
        it 13% less). One pass at the starting scale with 0, 1 and 2 keyframes decides: at the
        same steps the errors are about the same."""
        passes = []
        for count in range(3):
            self._set_layout(count)
            passes.append(self.run_pass(self.codes(self._first_scale())))
        best = int(np.argmin([len(self.body(ps)) for ps in passes]))
        self._set_layout(best)
        self.first_pass = passes[best]  # the search starts from it

    def _starting_pass(self) -> _Pass:
        """The pass at the starting scale (the keyframes' trial may have run it already)."""
        return self.first_pass or self.run_pass(self.codes(self._first_scale()))

    def _shape(self) -> tuple[np.ndarray, float]:
        """Steps (degrees per rotation joint, cm for translations) whose modelled bound is 1 cm.
        The levers are those of the motion's own bones (:func:`_bone_skeleton`), and a joint
        whose angles are all constant takes the step the model would give it if they moved:
        its constants turn everything below it (a dummy root: the whole body)."""
        sk = _bone_skeleton(self.skeleton, self.values, self.const)
        coded, rotating = [0] * len(sk), [0] * len(sk)
        translations = 0
        for g in _groups(self.skeleton):
            n = int((~self.const[g.channels]).sum())
            if g.rotation:
                coded[g.joint], rotating[g.joint] = n, g.channels.size
            else:
                translations += n
        measure, closed = self.cfg["error_measure"], self.cfg["closed_loop"]
        if self.cfg["allocation"] == "uniform":
            rot, trans = kinalloc.steps(sk, tuple(int(c > 0) for c in coded), int(translations > 0), measure, closed)
            finite = rot[np.isfinite(rot)]
            rot = np.full(len(sk), finite.min() if finite.size else 1.0)
        else:
            rot, trans = kinalloc.steps(sk, tuple(coded), translations, measure, closed)
        if not np.isfinite(rot).all() and any(rotating):
            still, _ = kinalloc.steps(sk, tuple(rotating), max(translations, 1), measure, closed)
            rot = np.where(np.isfinite(rot), rot, still)
        rot = np.where(np.isfinite(rot), rot, np.nanmin(rot) if np.isfinite(rot).any() else 1.0)
        return rot[self.rot_joints], trans

    def _choose_forms(self) -> np.ndarray:
        """Per 3-angle joint (:func:`_three_angle_groups`), the form its rotation is coded in
        (:mod:`mocodec.codecs.shared.rotvec`: the file's Euler angles, a rotation vector about the
        joint's mean rotation, or Euler angles in one of the six Tait-Bryan orders): each form
        of every joint is coded once on its own (open loop, the first TRIAL_FRAMES frames) at the
        step the search starts from,
        and the fewest bytes win, moved to the file angles' rotation error along the high-rate
        slope (a nonzero coefficient takes a bit more per halving of the error). A form whose
        middle angle comes within GIMBAL_MARGIN of its lock is out. The trial weighs the mean
        rotation error, which is what decides a mean bound; under a max bound it misjudged ASF
        joints (angles about axes chosen for each bone, small and decoupled), whose files came
        out 1-14% larger with vectors (and every axis-free bone taking forms was within 1.3%
        either way, a third slower), so there only the body's root (the first joint that turns,
        below any dummy root) and joints near their gimbal lock may change form; a joint whose
        angles are all constant keeps them always. All joints go through each transform
        together; only the byte counts are per joint."""
        groups = _three_angle_groups(self.skeleton)
        choice = np.zeros(len(groups), dtype=np.int64)
        moving = [k for k, (channels, _) in enumerate(groups) if not self.const[channels].all()]
        if self.cfg["error_measure"] == "mean" or not any(j.has_axis for j in self.skeleton.joints):
            live = moving
        else:  # ASF: the body's root (under a dummy root too) and joints near their gimbal lock
            locked = (
                rotvec.near_lock(
                    self.values[np.concatenate([groups[k][0] for k in moving])],
                    tuple(groups[k][1] for k in moving),
                    GIMBAL_MARGIN,
                )
                if moving
                else np.zeros(0, bool)
            )
            live = [k for i, k in enumerate(moving) if i == 0 or locked[i]]
        if not live or not self.frames:
            return choice
        channels = np.concatenate([groups[k][0] for k in live])
        orders = tuple(groups[k][1] for k in live)
        euler = self.values[channels, :TRIAL_FRAMES]
        lay = trendwave.layout(
            euler.shape[1], self.cfg["window"], int(self.lay.levels.max(initial=1)), 0, self.cfg["wavelet"]
        )
        step = _channel_steps(self.skeleton, self.codes(self._first_scale()))[channels]
        factors = _factors(np.zeros(lay.starts.size), lay)
        original = rotvec.euler_quats(euler, orders)
        pre = self.turns[live]
        whole = rotvec.euler_quats(self.values[channels], orders)
        turned = np.flatnonzero(self.turned[live])
        whole[:, turned] = rotations.quat_multiply(pre[turned][None], whole[:, turned])
        means = rotvec.mean_codes(whole, MEAN_QUANTUM, MEAN_LEAST)  # of pre q for the joints that may turn
        self.means[live] = means
        turns = rotvec.mean_quats(means, MEAN_QUANTUM)

        def trial(form: int, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            """The joints ``idx`` (of ``live``) coded in ``form``: (bytes, nonzero coefficients,
            mean rotation error), infinite bytes within GIMBAL_MARGIN of the form's lock."""
            rows = (3 * idx[:, None] + np.arange(3)).ravel()
            sub, kept = euler[rows], tuple(orders[i] for i in idx)
            forms = np.full(idx.size, form)
            values = sub if form == 0 else rotvec.to_forms(sub, kept, forms, turns[idx], pre=pre[idx])
            base = form % rotvec.WORLD
            locked = (
                rotvec.near_lock(
                    values, kept if base == 0 else (rotvec.CODING_ORDERS[base - 2],) * idx.size, GIMBAL_MARGIN
                )
                if base != rotvec.VECTOR
                else np.zeros(idx.size, bool)
            )
            flat, none = np.zeros(rows.size, dtype=bool), _Constants(1.0, np.zeros(rows.size))
            k_int, c_int = self._quantise(values, flat, step[rows], factors, none, lay)
            sizes = np.array(
                [
                    len(
                        coefcoder.encode(
                            np.zeros(3, np.int64),
                            k_int[3 * i : 3 * i + 3],
                            c_int[3 * i : 3 * i + 3],
                            lay.padded,
                            lay.levels,
                            revision=CODER_REVISION,
                        )
                    )
                    for i in range(idx.size)
                ]
            )
            rec = _reconstruct(k_int, c_int, flat, step[rows], lay, factors, none)
            back = rotvec.from_forms(rec, kept, forms, turns[idx], pre[idx]) if form else rec
            err = np.maximum(
                rotations.quat_distance(original[:, idx], rotvec.euler_quats(back, kept)).mean(axis=0), 1e-12
            )
            nonzero = (c_int != 0).reshape(idx.size, -1).sum(axis=1)
            return np.where(locked, np.inf, sizes), nonzero, err

        local = np.flatnonzero(~self.turned[live])
        candidates = [(form, local) for form in range(rotvec.FORMS)]
        candidates += [(rotvec.WORLD + form, turned) for form in range(rotvec.FORMS)]
        costs = np.full((len(candidates), len(live)), np.inf)
        reference = np.ones(len(live))  # the error of the file's own angles (forms 0 and WORLD)
        results: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []
        for form, idx in candidates:
            result = trial(form, idx) if idx.size else None
            results.append(result)
            if form % rotvec.WORLD == 0 and result is not None:
                reference[idx] = result[2]
        for row, ((_, idx), result) in enumerate(zip(candidates, results)):
            if result is not None:
                sizes, nonzero, err = result
                costs[row, idx] = sizes + nonzero / 8.0 * np.log2(err / reference[idx])
        choice[live] = np.array([form for form, _ in candidates])[np.argmin(costs, axis=0)]
        self.means[choice % rotvec.WORLD != rotvec.VECTOR] = 0
        return choice

    def _constant_in_forms(self) -> None:
        """Which channels of the joints coded in another form are constant in that form (a
        hinge written in a proper order is one moving angle again); the steps follow."""
        coded = np.flatnonzero(self.forms)
        if not coded.size:
            return
        groups = _three_angle_groups(self.skeleton)
        rows = np.concatenate([groups[k][0] for k in coded])
        values = rotvec.to_forms(
            self.values[rows],
            tuple(groups[k][1] for k in coded),
            self.forms[coded],
            rotvec.mean_quats(self.means[coded], MEAN_QUANTUM),
            pre=self.turns[coded],
        )
        const = np.ptp(values, axis=1) <= CONSTANT
        if (const != self.const[rows]).any():
            self.const[rows] = const
            self.shape_rot, self.shape_trans = self._shape()

    def _first_scale(self) -> float:
        """The scale the bound's search starts from (the model's, before any pass)."""
        return self.cfg["max_error_cm"] / (0.3 if self.cfg["error_measure"] == "mean" else 0.8)

    # ----- one pass -------------------------------------------------------------------------
    def codes(self, scale: float) -> np.ndarray:
        steps = np.append(self.shape_rot * scale, self.shape_trans * scale if self.trans else [])
        return np.clip(np.array([_code(s) for s in steps]) + self.joint_offsets, 0, 255).astype(np.uint8)

    def _adapt_joints(self, errors: np.ndarray, bound: float) -> float:
        """Correct the model's step shape by what a pass measured (max bounds): a joint whose
        points all stayed well below the worst one is coded finer than it needs (the model's
        uniform-noise error overstates quiet joints, whose coefficients mostly fall in the dead
        zone), so its steps grow by that slack (the clip's worst error over the worst among the
        points it moves), from the pass's ``errors (frames, points)``. Returns the scale factor
        that brings the pass's worst error to the middle of the accepted range."""
        err = errors.max(axis=0)
        worst = err.max()
        if worst <= 0:
            return 1.0
        self.joint_offsets = self._slack_codes(err, worst, JOINT_FEEDBACK)
        return float(np.clip(bound * (1.0 + ACCEPT) / 2.0 / worst, 0.25, 4.0))

    def _slack_codes(self, errors: np.ndarray, reference: float, share: float = 1.0) -> np.ndarray:
        """Per step code, the 1/8 octaves (times ``share``, floored) between ``reference`` and
        the worst of ``errors (points,)`` among the points the code moves (the joints below it,
        and with ``shell`` its own bone's shell; the translations: all)."""
        moved = _influence(self.skeleton, self.cfg["error_measure"])
        own = np.array([errors[row].max() if row.any() else errors.max() for row in moved])
        return np.floor(8.0 * share * np.log2(reference / np.maximum(own, reference * 2.0**-8)))

    def run_pass(self, codes: np.ndarray, offsets: np.ndarray | None = None) -> _Pass:
        """Quantise and reconstruct every channel down the tree (:func:`closedloop.code_down_tree`):
        a joint's closed-loop target needs its parent's decoded orientation, and the joints of
        one depth go through the transforms together (rows are independent, so each row's floats
        are those of coding it alone)."""
        sk, lay = self.skeleton, self.lay
        offsets = np.zeros(lay.starts.size, dtype=np.int8) if offsets is None else offsets.astype(np.int8)
        C = sk.num_channels
        knots = np.zeros((C, lay.num_knots), dtype=np.int64)
        coeffs = np.zeros((C, lay.num_coeffs), dtype=np.int64)
        decoded = np.zeros((C, self.frames))  # zeros: a WORLD form's turn reads the rows above it
        patches = np.zeros((C, self.isolated.size), dtype=np.int64)
        steps = _channel_steps(sk, codes)
        factors = _factors(offsets, lay)
        rotvec_groups = _three_angle_groups(sk)

        def code(channels: np.ndarray, targets: np.ndarray, exact: dict) -> np.ndarray:
            step, const = steps[channels], self.const[channels]
            column = {c: i for i, c in enumerate(channels)}
            vectors = (
                [k for k, (g, _) in enumerate(rotvec_groups) if self.forms[k] and g[0] in column]
                if len(self.forms)
                else []
            )
            moved = [(j, [column[c] for c in pos]) for j, pos in self.world_translations if pos[0] in column]
            turned = moved or any(self.forms[k] >= rotvec.WORLD for k in vectors)
            parents = (
                _parent_orientations(sk, decoded[:, 0]) if turned else np.zeros((0, 4))
            )  # of the decoded rows above
            values = targets.T.copy()
            if vectors:
                cols = [column[c] for k in vectors for c in rotvec_groups[k][0]]
                orders = tuple(rotvec_groups[k][1] for k in vectors)
                forms = self.forms[vectors]
                turns = rotvec.mean_quats(self.means[vectors], MEAN_QUANTUM)
                pre = _parent_turns(sk, parents)[vectors] if (forms >= rotvec.WORLD).any() else None
                quats = np.stack(
                    [
                        exact[j] if j in exact else rotvec.euler_quats(values[[column[c] for c in g]], (o,))[:, 0]
                        for j, (g, o) in (
                            (sk.channel_joints[rotvec_groups[k][0][0]], rotvec_groups[k]) for k in vectors
                        )
                    ],
                    axis=1,
                )
                values[cols] = rotvec.to_forms(values[cols], orders, forms, turns, quats, pre)
            for j, rows in moved:
                values[rows] = _on_axes(values[rows], parents[j])
            constants = _Constants(self.constants.fraction, self.constants.base[channels])
            iso = self.isolated
            wanted = values[:, iso]
            if iso.size:  # the wavelet sees the neighbours' mean there
                values[:, iso] = (values[:, iso - 1] + values[:, iso + 1]) / 2.0
            k_int, c_int = self._quantise(values, const, step, factors, constants)
            knots[channels], coeffs[channels] = k_int, c_int
            out = _reconstruct(k_int, c_int, const, step, lay, factors, constants)
            if iso.size:
                patch = np.round((wanted - out[:, iso]) / (step * trendwave.KEYFRAME_QUANTUM)).astype(np.int64)
                patch[const] = 0
                _patch(out, step, iso, patch)
                patches[channels] = patch
            for j, rows in moved:
                out[rows] = _on_axes(out[rows], parents[j], inverse=True)
            if vectors:
                out[cols] = rotvec.from_forms(out[cols], orders, forms, turns, pre)
            decoded[channels] = out
            return out.T

        exact = np.zeros(len(sk), dtype=bool)
        exact[sk.channel_joints[[g[0] for form, (g, _) in zip(self.forms, rotvec_groups) if form]]] = True
        closedloop.code_down_tree(
            sk, self.values.T, ~self.const, self.quats, code, self.cfg["closed_loop"], self.positions / self.cm, exact
        )
        return _Pass(codes, self.const.astype(np.int64), knots, coeffs, decoded, offsets, patches)

    def _quantise(
        self,
        target: np.ndarray,
        const: np.ndarray,
        step: np.ndarray,
        factors: tuple[np.ndarray, np.ndarray, np.ndarray],
        constants: _Constants,
        lay: trendwave.Layout | None = None,
    ):
        """Knots and dead-zone quantised coefficients of ``target (k, T)`` with steps ``(k, 1)``,
        the segments' step :func:`_factors` and the rows' :class:`_Constants`, laid out as
        ``lay`` (default: the payload's)."""
        lay = lay or self.lay
        knot_f, coeff_f, _ = factors
        quantum = step * lay.knot_quantum * knot_f
        k_int = np.round(target[:, lay.knot_frames] / quantum).astype(np.int64)
        k_int[const] = np.round(
            (target[const, :1] - constants.base[const, None]) / (step[const] * constants.fraction)
        ).astype(np.int64)
        residual = target - trendwave.trend(k_int * quantum, lay)
        residual[const] = 0.0
        c = trendwave.analyse(residual, lay) / (step * coeff_f)
        c_int = (np.sign(c) * np.floor(np.abs(c) + self.cfg["deadzone"])).astype(np.int64)
        c_int[const] = 0
        return k_int, c_int

    # ----- measures and bytes ---------------------------------------------------------------
    def _joint_errors(self, decoded: np.ndarray) -> np.ndarray:
        """``(frames, points)`` cm: the decoded output's error at every joint, or at the worst
        shell point of every bone."""
        pos, quat = forward_kinematics(self.output_skeleton, decoded.T)
        pos = pos * self.cm
        if self.cfg["error_measure"] == "shell":
            return shell_errors(self.skeleton, self.positions, self.quats, pos, quat).per_frame
        return np.linalg.norm(pos - self.positions, axis=2)

    def error(self, decoded: np.ndarray) -> float:
        err = self._joint_errors(decoded)
        return float(err.mean() if self.cfg["error_measure"] == "mean" else err.max())

    def body(self, ps: _Pass) -> bytes:
        flags = self.header[1]
        side: tuple[np.ndarray, ...] = (ps.steps,)
        if ps.offsets.any():
            flags, side = flags | FLAG_OFFSETS, side + (ps.offsets,)
        if self.forms.any():
            flags, side = flags | FLAG_FORMS, side + (self.forms,)
        if self.means.any():  # side sequences go as differences: a running sum sends the values
            flags, side = flags | FLAG_MEANS, side + (np.cumsum(self.means.ravel()),)
        count = b""
        if self.isolated.size:
            flags, count = flags | FLAG_ISOLATED, bytes([self.isolated.size])
            side = side + (self.isolated, np.cumsum(ps.patches.ravel()))
        head = self.header[:1] + bytes([flags]) + self.header[2:] + count
        return head + coefcoder.encode(
            ps.const, ps.knots, ps.coeffs, self.lay.padded, self.lay.levels, revision=CODER_REVISION, side=side
        )

    def run(self) -> bytes:
        if self.frames == 0:
            return self.body(self.run_pass(self.codes(1.0)))
        if self.cfg["bits_per_second"] > 0:
            return self._to_rate(self.cfg["bits_per_second"] * self.frames / self.motion.fps / 8.0)
        if (
            self.cfg["segment_steps"]
            and self.cfg["error_measure"] != "mean"
            and np.count_nonzero(self.lay.padded) >= ADAPTIVE_SEGMENTS
        ):
            return self._to_bound_by_segment(self.cfg["max_error_cm"])
        return self._to_bound(self.cfg["max_error_cm"])

    def _search(self, measure, goal: float, accept: float, scale: float, exponent: float, sign: float = 1.0):
        """Find x = log(scale) / sign with ``measure`` (rising with x) in [accept * goal, goal]:
        extrapolate until the target is bracketed (first with ``exponent``, the model's
        d log measure / dx, then with the slope the last two passes measured), then secant steps
        inside the bracket. Returns (best pass meeting the goal or None, last x)."""
        lo = hi = None  # (x, log value, pass)
        previous = None  # the last (x, log value) before bracketing
        seen: dict[bytes, tuple[float, _Pass]] = {}
        x = math.log(scale) / sign
        aim = math.log(goal * (1.0 + accept) / 2.0)
        for _ in range(MAX_PASSES):
            codes = self.codes(math.exp(sign * x))
            if codes.tobytes() not in seen:
                ps = self.run_pass(codes)
                seen[codes.tobytes()] = (measure(ps), ps)
            value, ps = seen[codes.tobytes()]
            y = math.log(max(value, 1e-300))
            if value <= goal:
                if lo is None or x > lo[0]:
                    lo = (x, y, ps)
                if value >= accept * goal:
                    break
            elif hi is None or x < hi[0]:
                hi = (x, y, ps)
            if lo is not None and hi is not None:
                if hi[0] - lo[0] < 1e-3:
                    break
                slope = (hi[1] - lo[1]) / (hi[0] - lo[0])
                x = lo[0] + (aim - lo[1]) / slope if slope > 0 else (lo[0] + hi[0]) / 2
                if not lo[0] < x < hi[0]:
                    x = (lo[0] + hi[0]) / 2
            else:
                slope = exponent
                if previous is not None and abs(x - previous[0]) > 1e-9:
                    measured = (y - previous[1]) / (x - previous[0])
                    slope = measured if measured > 0.1 * exponent else exponent
                previous = (x, y)
                x = x + float(np.clip((aim - y) / slope, -3.0, 3.0))
        return (lo[2] if lo else None), x

    def _use_slack(self, best: _Pass, bound: float, below: float = math.inf) -> _Pass:
        """Under a max bound, the final pass gives the slack to the codes whose points have it:
        each code coarser by the 1/8 octaves between the bound and the worst error among the
        points it moves, halved if the pass then breaks the bound (SLACK_PASSES rounds at most;
        segment offsets kept). The joint feedback set the codes' shape at the starting scale;
        at the final one, and near the bound, where the worst error jumps with single step
        codes (on short clips one code more took it from 77% to 110% of the bound), the points'
        errors differ again: 1-3% smaller files on both sources, and fewer clips far below their
        bound. A pass whose worst error is already ``below`` x bound or more is kept (the
        time-adaptive steps' segments take most of the slack; there the rounds cost a third of
        the encoding speed for 0.2% of the bytes)."""
        if self.cfg["error_measure"] == "mean":
            return best
        errors = self._joint_errors(best.decoded).max(axis=0)  # per point, over the frames
        for _ in range(SLACK_PASSES):
            if errors.max() >= below * bound:
                return best
            coarser = self._slack_codes(errors, bound)
            for _ in range(2):
                if not coarser.any():
                    break
                ps = self.run_pass(np.clip(best.steps + coarser, 0, 255).astype(np.uint8), best.offsets)
                trial = self._joint_errors(ps.decoded).max(axis=0)
                if trial.max() <= bound:
                    best, errors = ps, trial
                    break
                coarser = np.floor(coarser / 2.0)
            else:
                break
        return self._scale_up(best, errors.max(), bound)

    def _scale_up(self, best: _Pass, worst: float, bound: float) -> _Pass:
        """A final pass still under ACCEPT x bound (the time-adaptive search once stopped at 81%
        of it, after a seam made one segment's error jump and the segment went eight codes finer)
        takes every code coarser together by the 1/8 octaves between its worst error and the
        bound, halved while that breaks the bound."""
        while worst < ACCEPT * bound:
            shift = int(np.floor(8.0 * math.log2(bound / max(worst, bound * 2.0**-8))))
            while shift > 0:
                ps = self.run_pass(np.clip(best.steps.astype(np.int64) + shift, 0, 255).astype(np.uint8), best.offsets)
                trial = self._joint_errors(ps.decoded).max()
                if trial <= bound:
                    best, worst = ps, trial
                    break
                shift //= 2
            else:
                return best
        return best

    def _to_bound(self, bound: float) -> bytes:
        guess = self._first_scale()
        if self.cfg["error_measure"] != "mean" and self.cfg["joint_feedback"] and not self.joint_offsets.any():
            guess *= self._adapt_joints(self._joint_errors(self._starting_pass().decoded), bound)
        accept = MEAN_ACCEPT if self.cfg["error_measure"] == "mean" else ACCEPT
        best, x = self._search(lambda ps: self.error(ps.decoded), bound, accept, guess, 1.0)
        for _ in range(60):
            if best is not None:
                body = self.body(self._use_slack(best, bound))
                if self.error(self._decode_body(body)) <= bound:  # the guarantee, on the real decoder
                    return body
            x -= math.log(2.0)
            ps = self.run_pass(self.codes(math.exp(x)))
            best = ps if self.error(ps.decoded) <= bound else None
        raise CodecError(f"kinwave cannot reach {self.cfg['error_measure']} error {bound:g} cm")

    def _to_bound_by_segment(self, bound: float) -> bytes:
        """A max-error bound with time-adaptive steps: the joints' steps from the model's
        scale, then every segment's own offset (1/8 octave) searched so that its worst error
        lies in [SEGMENT_ACCEPT, 1] x bound, so quiet stretches no longer take the steps the busiest
        one needs. Segments meet at knots and seams, so the combination is checked as a whole
        and segments over the bound move finer until none is (else the single-scale search of
        :meth:`_to_bound` takes over); the final bytes are measured on the real decoder."""
        starts = self.lay.starts
        aim = bound * (1.0 + SEGMENT_ACCEPT) / 2.0

        def segment_errors(errors):
            return np.maximum.reduceat(errors.max(axis=1), starts)

        guess = self._first_scale()
        first = None
        if self.cfg["joint_feedback"]:
            errors = self._joint_errors(self._starting_pass().decoded)
            first = segment_errors(errors)
            guess *= self._adapt_joints(errors, bound)
        base = self.codes(guess)
        lowest, highest = max(-int(base.min()), -128), min(255 - int(base.max()), 127)
        passes: dict[bytes, tuple[_Pass, np.ndarray]] = {}

        def run(offsets):
            key = offsets.astype(np.int8).tobytes()
            if key not in passes:
                ps = self.run_pass(base, offsets)
                passes[key] = ps, segment_errors(self._joint_errors(ps.decoded))
            return passes[key]

        offsets = np.zeros(starts.size, dtype=np.int64)
        if first is not None:  # segments quieter in the first pass start coarser (half their slack)
            offsets = np.clip(np.round(4.0 * np.log2(first.max() / np.maximum(first, 1e-12))), 0, highest).astype(
                np.int64
            )
        feasible = np.full(starts.size, lowest - 1)  # the largest offset seen within the bound
        closest = np.zeros(starts.size)  # the error seen there
        failed = np.full(starts.size, highest + 1)  # the smallest offset seen over it
        for _ in range(SEGMENT_PASSES):
            _, seg = run(offsets)
            ok = seg <= bound
            closest = np.where(ok & (offsets >= feasible), seg, closest)
            feasible = np.where(ok, np.maximum(feasible, offsets), feasible)
            failed = np.where(ok, failed, np.minimum(failed, offsets))
            settled = (ok & (seg >= SEGMENT_ACCEPT * bound)) | (failed - feasible <= 1)
            if settled.all():
                break
            move = np.round(8.0 * np.log2(aim / np.maximum(seg, 1e-12)))
            target = np.clip(offsets + np.where(ok, np.maximum(move, 1), np.minimum(move, -1)), lowest, highest)
            target = np.where((target <= feasible) | (target >= failed), (feasible + failed) // 2, target)
            offsets = np.where(settled, offsets, target).astype(np.int64)
        offsets = np.where(feasible >= lowest, feasible, np.minimum(offsets, failed - 1))
        offsets = np.maximum(offsets - (closest > MARGIN * bound), lowest)  # neighbours move the errors too
        for _ in range(SEGMENT_PASSES + 3):
            ps, seg = run(offsets)
            over = seg > bound
            if not over.any():
                body = self.body(self._use_slack(ps, bound, SEGMENT_SLACK_BELOW))
                if self.error(self._decode_body(body)) <= bound:  # the guarantee, on the real decoder
                    return body
                over[:] = True
            if (offsets[over] == lowest).all():
                break
            finer = np.maximum(np.ceil(8.0 * np.log2(np.maximum(seg, bound) / bound)), 1)
            offsets = np.where(over, np.maximum(offsets - finer, lowest), offsets).astype(np.int64)
        return self._to_bound(bound)  # what the segments cannot fix (constant channels): one scale

    def _decode_body(self, body: bytes) -> np.ndarray:
        """What the decoder makes of ``body`` on the skeleton it will be given (a constant
        translation is coded about that skeleton's offsets)."""
        return KinwaveCodec()._decode(body, self.output_skeleton, self.frames, self.motion.fps).T

    def _to_rate(self, budget_bytes: float) -> bytes:
        # size / budget falls as the scale rises: search on x = -log(scale)
        best, _ = self._search(
            lambda ps: len(self.body(ps)) / budget_bytes, 1.0, 1 - RATE_TOLERANCE, 1.0, 0.8, sign=-1.0
        )
        return self.body(best if best is not None else self.run_pass(self.codes(2.0**40)))


class _SegmentEncoder(StreamEncoder):
    """One packet per ``window`` frames, each decoding on its own: a varint frame count, then
    the body."""

    def __init__(self, codec: KinwaveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.pending = np.zeros((0, skeleton.num_channels))

    def _packet(self, frames: np.ndarray) -> bytes:
        return varint.pack(len(frames)) + self.codec.encode(Motion(self.skeleton, self.fps, frames))

    def push(self, frames: np.ndarray) -> list[bytes]:
        self.pending = np.vstack([self.pending, np.atleast_2d(frames)])
        w = self.codec.config["window"]
        out = []
        while len(self.pending) >= w:
            out.append(self._packet(self.pending[:w]))
            self.pending = self.pending[w:]
        return out

    def flush(self) -> list[bytes]:
        if not len(self.pending):
            return []
        out = [self._packet(self.pending)]
        self.pending = self.pending[:0]
        return out


class _SegmentDecoder(StreamDecoder):
    def __init__(self, codec: KinwaveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps

    def push(self, packet: bytes) -> np.ndarray:
        try:
            frames, start = varint.unpack(packet, 0, 4)
        except ValueError as e:
            raise CorruptStreamError(f"kinwave packet: its frame count: {e}") from None
        return self.codec.decode(packet[start:], self.skeleton, frames, self.fps).channels
