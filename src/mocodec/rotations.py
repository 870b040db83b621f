"""Rotations: Euler angles (all 12 orders) <-> unit quaternions <-> 3x3 matrices.

Conventions, used everywhere in mocodec:

* Matrices act on column vectors (``v' = R @ v``).
* An Euler ``order`` is a string of axes in upper case, read as *intrinsic* rotations, the way
  BVH channels are written: ``"ZXY"`` means ``R = Rz(a0) @ Rx(a1) @ Ry(a2)`` (scipy's
  upper-case orders mean the same). Orders of one or two axes (a knee's ``"X"``, an elbow's
  ``"XY"``) are allowed for building matrices.
* Quaternions are scalar-first ``(w, x, y, z)`` and unit length.
* Angles are in degrees unless ``degrees=False``; every function is vectorised over any
  leading shape.
"""

from __future__ import annotations

import numpy as np

_AXIS = {"X": 0, "Y": 1, "Z": 2}

TAIT_BRYAN_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
PROPER_EULER_ORDERS = ("XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ")
EULER_ORDERS = TAIT_BRYAN_ORDERS + PROPER_EULER_ORDERS


def _check_order(order: str, allow_partial: bool) -> str:
    order = order.upper()
    if not order or any(c not in _AXIS for c in order):
        raise ValueError(f"rotation order {order!r}: expected letters X, Y, Z")
    if allow_partial and len(order) < 3:
        if len(order) == 2 and order[0] == order[1]:
            raise ValueError(f"rotation order {order!r}: consecutive axes must differ")
        return order
    if order not in EULER_ORDERS:
        raise ValueError(f"rotation order {order!r}: expected one of {', '.join(EULER_ORDERS)}")
    return order


def axis_matrix(axis: str, angle: np.ndarray, degrees: bool = True) -> np.ndarray:
    """Elementary rotation about ``axis`` ('X', 'Y' or 'Z'), shape ``angle.shape + (3, 3)``."""
    a = np.deg2rad(angle) if degrees else np.asarray(angle, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    i = _AXIS[axis.upper()]
    j, k = (i + 1) % 3, (i + 2) % 3
    m[..., i, i] = 1.0
    m[..., j, j] = c
    m[..., k, k] = c
    m[..., j, k] = -s
    m[..., k, j] = s
    return m


def euler_to_matrix(angles: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Intrinsic Euler angles ``(..., len(order))`` to matrices ``(..., 3, 3)``."""
    order = _check_order(order, allow_partial=True)
    angles = np.asarray(angles, dtype=np.float64)
    if angles.shape[-1] != len(order):
        raise ValueError(f"expected {len(order)} angles for order {order!r}, got {angles.shape[-1]}")
    m = axis_matrix(order[0], angles[..., 0], degrees)
    for n in range(1, len(order)):
        m = m @ axis_matrix(order[n], angles[..., n], degrees)
    return m


def quat_multiply_components(p: tuple, q: tuple) -> tuple:
    """Hamilton product ``p * q`` on quaternions held as four component arrays (w, x, y, z).

    The component form lets callers keep each component contiguous (forward kinematics)."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p * q`` (apply q, then p)."""
    p, q = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    return np.stack(quat_multiply_components(tuple(np.moveaxis(p, -1, 0)), tuple(np.moveaxis(q, -1, 0))), axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of a unit quaternion."""
    return np.asarray(q, dtype=np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def axis_angle_to_quat(axis: np.ndarray, angle: np.ndarray, degrees: bool = True) -> np.ndarray:
    """Rotation by ``angle`` about the (not necessarily unit) vector ``axis``."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * (np.deg2rad(angle) if degrees else np.asarray(angle, dtype=np.float64))
    return np.concatenate((np.cos(half)[..., None], np.sin(half)[..., None] * axis), axis=-1)


def euler_to_quat(angles: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Intrinsic Euler angles ``(..., len(order))`` to unit quaternions ``(..., 4)``."""
    order = _check_order(order, allow_partial=True)
    angles = np.asarray(angles, dtype=np.float64)
    if angles.shape[-1] != len(order):
        raise ValueError(f"expected {len(order)} angles for order {order!r}, got {angles.shape[-1]}")
    q = None
    for n, axis in enumerate(order):
        e = np.zeros(3)
        e[_AXIS[axis]] = 1.0
        qn = axis_angle_to_quat(e, angles[..., n], degrees)
        q = qn if q is None else quat_multiply(q, qn)
    assert q is not None, "an Euler order has at least one axis"
    return q


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` to matrices ``(..., 3, 3)``."""
    q = quat_normalize(q)
    w, x, y, z = np.moveaxis(q, -1, 0)
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` to unit quaternions with ``w >= 0``.

    Shepperd's method: take the largest of the four squared components for stability.
    """
    m = np.asarray(m, dtype=np.float64)
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cand = np.stack((trace, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]), axis=-1)
    best = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,))
    # w largest
    s = np.sqrt(np.maximum(1.0 + trace, 1e-300)) * 2
    qw = np.stack(
        (
            0.25 * s,
            (m[..., 2, 1] - m[..., 1, 2]) / s,
            (m[..., 0, 2] - m[..., 2, 0]) / s,
            (m[..., 1, 0] - m[..., 0, 1]) / s,
        ),
        -1,
    )
    s = np.sqrt(np.maximum(1.0 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2], 1e-300)) * 2
    qx = np.stack(
        (
            (m[..., 2, 1] - m[..., 1, 2]) / s,
            0.25 * s,
            (m[..., 0, 1] + m[..., 1, 0]) / s,
            (m[..., 0, 2] + m[..., 2, 0]) / s,
        ),
        -1,
    )
    s = np.sqrt(np.maximum(1.0 + m[..., 1, 1] - m[..., 0, 0] - m[..., 2, 2], 1e-300)) * 2
    qy = np.stack(
        (
            (m[..., 0, 2] - m[..., 2, 0]) / s,
            (m[..., 0, 1] + m[..., 1, 0]) / s,
            0.25 * s,
            (m[..., 1, 2] + m[..., 2, 1]) / s,
        ),
        -1,
    )
    s = np.sqrt(np.maximum(1.0 + m[..., 2, 2] - m[..., 0, 0] - m[..., 1, 1], 1e-300)) * 2
    qz = np.stack(
        (
            (m[..., 1, 0] - m[..., 0, 1]) / s,
            (m[..., 0, 2] + m[..., 2, 0]) / s,
            (m[..., 1, 2] + m[..., 2, 1]) / s,
            0.25 * s,
        ),
        -1,
    )
    for idx, cand_q in enumerate((qw, qx, qy, qz)):
        sel = best == idx
        q[sel] = cand_q[sel]
    q = quat_normalize(q)
    return np.where(q[..., :1] < 0, -q, q)


def quat_to_euler(q: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Unit quaternions to intrinsic Euler angles ``(..., 3)`` for any of the 12 orders.

    The direct formula of Bernardes and Viollet (2022), which scipy also uses. The first and
    third angles lie in (-180, 180]; the middle one in [-90, 90] (Tait-Bryan) or [0, 180]
    (proper Euler). At gimbal lock the split between first and third angle is arbitrary but
    the returned angles still reproduce the rotation.
    """
    order = _check_order(order, allow_partial=False)
    q = quat_normalize(q)
    # The formula is for extrinsic sequences: intrinsic "ABC" equals extrinsic "CBA" reversed.
    i, j, k = (_AXIS[c] for c in reversed(order))
    proper = i == k
    if proper:
        k = 3 - i - j
    eps = (i - j) * (j - k) * (k - i) / 2.0
    w = q[..., 0]
    qi, qj, qk = q[..., 1 + i], q[..., 1 + j], q[..., 1 + k]
    if proper:
        a, b, c, d = w, qi, qj, qk * eps
    else:
        a, b, c, d = w - qj, qi + qk * eps, qj + w, qk * eps - qi
    theta2 = 2.0 * np.arctan2(np.sqrt(c * c + d * d), np.sqrt(a * a + b * b))
    half_plus = np.arctan2(b, a)
    half_minus = np.arctan2(d, c)
    theta1 = half_plus - half_minus
    theta3 = half_plus + half_minus
    if not proper:
        theta3 = theta3 * eps
        theta2 = theta2 - np.pi / 2
    angles = np.stack((theta3, theta2, theta1), axis=-1)  # back to intrinsic order
    angles = (angles + np.pi) % (2 * np.pi) - np.pi
    return np.rad2deg(angles) if degrees else angles


def quat_to_partial_euler(q: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Unit quaternions to the angles of a joint with one, two or three rotation axes.

    Three axes: :func:`quat_to_euler`. Two axes ``"AB"``: the Tait-Bryan order ``"ABC"`` with the
    missing axis last, its angle dropped (it is zero for a rotation the joint can make). One axis:
    the twist about it, ``2 atan2(q_axis, w)``. For rotations the joint cannot make exactly (a
    coded approximation), the dropped part is the error.
    """
    order = _check_order(order, allow_partial=True)
    if len(order) == 3:
        return quat_to_euler(q, order, degrees)
    if len(order) == 2:
        missing = next(c for c in "XYZ" if c not in order)
        return quat_to_euler(q, order + missing, degrees)[..., :2]
    q = np.asarray(q, dtype=np.float64)
    angle = 2.0 * np.arctan2(q[..., 1 + _AXIS[order]], q[..., 0])
    angle = (angle + np.pi) % (2 * np.pi) - np.pi
    return (np.rad2deg(angle) if degrees else angle)[..., None]


def quat_to_exact_euler(q: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """:func:`quat_to_partial_euler` for rotations the joint can make exactly (a file's own
    joint angles read back): with two axes ``"AB"``, ``q = R_A(a) R_B(b)`` turns the B axis
    by ``a`` about A alone (R_B leaves it), which gives ``a`` without the gimbal and branch
    trouble of a three-angle split, then ``b`` is the twist left about B."""
    order = _check_order(order, allow_partial=True)
    if len(order) != 2:
        return quat_to_partial_euler(q, order, degrees)
    e_a, e_b = np.eye(3)[_AXIS[order[0]]], np.eye(3)[_AXIS[order[1]]]
    q = quat_normalize(np.asarray(q, dtype=np.float64))
    v = quat_rotate(q, np.broadcast_to(e_b, q.shape[:-1] + (3,)))
    a = np.arctan2(np.cross(e_b, v) @ e_a, v @ e_b)
    rest = quat_multiply(axis_angle_to_quat(e_a, -a, degrees=False), q)
    b = 2.0 * np.arctan2(rest[..., 1 + _AXIS[order[1]]], rest[..., 0])
    angles = (np.stack((a, b), axis=-1) + np.pi) % (2 * np.pi) - np.pi
    return np.rad2deg(angles) if degrees else angles


def quat_continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """``q`` with signs flipped along ``axis`` (time) so each quaternion lies in the hemisphere of
    the one before: the same rotations, with no jump between ``q`` and ``-q``."""
    q = np.moveaxis(np.asarray(q, dtype=np.float64), axis, 0)
    if len(q) < 2:
        return np.moveaxis(q.copy(), 0, axis)
    flips = np.sum(q[1:] * q[:-1], axis=-1) < 0
    sign = np.ones(q.shape[:-1])
    sign[1:] = np.where(np.cumsum(flips, axis=0) % 2 == 1, -1.0, 1.0)
    return np.moveaxis(q * sign[..., None], 0, axis)


def matrix_to_euler(m: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Rotation matrices to intrinsic Euler angles ``(..., 3)``."""
    return quat_to_euler(matrix_to_quat(m), order, degrees)


def quat_slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation (001 eq. 2.3), along the shorter arc.

    ``t`` broadcasts against the leading shape of ``q0`` and ``q1``.
    """
    q0, q1 = quat_normalize(q0), quat_normalize(q1)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-9
    safe = np.where(near, 1.0, sin_theta)
    w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    w1 = np.where(near, t, np.sin(t * theta) / safe)
    return quat_normalize(w0 * q0 + w1 * q1)


def quat_log(q: np.ndarray) -> np.ndarray:
    """Logarithm of unit quaternions: the rotation vector / 2, shape ``(..., 3)`` (radians)."""
    q = quat_normalize(q)
    v = q[..., 1:]
    vn = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = np.arctan2(vn, q[..., :1])
    scale = np.where(vn < 1e-12, 1.0, angle / np.where(vn < 1e-12, 1.0, vn))
    return v * scale


def quat_exp(v: np.ndarray) -> np.ndarray:
    """Exponential of pure quaternions ``(..., 3)``: inverse of :func:`quat_log`."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    sinc = np.where(n < 1e-12, 1.0, np.sin(n) / np.where(n < 1e-12, 1.0, n))
    return np.concatenate((np.cos(n), v * sinc), axis=-1)


def quat_distance(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Geodesic distance of 001 (5.3): ``arccos(2 (q1 . q2)^2 - 1)``, radians in [0, pi].

    It is the angle of the rotation taking one orientation to the other, and is blind to the
    sign of either quaternion.
    """
    dot = np.sum(quat_normalize(q1) * quat_normalize(q2), axis=-1)
    return np.arccos(np.clip(2.0 * dot * dot - 1.0, -1.0, 1.0))


def quat_rotate_components(q: tuple, v: tuple) -> tuple:
    """Rotate vectors (three component arrays) by unit quaternions (four component arrays):
    ``v + w t + u x t`` with ``t = 2 u x v``."""
    w, x, y, z = q
    vx, vy, vz = v
    tx, ty, tz = 2 * (y * vz - z * vy), 2 * (z * vx - x * vz), 2 * (x * vy - y * vx)
    return (vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz, vz + w * tz + x * ty - y * tx)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``(..., 3)`` by unit quaternions ``(..., 4)``."""
    q, v = np.asarray(q, dtype=np.float64), np.asarray(v, dtype=np.float64)
    return np.stack(quat_rotate_components(tuple(np.moveaxis(q, -1, 0)), tuple(np.moveaxis(v, -1, 0))), axis=-1)
