"""A procedural mannequin for any skeleton: a skinned mesh made from the skeleton alone, so a
motion is seen on a body rather than on dots and lines (docs/viewer.md).

Every bone below the hips (a joint and its parent, apart in the bind pose) is a capsule: a cylinder along the
bone with a hemisphere at each end, its radius set by the bone's body part (torso, head, arms,
hands, legs; :mod:`mocodec.bodyparts`), a limb's held under half the bone's length. Neighbouring
capsules overlap at their joint, so the surface stays closed when the joint bends. A capsule
follows its parent joint (whose rotation turns the bone). Near each end its vertices blend in
the joint across the joint, half and half at the joint itself. Linear-blend weights, two
influences there, bend elbows and knees smoothly instead of tearing them.

Positions are in the skeleton's units, in the bind pose. Levels of detail (:data:`LEVELS`) trade
roundness for triangles: a distant avatar needs few.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec import rotations
from mocodec.bodyparts import label_body_parts
from mocodec.skeleton import POSITION_CHANNELS, Skeleton

#: Capsule radius per body chain, metres, a limb's or the neck's held under RADIUS_OF_LENGTH of
#: the bone's length (a short spine bone is still as wide as the chest).
RADII_M = {"torso": 0.1, "head": 0.085, "arm": 0.045, "hand": 0.025, "leg": 0.065}
RADIUS_OF_LENGTH = 0.45
HEAD_OF_LENGTH = 0.9  # ... and the head's last bone under this share of its length
#: Bones shorter than this (metres) get no capsule: the joints they join are one point.
SHORTEST_M = 0.015
#: The share of a bone's length at each end over which its vertices blend into the next joint.
BLEND = 0.3
#: (segments around, rings per hemisphere, rings along the cylinder) per level of detail.
LEVELS = ((12, 3, 3), (8, 2, 2), (5, 1, 1))


@dataclass(frozen=True)
class Mesh:
    """A skinned triangle mesh: ``positions`` and ``normals`` ``(V, 3)`` (bind pose, skeleton
    units), ``triangles`` ``(F, 3)``, per vertex four ``joints`` and their ``weights`` (summing
    to 1), and the joint whose error paints each vertex (``owners``: the bone's far end)."""

    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    owners: np.ndarray


def bind_positions(skeleton: Skeleton, first_frame: np.ndarray | None = None) -> np.ndarray:
    """Joint positions ``(J, 3)`` of the bind pose: no rotation, each joint at its offset plus,
    for a joint below the root with translation channels (bones stored as channels, as
    MotionBuilder exports them), those channels' values in ``first_frame``."""
    local = skeleton.offsets.copy()
    if first_frame is not None:
        for j, joint in enumerate(skeleton.joints[1:], start=1):
            for axis, name in enumerate(POSITION_CHANNELS):
                if name in joint.channels:
                    local[j, axis] += first_frame[skeleton.channel_offsets[j] + joint.channels.index(name)]
    out = np.zeros_like(local)
    for j in range(len(skeleton)):
        parent = skeleton.joints[j].parent
        out[j] = local[j] + (out[parent] if parent >= 0 else 0.0)
    return out


def build(skeleton: Skeleton, bind: np.ndarray | None = None, level: int = 0) -> Mesh:
    """The mannequin of ``skeleton`` at level of detail ``level`` (0: the nearest), its bones
    where ``bind`` (default :func:`bind_positions` of the skeleton) puts the joints."""
    if not 0 <= level < len(LEVELS):
        raise ValueError(f"level must be 0 to {len(LEVELS) - 1}, got {level}")
    bind = bind_positions(skeleton) if bind is None else np.asarray(bind, dtype=np.float64)
    metre = skeleton.units_per_metre
    chains, _ = label_body_parts(skeleton)
    above = set(_above_the_body(skeleton))
    parts: list[tuple[np.ndarray, ...]] = []
    offset = 0
    for j, joint in enumerate(skeleton.joints):
        p = joint.parent
        if p < 0 or j in above:
            continue
        length = float(np.linalg.norm(bind[j] - bind[p]))
        if length < SHORTEST_M * metre:
            continue
        chain = chains[j] if chains[j] in RADII_M else "torso"
        radius = RADII_M[chain] * metre
        if chain == "head" and not any(  # the head itself (no bone beyond it): as wide as its bone is long
            np.linalg.norm(bind[k] - bind[j]) >= SHORTEST_M * metre for k in skeleton.children[j]
        ):
            radius = min(radius, HEAD_OF_LENGTH * length)
        elif chain != "torso":
            radius = min(radius, RADIUS_OF_LENGTH * length)
        grand = -1 if p in above else skeleton.joints[p].parent  # the hips blend with nothing above them
        piece = _capsule(bind[p], bind[j], radius, LEVELS[level], (grand, p, j))
        parts.append((*piece[:2], piece[2] + offset, *piece[3:], np.full(len(piece[0]), j)))
        offset += len(piece[0])
    if not parts:
        raise ValueError("the skeleton has no bone to build a mannequin on")
    return Mesh(*(np.concatenate(column) for column in zip(*parts)))


def _above_the_body(skeleton: Skeleton) -> list[int]:
    """The joints from the root down to the body's root, the first joint with more than one
    child (the hips), that joint included: a dummy root above the hips is no bone of the
    body, and the bone into the hips would join it to wherever the capture started."""
    chain = [0]
    while len(skeleton.children[chain[-1]]) == 1:
        chain.append(skeleton.children[chain[-1]][0])
    return chain


def _capsule(start: np.ndarray, end: np.ndarray, radius: float, level: tuple[int, int, int], joints: tuple):
    """Positions, normals, triangles, joints and weights of one capsule from ``start`` to
    ``end``; ``joints`` = (the joint before, the bone's own, the joint after)."""
    around, cap_rings, body_rings = level
    axis = end - start
    length = float(np.linalg.norm(axis))
    axis = axis / length
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    # rings from the start pole to the end pole: (height along the bone, ring radius, normal's axial part)
    angles = np.linspace(-np.pi / 2, 0.0, cap_rings + 1)[1:]  # the start hemisphere, pole excluded
    rings = [(radius * np.sin(a), radius * np.cos(a), np.sin(a)) for a in angles]
    rings += [(length * k / (body_rings + 1), radius, 0.0) for k in range(1, body_rings + 1)]
    rings += [(length + radius * np.sin(a), radius * np.cos(a), np.sin(a)) for a in -angles[::-1]]
    turn = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    circle = np.cos(turn)[:, None] * u + np.sin(turn)[:, None] * v  # (around, 3)
    positions = [start - radius * axis]
    normals = [-axis]
    for height, ring_radius, axial in rings:
        positions += list(start + height * axis + ring_radius * circle)
        radial = np.sqrt(max(1.0 - axial * axial, 0.0))
        normals += list(axial * axis + radial * circle)
    positions.append(end + radius * axis)
    normals.append(axis)
    heights = np.concatenate(([-radius], np.repeat([h for h, _, _ in rings], around), [length + radius]))
    triangles = _capsule_triangles(around, len(rings))
    joint_ids, weights = _blend(heights / length, joints)
    return np.array(positions), np.array(normals), triangles, joint_ids, weights


def _capsule_triangles(around: int, rings: int) -> np.ndarray:
    """Triangles of a capsule's vertices: the start pole, ``rings`` rings of ``around``, the end pole."""
    last = 1 + rings * around
    k = np.arange(around)
    nxt = (k + 1) % around
    tris = [np.stack([np.zeros(around, int), 1 + nxt, 1 + k], axis=1)]  # the start fan
    for r in range(rings - 1):
        a, b = 1 + r * around, 1 + (r + 1) * around
        tris.append(np.stack([a + k, a + nxt, b + nxt], axis=1))
        tris.append(np.stack([a + k, b + nxt, b + k], axis=1))
    a = 1 + (rings - 1) * around
    tris.append(np.stack([np.full(around, last), a + k, a + nxt], axis=1))  # the end fan
    return np.concatenate(tris)


def _blend(t: np.ndarray, joints: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Four joints and weights per vertex at ``t`` along the bone (0 at its start, 1 at its
    end; beyond on the caps): the bone's own joint, and within BLEND of an end the joint across
    it, rising smoothly to half at the joint (none before the root)."""
    before, own, after = joints
    ids = np.zeros((t.size, 4), dtype=np.int64)
    weights = np.zeros((t.size, 4))
    start = _smooth(np.clip((BLEND - t) / BLEND, 0.0, 1.0)) / 2 if before >= 0 else np.zeros(t.size)
    end = _smooth(np.clip((t - 1.0 + BLEND) / BLEND, 0.0, 1.0)) / 2
    ids[:, 0], ids[:, 1], ids[:, 2] = own, max(before, 0), after
    weights[:, 0], weights[:, 1], weights[:, 2] = 1.0 - start - end, start, end
    return ids, weights


def _smooth(x: np.ndarray) -> np.ndarray:
    return x * x * (3.0 - 2.0 * x)


def skinned(mesh: Mesh, bind: np.ndarray, positions: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """The mesh's vertices ``(V, 3)`` in a pose: joint ``positions (J, 3)`` and global
    orientations ``quats (J, 4)`` (:func:`mocodec.kinematics.forward_kinematics` of one frame),
    by linear-blend skinning from ``bind``, the pose it was built in (no rotation), as a
    three.js ``SkinnedMesh`` or a glTF viewer computes them."""
    matrices = rotations.quat_to_matrix(quats)  # (J, 3, 3)
    out = np.zeros_like(mesh.positions)
    for k in range(mesh.joints.shape[1]):
        j = mesh.joints[:, k]
        moved = np.einsum("vab,vb->va", matrices[j], mesh.positions - bind[j]) + positions[j]
        out += mesh.weights[:, k, None] * moved
    return out
