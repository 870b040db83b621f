"""Playing whole-body primitives end to end with the temporal blending of 001 §4.2.2: slerp
over a transition chosen by a distance map, the root re-placed by blended velocity (4.1).

Each primitive is resampled to its segment's length (:func:`play`, :func:`paths`). At each
seam a distance map (4.3) compares the root-centred joint positions of the last quarter of
the segment before with the first quarter of the one after; its smallest entry (i, j) gives
the transition (:func:`transitions`). Over frames i..j both motions run on (the one before
held at its last frame past the seam, the one after at its first frame before it) and each
joint is slerped (4.2) from the first to the second with a weight rising linearly from 0 at
i to 1 at j (:func:`blend_rotations`). The thesis's root (:func:`velocity_root`): horizontal
velocity and height blended with the same weights, the position summed from the start
(4.1), so the root follows the primitives and drifts from the original. Ours
(:func:`keyed_root`): the root position sent at every seam, the primitive's path bent
linearly to pass through those keys.
"""

from __future__ import annotations

import numpy as np

from mocodec import rotations
from mocodec.codecs.motionprimitives import quatseg
from mocodec.kinematics import forward_kinematics
from mocodec.skeleton import Skeleton


def play(normal: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Joint quaternions ``(F, R, 4)`` of normalised segments ``(n, 16, R, 4)`` resampled to
    ``lengths`` frames each and laid end to end, unblended."""
    n, _, count, _ = normal.shape
    flat = quatseg.denormalise(
        normal.transpose(0, 2, 1, 3).reshape(-1, quatseg.NORMAL_FRAMES, 4), np.repeat(lengths, count)
    )
    seg = np.repeat(np.arange(n), lengths)
    frame = np.arange(len(seg)) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    offset = np.repeat(count * (np.cumsum(lengths) - lengths), lengths)  # segment start in flat
    rows = offset[:, None] + np.arange(count)[None, :] * lengths[seg][:, None] + frame[:, None]
    return flat[rows]


def paths(root: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``(F, T)``: each segment's root trajectory ``root (n, 16, T)`` resampled (linearly) to
    its length, laid end to end."""
    out = []
    for k, length in enumerate(lengths):
        at = np.linspace(0, quatseg.NORMAL_FRAMES - 1, length)
        out.append(quatseg.interpolate_columns(at, np.arange(quatseg.NORMAL_FRAMES), root[k]))
    return np.concatenate(out) if out else np.zeros((0, root.shape[2]))


def transitions(skeleton: Skeleton, lay: quatseg.Layout, q: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``(n - 1, 3)`` rows (seam, i, j): the closest pair (4.3) of frames, i in the last quarter
    of the segment before the seam and j in the first quarter of the one after, by the
    root-centred positions of every joint."""
    cuts = np.cumsum(lengths)[:-1]
    if not len(cuts):
        return np.zeros((0, 3), dtype=np.int64)
    centred = quatseg.quaternions_to_channels(lay, q, np.zeros((len(q), len(lay.translation))), skeleton.num_channels)
    positions = forward_kinematics(skeleton, centred)[0]
    out = np.empty((len(cuts), 3), dtype=np.int64)
    for s, cut in enumerate(cuts):
        a, b = -(-lengths[s] // 4), -(-lengths[s + 1] // 4)
        dist = np.sum((positions[cut - a : cut, None] - positions[None, cut : cut + b]) ** 2, axis=(2, 3))
        i, j = np.unravel_index(np.argmin(dist), dist.shape)
        out[s] = cut, cut - a + i, cut + j
    return out


def _spans(seams: np.ndarray):
    """Per transition: its inner frames, their weights, and the frames of the motion before
    and after the seam they take."""
    for cut, i, j in seams:
        frames = np.arange(i + 1, j)
        if len(frames):
            yield frames, (frames - i) / (j - i), np.minimum(frames, cut - 1), np.maximum(frames, cut)


def blend_rotations(q: np.ndarray, seams: np.ndarray) -> np.ndarray:
    out = q.copy()
    for frames, t, before, after in _spans(seams):
        out[frames] = rotations.quat_slerp(q[before], q[after], t[:, None])  # (4.2)
    return out


def velocity_root(
    path: np.ndarray, lengths: np.ndarray, up: np.ndarray, start: np.ndarray, seams: np.ndarray
) -> np.ndarray:
    """(4.1): the root from the primitives' horizontal velocities and heights (``path``
    horizontal axes relative to each segment's start), blended over the transitions and summed
    from ``start``."""
    vel = np.diff(path, axis=0, prepend=path[:1])
    firsts = np.cumsum(lengths) - lengths
    vel[firsts] = vel[np.minimum(firsts + 1, len(vel) - 1)]  # a segment's first step: its second
    vel[0] = 0.0
    both = np.where(up, path, vel)
    blended = both.copy()
    for frames, t, before, after in _spans(seams):
        blended[frames] = (1 - t)[:, None] * both[before] + t[:, None] * both[after]
    return np.where(up, blended, start + np.cumsum(np.where(up, 0.0, blended), axis=0))


def keyed_root(path: np.ndarray, lengths: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """The root through ``keys``, its positions at every segment's first frame and at the last
    frame: the keys joined linearly, plus each segment's primitive path less its own straight
    line from first to last frame (so the keys are met exactly)."""
    firsts = np.cumsum(lengths) - lengths
    at = np.append(firsts, len(path) - 1)
    frames = np.arange(len(path))
    out = quatseg.interpolate_columns(frames, at, keys).reshape(path.shape)
    seg = np.repeat(np.arange(len(lengths)), lengths)
    ends = firsts + lengths - 1
    u = ((frames - firsts[seg]) / np.maximum(lengths[seg] - 1, 1))[:, None]
    return out + path - ((1 - u) * path[firsts[seg]] + u * path[ends[seg]])
