"""Motions to and from trees of node transforms: what glTF and FBX animations hold.

A reader gives each node's *world* transform at every frame (position, and rotation with any
scale taken out) and which nodes are joints; :func:`to_motion` turns them into the skeleton's
rule (:mod:`mocodec.kinematics`: ``x_i = x_p + G_p (offset_i + t_i)``, ``G_i = G_p C M C^-1``)
with ``offset_i + t_i = G_p^T (x_i - x_p)`` and ``C M C^-1 = G_p^T G_i``. Joint positions come
out exactly whatever the file's scales and scale-inheritance rules were: a scale only changes
where the nodes are, and that is what the world positions hold.

Each joint takes only the channels its node needs: translation channels where its offset from
the parent moves, Euler rotation channels where its rotation is not always the identity. "Moves"
knows the input's precision: exporters write 32-bit floats, so an offset that wobbles by a few
float32 steps is a constant (:func:`precision_m`). What dropping that wobble changes is measured
(the joint positions against the file's, by forward kinematics) and kept within the precision,
and recorded on the skeleton (``metadata["precision_m"]``, ``metadata["dropped_m"]``). A
node that carries the layout a :class:`~mocodec.skeleton.Joint` had when it was written (the
``mocodec`` extras of a glTF mocodec wrote) gets that layout back: channels, rotation order,
ASF axis and exact offset.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocodec import kinematics, limits, rotations
from mocodec.errors import ConversionError
from mocodec.motion import Motion
from mocodec.skeleton import CHANNEL_NAMES, POSITION_CHANNELS, Joint, Skeleton

#: The Euler order of rotation channels made for a node that states none (glTF and FBX keep
#: quaternions or their own orders): ``ZYX``, the order ASF files can hold as they are.
DEFAULT_ORDER = "ZYX"
#: The finest precision a file's joint positions are taken to have (metres): 1e-4 cm.
STILL_M = 1e-6
#: How many float32 steps at the skeleton's largest coordinate the precision is at least:
#: exporters compose and store transforms in 32-bit floats, a few rounding steps each.
FLOAT32_STEPS = 8
#: A rotation within this angle (radians) of the identity on every frame is no rotation
#: (eight float32 steps of a unit quaternion's components).
STILL_RAD = 1e-6
#: The stillness thresholds of a motion kept exact (metres, radians): what composing and
#: inverting float64 transforms leaves of a node that does not move.
EXACT_M, EXACT_RAD = 1e-8, 1e-9
#: Rounds of keeping the motion of the joints that moved beyond the precision and of their
#: parents, before every joint keeps all of its motion.
_TRIES = 8
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


def precision_m(position: np.ndarray) -> float:
    """The precision (metres) of joint world positions ``position``: :data:`FLOAT32_STEPS`
    float32 steps at their largest coordinate, and at least :data:`STILL_M`."""
    extent = float(np.abs(position).max(initial=0.0))
    return max(STILL_M, FLOAT32_STEPS * float(np.spacing(np.float32(extent))))


def to_motion(samples: NodeSamples, fps: float, units_per_metre: float, name: str = "") -> Motion:
    """The motion of the joint nodes: node 0 is the root joint (see the module docstring)."""
    if not (np.isfinite(samples.position).all() and np.abs(samples.position).max(initial=0.0) <= MAX_COORDINATE_M):
        raise ConversionError(f"a node lies beyond {MAX_COORDINATE_M:g} m of the origin")
    local = _local_transforms(samples, units_per_metre)
    precision = precision_m(samples.position)
    target = samples.position * units_per_metre
    exact: set[int] = set()  # joints whose every motion is kept
    for _ in range(_TRIES):
        motion = _build(samples, local, fps, units_per_metre, name, precision, exact)
        error = _joint_errors_m(motion, target)
        over = np.flatnonzero(error > precision)
        if not len(over):
            break
        # these joints and their parents keep their motion: a round up each joint's chain
        exact.update(int(j) for j in over)
        exact.update(int(samples.parents[j]) for j in over if samples.parents[j] >= 0)
    else:
        motion = _build(samples, local, fps, units_per_metre, name, precision, set(range(len(samples.names))))
        error = _joint_errors_m(motion, target)
    motion.skeleton.metadata.update(precision_m=precision, dropped_m=float(error.max(initial=0.0)))
    return motion


def _joint_errors_m(motion: Motion, target: np.ndarray) -> np.ndarray:
    """``(joints,)``: how far (metres) each joint of ``motion`` comes from ``target`` (its
    positions in the motion's units) at worst over the frames."""
    distance = np.linalg.norm(motion.positions() - target, axis=2)
    return distance.max(axis=0, initial=0.0) / motion.skeleton.units_per_metre


def _local_transforms(samples: NodeSamples, unit: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each joint's translation from its parent (``unit``s, in the parent's frame) and its
    rotation relative to its parent, every frame: ``G_p^T (x_i - x_p)`` and ``G_p^T G_i``."""
    local = []
    for i in range(len(samples.names)):
        parent = int(samples.parents[i])
        if parent < 0:
            translation, rotation = samples.position[:, i], samples.rotation[:, i]
        else:
            inverse = rotations.quat_conjugate(samples.rotation[:, parent])
            translation = rotations.quat_rotate(inverse, samples.position[:, i] - samples.position[:, parent])
            rotation = rotations.quat_multiply(inverse, samples.rotation[:, i])
        local.append((translation * unit, rotations.quat_normalize(rotation)))
    return local


def _build(
    samples: NodeSamples,
    local: list[tuple[np.ndarray, np.ndarray]],
    fps: float,
    unit: float,
    name: str,
    precision: float,
    exact: set[int],
) -> Motion:
    """The motion whose translations moving at most ``precision`` metres, and rotations within
    :data:`STILL_RAD` of the identity, are constants, except on the joints ``exact``."""
    n = len(samples.names)
    layouts = samples.layouts or [None] * n
    joints: list[Joint] = []
    columns: list[np.ndarray] = []
    for i, (translation, rotation) in enumerate(local):
        parent = int(samples.parents[i])
        still_m, still_rad = (EXACT_M, EXACT_RAD) if i in exact else (precision, STILL_RAD)
        joint, values = _layout_joint(
            samples.names[i], parent, translation, rotation, layouts[i], still_m * unit, still_rad
        )
        if joint is None:
            joint, values = _plain_joint(samples.names[i], parent, translation, rotation, still_m * unit, still_rad)
        joints.append(joint)
        columns.append(values)
    skeleton = Skeleton(tuple(joints), unit, name)
    frames = samples.position.shape[0]
    values = np.concatenate(columns, axis=1) if columns else np.zeros((frames, 0))
    if not np.isfinite(values).all():
        raise ConversionError("the node transforms give channel values that are not finite")
    return Motion(skeleton, fps, values)


def closure(parents: np.ndarray, wanted: set[int]) -> list[int] | None:
    """The nodes ``wanted`` with every node between them and their lowest common ancestor,
    depth first (children in node order); None when they have no common ancestor. Linear in
    the number of nodes, however deep the tree (``parents`` holds no cycle)."""
    children, order = _walk(parents)
    below = np.zeros(len(parents), dtype=np.int64)  # wanted nodes in each node's subtree
    for node in reversed(order):
        below[node] += node in wanted
        if parents[node] >= 0:
            below[int(parents[node])] += below[node]
    if not wanted:
        return None
    top = next((node for node in order if below[node] == len(wanted)), None)
    if top is None:
        return None
    while True:  # down to the lowest node holding every wanted node
        inside = [child for child in children[top] if below[child] == len(wanted)]
        if not inside or top in wanted:
            break
        top = inside[0]
    return [node for node in _depth_first(children, [top]) if below[node] > 0]


def tree_problem(parents: np.ndarray) -> str | None:
    """What makes a node tree unreadable, or None: a node no root reaches (each node has at
    most one parent, so it is on a cycle of parents or below one), or a node MAX_DEPTH deep or
    deeper. Linear, however deep the tree."""
    depth = -np.ones(len(parents), dtype=np.int64)
    for node in _walk(parents)[1]:
        depth[node] = depth[parents[node]] + 1 if parents[node] >= 0 else 0
    if (depth < 0).any():
        return f"node {int(np.argmin(depth))} is in a cycle of children"
    deepest = int(np.argmax(depth)) if len(depth) else 0
    if len(depth) and depth[deepest] >= limits.MAX_DEPTH:
        return f"node {deepest} is {int(depth[deepest])} deep, past {limits.MAX_DEPTH}"
    return None


def _walk(parents: np.ndarray) -> tuple[list[list[int]], list[int]]:
    """Each node's children (in node order), and the nodes the roots reach, depth first."""
    n = len(parents)
    children: list[list[int]] = [[] for _ in range(n)]
    for node in range(n):
        if parents[node] >= 0:
            children[int(parents[node])].append(node)
    return children, _depth_first(children, [node for node in range(n) if parents[node] < 0])


def _depth_first(children: list[list[int]], roots: list[int]) -> list[int]:
    """The nodes below ``roots`` depth first, children in node order (iterative)."""
    order: list[int] = []
    stack = list(reversed(roots))
    while stack:
        node = stack.pop()
        order.append(node)
        stack.extend(reversed(children[node]))
    return order


def world_transforms(
    parents: np.ndarray, translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World positions ``(F, n, 3)`` and rotations ``(F, n, 4)`` of nodes given parents first
    with local translations, rotations ``(w, x, y, z)`` and scales: ``M = M_p T R S``. With
    uniform scales (the usual case) composed as quaternions and scale factors; otherwise as
    matrices, the rotation then the nearest one to ``M``'s 3x3 part (its polar factor, or for a
    node a negative scale mirrors, the nearest rotation to it: joint positions stay exact, as
    they come from the matrices)."""
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
    u[..., :, 2] *= np.sign(np.linalg.det(u @ vt))[..., None]  # a mirrored node: the nearest rotation
    return world[..., :3, 3], rotations.matrix_to_quat(u @ vt)


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
    name: str, parent: int, translation: np.ndarray, rotation: np.ndarray, still: float, still_rad: float
) -> tuple[Joint, np.ndarray]:
    """A joint with the channels its node needs (see the module docstring): a moving root
    translates from the origin, any other moving joint from where it starts; a translation
    moving at most ``still`` units is the constant midway in its range."""
    low, high = translation.min(axis=0), translation.max(axis=0)
    moves = (high - low).max() > still
    offset = np.zeros(3) if moves and parent < 0 else translation[0] if moves else (low + high) / 2
    channels: list[str] = list(POSITION_CHANNELS) if moves else []
    values = [translation - offset] if moves else []
    angle = 2.0 * np.arccos(np.clip(np.abs(rotation[:, 0]), 0.0, 1.0))
    order = ""
    if angle.max() > still_rad:
        order = DEFAULT_ORDER
        channels += [f"{a}rotation" for a in order]
        values.append(_euler(rotation, order))
    joint = Joint(name, parent, tuple(float(v) for v in offset), tuple(channels), order)
    return joint, np.concatenate(values, axis=1) if values else np.zeros((len(rotation), 0))


def _layout_joint(
    name: str,
    parent: int,
    translation: np.ndarray,
    rotation: np.ndarray,
    layout: dict | None,
    still: float,
    still_rad: float,
) -> tuple[Joint | None, np.ndarray]:
    """The joint in the layout it was written with, or (None, ...) when there is no layout or
    the node's motion does not fit it (a file edited since): a translation it has no channel
    for moves more than ``still`` units, or a rotation it has none for turns over ``still_rad``."""
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
        turn = rotations.euler_to_quat(np.array(axis), axis_order)
    except (KeyError, TypeError, ValueError):  # a layout edited or forged: not used
        return None, np.zeros(0)
    values = np.zeros((len(translation), len(channels)))
    moved = translation - offset
    for k, axis_name in enumerate("XYZ"):
        channel = f"{axis_name}position"
        if channel in channels:
            values[:, channels.index(channel)] = moved[:, k]
        elif np.abs(moved[:, k]).max() > still:
            return None, np.zeros(0)
    if order:
        inner = rotations.quat_multiply(rotations.quat_multiply(rotations.quat_conjugate(turn), rotation), turn)
        values[:, joint.rotation_channel_indices()] = _euler(inner, order)
    elif (2.0 * np.arccos(np.clip(np.abs(rotation[:, 0]), 0.0, 1.0))).max() > still_rad:
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
