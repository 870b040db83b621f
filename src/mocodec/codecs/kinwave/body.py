"""kinwave's body, formats 1 to 3: what encoder and decoder share (the step codes, the
reconstruction of channels from their integers, the coding forms and world-axis translations)
and the decoder of a body.

Body body: u8 format (1), u8 flags (bits 0 and 5: one or two leading keyframes, bits 1-2
wavelet, bit 3 segment offsets, bit 4 coding forms, bit 6 mean rotations, bit 7 isolated
frames), u8 log2 window, u8 levels, u16 channels (a body for another skeleton is refused),
with bit 7 a u8 count of isolated frames (glitches coded apart: their positions and one patch
per channel follow in the stream's side sequences), then the arithmetic-coded
stream (:mod:`mocodec.coding.entropy.coefcoder`, revision 2), which opens with one step code per joint
with rotation channels and one for translations (step = 2^(code/8 - 20) degrees or cm), with
bit 3 one step offset per segment, with bit 4 a coding form per three-angle joint
(:mod:`mocodec.codecs.shared.rotvec`) and with bit 6 three mean-rotation integers per such joint.
Format 2 is format 1 with a byte of more flags after the header: bit 0, frame 0 is the
skeleton's rest pose (every rotation 0, the translations frame 1's), bit 1, the rest pose with
every translation 0 too, both bits, the rest pose with the root's rotations frame 1's as well
as the translations; that frame is not coded, and the rest is a format 1 body of the other
frames (:func:`rest_kind`); bits 2-3, the lead of the layout (:func:`trendwave.layout`); bit 4,
constant translations at a finer quantum, bit 5 constant turns above translations too, bit 6
constant translations about 0 instead of their joints' offsets (:class:`ConstantCoding`).
Format 3 is format 2 with a count byte after the more flags: that many joints' constant
translations are coded against an earlier joint's, some axes negated (the bones of a symmetric
skeleton held in translation channels: :func:`mirrored_constants`).
docs/formats.md gives the layout byte by byte.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mocodec import rotations
from mocodec.codecs.kinwave import channelcode
from mocodec.codecs.shared import rotvec
from mocodec.coding.entropy import coefcoder
from mocodec.coding.transforms import trendwave
from mocodec.errors import CorruptStreamError
from mocodec.kinematics import channel_plan, forward_kinematics, position_offsets, rest_frame
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

FORMAT = 1  # the body format (docs/formats.md), pinned by the golden fixtures
FORMAT_MORE = 2  # format 1 with a byte of more flags after the header
FORMAT_MIRRORED = 3  # format 2 with a byte m after the more flags: m joints' constant
# translations coded against an earlier joint's, axes negated (mirrored_constants)
REST = 1  # more flags bit 0: frame 0 is the rest pose, its translations frame 1's (not coded)
REST_AT_ZERO = 2  # more flags bit 1: frame 0 is the rest pose with every translation 0 (not coded)
REST_TURNED = 3  # more flags bits 0-1 both: the rest pose as REST, the root's turn frame 1's too (not coded)
#: A rest pose's translations are frame 1's within this share of their size: a float32 export
#: writes each frame's with noise in the last places (the bound at frame 0 is checked on the
#: decoder's output).
REST_RTOL = 1e-5
LEAD_SHIFT = 2  # more flags bits 2-3: the layout's lead (trendwave.layout), in frames
FINE_CONSTANTS = 16  # more flags bit 4: constant translations at FINE_CONST_FRACTION of their step
FINE_TURNS = 32  # more flags bit 5: constant rotations of joints above translation channels, the same
ZERO_CONSTANTS = 64  # more flags bit 6: constant translations coded about 0, not about their joints' offsets
MAX_MIRRORED = 255  # joints a body codes against earlier ones at most
MIRROR_ENTRY_BITS = 6.0  # about the bits a mirrored joint's index costs (the step from the previous one)
CODER_REVISION = 2  # the coefficient coder's revision (coefcoder: differences in the approximation band)
HEAD = struct.Struct("<BBBBH")  # format, flags, log2 window, levels, channels
FLAG_OFFSETS = 8  # flags bit 3: a signed step offset per segment follows the step codes
FLAG_FORMS = 16  # flags bit 4: per 3-angle joint its coding form (rotvec: 0 the file's Euler angles,
# 1 a rotation vector, 2-7 Euler angles in a Tait-Bryan order, 8-15 those forms of
# the rotation turned by the constant joints above, rotvec.WORLD; formats 1-2: 0, 1)
FLAG_MEANS = 64  # flags bit 6: three integers per 3-angle joint, a vector joint's mean rotation
MEAN_QUANTUM = 2.0  # degrees: a vector joint's mean rotation, as a rotation vector in these steps
FLAG_ISOLATED = 128  # flags bit 7: a byte n after the header; n isolated frames coded apart (format 3)
MAX_ISOLATED = 32  # isolated frames a body codes apart at most
FLAG_KEYFRAME = 1  # flags bit 0: frame 0 is a keyframe (a one-frame segment)
FLAG_SECOND_KEYFRAME = 32  # flags bit 5 (with bit 0): frame 1 is one too
WAVELET_IDS = ("cdf97", "d4", "haar")
CONST_FRACTION = 1.0 / 8.0  # format 3: a constant channel's quantum, in steps of its joint
FINE_CONST_FRACTION = 1.0 / 64.0  # ... with FINE_CONSTANTS or FINE_TURNS
COARSEST_BAND_S = 0.25  # seconds between the coarsest band's samples (the automatic levels)
SEAM_HALF_WIDTH = 8  # frames each side of a seam over which its step is spread
SEAM_LIMIT = 1.0  # the largest step removed, in quantiser steps of the channel


def step_codes(steps) -> np.ndarray:
    """The step code of each of ``steps`` (int64): 8 codes an octave, :func:`code_step`'s inverse."""
    logs = np.fromiter(map(math.log2, steps), dtype=np.float64, count=len(steps))
    return np.clip(np.round((logs + 20.0) * 8.0), 0, 255).astype(np.int64)


def code_step(code: int) -> float:
    return 2.0 ** (code / 8.0 - 20.0)


#: :func:`code_step` of every step code, for looking up many at once with the same values.
_CODE_STEPS = np.array([code_step(code) for code in range(256)])


@dataclass(frozen=True)
class StepGroup:
    """Channels coded together with one step: a joint's rotation steps, or its translations."""

    joint: int
    rotation: bool
    channels: np.ndarray  # channel indices (rotation: in rotation-order steps)
    axes: np.ndarray  # rotation axes of the steps


@lru_cache(maxsize=64)
def step_groups(skeleton: Skeleton) -> tuple[StepGroup, ...]:
    plan = channel_plan(skeleton)
    out = []
    none = np.zeros(0, dtype=np.int64)
    for j, (pos, rot, axes) in enumerate(zip(plan.pos_index.tolist(), plan.rot_index.tolist(), plan.rot_axis.tolist())):
        pos = [c for c in pos if c >= 0]
        if pos:
            out.append(StepGroup(j, False, np.array(pos, dtype=np.int64), none))
        k = sum(c >= 0 for c in rot)
        if k:
            out.append(StepGroup(j, True, np.array(rot[:k], dtype=np.int64), np.array(axes[:k], dtype=np.int64)))
    return tuple(out)


def group_step(g: StepGroup, codes: np.ndarray, skeleton: Skeleton) -> float:
    """A group's quantiser step from the body's step codes (one per rotation joint, then
    the translation code in cm): degrees, or skeleton units for translations."""
    if g.rotation:
        return code_step(codes[_rotation_joints(skeleton).index(g.joint)])
    return code_step(codes[-1]) * skeleton.units_per_metre / 100.0


def rotation_joints(skeleton: Skeleton) -> list[int]:
    return list(_rotation_joints(skeleton))


@lru_cache(maxsize=64)
def _rotation_joints(skeleton: Skeleton) -> tuple[int, ...]:
    return tuple(g.joint for g in step_groups(skeleton) if g.rotation)


def code_channels(skeleton: Skeleton) -> list[np.ndarray]:
    """Per step code (one per rotation joint, then the translations'), the channels it steps."""
    groups = step_groups(skeleton)
    rows = [g.channels for g in groups if g.rotation]
    translations = [g.channels for g in groups if not g.rotation]
    return rows + [np.concatenate(translations)] if translations else rows


def has_translation(skeleton: Skeleton) -> bool:
    return any(not g.rotation for g in step_groups(skeleton))


@lru_cache(maxsize=64)
def three_angle_groups(skeleton: Skeleton) -> tuple[tuple[np.ndarray, str], ...]:
    """``(channels, order)`` of every joint with three rotation channels (in rotation order):
    the joints that may be coded as rotation vectors."""
    return tuple(
        (g.channels, "".join("XYZ"[a] for a in g.axes.tolist()))
        for g in step_groups(skeleton)
        if g.rotation and g.channels.size == 3
    )


def parent_orientations(skeleton: Skeleton, frame: np.ndarray) -> np.ndarray:
    """``(joints, 4)``: each joint's parent's orientation ``G_p`` in one frame of channels
    ``frame (C,)`` (the identity for the root)."""
    _, quats = forward_kinematics(skeleton, frame[None])
    parents = skeleton.parents
    return np.where((parents >= 0)[:, None], quats[0, np.maximum(parents, 0)], np.array([1.0, 0.0, 0.0, 0.0]))


def parent_turns(skeleton: Skeleton, parents: np.ndarray) -> np.ndarray:
    """``(n, 4)``: per three-angle joint, ``conj(C) G_p C``, its parent's orientation
    (``parents``, :func:`parent_orientations`) seen through the joint's own pre-rotation ``C``:
    the turn a WORLD form (:mod:`mocodec.codecs.shared.rotvec`) puts on the joint's rotation ``M``,
    since ``G = G_p C M C^-1 = C (conj(C) G_p C M) C^-1``. Encoder and decoder compute it from
    the same decoded constants, so it is the same floats on both ends."""
    joints, axis, c = turn_setup(skeleton)
    out = parents[joints]
    if axis.any():
        out[axis] = rotations.quat_multiply(rotations.quat_conjugate(c), rotations.quat_multiply(out[axis], c))
    return out


@lru_cache(maxsize=64)
def turn_setup(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`parent_turns` needs of a skeleton (every pass of an encoder and every decode
    asks): the three-angle joints, which of them have a pre-rotation, and those pre-rotations
    ``C`` as quaternions."""
    joints = np.array([skeleton.channel_joints[g[0]] for g, _ in three_angle_groups(skeleton)], dtype=np.int64)
    axis = np.array([skeleton.joints[j].has_axis for j in joints], dtype=bool)
    c = rotations.matrix_to_quat(skeleton.axis_matrices)[joints[axis]] if axis.any() else np.zeros((0, 4))
    for a in (joints, axis, c):
        a.setflags(write=False)
    return joints, axis, c


def still_rotations(skeleton: Skeleton, const: np.ndarray) -> np.ndarray:
    """``(joints,)``: whether a joint and every joint above it hold constant rotations
    (``const (C,)`` per channel)."""
    return _still_rotations(skeleton, np.asarray(const, dtype=bool).tobytes()).copy()


@lru_cache(maxsize=256)
def _still_rotations(skeleton: Skeleton, const_flags: bytes) -> np.ndarray:
    const = np.frombuffer(const_flags, dtype=bool)
    plan = channel_plan(skeleton)
    rotating = np.zeros(len(skeleton), dtype=bool)  # a joint with a moving rotation channel
    rot = plan.rot_index
    rotating[np.nonzero((rot >= 0) & ~const[np.maximum(rot, 0)])[0]] = True
    still = np.ones(len(skeleton), dtype=bool)
    for j in range(len(skeleton)):  # a parent comes before its children
        p = skeleton.parents[j]
        still[j] = not rotating[j] and (p < 0 or still[p])
    return still


def world_translations(skeleton: Skeleton, const: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """``(joint, its X, Y, Z position channels)`` of every non-root joint whose three
    translations all move and whose ancestors' rotations are all constant (the body's root
    under a dummy root): they are coded on the world's axes, ``G_p t`` with ``G_p`` from the
    decoded constants, so a dummy's turn does not tilt their quantisation grid (under no turn
    ``G_p`` is the identity and nothing changes). Implied by the constant flags: no side data."""
    if not const.size:
        return []
    return [(j, pos.copy()) for j, pos in _world_translations(skeleton, np.asarray(const, dtype=bool).tobytes())]


@lru_cache(maxsize=256)
def _world_translations(skeleton: Skeleton, const_flags: bytes) -> tuple[tuple[int, np.ndarray], ...]:
    const = np.frombuffer(const_flags, dtype=bool)
    plan, still, out = channel_plan(skeleton), _still_rotations(skeleton, const_flags), []
    for j in range(1, len(skeleton)):
        pos = plan.pos_index[j]
        if still[skeleton.parents[j]] and (pos >= 0).all() and not const[pos].any():
            out.append((j, pos))
    return tuple(out)


def on_axes(rows: np.ndarray, turn: np.ndarray, inverse: bool = False) -> np.ndarray:
    """Translation rows ``(3, T)`` turned by the unit quaternion ``turn`` (its inverse)."""
    return rotvec.turn_vectors(np.broadcast_to(turn, (rows.shape[1], 4)), rows.T, back=inverse).T


def segment_factors(offsets: np.ndarray, lay: trendwave.Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step factors of the segments' offsets (1/8 octave each) at every knot (a knot takes its
    segment's; the end knot the last segment's), every coefficient, and every seam (the finer
    of its two sides)."""
    f = 2.0 ** (np.asarray(offsets, dtype=np.float64) / 8.0)
    last = max(lay.starts.size - 1, 0)
    knot = f[np.minimum(np.arange(lay.num_knots), last)] if f.size else np.ones(lay.num_knots)
    return knot, np.repeat(f, lay.padded), np.minimum(f[:-1], f[1:])


@dataclass(frozen=True)
class ConstantCoding:
    """How constant channels are coded: one knot, ``fraction`` of the joint's step, about
    ``base (C,)``. Format 3: a constant's error is the same in every frame and is not noise
    that the closed loop averages out (a dummy root's rotation turns the whole body), so its
    quantum is 8 times finer than the step. A constant translation is coded as its difference
    from the joint's offset on the decoder's skeleton, or with ZERO_CONSTANTS from 0: a file
    whose position channels hold the bones with the offsets 0 (one exporter's layout) keeps
    them near its offsets, one whose channels repeat its offsets (MotionBuilder's: the reader
    takes the offsets off) holds zeros there, and either costs a few bits a channel. With
    FINE_CONSTANTS a constant translation's quantum is 8 times finer again: a skeleton whose
    offsets are 0 and whose bones are constant position channels would otherwise add up a
    quantum's error along every chain, which the steps then pay. With FINE_TURNS so is a
    constant rotation of a joint with a translation channel below it: its quantum's error turns
    that translation, which can be far longer than any bone (a dummy root turned (0, 90, 0)
    above a body walking metres from the origin)."""

    fraction: np.ndarray  # (C,)
    base: np.ndarray  # (C,)
    fine: bool = False  # the more flag FINE_CONSTANTS
    fine_turns: bool = False  # the more flag FINE_TURNS
    about_zero: bool = False  # the more flag ZERO_CONSTANTS


def turns_over_translations(skeleton: Skeleton) -> np.ndarray:
    """``(C,)`` bool: the rotation channels of joints with a translation channel below them
    (FINE_TURNS)."""
    plan = channel_plan(skeleton)
    own = [max(row) >= 0 for row in plan.pos_index.tolist()]
    parents: list[int] = plan.parents.tolist()
    below = [False] * len(skeleton)
    for j in range(len(skeleton) - 1, 0, -1):  # a joint's parent comes before it
        below[parents[j]] = below[parents[j]] or own[j] or below[j]
    out = np.zeros(skeleton.num_channels, dtype=bool)
    rot = plan.rot_index[below]
    out[rot[rot >= 0]] = True
    return out


@lru_cache(maxsize=64)
def constant_coding(
    skeleton: Skeleton, fine: bool = False, fine_turns: bool = False, about_zero: bool = False
) -> ConstantCoding:
    """The coding of ``skeleton``'s constant channels (shared: its arrays are read-only)."""
    base = np.zeros(skeleton.num_channels) if about_zero else position_offsets(skeleton)
    fraction = np.full(skeleton.num_channels, CONST_FRACTION)
    if fine_turns:
        fraction[turns_over_translations(skeleton)] = FINE_CONST_FRACTION
    fraction[~skeleton.rotation_mask] = FINE_CONST_FRACTION if fine else CONST_FRACTION
    fraction.setflags(write=False)
    base.setflags(write=False)
    return ConstantCoding(fraction, base, fine, fine_turns, about_zero)


def reconstruct(
    knots: np.ndarray,
    coeffs: np.ndarray,
    const: np.ndarray,
    step: np.ndarray,
    lay: trendwave.Layout,
    factors: tuple[np.ndarray, np.ndarray, np.ndarray],
    constants: ConstantCoding,
) -> np.ndarray:
    """Decoded channels ``(k, T)`` from their integers, steps ``(k, 1)`` and the segments'
    step :func:`segment_factors`: the same arithmetic on both ends (the encoder calls it a tree depth
    at a time, the decoder for all channels at once; each row's floats are the same either
    way). A constant channel is its first knot as :class:`ConstantCoding` says (``base`` of these
    rows)."""
    return channelcode.reconstruct(
        knots,
        coeffs,
        const,
        step[:, 0],
        constants.fraction,
        constants.base,
        lay,
        factors,
        SEAM_LIMIT,
        SEAM_HALF_WIDTH,
    )


def levels_for(fps: float) -> int:
    """Wavelet levels whose coarsest band samples every ~1/4 s (COARSEST_BAND_S): the depth
    that was best at 120 fps (5) keeps its meaning at other rates (docs/kinwave.md)."""
    return int(np.clip(round(math.log2(max(fps, 1.0) * COARSEST_BAND_S)), 1, 10))


def decode_channels(
    skeleton: Skeleton,
    codes: np.ndarray,
    offsets: np.ndarray,
    const: np.ndarray,
    knots: np.ndarray,
    coeffs: np.ndarray,
    lay: trendwave.Layout,
    forms: np.ndarray,
    constants: ConstantCoding,
    means: np.ndarray,
    isolated: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """Channels ``(C, T)`` from the integers, in one reconstruction of all channels; the
    joints coded in another form (``forms``, one per three-angle joint, :mod:`rotvec`; ``means``
    a row of integers per such joint, or none; a WORLD form's turn from the decoded constants
    above it, :func:`parent_turns`) back to the file's Euler angles; translations coded on the
    world's axes back on their parent's (:func:`world_translations`); ``isolated`` frames and
    their patches (:func:`apply_patches`)."""
    steps = channel_steps(skeleton, codes)
    out = reconstruct(knots, coeffs, const == 1, steps, lay, segment_factors(offsets, lay), constants)
    apply_patches(out, steps, *isolated)
    moved = world_translations(skeleton, const == 1)
    world = bool(len(forms)) and bool((forms >= rotvec.WORLD).any())
    parents = (
        parent_orientations(skeleton, out[:, 0]) if moved or world else np.zeros((0, 4))
    )  # (the caller has frames)
    for j, pos in moved:
        out[pos] = on_axes(out[pos], parents[j], inverse=True)
    groups = three_angle_groups(skeleton)
    coded = np.flatnonzero(forms) if len(forms) else np.zeros(0, dtype=np.int64)
    if coded.size:
        rows = np.concatenate([groups[k][0] for k in coded])
        turns = rotvec.mean_quats(means[coded] if len(means) else np.zeros((coded.size, 3)), MEAN_QUANTUM)
        pre = parent_turns(skeleton, parents)[coded] if world else None
        out[rows] = rotvec.from_forms(out[rows], tuple(groups[k][1] for k in coded), forms[coded], turns, pre)
    return out


def apply_patches(out: np.ndarray, steps: np.ndarray, frames: np.ndarray, patches: np.ndarray) -> None:
    """Isolated frames coded apart: the decoded rows ``out (k, T)`` at ``frames`` move by their
    ``patches (k, n)`` in quanta of KEYFRAME_QUANTUM steps (the same arithmetic on both ends)."""
    if len(frames):
        out[:, frames] += patches * (steps * trendwave.KEYFRAME_QUANTUM)


def rest_kind(motion: Motion) -> int:
    """Whether frame 0 of ``motion`` is its skeleton's rest pose, which exporters write before
    a take (a bind pose, :attr:`Motion.starts_at_rest`), with the translations of frame 1
    (REST), all 0 (REST_AT_ZERO), or frame 1's under the root's turn of frame 1 (REST_TURNED,
    a game export's rotation-only root turned to the engine's axes). Such a frame costs a flag
    instead of a keyframe and the wavelet starts after it; 0 if not."""
    if not motion.starts_at_rest:
        return 0
    channels, rot = motion.channels, motion.skeleton.rotation_mask
    turned = bool(channels[0, motion.skeleton.root_turn_mask].any())
    if np.allclose(channels[0, ~rot], channels[1, ~rot], rtol=REST_RTOL, atol=0.0):
        return REST_TURNED if turned else REST
    return REST_AT_ZERO if not turned and not channels[0, ~rot].any() else 0


def rest_pose(skeleton: Skeleton, kind: int, frame1: np.ndarray) -> np.ndarray:
    """Frame 0 of a body whose more flags say ``kind``, from its decoded frame 1 ``(C,)``."""
    if kind == REST_AT_ZERO:
        return np.zeros_like(frame1)
    return rest_frame(skeleton, frame1, turned=kind == REST_TURNED)


def with_more(body: bytes, more: int) -> bytes:
    """``body`` (format 1, or 2 or 3 whose more flags are kept) as format 2 (or 3) with the more
    flags ``more`` set too: a rest pose before its frames (REST, REST_AT_ZERO), its layout's
    lead, fine constants (FINE_CONSTANTS, FINE_TURNS)."""
    if body[0] in (FORMAT_MORE, FORMAT_MIRRORED):
        return body[: HEAD.size] + bytes([body[HEAD.size] | more]) + body[HEAD.size + 1 :]
    return bytes([FORMAT_MORE]) + body[1 : HEAD.size] + bytes([more]) + body[HEAD.size :]


def with_mirrored(body: bytes, count: int) -> bytes:
    """``body`` (format 1 or 2 whose side sequences end with ``count`` mirrored joints and their
    references) as format 3: the count after the more flags (:func:`mirrored_constants`)."""
    more = with_more(body, 0) if body[0] == FORMAT else body
    return bytes([FORMAT_MIRRORED]) + more[1 : HEAD.size + 1] + bytes([count]) + more[HEAD.size + 1 :]


def channel_steps(skeleton: Skeleton, codes: np.ndarray) -> np.ndarray:
    """``(C, 1)``: every channel's quantiser step from the body's step codes (the values of
    :func:`group_step`, looked up at once)."""
    code_of, translation = _channel_codes(skeleton)
    steps = _CODE_STEPS[np.asarray(codes, dtype=np.int64)[code_of]]
    steps[translation] = steps[translation] * skeleton.units_per_metre / 100.0  # as group_step rounds
    return steps[:, None]


@lru_cache(maxsize=64)
def _channel_codes(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Each channel's index into the step codes (its rotation joint's, or the last for a
    translation), and which channels are translations."""
    code_of = np.zeros(skeleton.num_channels, dtype=np.int64)
    translation = np.zeros(skeleton.num_channels, dtype=bool)
    joints = _rotation_joints(skeleton)
    for g in step_groups(skeleton):
        code_of[g.channels] = joints.index(g.joint) if g.rotation else -1
        translation[g.channels] = not g.rotation
    return code_of, translation


def decode_body(body: bytes, skeleton: Skeleton, frames: int) -> np.ndarray:
    """Channels ``(frames, C)`` of a kinwave body (format 1, 2 or 3, docs/formats.md), every
    field checked."""
    if body[:1] not in (bytes([FORMAT_MORE]), bytes([FORMAT_MIRRORED])):
        return _decode_frames(body, skeleton, frames, 0, constant_coding(skeleton))
    if len(body) <= HEAD.size:
        raise CorruptStreamError(f"kinwave body of {len(body)} bytes is shorter than its {HEAD.size + 1}-byte header")
    more, mirroring = body[HEAD.size], body[0] == FORMAT_MIRRORED
    kind, lead = more & 3, (more >> LEAD_SHIFT) & 3
    if (not more and not mirroring) or more >> 7 or frames < 1 + bool(kind):
        raise CorruptStreamError(
            f"kinwave body's more flags at byte {HEAD.size} are damaged ({more} for {frames} frames)"
        )
    constants = constant_coding(
        skeleton, bool(more & FINE_CONSTANTS), bool(more & FINE_TURNS), bool(more & ZERO_CONSTANTS)
    )
    after = HEAD.size + 1
    mirrored = 0
    if mirroring:
        if len(body) <= after or not 1 <= body[after] <= len(translation_triples(skeleton)[0]):
            raise CorruptStreamError(f"kinwave body's mirrored joint count at byte {after} is damaged")
        mirrored, after = body[after], after + 1
    inner = bytes([FORMAT]) + body[1 : HEAD.size] + body[after:]
    if not kind:
        return _decode_frames(inner, skeleton, frames, lead, constants, mirrored)
    rest = _decode_frames(inner, skeleton, frames - 1, lead, constants, mirrored)
    return np.vstack((rest_pose(skeleton, kind, rest[0]), rest))


def _decode_frames(
    body: bytes, skeleton: Skeleton, frames: int, lead: int, constants: ConstantCoding, mirrored: int = 0
) -> np.ndarray:
    """Channels ``(frames, C)`` of a format 1 body whose layout has ``lead``, its constant
    channels coded as ``constants`` says, ``mirrored`` joints' constant translations against
    earlier joints' (:func:`mirrored_constants`)."""
    rot_joints = rotation_joints(skeleton)
    trans = has_translation(skeleton)
    num_codes = len(rot_joints) + trans
    if len(body) < HEAD.size:
        raise CorruptStreamError(f"kinwave body of {len(body)} bytes is shorter than its {HEAD.size}-byte header")
    version, flags, log_w, levels, channels = HEAD.unpack_from(body)
    if version != FORMAT:
        raise CorruptStreamError(
            f"kinwave body format {version}, this mocodec reads {FORMAT}, {FORMAT_MORE} and {FORMAT_MIRRORED}"
        )
    if channels != skeleton.num_channels:
        raise CorruptStreamError(
            f"kinwave body has {channels} channels, the skeleton {skeleton.num_channels}: wrong skeleton?"
        )
    if log_w > 16 or not 1 <= levels <= 10 or (flags >> 1) & 3 >= len(WAVELET_IDS):
        raise CorruptStreamError(f"kinwave body header is damaged (window 2^{log_w}, levels {levels})")
    keyframes = int(bool(flags & FLAG_KEYFRAME)) * (2 if flags & FLAG_SECOND_KEYFRAME else 1)
    lay = trendwave.layout(frames, 1 << log_w, levels, keyframes, WAVELET_IDS[(flags >> 1) & 3], lead)
    num_offsets = lay.starts.size if flags & FLAG_OFFSETS else 0
    num_vectors = len(three_angle_groups(skeleton)) if flags & FLAG_FORMS else 0
    num_means = 3 * num_vectors if flags & FLAG_MEANS else 0
    start, num_isolated = HEAD.size, 0
    if flags & FLAG_ISOLATED:
        if len(body) <= start or not 1 <= body[start] <= MAX_ISOLATED:
            raise CorruptStreamError(f"kinwave body's isolated frame count at byte {start} is damaged")
        start, num_isolated = start + 1, body[start]
    coded = coefcoder.decode(
        body[start:],
        skeleton.num_channels,
        lay.num_knots,
        lay.padded,
        lay.levels,
        CODER_REVISION,
        (
            num_codes,
            num_offsets,
            num_vectors,
            num_means,
            num_isolated,
            num_isolated * skeleton.num_channels,
            mirrored,
            mirrored,
        ),
    )
    codes, offsets, forms, _, isolated, _, targets, _ = coded.side
    if mirrored:
        unmirror(skeleton, coded.const, coded.knots, targets, coded.terms[7])
    means = coded.terms[3].reshape(-1, 3)  # (sent as running sums: the terms are the values)
    patches = coded.terms[5].reshape(skeleton.num_channels, num_isolated)
    if num_isolated and not (1 <= isolated[0] and (np.diff(isolated) > 1).all() and isolated[-1] < frames - 1):
        raise CorruptStreamError("kinwave body's isolated frames are damaged")
    if (
        (codes.size and not 0 <= codes.min() <= codes.max() <= 255)
        or np.abs(offsets).max(initial=0) > 128
        or not rotvec.valid_forms(forms)
        or np.abs(means).max(initial=0) * MEAN_QUANTUM > 360.0
    ):
        raise CorruptStreamError("kinwave body's step codes are damaged")
    if not num_offsets:
        offsets = np.zeros(lay.starts.size, dtype=np.int8)
    if not frames:
        return np.zeros((0, skeleton.num_channels))
    return decode_channels(
        skeleton,
        codes,
        offsets,
        coded.const,
        coded.knots,
        coded.coeffs,
        lay,
        forms,
        constants,
        means,
        (isolated, patches),
    ).T


@lru_cache(maxsize=64)
def translation_triples(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joints with three translation channels (the joints whose constant translations may
    be mirrored), those channels in channel order ``(J3, 3)``, and per joint its index among
    them (-1: not one of them)."""
    positions = channel_plan(skeleton).pos_index
    joints = np.flatnonzero((positions >= 0).all(axis=1))
    index = np.full(len(positions), -1, dtype=np.int64)
    index[joints] = np.arange(joints.size)
    return joints, np.sort(positions[joints], axis=1), index


_SIGNS = 1 - 2 * ((np.arange(8)[:, None] >> np.arange(3)) & 1)  # (8, 3): bit a negates axis a


def _bits(values: np.ndarray) -> np.ndarray:
    """About the bits the coefficient coder spends on integers, summed over the last axis (an
    adaptive Elias-gamma code: two per binary digit)."""
    return 2.0 * np.log2(1.0 + np.abs(values)).sum(axis=-1)


def mirrored_constants(
    skeleton: Skeleton, const: np.ndarray, knots: np.ndarray, slack: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A symmetric skeleton's bones held in translation channels come in mirrored pairs: per
    joint whose three translations are constant, the earlier such joint whose knots, some axes
    negated, are within ``slack`` of its own on every axis (the nearest of the closest), taken
    where coding the difference and the reference costs fewer bits than the knots (and all
    together more than the count byte; MAX_MIRRORED joints at most). Returns the joints,
    ``back << 3 | signs`` per joint (the reference ``back`` joints earlier, bit a set where
    translation a is negated) and the knots with each of those joints' constant knots less
    its reference's (what the coder then codes; :func:`unmirror` undoes it)."""
    coded, none = knots.copy(), np.zeros(0, dtype=np.int64)
    joints, rows, _ = translation_triples(skeleton)
    held = const[rows].all(axis=1)
    joints, rows = joints[held], rows[held]
    if not knots.shape[1] or joints.size < 2:  # (a body of no frames has no knot)
        return none, none, coded
    own = knots[rows, 0]  # (T, 3)
    apart = (np.abs(own[:, None] - own[None]), np.abs(own[:, None] + own[None]))  # (T, T, 3): axis kept, negated
    misses = np.stack(  # (T, T, 8): the largest miss over the axes, per sign pattern
        [np.maximum.reduce([apart[sign >> a & 1][..., a] for a in range(3)]) for sign in range(8)], axis=2
    )
    misses[np.triu_indices(len(joints))] = slack + 1  # earlier joints only
    closest = misses.min(axis=(1, 2), initial=slack + 1)
    picked = np.flatnonzero(closest <= slack)
    if not picked.size:
        return none, none, coded
    hits = misses[picked] == closest[picked, None, None]  # (P, T, 8)
    earlier = hits.shape[1] - 1 - np.argmax(hits.any(axis=2)[:, ::-1], axis=1)  # the nearest of the closest
    sign = np.argmax(hits[np.arange(picked.size), earlier], axis=1)  # its first signs
    refs = (joints[picked] - joints[earlier]) << 3 | sign
    differences = own[picked] - _SIGNS[sign] * own[earlier]
    gains = _bits(own[picked]) - _bits(differences) - _bits(refs[:, None]) - MIRROR_ENTRY_BITS
    kept = np.flatnonzero(gains > 0)[:MAX_MIRRORED]
    if gains[kept].sum() <= 8.0:  # (the count byte)
        return none, none, coded
    coded[rows[picked[kept]], 0] = differences[kept]
    return joints[picked[kept]], refs[kept], coded


def unmirror(skeleton: Skeleton, const: np.ndarray, knots: np.ndarray, joints: np.ndarray, refs: np.ndarray) -> None:
    """Add back, in place in ``knots``, the references' constant knots that
    :func:`mirrored_constants` took off (a reference mirrored itself first), every joint and
    reference checked."""
    _, rows, index_of = translation_triples(skeleton)
    index = index_of.tolist()
    if not knots.shape[1]:  # (a body of no frames has no knot to mirror)
        raise CorruptStreamError("kinwave body's mirrored joints are damaged: it has no frame")
    at, source_at, previous = [], [], -1
    for j, ref in zip(joints.tolist(), refs.tolist()):
        source = j - (ref >> 3)
        if not (previous < j < len(index) and 0 <= source < j) or index[j] < 0 or index[source] < 0:
            raise CorruptStreamError("kinwave body's mirrored joints are damaged")
        at.append(index[j])
        source_at.append(index[source])
        previous = j
    targets, sources = rows[at], rows[source_at]
    if not (const[targets].all() and const[sources].all()):
        raise CorruptStreamError("kinwave body's mirrored joints are damaged")
    signs = _SIGNS[refs & 7]
    if set(at).isdisjoint(source_at):
        knots[targets, 0] += signs * knots[sources, 0]
        return
    for k in range(len(at)):  # a reference mirrored itself comes back first: it is earlier
        knots[targets[k], 0] += signs[k] * knots[sources[k], 0]
