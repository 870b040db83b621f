"""The groups the model-based coders of 000 ch. 8 work on, and the joint-position vector of a
group's posture (8.4.1).

The groups are the body parts of Table 5-1 (:mod:`mocodec.bodyparts`), with one change: the
root joint's channels (its translation and global rotation) form a group of their own. A
posture table of the "root and torso" group would have to hold every heading and every place
on the floor; the model-based codecs send the root as quantised samples instead (the thesis's
own hybrid argument, 8.5: errors of the root propagate through the whole figure).

A group's posture vector is the position of every joint its angles move (the children of its
joints, end sites included), relative to the joint the group hangs from and in that joint's
frame, in metres: it does not depend on the rest of the body, and two postures that look alike
are close even when their Euler angles are not.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mocodec import rotations
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.groups import group_channels
from mocodec.skeleton import Skeleton


@dataclass(frozen=True, eq=False)
class Group:
    name: str
    channels: np.ndarray  # channel columns of the group's angles
    base: int  # the joint the group hangs from
    points: np.ndarray  # joints whose positions the group's angles set


@dataclass(frozen=True, eq=False)
class Groups:
    root: np.ndarray  # the root joint's channel columns
    parts: tuple[Group, ...]

    def channel_names(self, skeleton: Skeleton) -> list[list[str]]:
        return [[skeleton.channel_names[c] for c in g.channels] for g in self.parts]


@lru_cache(maxsize=32)
def model_groups(skeleton: Skeleton) -> Groups:
    joints = skeleton.channel_joints
    root = np.flatnonzero(joints == 0)
    parts = []
    for name, cols in group_channels(skeleton).items():
        cols = cols[joints[cols] != 0]
        if not cols.size:
            continue
        owners = np.unique(joints[cols])
        base = int(skeleton.parents[owners.min()])
        points = np.array(
            [j for j in range(len(skeleton)) if skeleton.parents[j] in set(owners.tolist())], dtype=np.int64
        )
        parts.append(Group(name, cols, base, points))
    return Groups(root, tuple(parts))


def posture_vectors(skeleton: Skeleton, channels: np.ndarray, groups: Groups) -> list[np.ndarray]:
    """Per group the posture vectors ``(frames, 3 x points)`` (metres) of ``channels``."""
    pos, quat = forward_kinematics(skeleton, channels)
    out = []
    for g in groups.parts:
        rel = pos[:, g.points] - pos[:, g.base : g.base + 1]
        rel = rotations.quat_rotate(rotations.quat_conjugate(quat[:, g.base : g.base + 1]), rel)
        out.append(rel.reshape(len(channels), -1) / skeleton.units_per_metre)
    return out


def entry_vectors(skeleton: Skeleton, group: Group, angles: np.ndarray, groups: Groups) -> np.ndarray:
    """The posture vectors of a group's table entries ``angles (M, K)`` on ``skeleton``."""
    channels = np.zeros((len(angles), skeleton.num_channels))
    channels[:, group.channels] = angles
    return posture_vectors(skeleton, channels, Groups(groups.root, (group,)))[0]
