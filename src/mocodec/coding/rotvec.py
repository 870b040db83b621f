"""Joint rotations as rotation vectors instead of Euler angles (kinwave.md, "what mattered" 5).

A joint's rotation as one turn about one axis: its three numbers move less jointly than Euler
angles do when a joint swings far, so they cost fewer bytes to code (BVH joints, 9-12%). Rows
come three per joint, ``(3n, T)``, in each joint's rotation order, degrees. Every operation is
elementwise or per joint, so a coder converting a few joints at a time (kinwave's encoder, a
tree depth at a time) and one converting them all (its decoder) get the same floats.
"""

from __future__ import annotations

import numpy as np

from mocodec import rotations
from mocodec.motion import continuous_triples


def _per_joint(rows: np.ndarray) -> np.ndarray:
    """``(3n, T)`` rows as ``(T, n, 3)``."""
    return rows.T.reshape(rows.shape[1], -1, 3)


def _rows(values: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_per_joint`."""
    return values.reshape(values.shape[0], -1).T


def _by_order(orders: tuple[str, ...]):
    """``(order, joints)`` for every rotation order present: joints of one order go in one call."""
    for order in sorted(set(orders)):
        yield order, [i for i, o in enumerate(orders) if o == order]


def euler_quats(rows: np.ndarray, orders: tuple[str, ...]) -> np.ndarray:
    """Unit quaternions ``(T, n, 4)`` of the joints' Euler angle rows."""
    euler = _per_joint(rows)
    out = np.empty(euler.shape[:2] + (4,))
    for order, joints in _by_order(orders):
        out[:, joints] = rotations.euler_to_quat(euler[:, joints], order)
    return out


def vector_quats(rows: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(T, n, 4)`` of the joints' rotation vector rows."""
    return rotations.quat_exp(np.radians(_per_joint(rows)) / 2.0)


def vectors_of(quats: np.ndarray) -> np.ndarray:
    """Rotation vector rows of unit quaternions ``(T, n, 4)``, continuous in time."""
    return _rows(np.degrees(2.0 * rotations.quat_log(rotations.quat_continuous(quats))))


def to_vectors(rows: np.ndarray, orders: tuple[str, ...]) -> np.ndarray:
    """Euler angle rows as rotation vector rows, continuous in time."""
    return vectors_of(euler_quats(rows, orders))


def to_euler(rows: np.ndarray, orders: tuple[str, ...]) -> np.ndarray:
    """Inverse of :func:`to_vectors`: Euler angle rows, each joint's triples as continuous as
    the Euler form allows (frame 0 in the principal range)."""
    q = vector_quats(rows)
    out = np.empty(q.shape[:2] + (3,))
    for order, joints in _by_order(orders):
        out[:, joints] = rotations.quat_to_euler(q[:, joints], order)
    for i, order in enumerate(orders):
        out[:, i] = continuous_triples(out[:, i], order)
    return _rows(out)
