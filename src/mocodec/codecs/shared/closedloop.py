"""Closed-loop coding down the kinematic tree (kinwave.md, "what mattered" 1).

A joint is coded so that, on top of its parent's *decoded* global orientation, it restores
its *original* global orientation: the target local rotation is ``conj(G'_p) G_j``. The
encoder therefore needs, per joint, the Euler angles (in the joint's own channels, order and
ASF pre-rotation ``C``) of that target, near the original angles; :func:`target_angles` finds
them by one damped Gauss-Newton step from the original angles (for three-DOF joints what is
left is second order in the parent's error, and a second step costs time for no byte less
(docs/kinwave.md); for one- and two-DOF joints
the step heads for the least-squares best rotation). Quantisation errors then stop
accumulating from the hips to the fingertips, as in a DPCM coder that predicts from the
decoded signal. :func:`compose` gives the decoded global orientation for the children.

Quaternions are (w, x, y, z), Hamilton products, the conventions of
:mod:`mocodec.kinematics`: ``L = C R_1 R_2 R_3 C^-1`` with ``R_k`` about axis ``a_k``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numba
import numpy as np

from mocodec.codecs.shared.rotvec import quat_product, rotate_vector
from mocodec.kernels import kernel
from mocodec.kinematics import channel_plan
from mocodec.skeleton import Skeleton

_DAMPING = 1e-9
PLAN_ENTRY_FRAMES = 1 << 20  # a loop keeps its joints' linearisations up to this many joint-frames (109 MB)


@numba.njit(inline="always")
def _axis_quat(axis, angle):
    c, s = np.cos(0.5 * angle), np.sin(0.5 * angle)
    if axis == 0:
        return c, s, 0.0, 0.0
    if axis == 1:
        return c, 0.0, s, 0.0
    return c, 0.0, 0.0, s


@kernel
def _linearise(angles, axes, cq, has_axis, lq, jac):
    """What a Gauss-Newton step from ``angles (T, k)`` reads, whatever its target: per frame the
    local rotation ``L = C R_1 .. R_k C^-1`` the angles make, into ``lq (T, 4)``, and each
    step's axis in the body frame (the Jacobian's rows), into ``jac (T, 3, 3)``."""
    k = axes.size
    steps = np.empty((3, 4))
    for f in range(angles.shape[0]):
        for i in range(k):
            steps[i, 0], steps[i, 1], steps[i, 2], steps[i, 3] = _axis_quat(axes[i], angles[f, i] * (np.pi / 180.0))
        # suffix products S_i = R_{i+1} ... R_k give the body-frame axis of step i
        sw, sx, sy, sz = 1.0, 0.0, 0.0, 0.0
        for i in range(k - 1, -1, -1):
            ex, ey, ez = (
                (1.0 if axes[i] == 0 else 0.0),
                (1.0 if axes[i] == 1 else 0.0),
                (1.0 if axes[i] == 2 else 0.0),
            )
            jx, jy, jz = rotate_vector(sw, -sx, -sy, -sz, ex, ey, ez)
            if has_axis:
                jx, jy, jz = rotate_vector(cq[0], cq[1], cq[2], cq[3], jx, jy, jz)
            jac[f, i, 0], jac[f, i, 1], jac[f, i, 2] = jx, jy, jz
            sw, sx, sy, sz = quat_product(steps[i, 0], steps[i, 1], steps[i, 2], steps[i, 3], sw, sx, sy, sz)
        lw, lx, ly, lz = sw, sx, sy, sz
        if has_axis:
            lw, lx, ly, lz = quat_product(cq[0], cq[1], cq[2], cq[3], lw, lx, ly, lz)
            lw, lx, ly, lz = quat_product(lw, lx, ly, lz, cq[0], -cq[1], -cq[2], -cq[3])
        lq[f, 0], lq[f, 1], lq[f, 2], lq[f, 3] = lw, lx, ly, lz


@kernel
def _step(angles, active, lq, jac, parent, goal, out):
    """One damped Gauss-Newton step per frame from ``angles (T, k)`` (degrees) towards the
    local rotation ``conj(parent) goal``, given the angles' :func:`_linearise`."""
    k = angles.shape[1]
    theta = np.empty(3)
    a = np.empty((3, 4))  # normal equations | right-hand side
    for f in range(angles.shape[0]):
        for i in range(k):
            theta[i] = angles[f, i] * (np.pi / 180.0)
        # wanted local rotation M = conj(parent) * goal
        mw, mx, my, mz = quat_product(
            parent[f, 0], -parent[f, 1], -parent[f, 2], -parent[f, 3], goal[f, 0], goal[f, 1], goal[f, 2], goal[f, 3]
        )
        # remaining rotation in the body frame: E = conj(L) M, as a rotation vector r
        ew, ex, ey, ez = quat_product(lq[f, 0], -lq[f, 1], -lq[f, 2], -lq[f, 3], mw, mx, my, mz)
        if ew < 0.0:
            ew, ex, ey, ez = -ew, -ex, -ey, -ez
        norm = np.sqrt(ex * ex + ey * ey + ez * ez)
        scale = 2.0 if norm < 1e-12 else 2.0 * np.arctan2(norm, ew) / norm
        rx, ry, rz = ex * scale, ey * scale, ez * scale
        # damped normal equations over the active steps: (J^T J + d I) delta = J^T r
        a[:] = 0.0
        for i in range(k):
            if not active[i]:
                a[i, i] = 1.0
                continue
            for m in range(k):
                if active[m]:
                    a[i, m] = jac[f, i, 0] * jac[f, m, 0] + jac[f, i, 1] * jac[f, m, 1] + jac[f, i, 2] * jac[f, m, 2]
            a[i, i] += _DAMPING
            a[i, 3] = jac[f, i, 0] * rx + jac[f, i, 1] * ry + jac[f, i, 2] * rz
        for i in range(k):  # Gaussian elimination with partial pivoting
            piv = i
            for m in range(i + 1, k):
                if abs(a[m, i]) > abs(a[piv, i]):
                    piv = m
            if piv != i:
                for col in range(4):
                    a[i, col], a[piv, col] = a[piv, col], a[i, col]
            for m in range(i + 1, k):
                factor = a[m, i] / a[i, i]
                for col in range(i, 4):
                    a[m, col] -= factor * a[i, col]
        for i in range(k - 1, -1, -1):
            v = a[i, 3]
            for m in range(i + 1, k):
                v -= a[i, m] * a[m, 3]
            a[i, 3] = v / a[i, i]
            if active[i]:
                theta[i] += a[i, 3]
        for i in range(k):
            out[f, i] = theta[i] * (180.0 / np.pi)


@kernel
def _targets(angles, axes, active, cq, has_axis, parent, goal, out):
    lq, jac = np.empty((angles.shape[0], 4)), np.empty((angles.shape[0], 3, 3))
    _linearise(angles, axes, cq, has_axis, lq, jac)
    _step(angles, active, lq, jac, parent, goal, out)


@kernel
def _compose(angles, axes, cq, has_axis, parent, out):
    for f in range(angles.shape[0]):
        w, x, y, z = 1.0, 0.0, 0.0, 0.0
        for i in range(axes.size):
            sw, sx, sy, sz = _axis_quat(axes[i], angles[f, i] * (np.pi / 180.0))
            w, x, y, z = quat_product(w, x, y, z, sw, sx, sy, sz)
        if has_axis:
            w, x, y, z = quat_product(cq[0], cq[1], cq[2], cq[3], w, x, y, z)
            w, x, y, z = quat_product(w, x, y, z, cq[0], -cq[1], -cq[2], -cq[3])
        out[f, 0], out[f, 1], out[f, 2], out[f, 3] = quat_product(
            parent[f, 0], parent[f, 1], parent[f, 2], parent[f, 3], w, x, y, z
        )


def target_angles(
    angles: np.ndarray,
    axes: np.ndarray,
    active: np.ndarray,
    axis_quat: np.ndarray,
    has_axis: bool,
    parent: np.ndarray,
    goal: np.ndarray,
) -> np.ndarray:
    """Euler angles ``(T, k)`` (degrees, in rotation-order steps) whose local rotation on top
    of the decoded ``parent (T, 4)`` global orientation comes closest to ``goal (T, 4)``,
    starting from ``angles``; inactive steps keep their value."""
    out = np.empty_like(angles)
    _targets(
        np.ascontiguousarray(angles, dtype=np.float64),
        np.ascontiguousarray(axes, dtype=np.int64),
        np.ascontiguousarray(active, dtype=np.bool_),
        np.ascontiguousarray(axis_quat, dtype=np.float64),
        bool(has_axis),
        np.ascontiguousarray(parent),
        np.ascontiguousarray(goal),
        out,
    )
    return out


def compose(
    angles: np.ndarray, axes: np.ndarray, axis_quat: np.ndarray, has_axis: bool, parent: np.ndarray
) -> np.ndarray:
    """Global orientation ``(T, 4)`` of a joint with local Euler ``angles`` under ``parent``."""
    out = np.empty((angles.shape[0], 4))
    _compose(
        np.ascontiguousarray(angles, dtype=np.float64),
        np.ascontiguousarray(axes, dtype=np.int64),
        np.ascontiguousarray(axis_quat, dtype=np.float64),
        bool(has_axis),
        np.ascontiguousarray(parent),
        out,
    )
    return out


@lru_cache(maxsize=64)
def depth_levels(skeleton: Skeleton) -> tuple[tuple[int, ...], ...]:
    """Joints by their depth in the tree, the root's first: the order closed-loop coding needs
    (a joint after its parent), and the joints of one depth can be coded together."""
    depths = skeleton.depths
    return tuple(tuple(int(j) for j in np.flatnonzero(depths == d)) for d in range(int(depths.max(initial=-1)) + 1))


@dataclass(frozen=True)
class _JointPlan:
    """What closed-loop coding reads of one joint, prepared once per skeleton: its translation
    channels and their axes, its rotation channels (in rotation-order steps) and their axes, its
    axis pre-rotation and offset."""

    moves: np.ndarray
    move_axes: np.ndarray
    chans: np.ndarray
    axes: np.ndarray
    axis_quat: np.ndarray
    has_axis: bool
    offset: np.ndarray
    has_children: bool


@lru_cache(maxsize=64)
def _joint_plans(skeleton: Skeleton) -> tuple[_JointPlan, ...]:
    plan = channel_plan(skeleton)
    out = []
    for j in range(len(skeleton)):
        k = int((plan.rot_index[j] >= 0).sum())
        out.append(
            _JointPlan(
                plan.pos_index[j][plan.pos_index[j] >= 0],
                np.flatnonzero(plan.pos_index[j] >= 0),
                plan.rot_index[j, :k],
                np.ascontiguousarray(plan.rot_axis[j, :k], dtype=np.int64),
                np.ascontiguousarray(plan.axis_quat[j], dtype=np.float64),
                bool(plan.has_axis[j]),
                plan.offsets[j],
                bool(skeleton.children[j]),
            )
        )
    return tuple(out)


@dataclass(frozen=True)
class _DepthPlan:
    """One depth's joints as the batched kernels read them: the channels coded together (each
    joint's translations, then its rotations, joint by joint), and per joint its parent, its
    rotation channels padded to three (-1) with their columns among the coded ones, its steps'
    axes, axis pre-rotation and whether it has children."""

    joints: np.ndarray
    parents: np.ndarray
    coded: np.ndarray
    move_columns: tuple[np.ndarray, ...]  # per joint: its translations' columns among the coded
    chans: np.ndarray  # (n, 3)
    columns: np.ndarray  # (n, 3)
    steps: np.ndarray  # (n,) rotation steps
    axes: np.ndarray  # (n, 3)
    axis_quats: np.ndarray  # (n, 4)
    has_axis: np.ndarray
    has_children: np.ndarray


@lru_cache(maxsize=64)
def _depth_plans(skeleton: Skeleton) -> tuple[_DepthPlan, ...]:
    plans, out = _joint_plans(skeleton), []
    for depth in depth_levels(skeleton):
        n = len(depth)
        chans, columns, axes = -np.ones((n, 3), np.int64), -np.ones((n, 3), np.int64), np.zeros((n, 3), np.int64)
        coded: list[int] = []
        move_columns = []
        for i, j in enumerate(depth):
            jp = plans[j]
            move_columns.append(np.arange(len(coded), len(coded) + jp.moves.size))
            coded += jp.moves.tolist()
            k = jp.chans.size
            chans[i, :k], axes[i, :k] = jp.chans, jp.axes
            columns[i, :k] = np.arange(len(coded), len(coded) + k)
            coded += jp.chans.tolist()
        out.append(
            _DepthPlan(
                np.array(depth, dtype=np.int64),
                np.array([skeleton.parents[j] for j in depth], dtype=np.int64),
                np.array(coded, dtype=np.int64),
                tuple(move_columns),
                chans,
                columns,
                np.array([plans[j].chans.size for j in depth], dtype=np.int64),
                axes,
                np.array([plans[j].axis_quat for j in depth], dtype=np.float64).reshape(n, 4),
                np.array([plans[j].has_axis for j in depth], dtype=np.bool_),
                np.array([plans[j].has_children for j in depth], dtype=np.bool_),
            )
        )
    return tuple(out)


class TreeArrays(NamedTuple):
    """The depth plans of a skeleton flattened for a compiled loop down the tree (one entry per
    joint, depth by depth; a depth's entries and coded channels between consecutive pointers):
    what :func:`code_down_tree` reads of them, as arrays a kernel takes at once."""

    depth_ptr: np.ndarray  # (D + 1,) each depth's first entry
    joints: np.ndarray
    parents: np.ndarray
    chans: np.ndarray  # (n, 3) rotation channels, -1 padded
    columns: np.ndarray  # (n, 3) their columns among the depth's coded channels
    steps: np.ndarray  # (n,) rotation steps
    axes: np.ndarray  # (n, 3)
    axis_quats: np.ndarray  # (n, 4)
    has_axis: np.ndarray
    has_children: np.ndarray
    coded_ptr: np.ndarray  # (D + 1,) each depth's first coded channel
    coded: np.ndarray  # each depth's channels, coded together
    move_ptr: np.ndarray  # (n + 1,) each entry's first translation channel
    moves: np.ndarray  # translation channels
    move_axes: np.ndarray  # their axes
    move_columns: np.ndarray  # their columns among the depth's coded channels
    offsets: np.ndarray  # (joints, 3)


@lru_cache(maxsize=64)
def tree_arrays(skeleton: Skeleton) -> TreeArrays:
    """:class:`TreeArrays` of ``skeleton`` (shared: read-only)."""
    plans, depths = _joint_plans(skeleton), _depth_plans(skeleton)
    joints = np.concatenate([dp.joints for dp in depths])
    counts = np.array([plans[j].moves.size for j in joints.tolist()], dtype=np.int64)

    def cat(name: str) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate([getattr(dp, name) for dp in depths]))

    out = TreeArrays(
        np.cumsum([0] + [dp.joints.size for dp in depths]).astype(np.int64),
        joints,
        cat("parents"),
        cat("chans"),
        cat("columns"),
        cat("steps"),
        cat("axes"),
        cat("axis_quats"),
        cat("has_axis"),
        cat("has_children"),
        np.cumsum([0] + [dp.coded.size for dp in depths]).astype(np.int64),
        cat("coded"),
        np.cumsum(np.concatenate([[0], counts])).astype(np.int64),
        np.concatenate([np.zeros(0, np.int64)] + [plans[j].moves for j in joints.tolist()]).astype(np.int64),
        np.concatenate([np.zeros(0, np.int64)] + [plans[j].move_axes for j in joints.tolist()]).astype(np.int64),
        np.concatenate([np.zeros(0, np.int64)] + [c for dp in depths for c in dp.move_columns]).astype(np.int64),
        np.ascontiguousarray([plans[j].offset for j in range(len(skeleton))], dtype=np.float64).reshape(-1, 3),
    )
    for a in out:
        a.setflags(write=False)
    return out


@kernel
def depth_targets(
    start, active, goal, glob, d_joints, d_parents, chans, columns, steps, axes, quats, has_axis, skip, out, a, plan
):
    """A depth's joints at once (tree entries ``a:``): each joint's orientation starts as its
    parent's decoded one (``glob``), and the rotation columns of ``out`` (the start values of
    the coded channels) of a non-root joint with an active channel, not ``skip``-ped, become
    :func:`target_angles`. ``plan``: :class:`TreeLoop`'s linearisations of the start angles,
    made at a joint's first pass and read at the next (empty: made every time)."""
    frames = start.shape[0]
    ready, kept_lq, kept_jac = plan
    for i in range(d_joints.size):
        j, p, k = d_joints[i], d_parents[i], steps[i]
        for f in range(frames):
            for m in range(4):
                glob[j, f, m] = glob[p, f, m] if p >= 0 else (1.0 if m == 0 else 0.0)
        if p < 0 or k == 0 or skip[j]:
            continue
        act = np.zeros(k, dtype=np.bool_)
        any_active = False
        for m in range(k):
            act[m] = active[chans[i, m]]
            any_active = any_active or act[m]
        if not any_active:
            continue
        angles = np.empty((frames, k))
        for f in range(frames):
            for m in range(k):
                angles[f, m] = start[f, chans[i, m]]
        target = np.empty((frames, k))
        if kept_lq.shape[0]:
            if not ready[a + i]:
                _linearise(angles, axes[i, :k], quats[i], has_axis[i], kept_lq[a + i], kept_jac[a + i])
                ready[a + i] = True
            _step(angles, act, kept_lq[a + i], kept_jac[a + i], glob[p], goal[:, j], target)
        else:
            _targets(angles, axes[i, :k], act, quats[i], has_axis[i], glob[p], goal[:, j], target)
        for f in range(frames):
            for m in range(k):
                out[f, columns[i, m]] = target[f, m]


@kernel
def depth_compose(decoded, glob, d_joints, columns, steps, axes, quats, has_axis, has_children):
    """The decoded orientation of each of a depth's joints with rotations and children, from
    the depth's decoded columns on top of its parent's (already in ``glob``)."""
    frames = decoded.shape[0]
    for i in range(d_joints.size):
        k = steps[i]
        if k == 0 or not has_children[i]:
            continue
        j = d_joints[i]
        angles = np.empty((frames, k))
        for f in range(frames):
            for m in range(k):
                angles[f, m] = decoded[f, columns[i, m]]
        parent = glob[j].copy()
        _compose(angles, axes[i, :k], quats[i], has_axis[i], parent, glob[j])


def placing_joints(skeleton: Skeleton, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per joint: whether closed-loop translations need its decoded position (an ancestor of a
    non-root joint with an active translation channel), and whether it is such a joint (its
    translations are targeted); shared, read-only."""
    return _placing_of(skeleton, np.ascontiguousarray(active, dtype=np.bool_).tobytes())


@lru_cache(maxsize=256)
def _placing_of(skeleton: Skeleton, active_flags: bytes) -> tuple[np.ndarray, np.ndarray]:
    active = np.frombuffer(active_flags, dtype=np.bool_)
    plan = channel_plan(skeleton)
    placing, targeted = np.zeros(len(skeleton), dtype=np.bool_), np.zeros(len(skeleton), dtype=np.bool_)
    for j in range(1, len(skeleton)):
        moves = plan.pos_index[j][plan.pos_index[j] >= 0]
        targeted[j] = bool(active[moves].any()) and skeleton.parents[j] >= 0
        p = skeleton.parents[j]
        while active[moves].any() and p >= 0 and not placing[p]:
            placing[p] = True
            p = skeleton.parents[p]
    for flags in (placing, targeted):
        flags.setflags(write=False)
    return placing, targeted


@kernel
def translation_targets(targets, tree, a, b, active, glob, where, goal_positions, targeted):
    """The active translations (columns of a depth's ``targets (T, k)``) of the tree entries
    ``a:b`` (:class:`TreeArrays`) whose joints are ``targeted``: the ones that restore each
    joint's original position ``goal_positions (T, joints, 3)`` from its parent's decoded
    position ``where`` and orientation ``glob``."""
    wanted = np.empty(3)
    for e in range(a, b):
        j, p = tree.joints[e], tree.parents[e]
        if not targeted[j]:
            continue
        for f in range(targets.shape[0]):
            wanted[0], wanted[1], wanted[2] = rotate_vector(
                glob[p, f, 0], -glob[p, f, 1], -glob[p, f, 2], -glob[p, f, 3],
                goal_positions[f, j, 0] - where[p, f, 0],
                goal_positions[f, j, 1] - where[p, f, 1],
                goal_positions[f, j, 2] - where[p, f, 2],
            )  # fmt: skip
            for m in range(tree.move_ptr[e], tree.move_ptr[e + 1]):
                if active[tree.moves[m]]:
                    axis = tree.move_axes[m]
                    targets[f, tree.move_columns[m]] = wanted[axis] - tree.offsets[j, axis]


@kernel
def place_joints(decoded, tree, a, b, glob, where, placing):
    """The decoded positions ``where`` of the tree entries ``a:b`` whose joints are
    ``placing``: from their decoded translations (columns of the depth's ``decoded (T, k)``) and
    their parents' decoded positions and orientations."""
    bone = np.empty(3)
    for e in range(a, b):
        j, p = tree.joints[e], tree.parents[e]
        if not placing[j]:
            continue
        for f in range(decoded.shape[0]):
            bone[0], bone[1], bone[2] = tree.offsets[j, 0], tree.offsets[j, 1], tree.offsets[j, 2]
            for m in range(tree.move_ptr[e], tree.move_ptr[e + 1]):
                bone[tree.move_axes[m]] += decoded[f, tree.move_columns[m]]
            if p < 0:
                where[j, f, :] = bone
                continue
            q = glob[p, f]
            x, y, z = rotate_vector(q[0], q[1], q[2], q[3], bone[0], bone[1], bone[2])
            where[j, f, 0], where[j, f, 1], where[j, f, 2] = where[p, f, 0] + x, where[p, f, 1] + y, where[p, f, 2] + z


@kernel
def exact_rotation(axis_quat, has_axis, parent, goal):
    """Quaternions ``(T, 4)`` of exactly the local rotation (the one its Euler angles make,
    without the axis pre-rotation) that restores ``goal`` on top of ``parent``:
    ``C^-1 conj(G'_p) G_j C``. For joints coded in another form than their Euler angles, where
    a Gauss-Newton step in Euler angles near a gimbal lock (a proper order's rest pose) would
    not converge."""
    out = np.empty((parent.shape[0], 4))
    cw, cx, cy, cz = axis_quat[0], axis_quat[1], axis_quat[2], axis_quat[3]
    for f in range(parent.shape[0]):
        w, x, y, z = quat_product(
            parent[f, 0], -parent[f, 1], -parent[f, 2], -parent[f, 3], goal[f, 0], goal[f, 1], goal[f, 2], goal[f, 3]
        )
        if has_axis:
            w, x, y, z = quat_product(cw, -cx, -cy, -cz, w, x, y, z)
            w, x, y, z = quat_product(w, x, y, z, cw, cx, cy, cz)
        out[f, 0], out[f, 1], out[f, 2], out[f, 3] = w, x, y, z
    return out


@kernel
def depth_start(tree, d, start, active, goal, glob, skip, where, goal_positions, targeted, plan):
    """``(T, k)``: what depth ``d`` of ``tree`` (:class:`TreeArrays`) codes its channels from:
    their start values, the closed-loop target angles (:func:`depth_targets`, not for ``skip``
    joints) and, where ``where`` holds the decoded positions, the translations that restore the
    ``targeted`` joints' positions (:func:`translation_targets`)."""
    a, b, ca, cb = tree.depth_ptr[d], tree.depth_ptr[d + 1], tree.coded_ptr[d], tree.coded_ptr[d + 1]
    targets = np.empty((start.shape[0], cb - ca))
    for f in range(start.shape[0]):
        for i in range(cb - ca):
            targets[f, i] = start[f, tree.coded[ca + i]]
    depth_targets(
        start, active, goal, glob, tree.joints[a:b], tree.parents[a:b], tree.chans[a:b], tree.columns[a:b],
        tree.steps[a:b], tree.axes[a:b], tree.axis_quats[a:b], tree.has_axis[a:b], skip, targets, a, plan,
    )  # fmt: skip
    if where.shape[0]:
        translation_targets(targets, tree, a, b, active, glob, where, goal_positions, targeted)
    return targets


@kernel
def depth_end(tree, d, decoded, glob, where, placing, steps):
    """After depth ``d`` is coded (``decoded (T, k)``): its joints' decoded orientations
    (:func:`depth_compose` of the joints whose rotation ``steps`` are not 0: ``tree.steps``,
    or fewer where a caller composes some joints itself) and, where ``where`` is kept,
    positions (:func:`place_joints`)."""
    a, b = tree.depth_ptr[d], tree.depth_ptr[d + 1]
    depth_compose(
        decoded, glob, tree.joints[a:b], tree.columns[a:b], steps[a:b], tree.axes[a:b], tree.axis_quats[a:b],
        tree.has_axis[a:b], tree.has_children[a:b],
    )  # fmt: skip
    if where.shape[0]:
        place_joints(decoded, tree, a, b, glob, where, placing)


class TreeLoop(NamedTuple):
    """What a loop down the tree reads and keeps (:func:`tree_loop`), in the order
    :func:`depth_start` and :func:`depth_end` take them: for a compiled loop that codes the
    depths itself (kinwave's passes, kinwave-live's packets)."""

    tree: TreeArrays
    start: np.ndarray  # (T, C) the values each channel is coded from
    active: np.ndarray  # (C,) the channels the coder changes
    goal: np.ndarray  # (T, joints, 4) the original global orientations
    glob: np.ndarray  # (joints, T, 4) the decoded ones, filled depth by depth
    skip: np.ndarray  # (joints,) joints without a closed-loop target
    where: np.ndarray  # (joints or 0, T, 3) the decoded positions kept for the joints below
    goal_positions: np.ndarray  # (T, joints or 0, 3)
    targeted: np.ndarray  # (joints,) joints whose active translations restore their positions
    placing: np.ndarray  # (joints,) joints whose decoded positions are kept
    plan: tuple  # per tree entry: made yet, and its start angles' linearisation (T, 4), (T, 3, 3)


def tree_loop(
    skeleton: Skeleton,
    start: np.ndarray,
    active: np.ndarray,
    goal: np.ndarray,
    closed_loop: bool = True,
    goal_positions: np.ndarray | None = None,
) -> TreeLoop:
    """The arrays of :func:`code_down_tree`'s loop (its arguments as there)."""
    frames = start.shape[0]
    placed = closed_loop and goal_positions is not None
    active = np.ascontiguousarray(active, dtype=np.bool_)
    placing, targeted = placing_joints(skeleton, active if placed else np.zeros_like(active))
    return TreeLoop(
        tree_arrays(skeleton),
        np.ascontiguousarray(start, dtype=np.float64),
        active,
        np.ascontiguousarray(goal, dtype=np.float64),
        np.empty((len(skeleton), frames, 4)),
        np.zeros(len(skeleton), dtype=np.bool_) if closed_loop else np.ones(len(skeleton), dtype=np.bool_),
        np.zeros((len(skeleton) if placing.any() else 0, frames, 3)),
        np.ascontiguousarray(goal_positions if placed else np.zeros((frames, 0, 3)), dtype=np.float64),
        targeted,
        placing,
        _plan(len(skeleton), frames),
    )


def _plan(entries: int, frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Room for every tree entry's :func:`_linearise` of its start angles (the same on every
    pass down the tree: a joint's target changes with its parent's decoded orientation only),
    or none where the loop is longer than PLAN_ENTRY_FRAMES joint-frames."""
    kept = entries if entries * frames <= PLAN_ENTRY_FRAMES else 0
    return (
        np.zeros(entries, dtype=np.bool_),
        np.empty((kept, frames if kept else 0, 4)),
        np.empty((kept, frames if kept else 0, 3, 3)),
    )


def code_down_tree(
    skeleton: Skeleton,
    start: np.ndarray,
    active: np.ndarray,
    goal: np.ndarray,
    code,
    closed_loop: bool = True,
    goal_positions: np.ndarray | None = None,
) -> None:
    """Drive a coder down the tree, the joints of one depth at a time. ``start (T, C)`` holds
    the values each channel is coded from, ``active (C,)`` the channels the coder will change
    (the others keep their start value), ``goal (T, joints, 4)`` the original global
    orientations. With ``closed_loop`` a joint's active angles are replaced by the target that
    restores its goal on top of its parent's *decoded* orientation; with ``goal_positions
    (T, joints, 3)`` (skeleton units) too, a non-root joint's active translations are replaced
    by those that restore its original position from its parent's decoded position and
    orientation (a translated joint below a rotated dummy root), else translations go as they
    are. ``code(channels, targets (T, k))`` codes a depth's channels and returns what the
    decoder will make of them ``(T, k)``. (kinwave's encoder and kinwave-live run the same loop
    compiled, from :func:`tree_arrays` and :func:`tree_loop`: :mod:`mocodec.codecs.kinwave.treepass`,
    :func:`mocodec.codecs.kinwave.live.predict.predict_tree`.)"""
    loop = tree_loop(skeleton, start, active, goal, closed_loop, goal_positions)
    tree = loop.tree
    for d in range(tree.depth_ptr.size - 1):
        targets = depth_start(tree, d, *loop[1:9], loop.plan)
        if not targets.shape[1]:
            continue
        coded = tree.coded[tree.coded_ptr[d] : tree.coded_ptr[d + 1]].copy()  # (the coder's own)
        decoded = np.ascontiguousarray(code(coded, targets), dtype=np.float64)
        depth_end(tree, d, decoded, loop.glob, loop.where, loop.placing, tree.steps)
