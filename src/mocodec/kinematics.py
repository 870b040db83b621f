"""Forward kinematics: global joint positions and orientations for all frames at once.

For joint ``i`` with parent ``p``, local rotation ``M_i`` (its Euler channels in
``rotation_order``), fixed pre-rotation ``C_i`` (the ASF ``axis``) and translation channels
``t_i``::

    G_i = G_p  C_i M_i C_i^-1
    x_i = x_p + G_p (offset_i + t_i)

This is the BVH rule (``C = I``) and the CMU ASF/AMC rule (offsets are bone ``direction *
length`` in the rest frame, ``C`` the bone ``axis``). Translation channels add to the offset.
Rotations are composed as quaternions and every joint of one tree depth is done in one numpy
step, so the cost is a few dozen array operations whatever the clip length.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mocodec import rotations
from mocodec.skeleton import Skeleton

_UNIT = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class _Plan:
    rot_index: np.ndarray  # (J, 3) channel of each rotation step, -1 = none
    rot_axis: np.ndarray  # (J, 3, 3) unit axis of each step
    pos_index: np.ndarray  # (J, 3) channel of X/Y/Z translation, -1 = none
    axis_quat: np.ndarray  # (J, 4) pre-rotation C
    has_axis: np.ndarray  # (J,) bool
    levels: tuple[np.ndarray, ...]  # joints of depth 1, 2, ...


@lru_cache(maxsize=64)
def _plan(skeleton: Skeleton) -> _Plan:
    n = len(skeleton)
    rot_index = -np.ones((n, 3), dtype=np.int64)
    rot_axis = np.zeros((n, 3, 3))
    rot_axis[..., 0] = 1.0
    pos_index = -np.ones((n, 3), dtype=np.int64)
    for i, j in enumerate(skeleton.joints):
        first = skeleton.channel_offsets[i]
        for step, (axis, channel) in enumerate(zip(j.rotation_order, j.rotation_channel_indices())):
            rot_index[i, step] = first + channel
            rot_axis[i, step] = _UNIT[axis]
        for k, axis in enumerate("XYZ"):
            if f"{axis}position" in j.channels:
                pos_index[i, k] = first + j.channels.index(f"{axis}position")
    axis_quat = rotations.matrix_to_quat(skeleton.axis_matrices)
    has_axis = np.array([j.has_axis for j in skeleton.joints])
    depths = skeleton.depths
    levels = tuple(np.flatnonzero(depths == d) for d in range(1, int(depths.max()) + 1))
    return _Plan(rot_index, rot_axis, pos_index, axis_quat, has_axis, levels)


def _gather(channels: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``channels[:, index]`` with 0 where ``index`` is -1."""
    out = channels[:, np.maximum(index, 0)]
    out[:, index < 0] = 0.0
    return out


def local_quaternions(skeleton: Skeleton, channels: np.ndarray) -> np.ndarray:
    """Each joint's rotation relative to its parent, ``(frames, joints, 4)``: ``C M C^-1``."""
    plan = _plan(skeleton)
    half = np.deg2rad(_gather(channels, plan.rot_index)) * 0.5  # (F, J, 3)
    steps = np.concatenate((np.cos(half)[..., None], np.sin(half)[..., None] * plan.rot_axis), axis=-1)
    q = rotations.quat_multiply(rotations.quat_multiply(steps[:, :, 0], steps[:, :, 1]), steps[:, :, 2])
    if plan.has_axis.any():
        c = plan.axis_quat[plan.has_axis]
        q[:, plan.has_axis] = rotations.quat_multiply(
            rotations.quat_multiply(c, q[:, plan.has_axis]), rotations.quat_conjugate(c))
    return q


def forward_kinematics(skeleton: Skeleton, channels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global pivot positions ``(frames, joints, 3)`` (skeleton units) and global orientations
    as unit quaternions ``(frames, joints, 4)`` for a ``(frames, channels)`` array."""
    channels = np.asarray(channels, dtype=np.float64)
    if channels.ndim != 2 or channels.shape[1] != skeleton.num_channels:
        raise ValueError(f"expected (frames, {skeleton.num_channels}) channels, got {channels.shape}")
    plan = _plan(skeleton)
    local_q = local_quaternions(skeleton, channels)
    local_pos = skeleton.offsets[None] + _gather(channels, plan.pos_index)
    glob_q = np.empty_like(local_q)
    glob_pos = np.empty_like(local_pos)
    glob_q[:, 0] = local_q[:, 0]
    glob_pos[:, 0] = local_pos[:, 0]
    parents = skeleton.parents
    for level in plan.levels:
        par = parents[level]
        parent_q = glob_q[:, par]
        glob_q[:, level] = rotations.quat_multiply(parent_q, local_q[:, level])
        glob_pos[:, level] = glob_pos[:, par] + rotations.quat_rotate(parent_q, local_pos[:, level])
    return glob_pos, glob_q


def global_matrices(skeleton: Skeleton, channels: np.ndarray) -> np.ndarray:
    """Global joint orientations as rotation matrices ``(frames, joints, 3, 3)``."""
    return rotations.quat_to_matrix(forward_kinematics(skeleton, channels)[1])
