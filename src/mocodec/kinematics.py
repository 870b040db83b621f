"""Forward kinematics: global joint positions and orientations for all frames at once.

For joint ``i`` with parent ``p``, local rotation ``M_i`` (its Euler channels in
``rotation_order``), fixed pre-rotation ``C_i`` (the ASF ``axis``) and translation channels
``t_i``::

    G_i = G_p  C_i M_i C_i^-1
    x_i = x_p + G_p (offset_i + t_i)

This is the BVH rule (``C = I``) and the CMU ASF/AMC rule (offsets are bone ``direction *
length`` in the rest frame, ``C`` the bone ``axis``). Translation channels add to the offset.
Rotations are composed as quaternions in a compiled (numba) loop over frames and joints;
joints come after their parents (the skeleton guarantees it), so one pass suffices. Every
error measure in centimetres and every error-bounded encoder runs it, so it is kept lean:
about 10 ms for 10,000 frames of a 38-joint CMU skeleton.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mocodec import rotations
from mocodec.kernels import kernel
from mocodec.skeleton import Skeleton

_AXIS_ID = {"X": 0, "Y": 1, "Z": 2}


@dataclass(frozen=True)
class ChannelPlan:
    """Where each joint's channels sit (the forward-kinematics kernel's and the closed loop's
    index tables), computed once per skeleton."""

    rot_index: np.ndarray  # (J, 3) channel of each rotation step, -1 = none
    rot_axis: np.ndarray  # (J, 3) axis (0 = X, 1 = Y, 2 = Z) of each step
    pos_index: np.ndarray  # (J, 3) channel of X/Y/Z translation, -1 = none
    axis_quat: np.ndarray  # (J, 4) pre-rotation C
    has_axis: np.ndarray  # (J,) bool
    offsets: np.ndarray  # (J, 3)
    parents: np.ndarray  # (J,)
    rot_columns: np.ndarray  # the rotation channels, ascending

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The fields in order, as the kernels take them (:func:`frame_orientations`)."""
        return (
            self.rot_index,
            self.rot_axis,
            self.pos_index,
            self.axis_quat,
            self.has_axis,
            self.offsets,
            self.parents,
            self.rot_columns,
        )


@lru_cache(maxsize=64)
def channel_plan(skeleton: Skeleton) -> ChannelPlan:
    """The :class:`ChannelPlan` of ``skeleton`` (cached)."""
    n = len(skeleton)
    rot_index = -np.ones((n, 3), dtype=np.int64)
    rot_axis = np.zeros((n, 3), dtype=np.int64)
    pos_index = -np.ones((n, 3), dtype=np.int64)
    for i, j in enumerate(skeleton.joints):
        first = skeleton.channel_offsets[i]
        for step, (axis, channel) in enumerate(zip(j.rotation_order, j.rotation_channel_indices())):
            rot_index[i, step] = first + channel
            rot_axis[i, step] = _AXIS_ID[axis]
        for k, axis in enumerate("XYZ"):
            if f"{axis}position" in j.channels:
                pos_index[i, k] = first + j.channels.index(f"{axis}position")
    has_axis = np.array([j.has_axis for j in skeleton.joints], dtype=bool)
    axis_quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))  # (the identity's quaternion, exactly)
    if has_axis.any():
        axis_quat[has_axis] = rotations.matrix_to_quat(skeleton.axis_matrices[has_axis])
    return ChannelPlan(
        rot_index,
        rot_axis,
        pos_index,
        axis_quat,
        has_axis,
        np.ascontiguousarray(skeleton.offsets, dtype=np.float64),
        skeleton.parents.astype(np.int64),
        np.sort(rot_index[rot_index >= 0]),
    )


@kernel
def _fk_kernel(
    channels,
    cos_half,
    sin_half,
    rot_index,
    rot_axis,
    pos_index,
    axis_quat,
    has_axis,
    offsets,
    parents,
    pos,
    quat,
    local,
    want_local,
):
    """Global positions and rotations; with ``want_local`` also each joint's C M C^-1.

    Each Euler step multiplies by (cos, sin * unit axis), written out per axis. Everything is
    in this one function on purpose: split into numba helpers it runs six times slower."""
    for f in range(channels.shape[0]):
        for j in range(parents.shape[0]):
            w, x, y, z = 1.0, 0.0, 0.0, 0.0
            for step in range(3):
                c = rot_index[j, step]
                if c < 0:
                    break
                cs, sn = cos_half[f, c], sin_half[f, c]
                a = rot_axis[j, step]
                if a == 0:
                    w, x, y, z = w * cs - x * sn, w * sn + x * cs, y * cs + z * sn, z * cs - y * sn
                elif a == 1:
                    w, x, y, z = w * cs - y * sn, x * cs - z * sn, w * sn + y * cs, x * sn + z * cs
                else:
                    w, x, y, z = w * cs - z * sn, x * cs + y * sn, y * cs - x * sn, w * sn + z * cs
            if has_axis[j]:
                cw, cx, cy, cz = axis_quat[j, 0], axis_quat[j, 1], axis_quat[j, 2], axis_quat[j, 3]
                w, x, y, z = (
                    cw * w - cx * x - cy * y - cz * z,
                    cw * x + cx * w + cy * z - cz * y,
                    cw * y - cx * z + cy * w + cz * x,
                    cw * z + cx * y - cy * x + cz * w,
                )
                w, x, y, z = (
                    w * cw + x * cx + y * cy + z * cz,
                    -w * cx + x * cw - y * cz + z * cy,
                    -w * cy + x * cz + y * cw - z * cx,
                    -w * cz - x * cy + y * cx + z * cw,
                )
            if want_local:
                local[f, j, 0] = w
                local[f, j, 1] = x
                local[f, j, 2] = y
                local[f, j, 3] = z
            tx, ty, tz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
            if pos_index[j, 0] >= 0:
                tx += channels[f, pos_index[j, 0]]
            if pos_index[j, 1] >= 0:
                ty += channels[f, pos_index[j, 1]]
            if pos_index[j, 2] >= 0:
                tz += channels[f, pos_index[j, 2]]
            p = parents[j]
            if p < 0:
                quat[f, j, 0] = w
                quat[f, j, 1] = x
                quat[f, j, 2] = y
                quat[f, j, 3] = z
                pos[f, j, 0] = tx
                pos[f, j, 1] = ty
                pos[f, j, 2] = tz
                continue
            pw, px, py, pz = quat[f, p, 0], quat[f, p, 1], quat[f, p, 2], quat[f, p, 3]
            quat[f, j, 0] = pw * w - px * x - py * y - pz * z
            quat[f, j, 1] = pw * x + px * w + py * z - pz * y
            quat[f, j, 2] = pw * y - px * z + py * w + pz * x
            quat[f, j, 3] = pw * z + px * y - py * x + pz * w
            # v + w t + u x t with t = 2 u x v: the parent's rotation applied to the offset
            ux, uy, uz = 2.0 * (py * tz - pz * ty), 2.0 * (pz * tx - px * tz), 2.0 * (px * ty - py * tx)
            pos[f, j, 0] = pos[f, p, 0] + tx + pw * ux + py * uz - pz * uy
            pos[f, j, 1] = pos[f, p, 1] + ty + pw * uy + pz * ux - px * uz
            pos[f, j, 2] = pos[f, p, 2] + tz + pw * uz + px * uy - py * ux


def _checked(skeleton: Skeleton, channels: np.ndarray) -> np.ndarray:
    channels = np.ascontiguousarray(channels, dtype=np.float64)
    if channels.ndim != 2 or channels.shape[1] != skeleton.num_channels:
        raise ValueError(f"expected (frames, {skeleton.num_channels}) channels, got {channels.shape}")
    return channels


@kernel
def _half_angles(channels: np.ndarray, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of the half angle of the rotation ``columns`` of every frame (the other
    columns are left unset: translations need no trigonometry, and are half of a
    MotionBuilder or game-engine export's channels)."""
    cos_half, sin_half = np.empty_like(channels), np.empty_like(channels)
    for f in range(channels.shape[0]):
        for c in columns:
            half = channels[f, c] * (np.pi / 360.0)
            cos_half[f, c], sin_half[f, c] = np.cos(half), np.sin(half)
    return cos_half, sin_half


@kernel
def frame_orientations(frame, rot_index, rot_axis, pos_index, axis_quat, has_axis, offsets, parents, rot_columns):
    """Global orientations ``(joints, 4)`` of one frame of channels ``frame (C,)``, for a
    compiled caller: :func:`forward_kinematics`' floats (the arguments are
    :class:`ChannelPlan`'s fields, in its order)."""
    channels = np.empty((1, frame.size))
    channels[0, :] = frame
    cos_half, sin_half = _half_angles(channels, rot_columns)
    joints = parents.shape[0]
    pos, quat = np.empty((1, joints, 3)), np.empty((1, joints, 4))
    _fk_kernel(
        channels, cos_half, sin_half, rot_index, rot_axis, pos_index, axis_quat, has_axis, offsets, parents, pos, quat,
        np.empty((0, 0, 4)), False,
    )  # fmt: skip
    return quat[0]


@kernel
def _place_kernel(channels, orientations, pos_index, offsets, parents, pos, quat):
    for f in range(channels.shape[1]):
        for j in range(parents.shape[0]):
            quat[f, j, 0], quat[f, j, 1] = orientations[j, f, 0], orientations[j, f, 1]
            quat[f, j, 2], quat[f, j, 3] = orientations[j, f, 2], orientations[j, f, 3]
            tx, ty, tz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
            if pos_index[j, 0] >= 0:
                tx += channels[pos_index[j, 0], f]
            if pos_index[j, 1] >= 0:
                ty += channels[pos_index[j, 1], f]
            if pos_index[j, 2] >= 0:
                tz += channels[pos_index[j, 2], f]
            p = parents[j]
            if p < 0:
                pos[f, j, 0], pos[f, j, 1], pos[f, j, 2] = tx, ty, tz
                continue
            pw, px, py, pz = orientations[p, f, 0], orientations[p, f, 1], orientations[p, f, 2], orientations[p, f, 3]
            ux, uy, uz = 2.0 * (py * tz - pz * ty), 2.0 * (pz * tx - px * tz), 2.0 * (px * ty - py * tx)
            pos[f, j, 0] = pos[f, p, 0] + tx + pw * ux + py * uz - pz * uy
            pos[f, j, 1] = pos[f, p, 1] + ty + pw * uy + pz * ux - px * uz
            pos[f, j, 2] = pos[f, p, 2] + tz + pw * uz + px * uy - py * ux


def positions_from_orientations(
    skeleton: Skeleton, rows: np.ndarray, orientations: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`forward_kinematics` of channel rows ``(channels, frames)`` whose joints' global
    orientations ``(joints, frames, 4)`` are known already (kinwave's passes compose them for
    the closed loop): the positions from the parents' orientations and the translations, as
    the kernel places them, without the rotations' trigonometry. An orientation only a leaf's
    own rotation changes places no joint, so may be left as its parent's."""
    pos, quat = np.empty((rows.shape[1], len(skeleton), 3)), np.empty((rows.shape[1], len(skeleton), 4))
    plan = channel_plan(skeleton)
    _place_kernel(
        np.ascontiguousarray(rows, dtype=np.float64),
        orientations,
        plan.pos_index,
        plan.offsets,
        plan.parents,
        pos,
        quat,
    )
    return pos, quat


def _run(skeleton: Skeleton, channels: np.ndarray, want_local: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    channels = _checked(skeleton, channels)
    plan = channel_plan(skeleton)
    frames, joints = len(channels), len(skeleton)
    pos, quat = np.empty((frames, joints, 3)), np.empty((frames, joints, 4))
    local = np.empty((frames, joints, 4) if want_local else (0, 0, 4))
    rot_index, rot_axis, pos_index, axis_quat, has_axis, offsets, parents, rot_columns = plan.arrays()
    cos_half, sin_half = _half_angles(channels, rot_columns)
    _fk_kernel(
        channels, cos_half, sin_half, rot_index, rot_axis, pos_index, axis_quat, has_axis, offsets, parents, pos, quat,
        local, want_local,
    )  # fmt: skip
    return pos, quat, local


def position_offsets(skeleton: Skeleton) -> np.ndarray:
    """``(channels,)``: each position channel's joint offset on its axis, 0 elsewhere (a BVH
    position channel holds the offset and the motion together; kinwave codes a constant
    translation about it)."""
    plan = channel_plan(skeleton)
    out = np.zeros(skeleton.num_channels)
    for k in range(3):
        has = plan.pos_index[:, k] >= 0
        out[plan.pos_index[has, k]] = plan.offsets[has, k]
    return out


def local_quaternions(skeleton: Skeleton, channels: np.ndarray) -> np.ndarray:
    """Each joint's rotation relative to its parent, ``(frames, joints, 4)``: ``C M C^-1``."""
    return _run(skeleton, channels, True)[2]


def rest_frame(skeleton: Skeleton, frame: np.ndarray, turned: bool = False) -> np.ndarray:
    """The skeleton's rest pose as one frame ``(C,)``: every rotation 0, the translations
    ``frame``'s. ``turned``: a game export's rotation-only root turns the axes, the rest pose
    with them, and the body stands as it does at rest: the root joint's rotations are
    ``frame``'s, and each joint right below it with three rotation channels (and no axis
    pre-rotation) turns back by them (its Euler angles in its own order)."""
    out = np.where(skeleton.rotation_mask, 0.0, frame)
    if not turned or not len(skeleton):
        return out
    turn = skeleton.root_turn_mask
    out[turn] = frame[turn]
    for channels, angles in _turned_back(skeleton, tuple(frame[turn].tolist())):
        out[channels] = angles
    return out


@lru_cache(maxsize=64)
def _turned_back(skeleton: Skeleton, turn: tuple[float, ...]) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """For :func:`rest_frame`: each joint right below the root that can turn back (three
    rotation channels, no axis pre-rotation), its rotation channels and the angles that undo
    the root's rotation channels' ``turn`` (the clips of one export share them)."""
    frame = np.zeros(skeleton.num_channels)
    frame[skeleton.root_turn_mask] = turn
    back = rotations.quat_conjugate(local_quaternions(skeleton, frame[None])[0, 0])
    out = []
    for j in np.flatnonzero(skeleton.parents == 0):
        joint = skeleton.joints[j]
        if len(joint.rotation_order) == 3 and not joint.has_axis:
            channels = skeleton.channel_offsets[j] + np.array(joint.rotation_channel_indices())
            out.append((channels, rotations.quat_to_euler(back, joint.rotation_order)))
    return tuple(out)


def forward_kinematics(skeleton: Skeleton, channels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global pivot positions ``(frames, joints, 3)`` (skeleton units) and global orientations
    as unit quaternions ``(frames, joints, 4)`` for a ``(frames, channels)`` array."""
    pos, quat, _ = _run(skeleton, channels, False)
    return pos, quat


def global_matrices(skeleton: Skeleton, channels: np.ndarray) -> np.ndarray:
    """Global joint orientations as rotation matrices ``(frames, joints, 3, 3)``."""
    return rotations.quat_to_matrix(forward_kinematics(skeleton, channels)[1])
