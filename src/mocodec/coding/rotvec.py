"""Joint rotations as rotation vectors instead of Euler angles (kinwave.md, "what mattered" 5).

A joint's rotation as one turn about one axis: its three numbers move less jointly than Euler
angles do when a joint swings far, so they cost fewer bytes to code (BVH joints, 9-12%). Rows
come three per joint, ``(3n, T)``, in each joint's rotation order (any of the 12), degrees. The conversions run in numba kernels, a joint at a time, so a coder converting a few
joints (kinwave's encoder, a tree depth at a time) and one converting them all (its decoder)
get the same floats; they compute what :mod:`mocodec.rotations` does (``euler_to_quat``,
``quat_continuous``, ``quat_log`` and back, ``quat_to_euler``), to rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from mocodec import rotations
from mocodec.motion import follow_nearest

_DEG = math.pi / 180.0


def _axes(orders: tuple[str, ...]) -> np.ndarray:
    """``(n, 3)`` axis indices (0 = X) of each joint's rotation order."""
    return np.array([["XYZ".index(c) for c in o] for o in orders], dtype=np.int64).reshape(-1, 3)


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
def _product(aw, ax, ay, az, bw, bx, by, bz):
    """The Hamilton product of two quaternions."""
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


@numba.njit(cache=True)
def _quats_kernel(euler, axes):
    frames, joints = euler.shape[0], euler.shape[1]
    out = np.empty((frames, joints, 4))
    for j in range(joints):
        for t in range(frames):
            w, x, y, z = 1.0, 0.0, 0.0, 0.0
            for k in range(3):
                w, x, y, z = _turn(w, x, y, z, axes[j, k], euler[t, j, k])
            out[t, j, 0], out[t, j, 1], out[t, j, 2], out[t, j, 3] = w, x, y, z
    return out


@numba.njit(cache=True)
def _vectors_kernel(q):
    """Rotation vectors (degrees) of quaternions ``(T, n, 4)``, signs made continuous in time."""
    frames, joints = q.shape[0], q.shape[1]
    out = np.empty((frames, joints, 3))
    for j in range(joints):
        sign = 1.0
        for t in range(frames):
            if t > 0 and (q[t, j, 0] * q[t - 1, j, 0] + q[t, j, 1] * q[t - 1, j, 1] + q[t, j, 2] * q[t - 1, j, 2]
                          + q[t, j, 3] * q[t - 1, j, 3]) < 0.0:
                sign = -sign
            w, x, y, z = q[t, j, 0], q[t, j, 1], q[t, j, 2], q[t, j, 3]
            norm = math.sqrt(w * w + x * x + y * y + z * z)
            w, x, y, z = sign * w / norm, sign * x / norm, sign * y / norm, sign * z / norm
            vn = math.sqrt(x * x + y * y + z * z)
            scale = 2.0 * (1.0 if vn < 1e-12 else math.atan2(vn, w) / vn) / _DEG
            out[t, j, 0], out[t, j, 1], out[t, j, 2] = x * scale, y * scale, z * scale
    return out


@numba.njit(cache=True)
def _euler_kernel(vectors, axes, means):
    """Euler angles (degrees, each joint's triples continuous in time) of rotation vectors, in
    Tait-Bryan or proper orders (the formula of :func:`mocodec.rotations.quat_to_euler`)."""
    frames, joints = vectors.shape[0], vectors.shape[1]
    out = np.empty((frames, joints, 3))
    angles = np.empty((frames, 3))
    for j in range(joints):
        i, jj, k = axes[j, 2], axes[j, 1], axes[j, 0]          # the extrinsic sequence: reversed
        proper = i == k
        if proper:
            k = 3 - i - jj
        eps = (i - jj) * (jj - k) * (k - i) / 2.0
        for t in range(frames):
            vx, vy, vz = vectors[t, j, 0] * _DEG / 2.0, vectors[t, j, 1] * _DEG / 2.0, vectors[t, j, 2] * _DEG / 2.0
            n = math.sqrt(vx * vx + vy * vy + vz * vz)
            sinc = 1.0 if n < 1e-12 else math.sin(n) / n
            q = _product(means[j, 0], means[j, 1], means[j, 2], means[j, 3],
                         math.cos(n), vx * sinc, vy * sinc, vz * sinc)
            w, qi, qj, qk = q[0], q[1 + i], q[1 + jj], q[1 + k]
            if proper:
                a, b, c, d = w, qi, qj, qk * eps
            else:
                a, b, c, d = w - qj, qi + qk * eps, qj + w, qk * eps - qi
            theta2 = 2.0 * math.atan2(math.hypot(c, d), math.hypot(a, b))
            plus, minus = math.atan2(b, a), math.atan2(d, c)
            if proper:
                triple = (plus + minus, theta2, plus - minus)
            else:
                triple = ((plus + minus) * eps, theta2 - math.pi / 2.0, plus - minus)
            for m in range(3):
                angles[t, m] = (((triple[m] + math.pi) % (2.0 * math.pi)) - math.pi) / _DEG
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
    return _quats_kernel(_per_joint(rows), _axes(orders))


def vector_quats(rows: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(T, n, 4)`` of the joints' rotation vector rows."""
    return rotations.quat_exp(np.radians(_per_joint(rows)) / 2.0)


def vectors_of(quats: np.ndarray) -> np.ndarray:
    """Rotation vector rows of unit quaternions ``(T, n, 4)``, continuous in time."""
    return _rows(_vectors_kernel(np.ascontiguousarray(quats, dtype=np.float64)))


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


def to_vectors(rows: np.ndarray, orders: tuple[str, ...], means: np.ndarray | None = None) -> np.ndarray:
    """Euler angle rows as rotation vector rows, continuous in time, each joint's taken about
    its mean rotation ``means (n, 4)`` (``conj(mean) q``; default: the identity)."""
    quats = euler_quats(rows, orders)
    if means is not None:
        quats = rotations.quat_multiply(rotations.quat_conjugate(means)[None], quats)
    return vectors_of(quats)


def to_euler(rows: np.ndarray, orders: tuple[str, ...], means: np.ndarray | None = None) -> np.ndarray:
    """Inverse of :func:`to_vectors`: Euler angle rows, each joint's triples as continuous as
    the Euler form allows (frame 0 in the principal range)."""
    n = len(orders)
    means = _identity_means(n) if means is None else np.ascontiguousarray(means, dtype=np.float64)
    return _rows(_euler_kernel(_per_joint(rows), _axes(orders), means))
