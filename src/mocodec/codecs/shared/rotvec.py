"""The form a three-angle joint's rotation is coded in (kinwave.md, "what mattered" 5).

A file's Euler angles are one way to write a joint's rotation, chosen by its exporter; where
they are unfavourable (near their gimbal lock, a proper order at rest, a large constant
turn) a coder does better with another form of the same rotation. Forms, per joint:

* ``0``: the file's own Euler angles (no conversion);
* ``VECTOR`` (1): the rotation vector of ``conj(mean) q``, about a mean rotation of the joint;
* ``2 + k``: Euler angles in the Tait-Bryan order ``CODING_ORDERS[k]``, whatever the file's
  order: a hinge written in a proper order (at its lock) is one angle again;
* ``WORLD + f``: the form ``f`` of ``pre q`` instead of ``q``, ``pre`` a constant rotation the
  coder gives per joint: under a dummy root turned by a constant rotation, the joint's
  rotation as if the dummy were not there, whose angles the file's exporter chose (a vector
  about the mean of ``pre q`` has the same mean, so the same quantised mean, as without the
  dummy; what a local form costs there: docs/kinwave.md).

Rows come three per joint, ``(3n, T)``, degrees. The way back (:func:`from_forms`) runs in a
numba kernel, a joint at a time, so a coder converting a few joints (kinwave's encoder, a tree
depth at a time) and one converting them all (its decoder) get the same floats; it gives the
file's Euler triple nearest the previous frame's (the formula of
:func:`mocodec.rotations.quat_to_euler`, any of the 12 orders).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numba
import numpy as np

from mocodec import rotations
from mocodec.kernels import kernel
from mocodec.motion import follow_nearest

_DEG = math.pi / 180.0
VECTOR = 1
CODING_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
FORMS = 2 + len(CODING_ORDERS)
WORLD = 8  # added to an Euler form: the form of pre q


def valid_forms(forms: np.ndarray) -> bool:
    """Whether every code of ``forms`` names a form."""
    forms = np.asarray(forms)
    return bool(((forms >= 0) & (forms < 2 * WORLD)).all())


@lru_cache(maxsize=1024)
def _axes(orders: tuple[str, ...]) -> np.ndarray:
    """``(n, 3)`` axis indices (0 = X) of each joint's rotation order (shared: read-only)."""
    axes = np.array([["XYZ".index(c) for c in o] for o in orders], dtype=np.int64).reshape(-1, 3)
    axes.setflags(write=False)
    return axes


@numba.njit(inline="always")
def _turn(w, x, y, z, axis, angle_deg):
    """``(w, x, y, z)`` times the rotation by ``angle_deg`` about axis 0, 1 or 2."""
    h = 0.5 * (angle_deg * _DEG)
    c, s = math.cos(h), math.sin(h)
    if axis == 0:
        return w * c - x * s, x * c + w * s, y * c + z * s, z * c - y * s
    if axis == 1:
        return w * c - y * s, x * c - z * s, y * c + w * s, z * c + x * s
    return w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s


@numba.njit(inline="always")
def quat_product(aw, ax, ay, az, bw, bx, by, bz):
    """The Hamilton product of two quaternions, component by component (for numba kernels;
    :func:`mocodec.rotations.quat_multiply` is the array form)."""
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@numba.njit(inline="always")
def rotate_vector(w, x, y, z, vx, vy, vz):
    """Vector (vx, vy, vz) rotated by the unit quaternion (w, x, y, z): ``v + w t + u x t``
    with ``t = 2 u x v``, term for term as :func:`mocodec.rotations.quat_rotate` (for numba
    kernels)."""
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    return vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz, vz + w * tz + x * ty - y * tx


@kernel
def _turn_vectors_kernel(q, v, sign, out):
    for t in range(v.shape[0]):
        out[t, 0], out[t, 1], out[t, 2] = rotate_vector(
            q[t, 0], sign * q[t, 1], sign * q[t, 2], sign * q[t, 3], v[t, 0], v[t, 1], v[t, 2]
        )


def turn_vectors(q: np.ndarray, v: np.ndarray, back: bool = False) -> np.ndarray:
    """``v (T, 3)`` rotated by unit quaternions ``q (T, 4)`` (with ``back``, by their inverse):
    :func:`mocodec.rotations.quat_rotate` in a compiled loop (the same floats)."""
    out = np.empty((v.shape[0], 3))
    _turn_vectors_kernel(np.ascontiguousarray(q), np.ascontiguousarray(v, dtype=np.float64), -1.0 if back else 1.0, out)
    return out


@kernel
def quats_of_euler(euler, axes):
    """Unit quaternions ``(T, n, 4)`` of Euler angles ``(T, n, 3)`` (degrees) about ``axes (n, 3)``."""
    frames, joints = euler.shape[0], euler.shape[1]
    out = np.empty((frames, joints, 4))
    for j in range(joints):
        for t in range(frames):
            w, x, y, z = 1.0, 0.0, 0.0, 0.0
            for k in range(3):
                w, x, y, z = _turn(w, x, y, z, axes[j, k], euler[t, j, k])
            out[t, j, 0], out[t, j, 1], out[t, j, 2], out[t, j, 3] = w, x, y, z
    return out


@numba.njit(inline="always")
def _vector_rows(q, mean, out):
    """Rotation vectors (degrees) ``out (T, 3)`` of one joint's quaternions ``q (T, 4)`` about
    its mean (conj(mean) q), signs made continuous in time from a frame 0 on the short way
    round."""
    mw, mx, my, mz = mean[0], -mean[1], -mean[2], -mean[3]
    sign = 1.0
    lw, lx, ly, lz = 0.0, 0.0, 0.0, 0.0
    for t in range(q.shape[0]):
        w, x, y, z = quat_product(mw, mx, my, mz, q[t, 0], q[t, 1], q[t, 2], q[t, 3])
        if t == 0:
            sign = 1.0 if w >= 0.0 else -1.0  # frame 0 turns by at most 180 degrees
        elif w * lw + x * lx + y * ly + z * lz < 0.0:
            sign = -sign
        lw, lx, ly, lz = w, x, y, z
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = sign * w / norm, sign * x / norm, sign * y / norm, sign * z / norm
        vn = math.sqrt(x * x + y * y + z * z)
        scale = 2.0 * (1.0 if vn < 1e-12 else math.atan2(vn, w) / vn) / _DEG
        out[t, 0], out[t, 1], out[t, 2] = x * scale, y * scale, z * scale


@numba.njit(inline="always")
def _order(axes_j):
    """The extrinsic sequence (i, j, k) of an intrinsic order's axes, whether it is proper,
    and the permutation's sign: the set-up of Bernardes and Viollet's formula."""
    i, jj, k = axes_j[2], axes_j[1], axes_j[0]
    proper = i == k
    if proper:
        k = 3 - i - jj
    return i, jj, k, proper, (i - jj) * (jj - k) * (k - i) / 2.0


@numba.njit(inline="always")
def _euler_of(q, i, jj, k, proper, eps, angles, t):
    """Row ``t`` of ``angles``: the Euler triple (degrees, principal range) of quaternion ``q``."""
    w, qi, qj, qk = q[0], q[1 + i], q[1 + jj], q[1 + k]
    if proper:
        a, b, c, d = w, qi, qj, qk * eps
    else:
        a, b, c, d = w - qj, qi + qk * eps, qj + w, qk * eps - qi
    theta2 = 2.0 * math.atan2(math.sqrt(c * c + d * d), math.sqrt(a * a + b * b))
    plus, minus = math.atan2(b, a), math.atan2(d, c)
    if proper:
        triple = (plus + minus, theta2, plus - minus)
    else:
        triple = ((plus + minus) * eps, theta2 - math.pi / 2.0, plus - minus)
    for m in range(3):  # into [-180, 180): Python's float modulo, without its fmod (the
        # triple lies within a turn of the range, where one turn on or off is exact)
        wrapped = triple[m] + math.pi
        if wrapped >= 2.0 * math.pi:
            wrapped -= 2.0 * math.pi
        elif wrapped < 0.0:
            wrapped += 2.0 * math.pi
        angles[t, m] = (wrapped - math.pi) / _DEG


@kernel
def quats_of_forms(values, form_axes, vector, means, world, pre):
    """Quaternions ``(T, n, 4)`` of rotations coded as rotation vectors (``vector[j]``) or Euler
    angles about ``form_axes[j]`` (degrees), each times its mean ``means[j]`` on the left, and
    where ``world[j]`` then by conj(``pre[j]``)."""
    frames, joints = values.shape[0], values.shape[1]
    out = np.empty((frames, joints, 4))
    for j in range(joints):
        for t in range(frames):
            if vector[j]:
                vx, vy, vz = values[t, j, 0] * _DEG / 2.0, values[t, j, 1] * _DEG / 2.0, values[t, j, 2] * _DEG / 2.0
                n = math.sqrt(vx * vx + vy * vy + vz * vz)
                sinc = 1.0 if n < 1e-12 else math.sin(n) / n
                rw, rx, ry, rz = math.cos(n), vx * sinc, vy * sinc, vz * sinc
            else:
                rw, rx, ry, rz = 1.0, 0.0, 0.0, 0.0
                for m in range(3):
                    rw, rx, ry, rz = _turn(rw, rx, ry, rz, form_axes[j, m], values[t, j, m])
            rw, rx, ry, rz = quat_product(means[j, 0], means[j, 1], means[j, 2], means[j, 3], rw, rx, ry, rz)
            if world[j]:
                rw, rx, ry, rz = quat_product(pre[j, 0], -pre[j, 1], -pre[j, 2], -pre[j, 3], rw, rx, ry, rz)
            out[t, j, 0], out[t, j, 1], out[t, j, 2], out[t, j, 3] = rw, rx, ry, rz
    return out


@kernel
def forms_of_quats(quats, vector, means, axes, world, pre):
    """Coding-form values ``(T, n, 3)`` of quaternions ``(T, n, 4)``: each joint's rotation,
    where ``world[j]`` first turned by ``pre[j]`` on the left, as a rotation vector about
    ``means[j]`` (``vector[j]``) or as Euler angles about ``axes[j]`` continuous in time."""
    frames, joints = quats.shape[0], quats.shape[1]
    out = np.empty((frames, joints, 3))
    turned = np.empty((frames, 4))
    angles = np.empty((frames, 3))
    for j in range(joints):
        for t in range(frames):
            w, x, y, z = quats[t, j, 0], quats[t, j, 1], quats[t, j, 2], quats[t, j, 3]
            if world[j]:
                w, x, y, z = quat_product(pre[j, 0], pre[j, 1], pre[j, 2], pre[j, 3], w, x, y, z)
            turned[t, 0], turned[t, 1], turned[t, 2], turned[t, 3] = w, x, y, z
        if vector[j]:
            _vector_rows(turned, means[j], out[:, j])
            continue
        i, jj, k, proper, eps = _order(axes[j])
        for t in range(frames):
            _euler_of(turned[t], i, jj, k, proper, eps, angles, t)
        out[:, j, :] = follow_nearest(angles, proper)
    return out


@kernel
def euler_of_quats(quats, axes):
    """Euler angles (degrees, each joint's triples continuous in time) of quaternions
    ``(T, n, 4)`` in the orders ``axes (n, 3)``."""
    frames, joints = quats.shape[0], quats.shape[1]
    out = np.empty((frames, joints, 3))
    angles = np.empty((frames, 3))
    for j in range(joints):
        i, jj, k, proper, eps = _order(axes[j])
        for t in range(frames):
            _euler_of(quats[t, j], i, jj, k, proper, eps, angles, t)
        out[:, j, :] = follow_nearest(angles, proper)
    return out


def _per_joint(rows: np.ndarray) -> np.ndarray:
    """``(3n, T)`` rows as ``(T, n, 3)``."""
    return np.ascontiguousarray(rows.T.reshape(rows.shape[1], -1, 3), dtype=np.float64)


def _rows(values: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_per_joint`."""
    return values.reshape(values.shape[0], -1).T


def euler_quats(rows: np.ndarray, orders: tuple[str, ...]) -> np.ndarray:
    """Unit quaternions ``(T, n, 4)`` of the joints' Euler angle rows."""
    return quats_of_euler(_per_joint(rows), _axes(orders))


def _identity_means(n: int) -> np.ndarray:
    means = np.zeros((n, 4))
    means[:, 0] = 1.0
    return means


def mean_codes(quats: np.ndarray, quantum: float, least: float) -> np.ndarray:
    """``(n, 3)`` integers: each joint's mean rotation over time (the normalised mean of its
    sign-aligned quaternions ``(T, n, 4)``) as a rotation vector in steps of ``quantum``
    degrees; zero for a joint whose mean turns less than ``least`` degrees."""
    aligned = np.where((np.sum(quats * quats[:1], axis=2) < 0.0)[..., None], -quats, quats)
    mean = rotations.quat_normalize(aligned.mean(axis=0))
    mean = np.where(mean[:, :1] < 0.0, -mean, mean)
    vector = np.degrees(2.0 * rotations.quat_log(mean))
    codes = np.round(vector / quantum).astype(np.int64)
    codes[np.linalg.norm(vector, axis=1) < least] = 0
    return codes


def mean_quats(codes: np.ndarray, quantum: float) -> np.ndarray:
    """Unit quaternions ``(n, 4)`` of :func:`mean_codes`' integers: the same floats on both
    ends of a coder."""
    return rotations.quat_exp(np.radians(np.asarray(codes, dtype=np.float64) * quantum) / 2.0)


def _form_axes(forms: np.ndarray, orders: tuple[str, ...]) -> np.ndarray:
    """Each Euler form's axes: a coding order, or the file's own (form 0, WORLD)."""
    base = np.asarray(forms) % WORLD
    return _axes(tuple(CODING_ORDERS[f - 2] if f >= 2 else o for f, o in zip(base, orders)))


class FormSet:
    """Joints in their coding forms, with what the conversions need worked out once: a coder
    converting the same joints many times (kinwave's encoder, once per depth and pass) pays
    for the set-up once. ``means (n, 4)`` are the vector joints' mean rotations (ignored for
    Euler forms)."""

    def __init__(self, orders: tuple[str, ...], forms: np.ndarray, means: np.ndarray):
        forms = np.asarray(forms, dtype=np.int64)
        self.vector = forms % WORLD == VECTOR
        self.world = forms >= WORLD
        self.unturned = np.zeros_like(self.world)
        self.file_axes = _axes(tuple(orders))
        self.form_axes = _form_axes(forms, tuple(orders))
        self.means = np.ascontiguousarray(np.where(self.vector[:, None], means, _identity_means(len(orders))))

    def _turns(self, pre: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Which joints ``pre (n, 4)`` turns (the WORLD ones, none without it), and the turns."""
        if pre is None:
            return self.unturned, self.means
        return self.world, np.ascontiguousarray(pre, dtype=np.float64)

    def kernel_arguments(self, pre: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """``(vector, means, form_axes, world, turns, file_axes)``: what :func:`forms_of_quats`,
        :func:`quats_of_forms` and :func:`euler_of_quats` take for these joints, for a compiled
        caller that converts them itself (:meth:`to_forms` and :meth:`from_forms` in one)."""
        world, turns = self._turns(pre)
        return self.vector, self.means, self.form_axes, world, turns, self.file_axes

    def to_forms(self, rows: np.ndarray, quats: np.ndarray | None = None, pre: np.ndarray | None = None) -> np.ndarray:
        """File-order Euler angle rows ``(3n, T)`` in each joint's coding form, continuous in
        time; ``pre (n, 4)`` the WORLD joints' turns. ``quats (T, n, 4)``, when given, are the
        rotations themselves (``rows`` is then unused)."""
        if quats is None:
            quats = quats_of_euler(_per_joint(rows), self.file_axes)
        world, turns = self._turns(pre)
        return _rows(forms_of_quats(np.ascontiguousarray(quats), self.vector, self.means, self.form_axes, world, turns))

    def quats(self, rows: np.ndarray, pre: np.ndarray | None = None) -> np.ndarray:
        """The rotations ``(T, n, 4)`` of rows in the coding forms (:meth:`from_forms` without
        the Euler angles: what a measure of rotation error needs)."""
        world, turns = self._turns(pre)
        return quats_of_forms(_per_joint(rows), self.form_axes, self.vector, self.means, world, turns)

    def from_forms(self, rows: np.ndarray, pre: np.ndarray | None = None) -> np.ndarray:
        """Inverse of :meth:`to_forms`: file-order Euler angle rows, each joint's triples as
        continuous as the Euler form allows (frame 0 in the principal range)."""
        return _rows(euler_of_quats(self.quats(rows, pre), self.file_axes))


def to_forms(
    rows: np.ndarray,
    orders: tuple[str, ...],
    forms: np.ndarray,
    means: np.ndarray,
    quats: np.ndarray | None = None,
    pre: np.ndarray | None = None,
) -> np.ndarray:
    """:meth:`FormSet.to_forms` for one conversion."""
    return FormSet(orders, forms, means).to_forms(rows, quats, pre)


def from_forms(
    rows: np.ndarray, orders: tuple[str, ...], forms: np.ndarray, means: np.ndarray, pre: np.ndarray | None = None
) -> np.ndarray:
    """:meth:`FormSet.from_forms` for one conversion."""
    return FormSet(orders, forms, means).from_forms(rows, pre)


def form_quats(
    rows: np.ndarray, orders: tuple[str, ...], forms: np.ndarray, means: np.ndarray, pre: np.ndarray | None = None
) -> np.ndarray:
    """:meth:`FormSet.quats` for one conversion."""
    return FormSet(orders, forms, means).quats(rows, pre)


def near_lock(rows: np.ndarray, orders: tuple[str, ...], margin_deg: float) -> np.ndarray:
    """Per joint (Euler angle rows, three per joint), whether its middle angle ever comes
    within ``margin_deg`` of its order's gimbal lock (90 for Tait-Bryan orders, 0 or 180 for
    proper ones, which sit there at rest)."""
    middle = np.radians(rows[1::3])
    proper = np.array([o[0] == o[2] for o in orders], dtype=bool)
    closeness = np.empty_like(middle)
    closeness[proper] = np.abs(np.sin(middle[proper]))  # (each joint's one function only)
    closeness[~proper] = np.abs(np.cos(middle[~proper]))
    return closeness.min(axis=1, initial=1.0) < math.sin(math.radians(margin_deg))


@kernel
def _mean_distances_kernel(a, b, out):
    for e in range(a.shape[1]):
        total = 0.0
        for t in range(a.shape[0]):
            na = np.sqrt(a[t, e, 0] ** 2 + a[t, e, 1] ** 2 + a[t, e, 2] ** 2 + a[t, e, 3] ** 2)
            nb = np.sqrt(b[t, e, 0] ** 2 + b[t, e, 1] ** 2 + b[t, e, 2] ** 2 + b[t, e, 3] ** 2)
            dot = (a[t, e, 0] / na) * (b[t, e, 0] / nb) + (a[t, e, 1] / na) * (b[t, e, 1] / nb)
            dot += (a[t, e, 2] / na) * (b[t, e, 2] / nb)
            dot += (a[t, e, 3] / na) * (b[t, e, 3] / nb)
            total += np.arccos(min(max(2.0 * dot * dot - 1.0, -1.0), 1.0))
        out[e] = total / a.shape[0]


def mean_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(E,)``: the mean over the frames of :func:`rotations.quat_distance` of quaternions
    ``a`` and ``b`` ``(T, E, 4)``, in one compiled loop (the same floats)."""
    out = np.empty(a.shape[1])
    _mean_distances_kernel(np.ascontiguousarray(a), np.ascontiguousarray(b), out)
    return out
