"""Whole-body motion primitives for the rhythmic framework of 001 ch. 4: segmentation, the
primitive database and its two files.

A motion (4.2.1) is the root position plus one quaternion per joint
(:mod:`mocodec.codecs.motionprimitives.quatseg`). Ch. 4 cuts the whole body at once, at key poses (it cites
[SI08]: dancers stop and recompose between beats); we sum ``a . w`` of (5.1)/(5.2) over the
joints, the derivative of the body's total squared joint speed, and cut at its zero crossings
with the segment bounds of ch. 5 (at least 15 frames, at most S_M); a frame where most joints
jump ends a segment, a jump of a few joints does not. A segment is kept as its
joint rotations time-normalised to 16 frames and its root trajectory at the same 16 instants:
the horizontal axes relative to its first frame (the root is re-placed by velocity on decode,
4.2.2), the vertical (``Yposition``) as it is.

The database holds ``count`` such segments of the training clips (the thesis: "a given
animation consists of 20 primitives", each a basic move of the dance), chosen as k-medoids
(k-means++ seeding, seeded) under the whole-body distance: the sum over joints of the segment
distance (5.4). Each primitive keeps its mean length in frames.

Two files: the ``MOCRD`` model file both ends load (:mod:`mocodec.codecs.shared.modelfile`, float32),
and a compact form a body can carry when the database is made from the clip itself
(quaternions and root trajectories quantised, differenced along time, range coded).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocodec.codecs.motionprimitives import quatseg
from mocodec.codecs.shared import modelfile
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

MAGIC = b"MOCRD"
VERSION = 1
COUNT = 20
MAX_ITERATIONS = 30
QUAT_STEP = 1.0 / 4096  # compact form: quaternion components, about 0.03 degrees
ROOT_STEP = 0.01  # compact form: root trajectory, skeleton units
_CHUNK = 64


def vertical(skeleton: Skeleton) -> np.ndarray:
    """Bool over the translation channels of :func:`quatseg.layout`: the up axis (Y)."""
    names = skeleton.channel_names
    return np.array([names[c].endswith("Yposition") for c in quatseg.layout(skeleton).translation], dtype=bool)


def body_cuts(q: np.ndarray, fps: float, max_segment: int) -> np.ndarray:
    """``(n, 2)`` [start, end) frames of whole-body segments of joint quaternions ``q``."""
    g = quatseg.speed_change(q, fps)
    jump = np.isinf(g)
    g = np.where(jump, 0.0, g).sum(axis=1)
    g[jump.mean(axis=1) > 0.5] = np.inf  # the whole body jumps (a T-pose frame 0), not one joint
    segs = quatseg.chop(g[:, None], np.zeros(1, dtype=np.int64), max_segment, final=True)
    return np.array(segs, dtype=np.int64).reshape(-1, 3)[:, 1:]


def normal_rotations(q: np.ndarray, cuts: np.ndarray) -> np.ndarray:
    """``(n, 16, R, 4)`` time-normalised joint rotations of each segment."""
    count = q.shape[1]
    rows = np.column_stack((np.tile(np.arange(count), len(cuts)), np.repeat(cuts, count, axis=0)))
    return quatseg.normalise(q, rows).reshape(len(cuts), count, quatseg.NORMAL_FRAMES, 4).transpose(0, 2, 1, 3)


def normal_root(t: np.ndarray, cuts: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``(n, 16, T)`` root trajectory of each segment at the 16 normalised instants, horizontal
    axes relative to the segment's first frame."""
    out = np.empty((len(cuts), quatseg.NORMAL_FRAMES, t.shape[1]))
    for k, (s, e) in enumerate(cuts):
        pos = np.linspace(s, e - 1, quatseg.NORMAL_FRAMES)
        out[k] = quatseg.interpolate_columns(pos, np.arange(s, e), t[s:e])
        out[k][:, ~up] -= t[s, ~up]
    return out


def body_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(n, K)`` whole-body distance between normalised segments ``a (n, 16, R, 4)`` and
    ``b (K, 16, R, 4)``: the sum over joints of (5.4)."""
    out = np.empty((len(a), len(b)))
    for s in range(0, len(a), _CHUNK):
        dots = np.abs(np.einsum("nfrc,kfrc->nkfr", a[s : s + _CHUNK], b)).min(axis=2)
        out[s : s + _CHUNK] = quatseg.distance_of_dot(dots).sum(axis=2)
    return out


def medoids(dist: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``count`` k-medoids of a distance matrix: k-means++ seeding, then assignment
    and medoid updates until nothing changes."""
    n = len(dist)
    seeds = [int(rng.integers(n))]
    while len(seeds) < min(count, n):
        near = dist[:, seeds].min(axis=1) ** 2
        if near.sum() <= 0.0:
            break
        seeds.append(int(rng.choice(n, p=near / near.sum())))
    chosen = np.array(seeds)
    for _ in range(MAX_ITERATIONS):
        labels = np.argmin(dist[:, chosen], axis=1)
        moved = chosen.copy()
        for k in range(len(chosen)):
            members = np.flatnonzero(labels == k)
            if len(members):
                moved[k] = members[np.argmin(dist[np.ix_(members, members)].sum(axis=1))]
        if np.array_equal(moved, chosen):
            break
        chosen = moved
    _, first = np.unique(chosen, return_index=True)  # two clusters can settle on one medoid
    return chosen[np.sort(first)]


@dataclass
class RhythmDB(modelfile.Model):
    """Whole-body primitives of one skeleton's joints (by name)."""

    WHAT = "rhythm database"

    names: tuple[str, ...]
    rotations: np.ndarray  # (K, 16, R, 4)
    root: np.ndarray  # (K, 16, T)
    lengths: np.ndarray  # (K,) frames
    fps: float
    max_segment: int
    seed: int
    error: float  # mean whole-body distance of a training segment to its primitive
    trained_on: list[str] = field(default_factory=list)

    @property
    def count(self) -> int:
        return len(self.lengths)

    def to_bytes(self) -> bytes:
        meta = {
            "frames": quatseg.NORMAL_FRAMES,
            "joints": list(self.names),
            "translations": self.root.shape[2],
            "lengths": [int(n) for n in self.lengths],
            "fps": self.fps,
            "max_segment": self.max_segment,
            "seed": self.seed,
            "error": self.error,
            "trained_on": self.trained_on,
        }
        return modelfile.pack(
            MAGIC, VERSION, meta, np.asarray(self.rotations, "<f4").tobytes() + np.asarray(self.root, "<f4").tobytes()
        )

    @classmethod
    def from_bytes(cls, data: bytes, where: str) -> RhythmDB:
        meta, offset = modelfile.unpack(data, MAGIC, VERSION, "rhythm database", where)
        try:
            names, lengths = tuple(map(str, meta["joints"])), np.array(meta["lengths"], dtype=np.int64)
            k, f, t = len(lengths), int(meta["frames"]), int(meta["translations"])
            if f != quatseg.NORMAL_FRAMES or offset + 4 * k * f * (4 * len(names) + t) != len(data) - 4:
                raise ValueError("the primitives do not fill the file")
            rot = np.frombuffer(data, "<f4", k * f * len(names) * 4, offset).reshape(k, f, len(names), 4)
            root = np.frombuffer(data, "<f4", k * f * t, offset + rot.nbytes).reshape(k, f, t)
            return cls(
                names,
                rot.astype(np.float64),
                root.astype(np.float64),
                lengths,
                float(meta["fps"]),
                int(meta["max_segment"]),
                int(meta["seed"]),
                float(meta["error"]),
                list(meta["trained_on"]),
            )
        except (ValueError, KeyError, TypeError) as e:
            raise CodecError(f"{where}: rhythm database description does not parse ({e})") from None

    def check(self, lay: quatseg.Layout, translations: int, fps: float, where: str) -> None:
        if tuple(lay.names) != self.names or translations != self.root.shape[2]:
            raise CodecError(
                f"{where} was trained on another skeleton ({len(self.names)} joints "
                f"{', '.join(self.names[:3])}, ...; this one has {lay.count})"
            )
        if abs(self.fps - fps) > 1e-6 * fps:
            raise CodecError(f"{where} was trained at {self.fps:g} Hz, the motion is {fps:g} Hz")

    # ----- the compact form a body carries -------------------------------------------
    def compact(self) -> bytes:
        rot = np.round(self.rotations / QUAT_STEP).astype(np.int64)
        root = np.round(self.root / ROOT_STEP).astype(np.int64)
        return join_parts(
            [
                encode_ints(self.lengths),
                encode_ints(np.diff(rot, axis=1, prepend=0)),
                encode_ints(np.diff(root, axis=1, prepend=0)),
            ]
        )

    @classmethod
    def from_compact(
        cls, data: bytes, lay: quatseg.Layout, translations: int, fps: float, max_segment: int, where: str
    ) -> RhythmDB:
        lengths, rot, root = (decode_ints(p) for p in split_parts(data, 3, where))
        k, f = len(lengths), quatseg.NORMAL_FRAMES
        if rot.size != k * f * lay.count * 4 or root.size != k * f * translations or lengths.min(initial=1) < 1:
            raise CorruptStreamError(f"{where}: the embedded primitives do not match the skeleton")
        rot = np.cumsum(rot.reshape(k, f, lay.count, 4), axis=1) * QUAT_STEP
        root = np.cumsum(root.reshape(k, f, translations), axis=1) * ROOT_STEP
        rot /= np.maximum(np.linalg.norm(rot, axis=-1, keepdims=True), 1e-12)
        return cls(tuple(lay.names), rot, root, lengths, fps, max_segment, 0, 0.0)

    def as_compact(self, lay: quatseg.Layout, fps: float) -> RhythmDB:
        """The database as its compact form decodes (what both ends use when it is embedded)."""
        return RhythmDB.from_compact(self.compact(), lay, self.root.shape[2], fps, self.max_segment, "")


def segments(clip: Motion, max_segment: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cuts ``(n, 2)``, normalised rotations ``(n, 16, R, 4)``, root trajectories
    ``(n, 16, T)``) of a clip's whole-body segments."""
    lay = quatseg.layout(clip.skeleton)
    q = quatseg.joint_quaternions(lay, clip.channels)
    cuts = body_cuts(q, clip.fps, max_segment)
    return (
        cuts,
        normal_rotations(q, cuts),
        normal_root(clip.channels[:, lay.translation], cuts, vertical(clip.skeleton)),
    )


def from_segments(
    names: tuple[str, ...],
    rot: np.ndarray,
    root: np.ndarray,
    lengths: np.ndarray,
    fps: float,
    count: int,
    max_segment: int,
    seed: int,
    trained_on: list[str],
) -> RhythmDB:
    """``count`` k-medoids of whole-body segments (:func:`segments`) as a database."""
    if count < 1:
        raise CodecError(f"a rhythm database needs at least one primitive, not {count}")
    dist = body_distance(rot, rot)
    chosen = medoids(dist, count, np.random.default_rng(seed))
    labels = np.argmin(dist[:, chosen], axis=1)
    labels[chosen] = np.arange(len(chosen))  # a medoid at zero distance from another keeps its own
    mean_length = np.array([np.round(lengths[labels == k].mean()) for k in range(len(chosen))], dtype=np.int64)
    return RhythmDB(
        names,
        rot[chosen].astype("<f4").astype(np.float64),
        root[chosen].astype("<f4").astype(np.float64),
        mean_length,
        float(fps),
        max_segment,
        seed,
        float(dist[np.arange(len(dist)), chosen[labels]].mean()),
        trained_on,
    )


def train(
    clips: list[Motion], count: int = COUNT, max_segment: int = 32, seed: int = 0, names: list[str] | None = None
) -> RhythmDB:
    """``count`` whole-body primitives of ``clips`` (one skeleton and frame rate)."""
    if not clips:
        raise CodecError("no clips to train a rhythm database on")
    lay, fps = quatseg.layout(clips[0].skeleton), clips[0].fps
    rot, root, lengths = [], [], []
    for clip in clips:
        if tuple(quatseg.layout(clip.skeleton).names) != lay.names or abs(clip.fps - fps) > 1e-6 * fps:
            raise CodecError("rhythm database clips must share one skeleton and frame rate")
        cuts, r, t = segments(clip, max_segment)
        rot.append(r)
        root.append(t)
        lengths.append(cuts[:, 1] - cuts[:, 0])
    return from_segments(
        lay.names,
        np.concatenate(rot),
        np.concatenate(root),
        np.concatenate(lengths),
        fps,
        count,
        max_segment,
        seed,
        list(names or []),
    )
