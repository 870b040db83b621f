"""Joint orientations as quaternion segments: the representation and segmentation of the
motion-primitive coders (001 §4.2.1, §5.3.1, §5.3.2).

A motion is its translation channels (the root position) plus one unit quaternion per joint
with rotation channels, from its Euler angles (one, two or three axes; the ASF ``axis``
pre-rotation is not part of it, it is fixed). Each joint's signal is cut into segments at
zero crossings of its angular acceleration: (5.1) gives the angular velocity
``w(i) = 2 log(q(i-1)^-1 q(i)) / h``, (5.2) the acceleration ``a(i) = (w(i) - w(i-1)) / h``.
The acceleration is a vector; "zero crossing" is read as a sign change of its component
along the velocity, ``a . w``, which is the derivative of the squared speed: segments end
where the joint's speed peaks or bottoms out (the beats of a rhythmic motion). A segment ends
at the first crossing at least :data:`MIN_SEGMENT` frames after its start, or after at most
``max_len`` frames (S_M). Beyond the thesis, a segment also ends before a jump, a frame
that turns a joint faster than :data:`JUMP_SPEED` (the T-pose that starts many BVH clips):
a 16-frame resampling cannot hold a step, and would smear it over the frames after it.
Every segment is resampled by slerp to :data:`NORMAL_FRAMES` frames (its first and last frame
kept exactly) for comparison with primitives, and back.

Whether frame ``e`` ends a segment depends on frames up to ``e`` only, so a segment is known
``max_len`` frames after its start at the latest: the coding delay of a streaming coder.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np

from mocodec import rotations
from mocodec.kernels import kernel
from mocodec.skeleton import Skeleton

NORMAL_FRAMES = 16
MIN_SEGMENT = 15
LOWER_BODY = ("left_leg", "right_leg")
JUMP_SPEED = 30.0  # rad/s: about four times a fast kick's peak joint speed


@dataclass(frozen=True, eq=False)
class Layout:
    """Which channels of a skeleton are which joint's rotation, and which are translations."""

    joints: np.ndarray  # (R,) skeleton index of every joint with rotation channels
    names: tuple[str, ...]
    orders: tuple[str, ...]
    columns: tuple[np.ndarray, ...]  # channel columns of each joint's angles, in rotation order
    translation: np.ndarray  # translation channel columns
    lower: np.ndarray  # (R,) bool: the joint is the root or in a leg (threshold t_L)

    @property
    def count(self) -> int:
        return len(self.joints)


@lru_cache(maxsize=32)
def layout(skeleton: Skeleton) -> Layout:
    rotating = [j for j, joint in enumerate(skeleton.joints) if joint.rotation_order]
    columns = [
        skeleton.channel_offsets[j] + np.array(skeleton.joints[j].rotation_channel_indices(), dtype=np.int64)
        for j in rotating
    ]
    joints = np.array(rotating, dtype=np.int64)
    parts = skeleton.body_parts
    lower = np.array([j == 0 or parts[j] in LOWER_BODY for j in joints], dtype=bool)
    return Layout(
        joints,
        tuple(skeleton.joints[j].name for j in joints),
        tuple(skeleton.joints[j].rotation_order for j in joints),
        tuple(columns),
        np.flatnonzero(~skeleton.rotation_mask),
        lower,
    )


def joint_quaternions(lay: Layout, channels: np.ndarray) -> np.ndarray:
    """``(frames, R, 4)`` unit quaternions of every joint, each continuous in time (no flips
    between ``q`` and ``-q``)."""
    channels = np.atleast_2d(channels)
    q = np.empty((len(channels), lay.count, 4))
    for r, (order, cols) in enumerate(zip(lay.orders, lay.columns)):
        q[:, r] = rotations.euler_to_quat(channels[:, cols], order)
    return rotations.quat_continuous(q, axis=0)


def quaternions_to_channels(lay: Layout, q: np.ndarray, translation: np.ndarray, num_channels: int) -> np.ndarray:
    """Channels ``(frames, num_channels)`` from joint quaternions and translation values; the
    angles are each rotation's principal Euler angles (the caller makes them continuous)."""
    out = np.zeros((len(q), num_channels))
    out[:, lay.translation] = translation
    for order in dict.fromkeys(lay.orders):  # joints of one order in one call
        rs = [r for r, o in enumerate(lay.orders) if o == order]
        angles = rotations.quat_to_partial_euler(q[:, rs], order)
        out[:, np.concatenate([lay.columns[r] for r in rs])] = angles.reshape(len(q), len(rs) * angles.shape[-1])
    return out


def speed_change(q: np.ndarray, fps: float) -> np.ndarray:
    """``a(i) . w(i)`` per frame and joint ``(frames, R)`` from (5.1) and (5.2), zero for the
    first two frames, where the acceleration is not defined; ``inf`` where the joint jumps
    (turns faster than :data:`JUMP_SPEED` since the frame before)."""
    out = np.zeros(q.shape[:2])
    if len(q) < 2:
        return out
    w = 2.0 * fps * rotations.quat_log(rotations.quat_multiply(rotations.quat_conjugate(q[:-1]), q[1:]))  # (5.1)
    a = np.diff(w, axis=0) * fps  # (5.2)
    out[2:] = np.sum(a * w[1:], axis=-1)
    out[1:][np.linalg.norm(w, axis=-1) > JUMP_SPEED] = np.inf
    return out


@kernel
def _chop(g, starts, available, max_len, final, ends_out, joint_out):
    """Segments of every joint from its open start, as far as ``available`` frames decide:
    (joint, end) pairs written to the outputs; returns their count and updates ``starts``."""
    count = 0
    for r in range(g.shape[1]):
        s = starts[r]
        while s < available:
            end = -1
            limit = min(s + max_len, available - 1)
            for i in range(s + 1, limit + 1):
                if g[i, r] == np.inf or (i >= s + 15 and g[i, r] * g[i - 1, r] < 0.0):
                    end = i
                    break
            if end < 0:
                if s + max_len <= available - 1:
                    end = s + max_len
                elif final:
                    end = available
                else:
                    break
            ends_out[count] = end
            joint_out[count] = r
            count += 1
            s = end
        starts[r] = s
    return count


def chop(g: np.ndarray, starts: np.ndarray, max_len: int, final: bool) -> list[tuple[int, int, int]]:
    """New segments ``(joint, start, end)`` of speed-change signal ``g (frames, R)`` (absolute
    frame indices), each joint continuing from ``starts[r]`` (updated in place). Without
    ``final`` a segment is cut only once the frames decide it; with it, the rest of each
    joint's frames form its last segments."""
    if max_len < MIN_SEGMENT:
        raise ValueError(f"segments of at most {max_len} frames cannot be {MIN_SEGMENT} long")
    room = g.shape[1] * (len(g) + 1)
    ends, joints = np.empty(room, dtype=np.int64), np.empty(room, dtype=np.int64)
    last = starts.copy()
    n = _chop(np.ascontiguousarray(g, dtype=np.float64), starts, len(g), int(max_len), bool(final), ends, joints)
    out = []
    for r, e in zip(joints[:n], ends[:n]):
        out.append((int(r), int(last[r]), int(e)))
        last[r] = e
    return out


def interpolate_columns(at: np.ndarray, xp: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``(len(at), T)``: each column of ``values (len(xp), T)`` linearly at ``at`` (a root
    trajectory resampled; a root without translations has no column)."""
    out = np.empty((len(at), values.shape[1]))
    for c in range(values.shape[1]):
        out[:, c] = np.interp(at, xp, values[:, c])
    return out


def normalise(q: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """``(n, 16, 4)`` time-normalised segments of joint signals ``q (frames, R, 4)`` for
    ``segments (n, 3)`` rows (joint, start, end), by slerp between neighbouring frames."""
    r, s, e = segments.T
    pos = s[:, None] + np.linspace(0.0, 1.0, NORMAL_FRAMES)[None, :] * (e - s - 1)[:, None]
    i0 = np.floor(pos).astype(np.int64)
    flat = q.reshape(-1, 4)
    width = q.shape[1]
    base = i0 * width + r[:, None]
    last = (e - 1)[:, None] * width + r[:, None]
    nxt = np.minimum(base + width, last)
    return rotations.quat_slerp(flat[base], flat[nxt], pos - i0)


@numba.njit(inline="always")
def slerp_into(out, a, b, t):
    """``out = slerp(a, b, t)`` for one quaternion, along the shorter arc."""
    dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
    sign = 1.0
    if dot < 0.0:
        dot, sign = -dot, -1.0
    if dot > 1.0:
        dot = 1.0
    theta = np.arccos(dot)
    s = np.sin(theta)
    if s < 1e-9:
        w0, w1 = 1.0 - t, t
    else:
        w0, w1 = np.sin((1.0 - t) * theta) / s, np.sin(t * theta) / s
    norm = 0.0
    for c in range(4):
        out[c] = w0 * a[c] + w1 * sign * b[c]
        norm += out[c] * out[c]
    norm = np.sqrt(norm)
    for c in range(4):
        out[c] /= norm


@kernel
def _denormalise(normal, lengths, out):
    f = 0
    for k in range(len(lengths)):
        scale = (NORMAL_FRAMES - 1) / max(lengths[k] - 1, 1)
        for i in range(lengths[k]):
            u = i * scale
            i0 = min(int(np.floor(u)), NORMAL_FRAMES - 2)
            slerp_into(out[f], normal[k, i0], normal[k, i0 + 1], u - i0)
            f += 1


def denormalise(normal: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Each ``(16, 4)`` segment back to its length in frames (slerp), one after the other:
    ``(sum(lengths), 4)``."""
    out = np.empty((int(lengths.sum()), 4))
    _denormalise(np.ascontiguousarray(normal, dtype=np.float64), lengths.astype(np.int64), out)
    return out


def min_abs_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest ``|a(i) . b(i)|`` over the frames of segments (broadcast over leading axes):
    the segment distance (5.4) is ``arccos(2 m^2 - 1)`` of it, monotone, so comparing this is
    comparing distances."""
    return np.abs(np.sum(a * b, axis=-1)).min(axis=-1)


def distance_of_dot(m: np.ndarray) -> np.ndarray:
    """Distance (5.3) for a quaternion dot product ``m``."""
    return np.arccos(np.clip(2.0 * m * m - 1.0, -1.0, 1.0))


def segment_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(5.4): the largest distance (5.3) between corresponding frames of two segments."""
    return distance_of_dot(min_abs_dot(a, b))


@kernel
def _smooth_seams(q, lefts, cuts, rights, m, jump):
    for s in range(len(cuts)):
        cut = cuts[s]
        across = abs(
            q[cut - 1, 0] * q[cut, 0]
            + q[cut - 1, 1] * q[cut, 1]
            + q[cut - 1, 2] * q[cut, 2]
            + q[cut - 1, 3] * q[cut, 3]
        )
        if 2.0 * np.arccos(min(across, 1.0)) > jump:
            continue
        best, x, y = -1.0, cut - 1, cut
        for i in range(max(lefts[s], cut - m), cut):
            for j in range(cut, min(rights[s], cut + m)):
                d = abs(q[i, 0] * q[j, 0] + q[i, 1] * q[j, 1] + q[i, 2] * q[j, 2] + q[i, 3] * q[j, 3])
                if d > best:
                    best, x, y = d, i, j
        a, b = q[x].copy(), q[y].copy()
        for k in range(x + 1, y):
            slerp_into(q[k], a, b, (k - x) / (y - x))


def smooth_seams(q: np.ndarray, cuts: np.ndarray, lefts: np.ndarray, rights: np.ndarray, m: int, fps: float) -> None:
    """The smoothing of consecutive segments of 5.3.4, in place on one joint's frames ``q (n, 4)``.

    At each seam ``cuts[s]`` (the first frame of a segment; the one before it starts at
    ``lefts[s]``, the one after ends before ``rights[s]``) the closest pair of frames (x, y),
    x among the last ``m`` frames before the seam and y among the first ``m`` after it
    (distance (5.3)), is joined by slerp, linearly in time: the frames between them are
    replaced. The thesis writes the weights as k / (x + y), indices counted from the seam; we
    read them as the time fraction between x and y, which keeps both ends in place.
    A seam where the adjacent frames are the closest pair is left as it is, and so is one the
    joint crosses faster than :data:`JUMP_SPEED` (a step such as a T-pose frame 0 is not
    motion to smooth)."""
    if len(cuts) and m > 0:
        _smooth_seams(q, lefts.astype(np.int64), cuts.astype(np.int64), rights.astype(np.int64), m, JUMP_SPEED / fps)
