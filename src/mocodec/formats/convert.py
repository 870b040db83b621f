"""Re-express a motion so a given file format can hold it, keeping every pose exactly.

* :func:`to_bvh_form`: BVH applies rotations in channel order and has no bone ``axis``. A joint
  BVH can hold keeps its channels in their order; joints
  whose rotation order differs from their channel order get their channels reordered; joints
  with an ASF axis ``C`` or a repeated axis (``YZY``) get three rotation channels (``ZYX``)
  holding ``C M C^-1``, with angles unwrapped over time. Limits of re-expressed joints are dropped (their axes changed).
  A joint with one or two rotation channels gets the other axes, at zero, after them.
* :func:`to_asf_form`: ASF bones start at their parent's end and only rotate. Rotation orders
  that the standard ``dof rx ry rz`` (order ``ZYX``) or a subset of it can express are kept;
  others are converted to ``ZYX``. A joint whose children start at different points (a BVH
  pelvis, chest or head) gets one dof-less link bone per child, which moves with it. A root
  without channels gets three that hold zero (an ASF root states its dofs).
  Translation channels below the root cannot be expressed: ConversionError.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mocodec import kinematics, rotations
from mocodec.errors import ConversionError
from mocodec.motion import Motion
from mocodec.skeleton import POSITION_CHANNELS, Joint, Skeleton

_ASF_ORDER = "ZYX"


def _rotation_channels(joint: Joint) -> list[str]:
    return [c for c in joint.channels if c.endswith("rotation")]


def _unwrap(angles: np.ndarray) -> np.ndarray:
    return np.unwrap(angles, period=360.0, axis=0) if len(angles) > 1 else angles


def _is_subsequence(order: str, of: str) -> bool:
    it = iter(of)
    return all(c in it for c in order)


class _Builder:
    """Collects new joints and the columns of their channels."""

    def __init__(self, motion: Motion):
        self.motion = motion
        self.joints: list[Joint] = []
        self.columns: list[np.ndarray] = []
        self.index: dict[int, int] = {}

    def old_columns(self, i: int, channels) -> np.ndarray:
        sk = self.motion.skeleton
        first = sk.channel_offsets[i]
        j = sk.joints[i]
        idx = [first + j.channels.index(c) for c in channels]
        return self.motion.channels[:, idx]

    def add(self, joint: Joint, values: np.ndarray) -> int:
        self.joints.append(joint)
        self.columns.append(values.reshape(len(self.motion.channels), len(joint.channels)))
        return len(self.joints) - 1

    def motion_out(self) -> Motion:
        sk = self.motion.skeleton
        skeleton = Skeleton(tuple(self.joints), sk.units_per_metre, sk.name, dict(sk.metadata))
        values = np.concatenate(self.columns, axis=1) if self.columns else np.zeros((len(self.motion.channels), 0))
        return Motion(skeleton, self.motion.fps, values)


def _limits_for(joint: Joint, channels) -> tuple:
    return tuple(joint.limits[joint.channels.index(c)] for c in channels)


def to_bvh_form(motion: Motion) -> Motion:
    """The same poses with BVH-expressible joints (no axis, rotations in channel order)."""
    sk = motion.skeleton
    local_q = None
    b = _Builder(motion)
    for i, j in enumerate(sk.joints):
        positions = [c for c in j.channels if c in POSITION_CHANNELS]
        parent = b.index[j.parent] if i else -1
        proper_euler = len(set(j.rotation_order)) < len(j.rotation_order)
        rotation_axes = "".join(c[0] for c in _rotation_channels(j))
        if (j.has_axis or proper_euler) and j.rotation_order:
            if local_q is None:
                local_q = kinematics.local_quaternions(sk, motion.channels)
            euler = _unwrap(rotations.quat_to_euler(local_q[:, i], _ASF_ORDER))
            channels = tuple(positions) + tuple(f"{a}rotation" for a in _ASF_ORDER)
            values = np.concatenate((b.old_columns(i, positions), euler), axis=1)
            new = Joint(j.name, parent, j.offset, channels, _ASF_ORDER, body_part=j.body_part)
        elif not j.has_axis and rotation_axes == j.rotation_order and len(rotation_axes) in (0, 3):
            # BVH's already: its channels keep their order (a root's rotations before its positions too)
            values = b.old_columns(i, j.channels)
            new = Joint(j.name, parent, j.offset, j.channels, j.rotation_order, limits=j.limits, body_part=j.body_part)
        else:
            kept = tuple(positions) + tuple(f"{a}rotation" for a in j.rotation_order)
            # one or two rotation channels get the others at zero (the identity, wherever it
            # stands in the order): Blender's importer reads only joints with three or none
            order = j.rotation_order + "".join(a for a in "XYZ" if j.rotation_order and a not in j.rotation_order)
            channels = tuple(positions) + tuple(f"{a}rotation" for a in order)
            values = np.concatenate(
                (b.old_columns(i, kept), np.zeros((len(motion.channels), len(channels) - len(kept)))), axis=1
            )
            limits = _limits_for(j, kept) + ((-np.inf, np.inf),) * (len(channels) - len(kept))
            new = Joint(j.name, parent, j.offset, channels, order, limits=limits, body_part=j.body_part)
        b.index[i] = b.add(new, values)
    return b.motion_out()


def to_asf_form(motion: Motion) -> Motion:
    """The same poses with ASF-expressible bones (see the module docstring)."""
    sk = motion.skeleton
    if len(sk) == 1:
        raise ConversionError(f"joint {sk.names[0]!r} alone: an ASF skeleton needs a bone below its root")
    b = _Builder(motion)
    names = set(sk.names)
    for i, j in enumerate(sk.joints):
        if i and any(c in POSITION_CHANNELS for c in j.channels):
            raise ConversionError(f"joint {j.name!r} has translation channels; ASF bones can only rotate")
        parent = b.index[j.parent] if i else -1
        offset = j.offset
        if i and _needs_link(sk, j.parent):
            if np.abs(j.offset).max() > 0:
                link = f"{sk.names[j.parent]}_{j.name}_link"
                while link in names:
                    link += "_"
                names.add(link)
                parent = b.add(Joint(link, parent, (0.0, 0.0, 0.0)), np.zeros((len(motion.channels), 0)))
        positions = [c for c in j.channels if c in POSITION_CHANNELS]
        order = j.rotation_order
        if i == 0 and not j.channels:  # an ASF root states at least one dof: still rotations
            order = _ASF_ORDER
            rot = [f"{a}rotation" for a in reversed(order)]
            values = np.zeros((len(motion.channels), len(rot)))
            limits = tuple((-np.inf, np.inf) for _ in rot)
        elif _is_subsequence(order, _ASF_ORDER):
            rot = [f"{a}rotation" for a in reversed(order)]
            values = b.old_columns(i, positions + rot)
            limits = _limits_for(j, positions + rot)
        else:
            first = sk.channel_offsets[i]
            q = rotations.euler_to_quat(motion.channels[:, first + np.array(j.rotation_channel_indices())], order)
            euler = _unwrap(rotations.quat_to_euler(q, _ASF_ORDER))[:, ::-1]
            order = _ASF_ORDER
            rot = [f"{a}rotation" for a in reversed(order)]
            values = np.concatenate((b.old_columns(i, positions), euler), axis=1)
            limits = _limits_for(j, positions) + tuple((-np.inf, np.inf) for _ in rot)
        new = Joint(j.name, parent, offset, tuple(positions + rot), order, j.axis, j.axis_order, limits, j.body_part)
        b.index[i] = b.add(new, values)
    return b.motion_out()


def _needs_link(sk: Skeleton, joint: int) -> bool:
    """Whether the children of ``joint`` cannot share one ASF bone vector."""
    kids = list(sk.children[joint])
    offs = sk.offsets[kids]
    if joint == 0:
        return bool(np.abs(offs).max() > 0)
    return bool(np.abs(offs - offs[0]).max() > 0)


def with_units(motion: Motion, units_per_metre: float) -> Motion:
    """The same motion measured in another unit: offsets, translations and their limits scale."""
    sk = motion.skeleton
    scale = units_per_metre / sk.units_per_metre
    joints = []
    for j in sk.joints:
        limits = tuple(
            (lo * scale, hi * scale) if c in POSITION_CHANNELS else (lo, hi)
            for c, (lo, hi) in zip(j.channels, j.limits)
        )
        joints.append(replace(j, offset=tuple(v * scale for v in j.offset), limits=limits))
    channels = motion.channels.copy()
    channels[:, ~sk.rotation_mask] *= scale
    skeleton = Skeleton(tuple(joints), units_per_metre, sk.name, dict(sk.metadata))
    return Motion(skeleton, motion.fps, channels)
