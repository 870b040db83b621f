"""Forward kinematics: global joint positions and orientations for all frames at once.

For joint ``i`` with parent ``p``, local rotation ``M_i`` (its Euler channels in
``rotation_order``), fixed pre-rotation ``C_i`` (the ASF ``axis``) and translation channels
``t_i``::

    G_i = G_p  C_i M_i C_i^-1
    x_i = x_p + G_p (offset_i + t_i)

This is the BVH rule (``C = I``) and the CMU ASF/AMC rule (offsets are bone ``direction *
length`` in the rest frame, ``C`` the bone ``axis``). Translation channels add to the offset.
Rotations are composed as quaternions held component by component, frames along the
contiguous axis, and every joint of one tree depth is done in one numpy step, so the cost is a
few hundred vector operations whatever the clip length.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mocodec import rotations
from mocodec.rotations import quat_multiply_components as qmul
from mocodec.rotations import quat_rotate_components as qrotate
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


def _by_channel(channels: np.ndarray) -> np.ndarray:
    """Channels as ``(channels + 1, frames)`` rows; the extra zero row is what index -1 reads."""
    return np.vstack((channels.T, np.zeros((1, len(channels)))))


def _local_components(skeleton: Skeleton, by_channel: np.ndarray) -> tuple:
    """Local rotations ``C M C^-1`` as four ``(joints, frames)`` component arrays.

    Frames run along the last, contiguous axis so every step is a plain vector operation and a
    tree level gathers whole rows.
    """
    plan = _plan(skeleton)
    half = np.deg2rad(by_channel[plan.rot_index]) * 0.5  # (J, 3, F)
    cos, sin = np.cos(half), np.sin(half)
    axis = plan.rot_axis[..., None]  # (J, 3, 3, 1)
    q = None
    for step in range(3):
        e = (cos[:, step], sin[:, step] * axis[:, step, 0], sin[:, step] * axis[:, step, 1],
             sin[:, step] * axis[:, step, 2])
        q = e if q is None else qmul(q, e)
    if plan.has_axis.any():
        rows = plan.has_axis
        c = tuple(plan.axis_quat[rows, k][:, None] for k in range(4))
        c_inv = (c[0], -c[1], -c[2], -c[3])
        rotated = qmul(qmul(c, tuple(comp[rows] for comp in q)), c_inv)
        for comp, new in zip(q, rotated):
            comp[rows] = new
    return q


def local_quaternions(skeleton: Skeleton, channels: np.ndarray) -> np.ndarray:
    """Each joint's rotation relative to its parent, ``(frames, joints, 4)``: ``C M C^-1``."""
    by_channel = _by_channel(np.asarray(channels, dtype=np.float64))
    return np.stack(_local_components(skeleton, by_channel), axis=-1).transpose(1, 0, 2)


def forward_kinematics(skeleton: Skeleton, channels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global pivot positions ``(frames, joints, 3)`` (skeleton units) and global orientations
    as unit quaternions ``(frames, joints, 4)`` for a ``(frames, channels)`` array."""
    channels = np.asarray(channels, dtype=np.float64)
    if channels.ndim != 2 or channels.shape[1] != skeleton.num_channels:
        raise ValueError(f"expected (frames, {skeleton.num_channels}) channels, got {channels.shape}")
    plan = _plan(skeleton)
    by_channel = _by_channel(channels)
    local_q = _local_components(skeleton, by_channel)
    local_pos = skeleton.offsets[:, :, None] + by_channel[plan.pos_index]  # (J, 3, F)
    glob_q = tuple(comp.copy() for comp in local_q)
    glob_pos = tuple(local_pos[:, k].copy() for k in range(3))
    parents = skeleton.parents
    for level in plan.levels:
        par = parents[level]
        parent_q = tuple(comp[par] for comp in glob_q)
        for comp, new in zip(glob_q, qmul(parent_q, tuple(comp[level] for comp in local_q))):
            comp[level] = new
        moved = qrotate(parent_q, tuple(local_pos[level, k] for k in range(3)))
        for comp, new in zip(glob_pos, moved):
            comp[level] = comp[par] + new
    positions = np.ascontiguousarray(np.stack(glob_pos, axis=-1).transpose(1, 0, 2))
    quats = np.ascontiguousarray(np.stack(glob_q, axis=-1).transpose(1, 0, 2))
    return positions, quats


def global_matrices(skeleton: Skeleton, channels: np.ndarray) -> np.ndarray:
    """Global joint orientations as rotation matrices ``(frames, joints, 3, 3)``."""
    return rotations.quat_to_matrix(forward_kinematics(skeleton, channels)[1])
