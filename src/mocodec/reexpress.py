"""The same motion in another pipeline's channel layout: every joint position unchanged.

Exporters differ in how they write one and the same motion: a dummy root above the hips
(rotated to another up axis), the translation on the root's child, another Euler order,
position channels on every joint, another unit, a bind pose in frame 0. Each function here
returns a :class:`Motion` whose forward kinematics places every joint where the input's does
(to rounding), in the layout such a pipeline writes. Codecs must not care (kinwave is tested
for it); users can convert files between conventions with them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mocodec import rotations
from mocodec.kinematics import forward_kinematics, local_quaternions
from mocodec.motion import Motion, continuous_triples
from mocodec.skeleton import POSITION_CHANNELS, Joint, Skeleton

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", "XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ")


def _rotation_channels(order: str) -> tuple[str, ...]:
    return tuple(f"{axis}rotation" for axis in order)


def _euler(q: np.ndarray, order: str) -> np.ndarray:
    """Continuous Euler angles (degrees, rotation-order steps) of quaternions ``(T, 4)``."""
    return continuous_triples(rotations.quat_to_euler(q, order), order)


def _write_rotation(channels: np.ndarray, joint: Joint, first: int, angles: np.ndarray) -> None:
    for step, c in enumerate(joint.rotation_channel_indices()):
        channels[:, first + c] = angles[:, step]


def with_dummy_root(
    motion: Motion,
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0),
    order: str = "ZXY",
    name: str = "dummy_root",
    position_channels: bool = False,
) -> Motion:
    """A new root joint at the origin with a constant rotation (intrinsic ``order``, degrees)
    above the old root, which keeps its offset, translation channels and rotation order: its
    channels are re-expressed in the dummy's frame. With ``position_channels`` the dummy also
    has three constant zero translation channels (MotionBuilder's export)."""
    sk = motion.skeleton
    root = sk.joints[0]
    if len(root.rotation_order) not in (0, 3) or root.has_axis:
        raise ValueError("the root must have three rotation channels or none, and no axis pre-rotation")
    turn = rotations.euler_to_quat(np.asarray(rotation, dtype=float), order)
    inverse = rotations.quat_conjugate(turn)
    pos, _ = forward_kinematics(sk, motion.channels)
    local = local_quaternions(sk, motion.channels)
    dummy_channels = (POSITION_CHANNELS if position_channels else ()) + _rotation_channels(order)
    dummy = Joint(name=name, parent=-1, offset=(0.0, 0.0, 0.0), channels=dummy_channels, rotation_order=order)
    joints = [dummy] + [replace(j, parent=j.parent + 1) for j in sk.joints]
    new_sk = Skeleton(tuple(joints), sk.units_per_metre, sk.name, dict(sk.metadata))
    out = np.zeros((motion.num_frames, new_sk.num_channels))
    width = len(dummy_channels)
    _write_rotation(out, dummy, 0, np.tile(np.asarray(rotation, dtype=float), (motion.num_frames, 1)))
    out[:, width:] = motion.channels
    # the old root: x = R (offset + t'), G = R L'
    old = new_sk.joints[1]
    first = width
    local_pos = rotations.quat_rotate(inverse, pos[:, 0]) - np.asarray(root.offset)
    for k, axis in enumerate("XYZ"):
        channel = f"{axis}position"
        if channel in old.channels:
            out[:, first + old.channels.index(channel)] = local_pos[:, k]
        elif np.ptp(local_pos[:, k]) > 1e-9 or abs(local_pos[0, k]) > 1e-9:
            raise ValueError(f"the root has no {channel} channel to hold its position under a rotated dummy root")
    if old.rotation_order:
        _write_rotation(out, old, first, _euler(rotations.quat_multiply(inverse, local[:, 0]), old.rotation_order))
    return Motion(new_sk, motion.fps, out)


def with_euler_orders(motion: Motion, order: str | dict[str, str]) -> Motion:
    """Every joint with three rotation channels (or those a ``{joint name: order}`` mapping
    names) written in another of the 12 Euler orders (proper ones included); same poses."""
    sk = motion.skeleton
    local = local_quaternions(sk, motion.channels)
    joints, columns = [], []
    for j, joint in enumerate(sk.joints):
        new = order.get(joint.name) if isinstance(order, dict) else order
        first = sk.channel_offsets[j]
        if len(joint.rotation_order) != 3 or new is None or joint.has_axis:
            joints.append(joint)
            columns.append(motion.channels[:, first : first + len(joint.channels)])
            continue
        if new not in EULER_ORDERS:
            raise ValueError(f"unknown Euler order {new!r}")
        positions = tuple(c for c in joint.channels if c in POSITION_CHANNELS)
        moved = replace(joint, channels=positions + _rotation_channels(new), rotation_order=new, limits=())
        block = np.empty((motion.num_frames, len(moved.channels)))
        for k, c in enumerate(positions):
            block[:, k] = motion.channels[:, first + joint.channels.index(c)]
        _write_rotation(block, moved, 0, _euler(local[:, j], new))
        joints.append(moved)
        columns.append(block)
    new_sk = Skeleton(tuple(joints), sk.units_per_metre, sk.name, dict(sk.metadata))
    return Motion(new_sk, motion.fps, np.hstack(columns) if columns else motion.channels.copy())


def with_position_channels(motion: Motion, keep_offsets: bool = False) -> Motion:
    """Every non-root joint with rotation channels gets three translation channels, constant
    and equal to its offset, and an offset of zero (position channels add to the offset here,
    so every joint stays where it was): 6 channels a joint, the bones in the channels. With
    ``keep_offsets`` the offsets stay and the channels hold 0: MotionBuilder's layout as the
    BVH reader gives it (its files repeat every offset in the position channels, and the
    reader takes the offsets off)."""
    sk = motion.skeleton
    joints, columns = [], []
    for j, joint in enumerate(sk.joints):
        first = sk.channel_offsets[j]
        block = motion.channels[:, first : first + len(joint.channels)]
        if j == 0 or not joint.rotation_order or any(c in POSITION_CHANNELS for c in joint.channels):
            joints.append(joint)
            columns.append(block)
            continue
        joints.append(
            replace(
                joint,
                offset=joint.offset if keep_offsets else (0.0, 0.0, 0.0),
                channels=POSITION_CHANNELS + joint.channels,
                limits=((-np.inf, np.inf),) * 3 + joint.limits,
            )
        )
        held = np.zeros(3) if keep_offsets else np.asarray(joint.offset, dtype=float)
        columns.append(np.hstack([np.tile(held, (motion.num_frames, 1)), block]))
    new_sk = Skeleton(tuple(joints), sk.units_per_metre, sk.name, dict(sk.metadata))
    return Motion(new_sk, motion.fps, np.hstack(columns))


def with_units(motion: Motion, factor: float) -> Motion:
    """The motion in a unit ``factor`` times smaller (``factor`` file units per old unit):
    offsets and translation channels scaled, ``units_per_metre`` with them."""
    if not factor > 0:
        raise ValueError(f"the unit factor must be positive, got {factor}")
    sk = motion.skeleton
    joints = tuple(replace(j, offset=tuple(float(v) * factor for v in j.offset)) for j in sk.joints)
    new_sk = Skeleton(joints, sk.units_per_metre * factor, sk.name, dict(sk.metadata))
    out = motion.channels.copy()
    out[:, ~sk.rotation_mask] *= factor
    return Motion(new_sk, motion.fps, out)


def with_bind_frame(motion: Motion) -> Motion:
    """A bind pose (every rotation zero, the first frame's translations) before frame 0, as
    exporters that start a take with the skeleton's rest pose write it."""
    sk = motion.skeleton
    bind = motion.channels[:1].copy()
    bind[:, sk.rotation_mask] = 0.0
    return Motion(sk, motion.fps, np.vstack([bind, motion.channels]))
