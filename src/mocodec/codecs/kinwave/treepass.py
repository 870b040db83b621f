"""kinwave's pass down the tree in one compiled call: the loop of
:func:`mocodec.codecs.shared.closedloop.code_down_tree` (its steps before and after a depth's
coding, :func:`closedloop.depth_start` and :func:`closedloop.depth_end`: closed-loop targets,
translations restored from the parent's decoded position, decoded orientations and positions
for the children) with each depth's coding (:func:`channelcode.depth_kernel`: coding forms, world-axis
translations, isolated frames, quantisation and reconstruction) inside it. The joints in a
coding form take their closed-loop target as a rotation (:func:`closedloop.exact_rotation`)
rather than as angles; a WORLD form's turn and a world-axis translation's come from the
orientations of the decoded rows above at frame 0, as the decoder computes them
(:func:`body.parent_orientations`, :func:`body.parent_turns`). The same floats as that loop
driven from Python one depth at a time, without a Python call per depth: a short clip's pass
was mostly calls (docs/kinwave.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from mocodec.codecs.kinwave.body import MEAN_QUANTUM, three_angle_groups, turn_setup
from mocodec.codecs.kinwave.channelcode import coder_arguments, constant_knot, constant_value, depth_kernel
from mocodec.codecs.shared import rotvec
from mocodec.codecs.shared.closedloop import depth_end, depth_start, exact_rotation, tree_arrays, tree_loop
from mocodec.codecs.shared.rotvec import quat_product, quats_of_euler
from mocodec.coding.transforms import trendwave
from mocodec.kernels import kernel
from mocodec.kinematics import channel_plan, frame_orientations

if TYPE_CHECKING:
    from mocodec.codecs.kinwave.encoder import Encoder


class DepthCoding(NamedTuple):
    """What kinwave codes at each depth, flattened beside :class:`closedloop.TreeArrays`: per
    coded channel its constant flag and constant's coding; per depth the rows (among its
    channels) that go through :func:`channelcode.depth_kernel` (``kernel_ptr``) and the
    constant ones held at their first knot beside it (``held_ptr``: not in a coding form nor
    on the world's axes); per joint in a coding form (a depth's between consecutive
    ``form_ptr``) its rows among the depth's kernel rows, its form's arrays
    (:meth:`rotvec.FormSet.kernel_arguments`), its joint, three-angle group and tree entry,
    and whether the closed loop gives its rotation; per translation on the world's axes its
    joint and kernel rows; per depth whether it needs the decoded rows' orientations above it."""

    const: np.ndarray
    fraction: np.ndarray
    base: np.ndarray
    kernel_ptr: np.ndarray
    kernel_rows: np.ndarray
    held_ptr: np.ndarray
    held_rows: np.ndarray
    form_ptr: np.ndarray
    form_rows: np.ndarray  # (3 n,)
    vector: np.ndarray
    means: np.ndarray
    form_axes: np.ndarray
    world: np.ndarray
    file_axes: np.ndarray
    form_group: np.ndarray
    form_entry: np.ndarray
    form_exact: np.ndarray
    moved_ptr: np.ndarray
    moved_joints: np.ndarray
    moved_rows: np.ndarray  # (m, 3)
    turned: np.ndarray  # (D,)
    has_world: np.ndarray  # (D,)


def depth_coding(enc: Encoder) -> DepthCoding:
    """:class:`DepthCoding` of an encoder's body: its constants, its three-angle joints in
    another form than their file's angles (:class:`rotvec.FormSet`, depth by depth, in the
    order of :func:`body.three_angle_groups`) and its translations on the world's axes, each
    placed among its depth's coded channels."""
    sk, tree = enc.skeleton, tree_arrays(enc.skeleton)
    depth_of = np.repeat(np.arange(tree.coded_ptr.size - 1), np.diff(tree.coded_ptr))
    depth, row = np.empty(sk.num_channels, dtype=np.int64), np.empty(sk.num_channels, dtype=np.int64)
    depth[tree.coded], row[tree.coded] = depth_of, np.arange(tree.coded.size) - tree.coded_ptr[depth_of]
    groups = three_angle_groups(sk)
    coded = [k for k in range(len(groups)) if len(enc.forms) and enc.forms[k]]
    coded.sort(key=lambda k: depth[groups[k][0][0]])  # (stable: group order within a depth)
    forms = rotvec.FormSet(
        tuple(groups[k][1] for k in coded),
        enc.forms[coded] if coded else np.zeros(0, dtype=np.int64),
        rotvec.mean_quats(enc.means[coded], MEAN_QUANTUM) if coded else np.zeros((0, 4)),
    )
    joints = [int(sk.channel_joints[groups[k][0][0]]) for k in coded]
    entry = {j: e for e, j in enumerate(tree.joints.tolist())}
    moved = sorted(enc.world_translations, key=lambda jp: depth[jp[1][0]])
    depths = tree.coded_ptr.size - 1
    form_depths = np.array([depth[groups[k][0][0]] for k in coded], dtype=np.int64)
    moved_depths = np.array([depth[pos[0]] for _, pos in moved], dtype=np.int64)
    has_world = np.zeros(depths, dtype=np.bool_)
    has_world[form_depths[forms.world]] = True
    turned = has_world.copy()
    turned[moved_depths] = True
    const = np.ascontiguousarray(enc.const[tree.coded], dtype=np.bool_)
    place = np.empty(sk.num_channels, dtype=np.int64)  # each channel's place in tree.coded
    place[tree.coded] = np.arange(tree.coded.size)
    kernel = ~const
    kernel[place[[c for k in coded for c in groups[k][0]]]] = True
    kernel[place[[c for _, pos in moved for c in pos]]] = True
    kernel_ptr = np.concatenate(([0], np.cumsum(np.bincount(depth_of[kernel], minlength=depths)))).astype(np.int64)
    kernel_row: np.ndarray = np.cumsum(kernel) - kernel - kernel_ptr[depth_of]  # among its depth's kernel rows
    return DepthCoding(
        const,
        np.ascontiguousarray(enc.constants.fraction[tree.coded], dtype=np.float64),
        np.ascontiguousarray(enc.constants.base[tree.coded], dtype=np.float64),
        kernel_ptr,
        row[tree.coded][kernel],
        tree.coded_ptr - kernel_ptr,  # the held rows before each depth
        row[tree.coded][~kernel],
        np.searchsorted(form_depths, np.arange(depths + 1)).astype(np.int64),
        np.array([kernel_row[place[c]] for k in coded for c in groups[k][0]], dtype=np.int64),
        forms.vector,
        forms.means,
        forms.form_axes,
        forms.world,
        forms.file_axes,
        np.array(coded, dtype=np.int64),
        np.array([entry[j] for j in joints], dtype=np.int64),
        np.array([enc.cfg["closed_loop"] and sk.parents[j] >= 0 for j in joints], dtype=np.bool_),
        np.searchsorted(moved_depths, np.arange(depths + 1)).astype(np.int64),
        np.array([j for j, _ in moved], dtype=np.int64),
        np.array([[kernel_row[place[c]] for c in pos] for _, pos in moved], dtype=np.int64).reshape(-1, 3),
        turned,
        has_world,
    )


class TreePass:
    """An encoder's passes in one compiled call each (:meth:`run`), with what no pass changes
    set up once: the closed loop's arrays, the depths' coding, the skeleton's forward
    kinematics and WORLD turns."""

    def __init__(self, enc: Encoder):
        sk = enc.skeleton
        self.coding = depth_coding(enc)
        closed = bool(enc.cfg["closed_loop"])
        self.loop = tree_loop(sk, enc.by_frame, ~enc.const, enc.quats, closed, enc.goal_positions)
        if closed:  # the joints in a coding form: no target angles (their rotations instead)
            flagged = np.zeros(len(sk), dtype=np.bool_)
            flagged[self.loop.tree.joints[self.coding.form_entry]] = True
            self.loop = self.loop._replace(skip=flagged)
        self.kinematics = channel_plan(sk).arrays()
        group_joints, group_axis, c = turn_setup(sk)
        turns = np.tile([1.0, 0.0, 0.0, 0.0], (group_joints.size, 1))
        turns[group_axis] = c
        self.turns = (group_joints, np.ascontiguousarray(group_axis), turns)
        self.isolated = np.ascontiguousarray(enc.isolated, dtype=np.int64)
        steps = self.loop.tree.steps.copy()  # what depth_compose composes from decoded angles:
        steps[self.coding.form_entry] = 0  # not the joints in a coding form (_compose_forms)
        self.compose_steps = steps

    def run(
        self,
        steps: np.ndarray,
        factors: tuple[np.ndarray, np.ndarray, np.ndarray],
        lay: trendwave.Layout,
        deadzone: float,
        seam_limit: float,
        half_width: int,
        far_steps: float,
        every_frame: bool,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One pass at channel ``steps (C,)``: knots, coefficients, decoded channels ``(C, T)``
        and the isolated frames' patches (:func:`channelcode.code_depth`'s arguments). Without
        ``every_frame`` the rows of the joints in a coding form are decoded at frame 0 only:
        a pass measured from the loop's decoded orientations (``loop.glob``) needs no more."""
        return _tree_pass(
            self.loop,
            self.coding,
            self.kinematics,
            self.turns,
            np.ascontiguousarray(steps, dtype=np.float64),
            (factors[0], factors[1], np.asarray(factors[2], dtype=np.float64)),
            self.isolated,
            coder_arguments(lay, deadzone, seam_limit, half_width, far_steps),
            (int(lay.num_knots), int(lay.num_coeffs)),
            self.compose_steps,
            every_frame,
        )


@kernel
def _orientations_above(decoded, kinematics):
    """``(joints, 4)``: each joint's parent's orientation in frame 0 of the decoded rows so far
    (the identity for a root), as :func:`body.parent_orientations` gives it."""
    parents = kinematics[6]
    above = np.zeros((parents.size, 4))
    orientations = frame_orientations(decoded[:, 0].copy(), *kinematics)
    for j in range(parents.size):
        if parents[j] >= 0:
            above[j, :] = orientations[parents[j]]
        else:
            above[j, 0] = 1.0
    return above


@kernel
def _form_rotations(values, tree, coding, fa, fb, glob, goal):
    """``(T, n, 4)``: the rotations of the depth's joints in coding forms ``fa:fb``: their
    closed-loop targets where the loop gives them (:func:`closedloop.exact_rotation`), else
    those of their file's angles in ``values (k, T)``."""
    frames, n = values.shape[1], fb - fa
    quats = np.empty((frames, n, 4))
    if not coding.form_exact[fa:fb].all():
        euler = np.empty((frames, n, 3))
        for v in range(n):
            for m in range(3):
                for f in range(frames):
                    euler[f, v, m] = values[coding.form_rows[3 * (fa + v) + m], f]
        quats = quats_of_euler(euler, coding.file_axes[fa:fb])
    for v in range(n):
        if coding.form_exact[fa + v]:
            e = coding.form_entry[fa + v]
            j = tree.joints[e]
            quats[:, v, :] = exact_rotation(tree.axis_quats[e], tree.has_axis[e], glob[j], goal[:, j])
    return quats


@kernel
def _world_turns(coding, d, fa, fb, above, turns):
    """Which of the depth's joints in coding forms ``fa:fb`` a WORLD form turns, and the turns
    ``conj(C) G_p C`` (:func:`body.parent_turns`; the forms' means where none)."""
    n = fb - fa
    turned = np.zeros(n, dtype=np.bool_)
    pre = coding.means[fa:fb].copy()
    if not coding.has_world[d]:
        return turned, pre
    group_joints, group_axis, group_turns = turns
    turned[:] = coding.world[fa:fb]
    for v in range(n):
        g = coding.form_group[fa + v]
        q = above[group_joints[g]]
        w, x, y, z = q[0], q[1], q[2], q[3]
        if group_axis[g]:
            c = group_turns[g]
            w, x, y, z = quat_product(w, x, y, z, c[0], c[1], c[2], c[3])
            w, x, y, z = quat_product(c[0], -c[1], -c[2], -c[3], w, x, y, z)
        pre[v, 0], pre[v, 1], pre[v, 2], pre[v, 3] = w, x, y, z
    return turned, pre


@kernel
def _compose_forms(glob, rotations, tree, coding, fa, fb):
    """The decoded orientations of a depth's joints in coding forms ``fa:fb`` (with children)
    from their decoded rotations ``(T, n, 4)`` (:func:`rotvec.quats_of_forms`, the rotation
    their Euler angles make without the axis pre-rotation C): ``G_j = G_p C q C^-1``, what
    :func:`closedloop.depth_compose` makes of the angles the decoder writes, up to rounding
    (a test checks a pass's errors against the decoder's output, and every final body is
    checked on the real decoder), without going to the angles and back."""
    for v in range(fb - fa):
        e = coding.form_entry[fa + v]
        if not tree.has_children[e]:
            continue
        j = tree.joints[e]
        cw, cx, cy, cz = tree.axis_quats[e, 0], tree.axis_quats[e, 1], tree.axis_quats[e, 2], tree.axis_quats[e, 3]
        for f in range(rotations.shape[0]):
            w, x, y, z = rotations[f, v, 0], rotations[f, v, 1], rotations[f, v, 2], rotations[f, v, 3]
            if tree.has_axis[e]:
                w, x, y, z = quat_product(cw, cx, cy, cz, w, x, y, z)
                w, x, y, z = quat_product(w, x, y, z, cw, -cx, -cy, -cz)
            glob[j, f, 0], glob[j, f, 1], glob[j, f, 2], glob[j, f, 3] = quat_product(
                glob[j, f, 0], glob[j, f, 1], glob[j, f, 2], glob[j, f, 3], w, x, y, z
            )


@kernel
def _tree_pass(loop, coding, kinematics, turns, steps, factors, isolated, coder, sizes, compose_steps, every_frame):
    """:meth:`TreePass.run` (``loop``: :func:`closedloop.tree_loop`'s arrays, whose decoded
    orientations and positions each pass writes before it reads them; ``coder``:
    :func:`channelcode.coder_arguments`, ``sizes``: the layout's knots and coefficients;
    ``compose_steps``: the tree's rotation steps, 0 for the joints in a coding form, whose
    orientations come from their decoded rotations, :func:`_compose_forms`)."""
    tree, start, active, goal, glob, skip, where, goal_positions, targeted, placing, plan = loop
    num_knots, num_coeffs = sizes
    frames, channels = start.shape
    count = tree.offsets.shape[0]
    knots = np.zeros((channels, num_knots), dtype=np.int64)
    coeffs = np.zeros((channels, num_coeffs), dtype=np.int64)
    decoded = np.zeros((channels, frames))  # zeros: a WORLD form's turn reads the rows above it
    patches = np.zeros((channels, isolated.size), dtype=np.int64)
    for d in range(tree.depth_ptr.size - 1):
        ca, cb = tree.coded_ptr[d], tree.coded_ptr[d + 1]
        targets = depth_start(tree, d, start, active, goal, glob, skip, where, goal_positions, targeted, plan)
        if cb == ca:
            continue
        fa, fb, ma, mb = coding.form_ptr[d], coding.form_ptr[d + 1], coding.moved_ptr[d], coding.moved_ptr[d + 1]
        above = _orientations_above(decoded, kinematics) if coding.turned[d] and frames else np.zeros((count, 4))
        rows = coding.kernel_rows[coding.kernel_ptr[d] : coding.kernel_ptr[d + 1]] + ca  # (in tree.coded)
        values = np.empty((rows.size, frames))
        for i in range(rows.size):
            values[i, :] = targets[:, rows[i] - ca]
        quats = _form_rotations(values, tree, coding, fa, fb, glob, goal)
        turned, pre = _world_turns(coding, d, fa, fb, above, turns)
        moved_turns = np.empty((mb - ma, 4))
        for i in range(mb - ma):
            moved_turns[i, :] = above[coding.moved_joints[ma + i]]
        k_int, c_int, out, patch, rotations = depth_kernel(
            values, coding.form_rows[3 * fa : 3 * fb], quats,
            (coding.vector[fa:fb], coding.means[fa:fb], coding.form_axes[fa:fb], turned, pre, coding.file_axes[fa:fb]),
            coding.moved_rows[ma:mb], moved_turns, isolated, coding.const[rows], steps[tree.coded[rows]],
            coding.fraction[rows], coding.base[rows], factors, coder, every_frame,
        )  # fmt: skip
        depth = np.empty((frames, cb - ca))  # the depth's decoded rows, for depth_end
        for i in range(rows.size):
            c = tree.coded[rows[i]]
            knots[c, :] = k_int[i]
            coeffs[c, :] = c_int[i]
            patches[c, :] = patch[i]
            decoded[c, :] = out[i]
            depth[:, rows[i] - ca] = out[i]
        for r in coding.held_rows[coding.held_ptr[d] : coding.held_ptr[d + 1]]:
            c, at = tree.coded[ca + r], ca + r
            _hold(knots, decoded, depth, r, c, targets, steps[c] * coding.fraction[at], coding.base[at])
        depth_end(tree, d, depth, glob, where, placing, compose_steps)
        _compose_forms(glob, rotations, tree, coding, fa, fb)  # (placing reads the depths above only)
    return knots, coeffs, decoded, patches


@kernel
def _hold(knots, decoded, depth, r, c, targets, quantum, base):
    """A constant row outside the depth kernel (row ``r`` of the depth, channel ``c``): its
    knots and decoded value as :func:`channelcode.quantise` and :func:`channelcode.reconstruct`
    make them (no coefficients, no patches, nothing at a seam)."""
    knots[c, :] = constant_knot(targets[:, r], base, quantum)
    value = constant_value(knots[c, 0], base, quantum)
    decoded[c, :] = value
    depth[:, r] = value
