"""One kinwave body's encoder: the coding form of every joint, the step shape, the
leading keyframes and isolated frames, one closed-loop pass down the kinematic tree at given
steps, and the body bytes of a pass (:mod:`.body`). :mod:`.search` finds the steps."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from mocodec import rotations
from mocodec.codecs.base import Codec
from mocodec.codecs.kinwave import channelcode, kinalloc, treepass
from mocodec.codecs.kinwave.body import (
    CODER_REVISION,
    FINE_CONSTANTS,
    FINE_TURNS,
    FLAG_FORMS,
    FLAG_ISOLATED,
    FLAG_KEYFRAME,
    FLAG_MEANS,
    FLAG_OFFSETS,
    FLAG_SECOND_KEYFRAME,
    FORMAT,
    HEAD,
    LEAD_SHIFT,
    MAX_ISOLATED,
    MEAN_QUANTUM,
    SEAM_HALF_WIDTH,
    SEAM_LIMIT,
    WAVELET_IDS,
    ZERO_CONSTANTS,
    ConstantCoding,
    channel_steps,
    constant_coding,
    has_translation,
    levels_for,
    mirrored_constants,
    parent_orientations,
    parent_turns,
    reconstruct,
    rotation_joints,
    segment_factors,
    step_codes,
    still_rotations,
    three_angle_groups,
    turns_over_translations,
    with_mirrored,
    with_more,
    world_translations,
)
from mocodec.codecs.shared import rotvec
from mocodec.coding.entropy import coefcoder
from mocodec.coding.transforms import trendwave
from mocodec.kernels import kernel
from mocodec.kinematics import channel_plan, forward_kinematics, positions_from_orientations
from mocodec.metrics.pose import bone_joints, joint_errors as distances, shell_errors
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

MEAN_LEAST = 20.0  # degrees: a mean rotation smaller than this is left at the identity
CONSTANT = 1e-6  # a channel whose range is below this is one knot
CONSTANT_SPOT = 8  # ... looked for in coding forms on every 8th frame first (Encoder._constant_in_forms)
FLOAT32_STEPS = 16  # ... and a translation whose range is this many float32 steps of its size (storage noise)
NOISE_SHARE = 1.0 / 64.0  # ... if that range is under this share of a max bound
JUMP_CM = 10.0  # a leading frame jumping less than this is not tried as a keyframe
TRIAL_FRAMES = 1024  # frames the choice of forms codes each form of every joint on (effort 3)
TRIAL_RATE = 15.0  # frames/s the trial keeps of a faster body (effort < 3; Encoder._trial_stride)
TRIAL_SAMPLE = 512  # ... below it, of a longer body, this many (Encoder._trial_frames)
FAR_STEPS = 0.7  # a frame missing its target by more than this many steps rounds its coefficients plainly
CONST_AWAY_CM = 0.1  # a constant translation this far from its joint's offset takes fine constants
MIRROR_SLACK = 1  # knots: a constant bone mirrors an earlier one this close (body.mirrored_constants)
GIMBAL_MARGIN = 15.0  # degrees from an Euler order's lock within which a joint goes as a vector
BONE_PLACES = 4  # decimals of a bone held in translation channels that the allocation sees
QUIET_TURN, QUIET_ANGLES = 20.0, 30.0  # degrees: a joint within both tries no other Euler order (effort < 3)


@lru_cache(maxsize=64)
def influence(skeleton: Skeleton, measure: str) -> np.ndarray:
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
    rows = [below[j] for j in rotation_joints(skeleton)]
    if has_translation(skeleton):
        rows.append(np.ones(below.shape[1], dtype=bool))
    return np.array(rows)


def frame_moves(positions_cm: np.ndarray) -> np.ndarray:
    """``(T - 1,)`` cm: how far the farthest-moving joint goes from each frame to the next."""
    return _farthest(np.ascontiguousarray(positions_cm, dtype=np.float64), 1)


@kernel
def _farthest(positions, gap):
    """``(T - gap,)``: the largest distance a joint of ``positions (T, J, 3)`` goes from frame
    t to frame t + gap, in one loop (the floats of numpy's norm of the differences)."""
    frames = max(positions.shape[0] - gap, 0)
    out = np.zeros(frames)
    for t in range(frames):
        far = 0.0
        for j in range(positions.shape[1]):
            dx = positions[t + gap, j, 0] - positions[t, j, 0]
            dy = positions[t + gap, j, 1] - positions[t, j, 1]
            dz = positions[t + gap, j, 2] - positions[t, j, 2]
            far = max(far, math.sqrt(dx * dx + dy * dy + dz * dz))
        out[t] = far
    return out


def linear_percentile(values: np.ndarray, q: float) -> float:
    """``np.percentile(values, q)`` of a 1-D array (linear interpolation, its default), from the
    two values around it: the same float, without the general machinery that a short clip's
    set-up paid for twice."""
    n = values.size
    index = (n - 1) * (q / 100.0)
    below = math.floor(index)
    above = min(below + 1, n - 1)
    a, b = np.partition(values, (below, above))[[below, above]].tolist()
    t, d = index - below, b - a
    return b - d * (1.0 - t) if t >= 0.5 else a + d * t


def leading_jumps(moves: np.ndarray) -> np.ndarray:
    """``(2,)`` bool: whether the first and the second frame jump far from the next one
    (``moves``: :func:`frame_moves`): twice the clip's own largest frame-to-frame motion after
    them, and at least JUMP_CM (a bind pose, a T-pose, or both, lead the clip; a walk's first
    step does not)."""
    if len(moves) < 7:
        return np.zeros(2, dtype=bool)
    return moves[:2] > max(2.0 * linear_percentile(moves[2:], 99) + 1.0, JUMP_CM)


def smoothest_orders(values: np.ndarray, forms: np.ndarray, joints: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Per trial entry (a joint ``joints[e]`` in ``forms[e]``, its angles rows ``3e..3e+2`` of
    ``values (3n, T)``): whether it is to be coded. Of a joint's ``usable`` Tait-Bryan orders,
    per frame of reference (the joint's or its parent's), only the one whose angles change
    least in slope (the sum of their absolute second differences); every other form. Coding
    only that order costs about 0.1% of the trial's bytes, for under half of its work
    (docs/kinwave.md)."""
    euler = (forms % rotvec.WORLD >= 2) & usable
    bend = np.abs(np.diff(values, 2, axis=1)).sum(axis=1).reshape(-1, 3).sum(axis=1)
    key = np.where(euler, 2 * joints + (forms >= rotvec.WORLD), -1)
    least = np.full(2 * (int(joints.max(initial=0)) + 1), np.inf)
    np.minimum.at(least, key[euler], bend[euler])
    keep = ~euler & usable
    keep[euler] = bend[euler] == least[key[euler]]
    return keep


def _angle_rows(joints: np.ndarray) -> np.ndarray:
    """The rows of three-angle joints ``joints`` in an array of their angles, three a joint."""
    return (3 * joints[:, None] + np.arange(3)).ravel()


@dataclass
class Pass:
    steps: np.ndarray  # u8 codes: rotation joints, then translation
    const: np.ndarray
    knots: np.ndarray
    coeffs: np.ndarray
    decoded: np.ndarray | None  # (C, T); None for a bound's pass unless every_frame (Encoder.run_pass)
    offsets: np.ndarray  # i8 per segment: its steps are 2^(offset/8) times the joints'
    patches: np.ndarray  # (C, isolated frames): each isolated frame's correction (apply_patches)
    errors: np.ndarray | None = None  # (frames, points) cm, once measured (Encoder.pass_errors)


def isolated_frames(positions_cm: np.ndarray, moves: np.ndarray, skip: int) -> np.ndarray:
    """Frames (after the first ``skip``) that jump far from both neighbours while the
    neighbours are close to each other (``moves``: :func:`frame_moves`): a glitch, coded apart
    so it does not cost the wavelet (what one spike costs otherwise: docs/kinwave.md)."""
    frames = len(positions_cm)
    if frames < 8:
        return np.zeros(0, dtype=np.int64)
    usual = linear_percentile(moves, 90)
    across = _farthest(np.ascontiguousarray(positions_cm, dtype=np.float64), 2)
    far = 4.0 * usual + 1.0
    t = np.arange(1, frames - 1)
    found = t[(moves[:-1] > far) & (moves[1:] > far) & (across <= 2.0 * usual + 1.0) & (t >= max(skip, 1))]
    keep: list[int] = []
    for f in found:  # neither neighbour of an isolated frame is one
        if not keep or f > keep[-1] + 1:
            keep.append(int(f))
    return np.array(keep[:MAX_ISOLATED], dtype=np.int64)


def bone_skeleton(skeleton: Skeleton, values: np.ndarray, const: np.ndarray) -> Skeleton:
    """The skeleton with each non-root joint's constant translation channels (``values (C, T)``)
    added to its offset: the bones the motion really has, whose lengths are the allocation's
    levers (a MotionBuilder export keeps every bone in position channels). The constants are
    rounded to BONE_PLACES decimals of the skeleton's unit: a game export stores them with
    float32 noise that differs from clip to clip, and the allocation (cached per skeleton)
    would otherwise be solved again for every clip of the same body; the clips of one body
    share one such skeleton (made once)."""
    if not values.shape[1]:
        return skeleton
    index = channel_plan(skeleton).pos_index
    channel = np.where(index >= 0, index, 0)
    joints, axes = np.nonzero((index >= 0) & const[channel])
    kept = joints > 0
    joints, axes, channels = joints[kept], axes[kept], channel[joints[kept], axes[kept]]
    held = tuple(
        (j, k, round(v, BONE_PLACES)) for j, k, v in zip(joints.tolist(), axes.tolist(), values[channels, 0].tolist())
    )
    return _with_bones(skeleton, held)


@lru_cache(maxsize=64)
def _with_bones(skeleton: Skeleton, held: tuple[tuple[int, int, float], ...]) -> Skeleton:
    """:func:`bone_skeleton`'s skeleton: each ``(joint, axis, value)`` of ``held`` added to
    that joint's offset."""
    offsets: dict[int, list[float]] = {}
    for j, k, value in held:
        offsets.setdefault(j, list(skeleton.joints[j].offset))[k] += value
    joints = list(skeleton.joints)
    for j, offset in offsets.items():  # (one replace a joint: each checks the joint again)
        joints[j] = replace(joints[j], offset=tuple(offset))
    if joints == list(skeleton.joints):
        return skeleton
    return Skeleton(tuple(joints), skeleton.units_per_metre, skeleton.name)


class Encoder:
    """One body: the passes of the scale search and the final bytes."""

    def __init__(self, codec: Codec, motion: Motion, output_skeleton: Skeleton | None = None):
        self.cfg = codec.config
        self.skeleton = sk = motion.skeleton
        self.output_skeleton = output_skeleton or sk  # the decoder's: errors are measured on its joints
        self.motion = motion.continuous() if motion.num_frames else motion
        self.values = self.motion.channels.T.copy()  # (C, T)
        self.by_frame = np.ascontiguousarray(self.values.T)  # (T, C), as the closed loop reads it
        self.frames = motion.num_frames
        pos, quat = forward_kinematics(sk, self.motion.channels)
        self.cm = 100.0 / sk.units_per_metre
        self.positions = pos * self.cm
        self.goal_positions = self.positions / self.cm  # (skeleton units, as the closed loop reads them)
        self.quats = quat
        self.const = self._constant_channels() if self.frames else np.ones(sk.num_channels, bool)
        self.constants = self._constant_coding()
        self.first_pass: Pass | None = None
        self._tree_pass: treepass.TreePass | None = None
        moves = frame_moves(self.positions) if self.cfg["keyframes"] else np.zeros(0)
        self.isolated = isolated_frames(self.positions, moves, 2) if self.cfg["keyframes"] else np.zeros(0, np.int64)
        self.rot_joints = rotation_joints(sk)
        self.trans = has_translation(sk)
        self.shape_rot, self.shape_trans = self._shape()
        self.joint_offsets = np.zeros(len(self.rot_joints) + self.trans, dtype=np.int64)
        self.grid = self._grid_phase()  # the frames (mod trendwave.LEADS) the blocks' grid starts on
        self.set_layout(0)
        self.means = np.zeros((len(three_angle_groups(sk)), 3), dtype=np.int64)
        self.turns, self.turned = self._turns()
        self.forms = self._choose_forms() if self.cfg["rotation_vectors"] else np.zeros(0, dtype=np.int64)
        self._constant_in_forms()
        self.world_translations = world_translations(sk, self.const)
        if self.cfg["keyframes"]:
            self._choose_keyframes(leading_jumps(moves))

    def _constant_channels(self) -> np.ndarray:
        """Channels coded as one knot: a range below CONSTANT, or a translation whose range is
        the noise of float32 storage (FLOAT32_STEPS of its size's float32 step, and small
        against a max bound). An FBX pipeline stores every bone's translation so: coded as
        motion, a bone's translation restores its position from its parent's decoded one and
        codes the parent's error (docs/kinwave.md, "Game exports")."""
        spread = np.ptp(self.values, axis=1)
        const = spread <= CONSTANT
        moving = ~self.skeleton.rotation_mask & ~const
        size = np.abs(self.values[moving]).max(axis=1).astype(np.float32)
        noise = FLOAT32_STEPS * np.spacing(size).astype(np.float64)
        if not self.cfg["bits_per_second"]:
            noise = np.minimum(noise, NOISE_SHARE * self.cfg["max_error_cm"] / self.cm)
        const[moving] = spread[moving] <= noise
        return const

    def _turns(self) -> tuple[np.ndarray, np.ndarray]:
        """Per three-angle joint, the turn a WORLD form would take off (:func:`parent_turns`,
        exact) and whether it may: every joint above it holds a constant rotation, and together
        they turn it (a dummy root's constant rotation)."""
        groups = three_angle_groups(self.skeleton)
        if not self.frames or not groups:
            return np.tile([1.0, 0.0, 0.0, 0.0], (len(groups), 1)), np.zeros(len(groups), dtype=bool)
        sk = self.skeleton
        still = still_rotations(sk, self.const)
        parents = sk.parents[[sk.channel_joints[g[0]] for g, _ in groups]]
        above = np.where(parents >= 0, still[np.maximum(parents, 0)], False)
        turns = parent_turns(sk, parent_orientations(sk, self.values[:, 0]))
        return turns, above & (np.abs(turns[:, 0]) < 1.0 - 1e-12)

    def _constant_coding(self) -> ConstantCoding:
        """Constant translations about 0 (ZERO_CONSTANTS) where that is nearer them in all than
        their joints' offsets on the decoder's skeleton; fine constants (:class:`ConstantCoding`):
        at the highest effort translations where a constant one lies CONST_AWAY_CM or more from
        its base (below it they take the 8th: as many files grow as shrink with the 64th, and
        the constants' own bytes go; docs/kinwave.md), rotations where a joint with a
        translation channel below it holds a constant rotation other than 0 (a turned dummy
        root)."""
        offsets = constant_coding(self.output_skeleton)
        if not self.frames:
            return offsets
        held = self.const & ~self.skeleton.rotation_mask
        first = self.values[:, 0]
        about_zero = bool(np.abs(first[held]).sum() < np.abs(first[held] - offsets.base[held]).sum())
        base = np.zeros_like(offsets.base) if about_zero else offsets.base
        away = np.abs(first - base) * self.cm >= CONST_AWAY_CM
        turned = self.const & turns_over_translations(self.skeleton) & (first != 0)
        fine = bool((held & away).any()) and self.cfg["effort"] >= 3
        return constant_coding(self.output_skeleton, fine, turned.any(), about_zero)

    def _grid_phase(self) -> int | None:
        """Where the wavelet grid goes (:func:`trendwave.grid_phase`, the moving channels in
        the starting scale's steps, the two frames keyframes may take left out); None: after
        the keyframes, as it would without a lead."""
        steps = channel_steps(self.skeleton, self.codes(self.first_scale()))
        moving = ~self.const
        return trendwave.grid_phase(self.values[moving] / steps[moving], self.cfg["wavelet"], skip=2)

    def set_layout(self, keyframes: int) -> None:
        """Segments and knots with ``keyframes`` leading one-frame segments, the wavelet grid
        on ``self.grid``, and the header."""
        self.keyframes = keyframes
        levels = self.cfg["levels"] or levels_for(self.motion.fps)
        first = trendwave.first_window(self.frames, keyframes)
        self.lead = 0 if self.grid is None else (first - self.grid) % trendwave.LEADS
        self.lay = trendwave.layout(self.frames, self.cfg["window"], levels, keyframes, self.cfg["wavelet"], self.lead)
        flags = (FLAG_KEYFRAME if keyframes else 0) | (FLAG_SECOND_KEYFRAME if keyframes == 2 else 0)
        self.header = HEAD.pack(
            FORMAT,
            flags | WAVELET_IDS.index(self.cfg["wavelet"]) << 1,
            int(math.log2(self.cfg["window"])),
            levels,
            self.skeleton.num_channels,
        )

    def _choose_keyframes(self, jumps: np.ndarray) -> None:
        """Leading frames that jump away (a bind pose, a T-pose) cost the wavelet a jump, but
        as keyframes a finely quantised pose each; which is cheaper depends on the pose and the
        bound (docs/kinwave.md). At the highest effort one pass at the starting scale with 0,
        1 and 2 keyframes decides (at the same steps the errors are about the same). Below it,
        the counts that won on the shared clips, without a trial: a first frame jumping alone
        is one keyframe, a second frame jumping, alone or with the first, makes both keyframes
        (how often each won, and what a fixed count costs against the trial, whose passes are
        at the starting scale and not the final one: docs/kinwave.md)."""
        if not jumps.any():
            return
        if self.cfg["effort"] < 3:
            self.set_layout(2 if jumps[1] else 1)
            return
        counts = (0, 1, 2)
        passes = []
        for count in counts:
            self.set_layout(count)
            passes.append(self.run_pass(self.codes(self.first_scale())))
        best = int(np.argmin([len(self.body(ps)) for ps in passes]))
        self.set_layout(counts[best])
        self.first_pass = passes[best]  # the search starts from it

    def starting_pass(self) -> Pass:
        """The pass at the starting scale, without joint offsets, run once (the keyframes' trial
        may have run it; every landing of a body starts from it, and it is measured as it runs)."""
        if self.first_pass is None:
            self.first_pass = self.run_pass(self.codes(self.first_scale()))
        return self.first_pass

    def _shape(self) -> tuple[np.ndarray, float]:
        """Steps (degrees per rotation joint, cm for translations) whose modelled bound is 1 cm.
        The levers are those of the motion's own bones (:func:`bone_skeleton`), and a joint
        whose angles are all constant takes the step the model would give it if they moved:
        its constants turn everything below it (a dummy root: the whole body)."""
        sk = bone_skeleton(self.skeleton, self.values, self.const)
        joint_of, moving, translation = self.skeleton.channel_joints, ~self.const, ~self.skeleton.rotation_mask
        coded = np.bincount(joint_of[moving & ~translation], minlength=len(sk)).tolist()
        rotating = np.bincount(joint_of[~translation], minlength=len(sk)).tolist()
        translations = int(np.count_nonzero(moving & translation))
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
        """Per 3-angle joint (:func:`three_angle_groups`), the form its rotation is coded in
        (:mod:`mocodec.codecs.shared.rotvec`: the file's Euler angles, a rotation vector about the
        joint's mean rotation, or Euler angles in one of the six Tait-Bryan orders): each form
        of every joint is coded once on its own (open loop, on :meth:`_trial_frames`) at the
        step the search starts from,
        and the fewest bytes win, moved to the file angles' rotation error along the high-rate
        slope (a nonzero coefficient takes a bit more per halving of the error). A form whose
        middle angle comes within GIMBAL_MARGIN of its lock is out. The trial weighs the mean
        rotation error, which is what decides a mean bound; under a max bound it misjudged ASF
        joints (angles about axes chosen for each bone, small and decoupled; docs/kinwave.md),
        so there only the body's root (the first joint that turns,
        below any dummy root) and joints near their gimbal lock may change form; a joint whose
        angles are all constant keeps them always. All joints go through each transform
        together; only the byte counts are per joint. The Tait-Bryan form in the file's own order
        is form 0 and is not tried twice; below the highest effort a quiet joint (:meth:`_quiet`)
        other than the body's root tries only its file's angles and a vector."""
        groups = three_angle_groups(self.skeleton)
        choice = np.zeros(len(groups), dtype=np.int64)
        moving = np.flatnonzero(~self.const[np.array([c for c, _ in groups]).reshape(-1, 3)].all(axis=1)).tolist()
        every_joint = self.cfg["error_measure"] == "mean" or not any(j.has_axis for j in self.skeleton.joints)
        if every_joint:
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
        stride = self._trial_stride() if every_joint else 1
        sample = self._trial_frames()[::stride]
        euler = self.values[channels][:, sample]
        levels = max(1, int(self.lay.levels.max(initial=1)) - stride.bit_length() + 1)
        lay = trendwave.layout(euler.shape[1], self.cfg["window"], levels, 0, self.cfg["wavelet"])
        step = channel_steps(self.skeleton, self.codes(self.first_scale()))[channels]
        factors = segment_factors(np.zeros(lay.starts.size), lay)
        pre = self.turns[live]
        whole = rotvec.euler_quats(self.values[channels], orders)
        original = whole[sample]
        turned = np.flatnonzero(self.turned[live])
        whole[:, turned] = rotations.quat_multiply(pre[turned][None], whole[:, turned])
        means = rotvec.mean_codes(whole, MEAN_QUANTUM, MEAN_LEAST)  # of pre q for the joints that may turn
        self.means[live] = means
        turns = rotvec.mean_quats(means, MEAN_QUANTUM)

        def trial(forms: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            """Each joint ``idx[e]`` (of ``live``) coded in ``forms[e]``, all in one batch (each
            joint's rows are coded on their own): (bytes, nonzero coefficients, mean rotation
            error) per entry, infinite bytes within GIMBAL_MARGIN of the form's lock."""
            rows = _angle_rows(idx)
            sub, kept = euler[rows], tuple(orders[i] for i in idx)
            values = sub.copy()
            moved = np.flatnonzero(forms)  # form 0: the file's Euler angles as they are
            if moved.size:
                cols = _angle_rows(moved)
                tb = tuple(kept[e] for e in moved)
                values[cols] = rotvec.to_forms(
                    sub[cols], tb, forms[moved], turns[idx[moved]], original[:, idx[moved]], pre[idx[moved]]
                )
            base = forms % rotvec.WORLD
            lock_orders = tuple(o if f == 0 else rotvec.CODING_ORDERS[max(f - 2, 0)] for o, f in zip(kept, base))
            locked = rotvec.near_lock(values, lock_orders, GIMBAL_MARGIN) & (base != rotvec.VECTOR)
            sizes, nonzero, err = np.full(idx.size, np.inf), np.zeros(idx.size, dtype=np.int64), np.ones(idx.size)
            tried = ~locked if self.cfg["effort"] >= 3 else smoothest_orders(values, forms, idx, ~locked)
            coded = np.flatnonzero(tried | (base == 0))  # (the file's angles give the reference error)
            if coded.size:
                sizes[coded], nonzero[coded], err[coded] = code(forms[coded], idx[coded], values[_angle_rows(coded)])
            return np.where(tried, sizes, np.inf), nonzero, err

        def code(forms: np.ndarray, idx: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            """The trial's entries ``idx`` in ``forms``, their rows ``values`` in those forms,
            coded: (bytes, nonzero coefficients, mean rotation error) per entry."""
            rows, kept = _angle_rows(idx), tuple(orders[i] for i in idx)
            flat, none = np.zeros(rows.size, dtype=bool), ConstantCoding(np.ones(rows.size), np.zeros(rows.size))
            k_int, c_int, _ = self.quantise(values, flat, step[rows], factors, none, lay)
            sizes = coefcoder.group_sizes(k_int, c_int, lay.padded, lay.levels, 3, revision=CODER_REVISION)
            rec = reconstruct(k_int, c_int, flat, step[rows], lay, factors, none)
            back = np.empty((rec.shape[1], idx.size, 4))
            kept_as_is, moved = np.flatnonzero(forms == 0), np.flatnonzero(forms)
            if kept_as_is.size:
                as_is_orders = tuple(kept[e] for e in kept_as_is)
                back[:, kept_as_is] = rotvec.euler_quats(rec[_angle_rows(kept_as_is)], as_is_orders)
            if moved.size:
                back[:, moved] = rotvec.form_quats(
                    rec[_angle_rows(moved)],
                    tuple(kept[e] for e in moved),
                    forms[moved],
                    turns[idx[moved]],
                    pre[idx[moved]],
                )
            err = np.maximum(rotvec.mean_distances(original[:, idx], back), 1e-12)
            return sizes, (c_int != 0).reshape(idx.size, -1).sum(axis=1), err

        own = np.array([2 + rotvec.CODING_ORDERS.index(o) if o in rotvec.CODING_ORDERS else -1 for o in orders])
        local = ~self.turned[live]
        quiet = self._quiet(original, euler) if self.cfg["effort"] <= 2 else np.zeros(len(live), dtype=bool)
        quiet[0] &= live[0] != moving[0]  # the body's root, which turns everything, tries every form
        candidates = [
            (base + form, np.flatnonzero(joints & (own != form) & ((form <= rotvec.VECTOR) | ~quiet)))
            for base, joints in ((0, local), (rotvec.WORLD, ~local))
            for form in range(rotvec.FORMS)
        ]
        entry_forms = np.concatenate([np.full(idx.size, form) for form, idx in candidates]).astype(np.int64)
        entry_joints = np.concatenate([idx for _, idx in candidates]).astype(np.int64)
        sizes, nonzero, err = trial(entry_forms, entry_joints)
        at = np.cumsum([0] + [idx.size for _, idx in candidates])
        reference = np.ones(len(live))  # the error of the file's own angles (forms 0 and WORLD)
        for row, (form, idx) in enumerate(candidates):
            if form % rotvec.WORLD == 0:
                reference[idx] = err[at[row] : at[row + 1]]
        costs = np.full((len(candidates), len(live)), np.inf)
        for row, (_, idx) in enumerate(candidates):
            part = slice(at[row], at[row + 1])
            costs[row, idx] = sizes[part] + nonzero[part] / 8.0 * np.log2(err[part] / reference[idx])
        choice[live] = np.array([form for form, _ in candidates])[np.argmin(costs, axis=0)]
        self.means[choice % rotvec.WORLD != rotvec.VECTOR] = 0
        return choice

    def _trial_frames(self) -> np.ndarray:
        """The frames the form trial codes: all of a body up to TRIAL_FRAMES (a .moc chunk);
        of a longer one, the first TRIAL_FRAMES at the highest effort, and below it two windows
        of TRIAL_SAMPLE / 2 frames centred on its thirds (a clip's first frames are often a
        T-pose and a start, unlike the rest; the windows choose forms as good as the first
        1024 frames for half the work, where a whole chunk's frames choose better:
        docs/kinwave.md)."""
        if self.cfg["effort"] >= 3 or self.frames <= TRIAL_FRAMES:
            return np.arange(min(self.frames, TRIAL_FRAMES))
        half = TRIAL_SAMPLE // 2
        starts = (self.frames * np.array([1, 2]) // 3 - half // 2).clip(0, self.frames - half)
        return (starts[:, None] + np.arange(half)).ravel()

    def _trial_stride(self) -> int:
        """Below the highest effort, a trial of every joint codes every n-th frame of a body
        faster than TRIAL_RATE (n a power of 2, the nearest in octaves; the trial's wavelet a
        level shallower per halving): the forms' costs against each other show at 12-15
        frames/s as well as at 120 (every eighth frame there, every other at 24 and 30
        frames/s), for a fraction of the trial's work. A trial of the few ASF joints that
        may change form is cheap, and its choice is delicate there: it keeps every frame
        (docs/kinwave.md)."""
        if self.cfg["effort"] >= 3:
            return 1
        return 1 << max(0, int(math.floor(math.log2(max(self.motion.fps, 1.0) / TRIAL_RATE) + 0.5)))

    @staticmethod
    def _quiet(quats: np.ndarray, euler: np.ndarray) -> np.ndarray:
        """Per joint of quaternions ``quats (T, n, 4)`` and Euler angle rows ``euler (3n, T)``:
        whether it stays within QUIET_TURN degrees of its first frame's rotation and its angles
        within QUIET_ANGLES of their first frame's. Another Euler order hardly changes what such
        a joint costs, against a large share of the trial's time (docs/kinwave.md)."""
        closeness = np.abs(np.einsum("tjk,jk->tj", quats, quats[0])).min(axis=0, initial=1.0)
        turn = np.degrees(2.0 * np.arccos(np.minimum(closeness, 1.0)))
        angles = np.abs(euler - euler[:, :1]).max(axis=1, initial=0.0).reshape(-1, 3).max(axis=1)
        return (turn < QUIET_TURN) & (angles < QUIET_ANGLES)

    def _constant_in_forms(self) -> None:
        """Which channels of the joints coded in another form are constant in that form (a
        hinge written in a proper order is one moving angle again); the steps follow. The
        forms of every CONSTANT_SPOT-th frame first: a channel that moves there moves (most
        do), and only a joint with a channel still there is converted at every frame."""
        coded = np.flatnonzero(self.forms)
        if not coded.size:
            return
        groups = three_angle_groups(self.skeleton)
        rows = np.concatenate([groups[k][0] for k in coded])

        def still(joints: np.ndarray, frames: slice) -> np.ndarray:
            """Per channel of ``joints``, whether its form is constant over ``frames``."""
            values = rotvec.to_forms(
                np.ascontiguousarray(self.values[np.concatenate([groups[k][0] for k in joints])][:, frames]),
                tuple(groups[k][1] for k in joints),
                self.forms[joints],
                rotvec.mean_quats(self.means[joints], MEAN_QUANTUM),
                pre=self.turns[joints],
            )
            return np.ptp(values, axis=1) <= CONSTANT

        per_joint = still(coded, slice(None, None, CONSTANT_SPOT)).reshape(-1, 3)
        maybe = per_joint.any(axis=1)
        if maybe.any():
            per_joint[maybe] = still(coded[maybe], slice(None)).reshape(-1, 3)
        const = per_joint.ravel()
        if (const != self.const[rows]).any():
            self.const[rows] = const
            self.shape_rot, self.shape_trans = self._shape()

    def first_scale(self) -> float:
        """The scale the bound's search starts from (the model's, before any pass)."""
        return self.cfg["max_error_cm"] / (0.3 if self.cfg["error_measure"] == "mean" else 0.8)

    # ----- one pass -------------------------------------------------------------------------
    def codes(self, scale: float) -> np.ndarray:
        steps = np.append(self.shape_rot * scale, self.shape_trans * scale if self.trans else [])
        return np.clip(step_codes(steps) + self.joint_offsets, 0, 255).astype(np.uint8)

    def run_pass(self, codes: np.ndarray, offsets: np.ndarray | None = None, every_frame: bool = False) -> Pass:
        """Quantise and reconstruct every channel down the tree in one compiled call
        (:class:`treepass.TreePass`, the loop of :func:`closedloop.code_down_tree`): a joint's
        closed-loop target needs its parent's decoded orientation, and the joints of one depth
        go through the transforms together (rows are independent, so each row's floats are
        those of coding it alone). A bound's pass is measured here, from the loop's decoded
        orientations (the next pass writes over them), and keeps its decoded rows (what the
        decoder will make of them, bit for bit) only with ``every_frame``: the rows of the
        joints in a coding form go back to the file's angles at every frame only then (at
        frame 0 otherwise)."""
        lay = self.lay
        offsets = np.zeros(lay.starts.size, dtype=np.int8) if offsets is None else offsets.astype(np.int8)
        if self._tree_pass is None:  # (the forms, constants and isolated frames are set by now)
            self._tree_pass = treepass.TreePass(self)
        measured = self.cfg["bits_per_second"] <= 0  # a bound's search measures every pass
        every_frame = every_frame or not measured  # (a bit rate's search reads no errors)
        knots, coeffs, decoded, patches = self._tree_pass.run(
            channel_steps(self.skeleton, codes)[:, 0], segment_factors(offsets, lay), lay, self.cfg["deadzone"],
            SEAM_LIMIT, SEAM_HALF_WIDTH, self.far_steps, every_frame,
        )  # fmt: skip
        errors = None
        if measured:
            pose = positions_from_orientations(self.output_skeleton, decoded, self._tree_pass.loop.glob)
            errors = self._errors_at(*pose)
        kept = decoded if every_frame else None
        return Pass(codes, self.const.astype(np.int64), knots, coeffs, kept, offsets, patches, errors)

    @property
    def far_steps(self) -> float:
        """Max bounds: where a depth's reconstruction misses its target by more than this many
        of the frame's steps (FAR_STEPS), the coefficients reaching that frame are rounded to
        the nearest integer instead of through the dead zone (:func:`channelcode.code_depth`).
        A max bound is set by a few such frames (several zeroed coefficients adding up), and
        the whole clip's steps went finer for them; the dead zone keeps its savings everywhere
        else (docs/kinwave.md). Encoder only: the decoder reads the integers as ever. 0 (none)
        under a mean bound, which single frames do not set, or with plain rounding already."""
        if self.cfg["error_measure"] == "mean" or self.cfg["deadzone"] >= 0.5:
            return 0.0
        return FAR_STEPS

    def quantise(
        self,
        target: np.ndarray,
        const: np.ndarray,
        step: np.ndarray,
        factors: tuple[np.ndarray, np.ndarray, np.ndarray],
        constants: ConstantCoding,
        lay: trendwave.Layout | None = None,
    ):
        """Knots and dead-zone quantised coefficients of ``target (k, T)`` with steps ``(k, 1)``,
        the segments' step :func:`segment_factors` and the rows' :class:`ConstantCoding`, laid out as
        ``lay`` (default: the body's), and the coefficients in steps before rounding."""
        return channelcode.quantise(
            target,
            const,
            step[:, 0],
            constants.fraction,
            constants.base,
            lay or self.lay,
            factors,
            self.cfg["deadzone"],
        )

    # ----- measures and bytes ---------------------------------------------------------------
    def joint_errors(self, decoded: np.ndarray) -> np.ndarray:
        """``(frames, points)`` cm: the decoded output's error at every joint, or at the worst
        shell point of every bone."""
        return self._errors_at(*forward_kinematics(self.output_skeleton, decoded.T))

    def _errors_at(self, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
        """:meth:`joint_errors` of decoded positions and orientations (skeleton units)."""
        if self.cfg["error_measure"] == "shell":
            return shell_errors(self.skeleton, self.positions, self.quats, pos * self.cm, quat).per_frame
        return distances(self.positions, pos, self.cm).per_frame

    def error(self, decoded: np.ndarray) -> float:
        return self._summary(self.joint_errors(decoded))

    def _summary(self, err: np.ndarray) -> float:
        return float(err.mean() if self.cfg["error_measure"] == "mean" else err.max())

    def pass_errors(self, ps: Pass) -> np.ndarray:
        """:meth:`joint_errors` of a pass's output, measured once (the search reads them again;
        a bound's pass is measured as it is run, from the closed loop's decoded orientations)."""
        if ps.errors is None:
            assert ps.decoded is not None  # (a pass without its decoded rows was measured as it ran)
            ps.errors = self.joint_errors(ps.decoded)
        return ps.errors

    def pass_error(self, ps: Pass) -> float:
        """:meth:`error` of a pass's output."""
        return self._summary(self.pass_errors(ps))

    def body(self, ps: Pass) -> bytes:
        flags = self.header[1]
        side: tuple[np.ndarray, ...] = (ps.steps,)
        mirrored, refs, knots = mirrored_constants(self.skeleton, ps.const, ps.knots, MIRROR_SLACK)
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
        if mirrored.size:
            side = side + (mirrored, np.cumsum(refs))
        head = self.header[:1] + bytes([flags]) + self.header[2:] + count
        body = head + coefcoder.encode(
            ps.const, knots, ps.coeffs, self.lay.padded, self.lay.levels, revision=CODER_REVISION, side=side
        )
        more = self.lead << LEAD_SHIFT | (FINE_CONSTANTS if self.constants.fine else 0)
        more |= FINE_TURNS if self.constants.fine_turns else 0
        more |= ZERO_CONSTANTS if self.constants.about_zero else 0
        body = with_more(body, more) if more else body
        return with_mirrored(body, mirrored.size) if mirrored.size else body
