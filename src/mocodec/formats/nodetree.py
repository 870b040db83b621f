"""Motions to and from trees of node transforms: what glTF and FBX animations hold.

A reader gives each node's *world* transform at every frame (position, and rotation with any
scale taken out) and which nodes are joints; :func:`to_motion` turns them into the skeleton's
rule (:mod:`mocodec.kinematics`: ``x_i = x_p + G_p (offset_i + t_i)``, ``G_i = G_p C M C^-1``)
with ``offset_i + t_i = G_p^T (x_i - x_p)`` and ``C M C^-1 = G_p^T G_i``. Joint positions come
out exactly whatever the file's scales and scale-inheritance rules were: a scale only changes
where the nodes are, and that is what the world positions hold.

Each joint takes only the channels its node needs: translation channels where its offset from
the parent moves, Euler rotation channels where its rotation is not always the identity. A
node that carries the layout a :class:`~mocodec.skeleton.Joint` had when it was written (the
``mocodec`` extras of a glTF mocodec wrote) gets that layout back: channels, rotation order,
ASF axis and exact offset.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocodec import kinematics, rotations
from mocodec.errors import ConversionError
from mocodec.motion import Motion
from mocodec.skeleton import CHANNEL_NAMES, POSITION_CHANNELS, Joint, Skeleton

#: The Euler order of rotation channels made for a node that states none (glTF and FBX keep
#: quaternions or their own orders): ``ZYX``, the order ASF files can hold as they are.
DEFAULT_ORDER = "ZYX"
#: A translation that moves less than this (metres) over the clip is a constant offset.
STILL_M = 1e-8
#: A rotation within this angle (radians) of the identity on every frame is no rotation.
STILL_RAD = 1e-9
#: The farthest a node may be from the origin (metres; the diameter of the Earth's orbit),
#: so that no composed transform overflows.
MAX_COORDINATE_M = 3e11


@dataclass
class NodeSamples:
    """World transforms of ``n`` joint nodes at ``F`` frames, parents first (``parents[0]`` is
    -1): ``position`` ``(F, n, 3)`` in metres, ``rotation`` ``(F, n, 4)`` unit quaternions
    ``(w, x, y, z)``; ``layouts`` an optional joint layout per node."""

    names: list[str]
    parents: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    layouts: list[dict | None] = field(default_factory=list)


def to_motion(samples: NodeSamples, fps: float, units_per_metre: float, name: str = "") -> Motion:
    """The motion of the joint nodes: node 0 is the root joint."""
    n = len(samples.names)
    layouts = samples.layouts or [None] * n
    joints: list[Joint] = []
    columns: list[np.ndarray] = []
    if not (np.isfinite(samples.position).all() and np.abs(samples.position).max(initial=0.0) <= MAX_COORDINATE_M):
        raise ConversionError(f"a node lies beyond {MAX_COORDINATE_M:g} m of the origin")
    for i in range(n):
        parent = int(samples.parents[i])
        if parent < 0:
            translation, rotation = samples.position[:, i], samples.rotation[:, i]
        else:
            inverse = rotations.quat_conjugate(samples.rotation[:, parent])
            translation = rotations.quat_rotate(inverse, samples.position[:, i] - samples.position[:, parent])
            rotation = rotations.quat_multiply(inverse, samples.rotation[:, i])
        translation = translation * units_per_metre
        rotation = rotations.quat_normalize(rotation)
        joint, values = _layout_joint(samples.names[i], parent, translation, rotation, layouts[i], units_per_metre)
        if joint is None:
            joint, values = _plain_joint(samples.names[i], parent, translation, rotation, units_per_metre)
        joints.append(joint)
        columns.append(values)
    skeleton = Skeleton(tuple(joints), units_per_metre, name)
    frames = samples.position.shape[0]
    values = np.concatenate(columns, axis=1) if columns else np.zeros((frames, 0))
    if not np.isfinite(values).all():
        raise ConversionError("the node transforms give channel values that are not finite")
    return Motion(skeleton, fps, values)


def closure(parents: np.ndarray, wanted: set[int]) -> list[int] | None:
    """The nodes ``wanted`` with every node between them and their lowest common ancestor,
    parents first (in node order when that is parents first, else depth first); None when
    they have no common ancestor."""
    chains = []
    for node in sorted(wanted):
        chain = [node]
        while parents[chain[-1]] >= 0:
            chain.append(int(parents[chain[-1]]))
        chains.append(chain[::-1])
    common = 0
    while all(len(c) > common and c[common] == chains[0][common] for c in chains):
        common += 1
    if common == 0:
        return None
    keep = {n for c in chains for n in c[common - 1 :]}
    top = chains[0][common - 1]
    by_index = sorted(keep)
    if by_index[0] == top and all(parents[n] in keep and parents[n] < n for n in by_index[1:]):
        return by_index
    children: dict[int, list[int]] = {}
    for n in by_index[1:]:
        children.setdefault(int(parents[n]), []).append(n)
    order: list[int] = []
    stack = [top]
    while stack:
        node = stack.pop()
        order.append(node)
        stack.extend(reversed(children.get(node, [])))
    return order


def world_transforms(
    parents: np.ndarray, translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World positions ``(F, n, 3)`` and rotations ``(F, n, 4)`` of nodes given parents first
    with local translations, rotations ``(w, x, y, z)`` and scales: ``M = M_p T R S``. With
    uniform scales (the usual case) composed as quaternions and scale factors; otherwise as
    matrices, the rotation then the nearest one to ``M``'s 3x3 part (its polar factor)."""
    with np.errstate(all="ignore"):
        if np.all(np.abs(scale - scale[..., :1]) <= 1e-12 * np.abs(scale[..., :1])):
            position, turn = _compose_uniform(parents, translation, rotation, scale[..., 0])
        else:
            position, turn = _compose_matrices(parents, translation, rotation, scale)
    if (
        not (np.isfinite(position).all() and np.isfinite(turn).all())
        or np.abs(position).max(initial=0.0) > MAX_COORDINATE_M
    ):
        raise ConversionError(f"node transforms compose to a position beyond {MAX_COORDINATE_M:g} m")
    return position, turn


def _compose_uniform(parents, translation, rotation, scale) -> tuple[np.ndarray, np.ndarray]:
    """``x = x_p + s_p R_p T``, ``R = R_p R``, ``s = s_p s`` node by node."""
    position, turn, size = np.empty_like(translation), np.empty_like(rotation), np.empty_like(scale)
    for i in range(len(parents)):
        p = parents[i]
        if p < 0:
            position[:, i], turn[:, i], size[:, i] = translation[:, i], rotation[:, i], scale[:, i]
            continue
        moved = rotations.quat_rotate(turn[:, p], translation[:, i]) * size[:, p, None]
        position[:, i] = position[:, p] + moved
        turn[:, i] = rotations.quat_multiply(turn[:, p], rotation[:, i])
        size[:, i] = size[:, p] * scale[:, i]
    return position, turn


def _compose_matrices(parents, translation, rotation, scale) -> tuple[np.ndarray, np.ndarray]:
    """The same with 4x4 matrices, for non-uniform scales."""
    frames, n = translation.shape[:2]
    local = np.zeros((frames, n, 4, 4))
    local[..., :3, :3] = rotations.quat_to_matrix(rotation) * scale[..., None, :]
    local[..., :3, 3] = translation
    local[..., 3, 3] = 1.0
    world = np.empty_like(local)
    for i in range(n):
        world[:, i] = local[:, i] if parents[i] < 0 else world[:, parents[i]] @ local[:, i]
    if not np.isfinite(world).all():
        raise ConversionError(f"node transforms compose to a position beyond {MAX_COORDINATE_M:g} m")
    u, _, vt = np.linalg.svd(world[..., :3, :3])
    polar = u @ vt
    if (np.linalg.det(polar) < 0).any():
        raise ConversionError("a node's scale mirrors it (a negative scale), which a joint rotation cannot hold")
    return world[..., :3, 3], rotations.matrix_to_quat(polar)


def ancestors(parents: np.ndarray, node: int) -> list[int]:
    """The ancestors of ``node``, from the scene's root down to its parent."""
    chain: list[int] = []
    node = int(parents[node])
    while node >= 0:
        chain.append(node)
        node = int(parents[node])
    return chain[::-1]


def joint_parents(parents: np.ndarray, keep: list[int]) -> np.ndarray:
    """The parent of each node of ``keep`` as an index into ``keep`` (-1 for the top)."""
    index = {node: k for k, node in enumerate(keep)}
    return np.array([index.get(int(parents[node]), -1) if k else -1 for k, node in enumerate(keep)], dtype=np.int64)


def unique_names(names: list[str], nodes: list[int]) -> list[str]:
    """``names`` with a repeated one made unique by its node's index (joint names are unique)."""
    out: list[str] = []
    for name, node in zip(names, nodes):
        name = name or f"node{node}"
        out.append(name if name not in out else f"{name}_{node}")
    return out


def _euler(rotation: np.ndarray, order: str) -> np.ndarray:
    """Euler angles (degrees) of ``rotation`` in ``order``, unwrapped over time."""
    angles = rotations.quat_to_exact_euler(rotation, order)
    return np.unwrap(angles, period=360.0, axis=0) if len(angles) > 1 else angles


def _plain_joint(
    name: str, parent: int, translation: np.ndarray, rotation: np.ndarray, unit: float
) -> tuple[Joint, np.ndarray]:
    """A joint with the channels its node needs (see the module docstring): a moving root
    translates from the origin, any other moving joint from where it starts."""
    moves = np.abs(translation - translation[0]).max() > STILL_M * unit
    offset = np.zeros(3) if moves and parent < 0 else translation[0]
    channels: list[str] = list(POSITION_CHANNELS) if moves else []
    values = [translation - offset] if moves else []
    angle = 2.0 * np.arccos(np.clip(np.abs(rotation[:, 0]), 0.0, 1.0))
    order = ""
    if angle.max() > STILL_RAD:
        order = DEFAULT_ORDER
        channels += [f"{a}rotation" for a in order]
        values.append(_euler(rotation, order))
    joint = Joint(name, parent, tuple(float(v) for v in offset), tuple(channels), order)
    return joint, np.concatenate(values, axis=1) if values else np.zeros((len(rotation), 0))


def _layout_joint(
    name: str, parent: int, translation: np.ndarray, rotation: np.ndarray, layout: dict | None, unit: float
) -> tuple[Joint | None, np.ndarray]:
    """The joint in the layout it was written with, or (None, ...) when there is no layout or
    the node's motion does not fit it (a file edited since)."""
    if not isinstance(layout, dict):
        return None, np.zeros(0)
    try:
        channels = tuple(str(c) for c in layout["channels"])
        order = str(layout["rotation_order"])
        offset = np.array(layout["offset"], dtype=np.float64)
        axis = tuple(float(a) for a in layout.get("axis", (0.0, 0.0, 0.0)))
        axis_order = str(layout.get("axis_order", "ZYX"))
        if offset.shape != (3,) or not np.isfinite(offset).all() or len(axis) != 3:
            return None, np.zeros(0)
        if any(c not in CHANNEL_NAMES for c in channels) or len(set(channels)) != len(channels):
            return None, np.zeros(0)
        limits = tuple(
            (-np.inf if lo is None else float(lo), np.inf if hi is None else float(hi))
            for lo, hi in layout.get("limits", [[None, None]] * len(channels))
        )
        joint = Joint(name, parent, tuple(float(v) for v in offset), channels, order, axis, axis_order, limits)
    except (KeyError, TypeError, ValueError):
        return None, np.zeros(0)
    values = np.zeros((len(translation), len(channels)))
    moved = translation - offset
    for k, axis_name in enumerate("XYZ"):
        channel = f"{axis_name}position"
        if channel in channels:
            values[:, channels.index(channel)] = moved[:, k]
        elif np.abs(moved[:, k]).max() > STILL_M * unit:
            return None, np.zeros(0)
    if order:
        c = rotations.euler_to_quat(np.array(axis), axis_order)
        inner = rotations.quat_multiply(rotations.quat_multiply(rotations.quat_conjugate(c), rotation), c)
        values[:, joint.rotation_channel_indices()] = _euler(inner, order)
    elif (2.0 * np.arccos(np.clip(np.abs(rotation[:, 0]), 0.0, 1.0))).max() > STILL_RAD:
        return None, np.zeros(0)
    return joint, values


def from_motion(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's local translation ``(F, J, 3)`` in metres and rotation ``(F, J, 4)`` (``w, x,
    y, z``): ``offset + t`` and ``C M C^-1``, the transforms a node tree holds."""
    sk = motion.skeleton
    plan = kinematics.channel_plan(sk)
    translation = np.broadcast_to(sk.offsets, (motion.num_frames, len(sk), 3)).copy()
    for k in range(3):
        has = plan.pos_index[:, k] >= 0
        translation[:, has, k] += motion.channels[:, plan.pos_index[has, k]]
    return translation / sk.units_per_metre, kinematics.local_quaternions(sk, motion.channels)


def layout_of(joint: Joint) -> dict:
    """The layout :func:`to_motion` restores a joint from (stored beside a node)."""
    layout: dict = {"channels": list(joint.channels), "rotation_order": joint.rotation_order}
    layout["offset"] = [float(v) for v in joint.offset]
    if any(np.isfinite(limit).any() for limit in joint.limits):
        layout["limits"] = [[float(v) if np.isfinite(v) else None for v in limit] for limit in joint.limits]
    if joint.has_axis:
        layout["axis"] = [float(a) for a in joint.axis]
        layout["axis_order"] = joint.axis_order
    return layout
