"""Pose measures in centimetres, via forward kinematics (beyond the theses).

- Joint position error: |u(n) - u'(n)| of every pivot (joints and end sites), per joint and
  overall, mean and max.
- Shell error: the error at points a shell distance (3 cm by default) off each bone, along
  the three axes of the joint's global frame, worst of the three: the points a skin or mesh
  near the bone would follow. It sees twists about the bone that pivot positions miss.
- Foot sliding: horizontal speed of the decoded foot while the original foot is planted
  (near the ground and nearly still), beside the original's own speed in those frames.
- Jerk: RMS third derivative of the pivot positions, original and decoded; a coder that adds
  jitter raises it, one that over-smooths lowers it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec.kernels import kernel
from mocodec.skeleton import Skeleton

SHELL_CM = 3.0
CONTACT_HEIGHT_CM = 5.0
CONTACT_SPEED_CM_S = 20.0


@dataclass(frozen=True)
class JointErrors:
    """Distances in cm: ``per_frame (frames, joints)`` and its summaries."""

    per_frame: np.ndarray

    @property
    def joint_mean(self) -> np.ndarray:
        return self.per_frame.mean(axis=0)

    @property
    def joint_max(self) -> np.ndarray:
        return self.per_frame.max(axis=0)

    @property
    def mean(self) -> float:
        return float(self.per_frame.mean()) if self.per_frame.size else 0.0

    @property
    def max(self) -> float:
        return float(self.per_frame.max()) if self.per_frame.size else 0.0


def joint_errors(positions_cm: np.ndarray, decoded_positions_cm: np.ndarray, scale: float = 1.0) -> JointErrors:
    """Pivot position errors (cm) of ``(frames, joints, 3)`` arrays, the decoded positions in
    units of 1/``scale`` cm."""
    out = np.empty(positions_cm.shape[:2])
    _distance_kernel(
        np.ascontiguousarray(positions_cm, dtype=np.float64),
        np.ascontiguousarray(decoded_positions_cm, dtype=np.float64),
        float(scale),
        out,
    )
    return JointErrors(out)


@kernel
def _distance_kernel(pos, dpos, scale, out):
    """|scale dpos - pos| of every frame and joint, in one loop (no temporaries)."""
    for f in range(pos.shape[0]):
        for j in range(pos.shape[1]):
            ex = dpos[f, j, 0] * scale - pos[f, j, 0]
            ey = dpos[f, j, 1] * scale - pos[f, j, 1]
            ez = dpos[f, j, 2] * scale - pos[f, j, 2]
            out[f, j] = np.sqrt(ex * ex + ey * ey + ez * ez)


def bone_joints(skeleton: Skeleton) -> np.ndarray:
    """Joints that carry a bone (have children): the ones a shell surrounds."""
    return np.flatnonzero(~skeleton.end_sites & (np.array([len(c) for c in skeleton.children]) > 0))


def shell_errors(
    skeleton: Skeleton,
    positions_cm: np.ndarray,
    quats: np.ndarray,
    decoded_positions_cm: np.ndarray,
    decoded_quats: np.ndarray,
    shell_cm: float = SHELL_CM,
) -> JointErrors:
    """Worst error (cm) of the three points ``shell_cm`` along each global axis of every bone
    joint, ``per_frame (frames, bones)`` in the order of :func:`bone_joints`."""
    idx = bone_joints(skeleton)
    out = np.empty((positions_cm.shape[0], idx.size))
    _shell_kernel(
        np.ascontiguousarray(positions_cm),
        np.ascontiguousarray(quats),
        np.ascontiguousarray(decoded_positions_cm),
        np.ascontiguousarray(decoded_quats),
        idx,
        float(shell_cm),
        out,
    )
    return JointErrors(out)


def worst_error(
    skeleton: Skeleton,
    positions_cm: np.ndarray,
    quats: np.ndarray,
    decoded_positions_cm: np.ndarray,
    decoded_quats: np.ndarray,
    measure: str,
) -> float:
    """The worst error (cm) a max bound of ``measure`` limits: with "shell" that of
    :func:`shell_errors`, else the largest joint distance."""
    if measure == "shell":
        return shell_errors(skeleton, positions_cm, quats, decoded_positions_cm, decoded_quats).max
    return joint_errors(positions_cm, decoded_positions_cm).max


@kernel
def _shell_kernel(pos, quat, dpos, dquat, joints, d, out):
    """For each frame and bone joint: max over k of |dp + d (R'_k - R_k)|, with R_k the k-th
    column of the rotation matrix of the joint's global quaternion."""
    for f in range(pos.shape[0]):
        for b in range(joints.size):
            j = joints[b]
            w, x, y, z = quat[f, j, 0], quat[f, j, 1], quat[f, j, 2], quat[f, j, 3]
            v, s, t, u = dquat[f, j, 0], dquat[f, j, 1], dquat[f, j, 2], dquat[f, j, 3]
            ex, ey, ez = dpos[f, j, 0] - pos[f, j, 0], dpos[f, j, 1] - pos[f, j, 1], dpos[f, j, 2] - pos[f, j, 2]
            # columns of the rotation matrices, decoded minus original, scaled by d
            a0 = ex + d * (-2 * (t * t + u * u) + 2 * (y * y + z * z))
            a1 = ey + d * (2 * (s * t + u * v) - 2 * (x * y + z * w))
            a2 = ez + d * (2 * (s * u - t * v) - 2 * (x * z - y * w))
            b0 = ex + d * (2 * (s * t - u * v) - 2 * (x * y - z * w))
            b1 = ey + d * (-2 * (s * s + u * u) + 2 * (x * x + z * z))
            b2 = ez + d * (2 * (t * u + s * v) - 2 * (y * z + x * w))
            c0 = ex + d * (2 * (s * u + t * v) - 2 * (x * z + y * w))
            c1 = ey + d * (2 * (t * u - s * v) - 2 * (y * z - x * w))
            c2 = ez + d * (-2 * (s * s + t * t) + 2 * (x * x + y * y))
            worst = max(a0 * a0 + a1 * a1 + a2 * a2, b0 * b0 + b1 * b1 + b2 * b2, c0 * c0 + c1 * c1 + c2 * c2)
            out[f, b] = np.sqrt(worst)


def up_axis(skeleton: Skeleton) -> tuple[int, float]:
    """(axis, sign) of 'up': opposite to the direction from the root to the leg ends in the
    rest pose; Y up when the skeleton has no legs."""
    legs = [i for i, p in enumerate(skeleton.body_parts) if p.endswith("_leg") and not skeleton.children[i]]
    if not legs:
        return 1, 1.0
    down = skeleton.rest_positions[legs].mean(axis=0) - skeleton.rest_positions[0]
    axis = int(np.argmax(np.abs(down)))
    return axis, -float(np.sign(down[axis]) or -1.0)


def foot_points(skeleton: Skeleton) -> np.ndarray:
    """Leg joints in the lowest fifth of the legs' rest-pose height: ankles, toes, their ends."""
    legs = np.array([p.endswith("_leg") for p in skeleton.body_parts])
    if not legs.any():
        return np.zeros(0, dtype=int)
    axis, sign = up_axis(skeleton)
    height = sign * skeleton.rest_positions[:, axis]
    low, high = height[legs].min(), height[legs].max()
    return np.flatnonzero(legs & (height <= low + 0.2 * (high - low)))


@dataclass(frozen=True)
class FootSliding:
    contact_fraction: float  # share of foot-point samples planted in the original
    original_cm_s: float  # mean horizontal speed of the original foot while planted
    decoded_cm_s: float  # the same for the decoded foot

    @property
    def excess_cm_s(self) -> float:
        return self.decoded_cm_s - self.original_cm_s


def foot_sliding(
    skeleton: Skeleton,
    positions_cm: np.ndarray,
    decoded_positions_cm: np.ndarray,
    fps: float,
    contact_height_cm: float = CONTACT_HEIGHT_CM,
    contact_speed_cm_s: float = CONTACT_SPEED_CM_S,
) -> FootSliding | None:
    """Foot sliding over the frames where the original foot is planted; None without feet.

    A foot point is planted when it is within ``contact_height_cm`` of the ground (the lowest
    foot point's 1st-percentile height, plus the point's own rest height above the sole) and
    its horizontal speed is below ``contact_speed_cm_s``."""
    feet = foot_points(skeleton)
    if feet.size == 0 or positions_cm.shape[0] < 2:
        return None
    axis, sign = up_axis(skeleton)
    flat = [k for k in range(3) if k != axis]
    height = sign * positions_cm[:, feet, axis]
    rest = sign * skeleton.rest_positions[feet, axis] * (100.0 / skeleton.units_per_metre)
    lift = rest - rest.min()
    ground = np.percentile(height, 1, axis=0).min()

    def speed(p):
        return np.linalg.norm(np.gradient(p[:, feet][:, :, flat], axis=0), axis=2) * fps

    orig_speed = speed(positions_cm)
    planted = (height - ground <= lift + contact_height_cm) & (orig_speed <= contact_speed_cm_s)
    if not planted.any():
        return FootSliding(0.0, float("nan"), float("nan"))
    return FootSliding(
        float(planted.mean()), float(orig_speed[planted].mean()), float(speed(decoded_positions_cm)[planted].mean())
    )


@dataclass(frozen=True)
class Jerk:
    original_m_s3: float  # RMS jerk of the original pivots
    decoded_m_s3: float

    @property
    def ratio(self) -> float:
        return self.decoded_m_s3 / self.original_m_s3 if self.original_m_s3 > 0 else float("nan")


def rms_jerk(positions_cm: np.ndarray, fps: float) -> float:
    """RMS over frames and pivots of |d^3 u / dt^3| in m/s^3 (third differences)."""
    if positions_cm.shape[0] < 4:
        return float("nan")
    third = np.diff(positions_cm, n=3, axis=0) * (fps**3 / 100.0)
    return float(np.sqrt(np.square(third).sum(axis=2).mean()))


def jerk(positions_cm: np.ndarray, decoded_positions_cm: np.ndarray, fps: float) -> Jerk:
    return Jerk(rms_jerk(positions_cm, fps), rms_jerk(decoded_positions_cm, fps))
