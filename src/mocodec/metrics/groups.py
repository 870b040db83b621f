"""Group measures (000 §6.1.3-6.1.4): the normalised weighted vector error (6-9), its maximum
form (6-10), their sequence forms (6-11), the joint position error (6-12) and the
configuration-vector error (6-14).

Groups are the body parts of the skeleton (for the built-in model exactly the 8 groups of
Table 6-1; for any other skeleton the labels of :mod:`mocodec.bodyparts`). Weights ``a``
default to 1; ranges ``b`` default to the joint limits, or to the original's range where a
DOF has no limits, or to 1 where it is constant too. Weights and ranges may be given as one
number, an array over channels (or joints), or a ``{name: value}`` mapping overriding the
defaults.

Two equations are lost in the OCR. (6-12) is read as the analogue of (6-9) for positions,
p_i(n) = 1/K sum_j a_ij |u_ij(n) - u'_ij(n)|^2 / b_ij^2, with positions in metres and b = 1 m
by default (so p has units of m^2). (6-14) is (6-9) over the configuration vector c of
(6-13): the group's DOFs followed by the positions of its joints relative to the group's first
joint, expressed in the frame of that joint's parent ("the shoulder fixed at the world origin"),
so errors further up the body do not leak into the group.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec import rotations
from mocodec.metrics.waveform import value_range
from mocodec.skeleton import BODY_PARTS, Skeleton


def group_joints(skeleton: Skeleton) -> dict[str, np.ndarray]:
    """Joint indices of every non-empty body part, in Table 5-1 order."""
    parts = np.array(skeleton.body_parts)
    return {p: np.flatnonzero(parts == p) for p in BODY_PARTS if (parts == p).any()}


def group_channels(skeleton: Skeleton) -> dict[str, np.ndarray]:
    """Channel indices of every body part that has channels, in Table 5-1 order."""
    parts = np.array(skeleton.body_parts)[skeleton.channel_joints]
    return {p: np.flatnonzero(parts == p) for p in BODY_PARTS if (parts == p).any()}


def per_item(values, names: tuple[str, ...], default: np.ndarray, what: str) -> np.ndarray:
    """``values`` (None, a number, an array or a ``{name: value}`` mapping) as one float per name."""
    out = np.array(default, dtype=np.float64, copy=True)
    if values is None:
        return out
    if isinstance(values, dict):
        index = {n: i for i, n in enumerate(names)}
        for name, v in values.items():
            if name not in index:
                raise KeyError(f"no {what} named {name!r}")
            out[index[name]] = v
        return out
    arr = (
        np.broadcast_to(np.asarray(values, dtype=np.float64), out.shape)
        if np.ndim(values) == 0
        else np.asarray(values, dtype=np.float64)
    )
    if arr.shape != out.shape:
        raise ValueError(f"expected {out.shape[0]} {what} values, got {arr.shape}")
    return arr.copy()


def default_ranges(skeleton: Skeleton, original: np.ndarray) -> np.ndarray:
    """b per channel: the joint-limit width, else the original's range, else 1."""
    lim = skeleton.limits
    width = lim[:, 1] - lim[:, 0] if len(lim) else np.zeros(0)
    b = np.where(np.isfinite(width) & (width > 0), width, value_range(original))
    return np.where(b > 0, b, 1.0)


@dataclass(frozen=True)
class GroupSeries:
    """A per-sample group measure ``values (frames, groups)`` with its sequence summaries."""

    groups: tuple[str, ...]
    values: np.ndarray

    @property
    def mean(self) -> np.ndarray:
        """(6-11): the mean over the sequence, per group."""
        return self.values.mean(axis=0)

    @property
    def max(self) -> np.ndarray:
        return self.values.max(axis=0)

    def as_dict(self) -> dict[str, dict[str, float]]:
        return {g: {"mean": float(m), "max": float(x)} for g, m, x in zip(self.groups, self.mean, self.max)}


def _per_group(values: np.ndarray, groups: dict[str, np.ndarray], reduce) -> np.ndarray:
    """``(frames, groups)``: ``reduce`` over each group's columns of ``values`` (no columns
    for a rig without channels, which has no groups)."""
    if not groups:
        return np.zeros((values.shape[0], 0))
    return np.stack([reduce(values[:, idx], axis=1) for idx in groups.values()], axis=1)


def _weighted_mean_square(err: np.ndarray, a: np.ndarray, b: np.ndarray, groups: dict[str, np.ndarray]) -> np.ndarray:
    return _per_group(a * np.square(err / b), groups, np.mean)


def vector_error(skeleton: Skeleton, original: np.ndarray, error: np.ndarray, weights=None, ranges=None) -> GroupSeries:
    """w_i(n) (6-9) per group, from the channel error ``(frames, channels)``."""
    groups = group_channels(skeleton)
    names = skeleton.channel_names
    a = per_item(weights, names, np.ones(len(names)), "channel")
    b = per_item(ranges, names, default_ranges(skeleton, original), "channel")
    return GroupSeries(tuple(groups), _weighted_mean_square(error, a, b, groups))


def max_vector_error(
    skeleton: Skeleton, original: np.ndarray, error: np.ndarray, weights=None, ranges=None
) -> GroupSeries:
    """m_i(n) (6-10) per group: max_j a_ij |error_ij(n)| / b_ij."""
    groups = group_channels(skeleton)
    names = skeleton.channel_names
    a = per_item(weights, names, np.ones(len(names)), "channel")
    b = per_item(ranges, names, default_ranges(skeleton, original), "channel")
    return GroupSeries(tuple(groups), _per_group(a * np.abs(error) / b, groups, np.max))


def joint_position_error(
    skeleton: Skeleton, positions_m: np.ndarray, decoded_positions_m: np.ndarray, weights=None, ranges=None
) -> GroupSeries:
    """p_i(n) (6-12) per group from global positions in metres ``(frames, joints, 3)``."""
    groups = group_joints(skeleton)
    a = per_item(weights, skeleton.names, np.ones(len(skeleton)), "joint")
    b = per_item(ranges, skeleton.names, np.ones(len(skeleton)), "joint")
    sq = np.square(decoded_positions_m - positions_m).sum(axis=2)
    return GroupSeries(tuple(groups), _weighted_mean_square(np.sqrt(sq), a, b, groups))


def relative_positions(skeleton: Skeleton, positions: np.ndarray, quats: np.ndarray) -> dict[str, np.ndarray]:
    """Per group, the positions of its joints other than the first relative to the first,
    in the frame of the first joint's parent: ``(frames, joints - 1, 3)``."""
    out = {}
    for part, idx in group_joints(skeleton).items():
        base = idx[0]
        rel = positions[:, idx[1:]] - positions[:, base : base + 1]
        parent = skeleton.parents[base]
        if parent >= 0:
            inv = rotations.quat_conjugate(quats[:, parent : parent + 1])
            rel = rotations.quat_rotate(inv, rel)
        out[part] = rel
    return out


def configuration_error(
    skeleton: Skeleton,
    original: np.ndarray,
    error: np.ndarray,
    rel_original_m: dict[str, np.ndarray],
    rel_decoded_m: dict[str, np.ndarray],
    weights=None,
    ranges=None,
) -> GroupSeries:
    """c_i(n) (6-14) per group. The DOF part uses the channel ``weights`` and ``ranges`` of
    (6-9); each relative position component has a = 1 and b = the group's reach (the largest
    rest-pose distance of its joints from its first joint, metres; 1 m for a one-joint group)."""
    chans = group_channels(skeleton)
    names = skeleton.channel_names
    a = per_item(weights, names, np.ones(len(names)), "channel")
    b = per_item(ranges, names, default_ranges(skeleton, original), "channel")
    dof = a * np.square(error / b)
    columns = []
    rest_m = skeleton.rest_positions / skeleton.units_per_metre
    for part, joints in group_joints(skeleton).items():
        rel = rel_original_m[part]
        reach = np.linalg.norm(rest_m[joints] - rest_m[joints[0]], axis=1).max()
        pos = np.square((rel_decoded_m[part] - rel) / (reach if reach > 0 else 1.0)).reshape(len(rel), -1)
        idx = chans.get(part, np.zeros(0, dtype=int))
        total = dof[:, idx].sum(axis=1) + pos.sum(axis=1)
        columns.append(total / max(len(idx) + pos.shape[1], 1))
    return GroupSeries(tuple(group_joints(skeleton)), np.stack(columns, axis=1))
