"""Perceptual importance of channels (001 §6.3.3) and bit allocation (6.1).

F_c = S_k P(j) E(c) l(j): the body-part score S_k of the joint's kinematic chain (legs 1, arms,
torso and head 0.5 by default: foot sliding is the most visible error), the depth factor
P(j) = (h - D(j) + 1) / (h + 1) of the joint in its chain (6.2), the channel energy
E = sum (c(f+1) - c(f))^2 / (W D) with D the largest squared step (6.3), and the bone length
normalised by the longest bone of its chain. The thesis's six chains are our body parts with
the hands counted as arms. The root's channels move the whole figure: they get the longest
bone (l = 1) and depth 0.

B_c = F_c B_T / sum F_i (6.1) splits a segment's bit budget B_T.

Beyond the thesis, ``impact`` scores a channel by how far its motion moves the figure: the
channel's standard deviation in the segment times its lever arm (the longest path from the
joint to a point below it, plus the 3 cm shell; cm for root translations), in millimetres,
on a log scale, log2(1 + moved / 1 mm). Bits buy error reduction exponentially, so shares that
grow with the logarithm of the amplitude (the reverse water-filling rule of rate-distortion
theory) beat shares proportional to the amplitude (measured against uniform allocation and the
thesis's rule in docs/codecs.md).
"""

from __future__ import annotations

import numpy as np

from mocodec.skeleton import Skeleton

DEFAULT_SCORES = {
    "left_leg": 1.0,
    "right_leg": 1.0,
    "torso": 0.5,
    "head": 0.5,
    "left_arm": 0.5,
    "right_arm": 0.5,
    "left_hand": 0.5,
    "right_hand": 0.5,
}
ALLOCATIONS = ("perceptual", "energy", "uniform", "impact")
SHELL_M = 0.03
IMPACT_UNIT_M = 0.001


def depth_factors(skeleton: Skeleton) -> np.ndarray:
    """P(j) (6.2) per joint; h is the deepest joint of the joint's chain."""
    parts = np.array(skeleton.body_parts)
    depth = skeleton.chain_depths.astype(np.float64)
    out = np.ones(len(skeleton))
    for part in set(parts):
        sel = parts == part
        h = depth[sel].max()
        out[sel] = (h - depth[sel] + 1) / (h + 1)
    out[0] = 1.0
    return out


def bone_factors(skeleton: Skeleton) -> np.ndarray:
    """Bone length over the longest bone of the joint's chain; 1 for the root."""
    parts = np.array(skeleton.body_parts)
    bones = skeleton.bone_lengths
    out = np.zeros(len(skeleton))
    for part in set(parts):
        sel = parts == part
        longest = bones[sel].max()
        out[sel] = bones[sel] / longest if longest > 0 else 1.0
    out[0] = 1.0
    return out


def lever_arms(skeleton: Skeleton) -> np.ndarray:
    """Per joint, the longest rest-pose path (metres) from it to any pivot below it, plus the
    3 cm shell: how far a unit rotation of the joint can move a point of the figure."""
    pos = skeleton.rest_positions / skeleton.units_per_metre
    reach = np.zeros(len(skeleton))
    for j in range(len(skeleton) - 1, 0, -1):
        p = skeleton.parents[j]
        reach[p] = max(reach[p], reach[j] + np.linalg.norm(pos[j] - pos[p]))
    return reach + SHELL_M


def channel_energy(segment: np.ndarray) -> np.ndarray:
    """E (6.3) of every column of a ``(frames, channels)`` segment; 0 for a constant one."""
    if len(segment) < 2:
        return np.zeros(segment.shape[1])
    steps = np.square(np.diff(segment, axis=0))
    peak = steps.max(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(peak > 0, steps.sum(axis=0) / (len(segment) * peak), 0.0)


def static_factors(skeleton: Skeleton, scores: dict[str, float] | None = None) -> np.ndarray:
    """S_k P(j) l(j) per channel: the part of F that does not depend on the motion."""
    scores = {**DEFAULT_SCORES, **(scores or {})}
    per_joint = (
        np.array([scores.get(p, 0.5) for p in skeleton.body_parts]) * depth_factors(skeleton) * bone_factors(skeleton)
    )
    return per_joint[skeleton.channel_joints]


def channel_importance(
    skeleton: Skeleton, segment: np.ndarray, mode: str = "perceptual", scores: dict[str, float] | None = None
) -> np.ndarray:
    """F_c for one segment: ``perceptual`` (all four factors), ``energy`` (E only),
    ``uniform`` (1 for every channel) or ``impact`` (ours, see the module doc)."""
    if mode == "uniform":
        return np.ones(segment.shape[1])
    if mode == "impact":
        metres = np.where(
            skeleton.rotation_mask,
            np.deg2rad(1.0) * lever_arms(skeleton)[skeleton.channel_joints],
            1.0 / skeleton.units_per_metre,
        )
        return np.log2(1.0 + segment.std(axis=0) * metres / IMPACT_UNIT_M)
    energy = channel_energy(segment)
    if mode == "energy":
        return energy
    if mode != "perceptual":
        raise ValueError(f"allocation must be one of {', '.join(ALLOCATIONS)}, got {mode!r}")
    return static_factors(skeleton, scores) * energy


def allocate(importance: np.ndarray, total: int) -> np.ndarray:
    """B_c = floor(F_c B_T / sum F) (6.1); all zero when every F is zero."""
    importance = np.asarray(importance, dtype=np.float64)
    s = importance.sum()
    if s <= 0 or total <= 0:
        return np.zeros(importance.size, dtype=np.int64)
    return np.floor(importance * total / s).astype(np.int64)
