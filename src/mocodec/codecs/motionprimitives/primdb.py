"""The primitive database of the motion-primitive coder (001 §5.3.3): training and the file.

Per joint (by name), the time-normalised quaternion segments of the training clips
(:mod:`mocodec.codecs.motionprimitives.quatseg`) are clustered by a k-means++ variant in quaternion space:
distance (5.3) between orientations, (5.4) between segments (the largest over their frames);
k-means++ seeding with probability proportional to the squared distance; a cluster's centre
is built by incremental slerp weighting (a new member gets weight 1, the centre so far the
number of members before it), members in the order of the training data; the clustering
error (5.6) is the largest distance of any segment to its centre. ``K`` starts at 5 and grows
by one (a new k-means++ seed added to the converged clusters) until the error is below the
threshold (0.01) or ``K`` reaches 25. The centres are the primitives.

The file both ends load (little-endian): ``MOCPD``, a version byte, the length of a JSON
description (joint names with their primitive counts, clustering errors and segment counts,
the training settings and clips), the JSON, the primitives as float32 ``(K, 16, 4)`` per joint
in that order, and a CRC-32 of everything before it, which is also the database's
fingerprint that a body coded with it carries. Training is deterministic for a seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocodec.codecs.motionprimitives import quatseg
from mocodec.codecs.shared import modelfile
from mocodec.errors import CodecError
from mocodec.kernels import kernel
from mocodec.motion import Motion

MAGIC = b"MOCPD"
VERSION = 1
START_CLUSTERS = 5
MAX_CLUSTERS = 25
ERROR_THRESHOLD = 0.01
MAX_SEGMENTS = 3000  # training segments per joint, evenly taken
MAX_ITERATIONS = 30


@kernel
def _assign(segs, centres, labels, best):
    """Nearest centre (5.4) of every segment; ``best`` = its smallest frame |dot| there."""
    for i in range(segs.shape[0]):
        best[i] = -1.0
        for k in range(centres.shape[0]):
            m = 1.0
            for f in range(segs.shape[1]):
                d = 0.0
                for c in range(4):
                    d += segs[i, f, c] * centres[k, f, c]
                d = abs(d)
                if d < m:
                    m = d
            if m > best[i]:
                best[i] = m
                labels[i] = k


@kernel
def _centres(segs, labels, centres):
    """Incremental slerp centres: member m (from 0, in data order) enters with weight 1 against
    the centre's m, i.e. ``c = slerp(c, member, 1 / (m + 1))``; empty clusters keep theirs."""
    count = np.zeros(centres.shape[0], dtype=np.int64)
    tmp = np.empty(4)
    for i in range(segs.shape[0]):
        k = labels[i]
        if count[k] == 0:
            centres[k] = segs[i]
        else:
            for f in range(segs.shape[1]):
                quatseg.slerp_into(tmp, centres[k, f], segs[i, f], 1.0 / (count[k] + 1))
                centres[k, f] = tmp
        count[k] += 1


def _next_seed(segs: np.ndarray, best: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """k-means++: a segment drawn with probability proportional to its squared distance (5.4)
    to the nearest centre so far."""
    d2 = quatseg.distance_of_dot(best) ** 2
    total = d2.sum()
    i = rng.integers(len(segs)) if total <= 0 else rng.choice(len(segs), p=d2 / total)
    return segs[i]


def _converge(segs: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    labels = np.zeros(len(segs), dtype=np.int64)
    best = np.empty(len(segs))
    previous = None
    for _ in range(MAX_ITERATIONS):
        _assign(segs, centres, labels, best)
        if previous is not None and np.array_equal(labels, previous):
            break
        previous = labels.copy()
        _centres(segs, labels, centres)
    else:
        _assign(segs, centres, labels, best)
    return labels, best


def cluster(
    segs: np.ndarray, rng: np.random.Generator, threshold: float = ERROR_THRESHOLD, max_clusters: int = MAX_CLUSTERS
) -> tuple[np.ndarray, float]:
    """Primitives ``(K, 16, 4)`` of segments ``(n, 16, 4)`` and their clustering error (5.6)."""
    segs = np.ascontiguousarray(segs, dtype=np.float64)
    k_max = min(max_clusters, len(segs))
    centres = segs[rng.integers(len(segs))][None].copy()
    best = np.abs(np.sum(segs * centres[0], axis=-1)).min(axis=-1)
    while len(centres) < min(START_CLUSTERS, k_max):
        centres = np.concatenate((centres, _next_seed(segs, best, rng)[None]))
        best = np.maximum(best, quatseg.min_abs_dot(segs, centres[-1]))
    while True:
        _, best = _converge(segs, centres)
        error = float(quatseg.distance_of_dot(best.min()))
        if error < threshold or len(centres) >= k_max:
            return centres, error
        centres = np.concatenate((centres, _next_seed(segs, best, rng)[None]))


@dataclass
class PrimitiveDB(modelfile.Model):
    WHAT = "primitive database"

    primitives: dict[str, np.ndarray]  # joint name -> (K, 16, 4)
    errors: dict[str, float]  # clustering error (5.6) per joint
    segments: dict[str, int]  # training segments per joint
    max_segment: int
    seed: int
    threshold: float
    max_clusters: int
    fps: float
    trained_on: list[str] = field(default_factory=list)

    def to_bytes(self) -> bytes:
        names = list(self.primitives)
        meta = {
            "frames": quatseg.NORMAL_FRAMES,
            "max_segment": self.max_segment,
            "seed": self.seed,
            "threshold": self.threshold,
            "max_clusters": self.max_clusters,
            "fps": self.fps,
            "trained_on": self.trained_on,
            "joints": [
                {"name": n, "count": len(self.primitives[n]), "error": self.errors[n], "segments": self.segments[n]}
                for n in names
            ],
        }
        return modelfile.pack(
            MAGIC, VERSION, meta, b"".join(np.asarray(self.primitives[n], dtype="<f4").tobytes() for n in names)
        )

    @property
    def count(self) -> int:
        return sum(len(p) for p in self.primitives.values())

    @classmethod
    def from_bytes(cls, data: bytes, where: str) -> PrimitiveDB:
        meta, offset = modelfile.unpack(data, MAGIC, VERSION, "primitive database", where)
        try:
            if meta["frames"] != quatseg.NORMAL_FRAMES:
                raise ValueError(f"primitives of {meta['frames']} frames, expected {quatseg.NORMAL_FRAMES}")
            prims, errors, segments = {}, {}, {}
            for j in meta["joints"]:
                n = int(j["count"]) * quatseg.NORMAL_FRAMES * 4
                prims[str(j["name"])] = (
                    np.frombuffer(data, "<f4", n, offset).reshape(-1, quatseg.NORMAL_FRAMES, 4).astype(np.float64)
                )
                errors[str(j["name"])] = float(j["error"])
                segments[str(j["name"])] = int(j["segments"])
                offset += 4 * n
            if offset != len(data) - 4:
                raise ValueError(f"{len(data) - 4 - offset} bytes left after the primitives")
            return cls(
                prims,
                errors,
                segments,
                int(meta["max_segment"]),
                int(meta["seed"]),
                float(meta["threshold"]),
                int(meta["max_clusters"]),
                float(meta["fps"]),
                list(meta.get("trained_on", [])),
            )
        except (ValueError, KeyError, TypeError) as e:
            raise CodecError(f"{where}: primitive database description does not parse ({e})") from None

    def for_layout(self, lay: quatseg.Layout, where: str) -> list[np.ndarray]:
        """Each joint's primitives ``(K, 16, 4)`` (none for joints the database lacks); an error
        if it knows fewer than half of them (a database trained on another skeleton)."""
        empty = np.zeros((0, quatseg.NORMAL_FRAMES, 4))
        known = [n for n in lay.names if n in self.primitives]
        if 2 * len(known) < lay.count:
            raise CodecError(
                f"{where} knows {len(known)} of the {lay.count} joints of this skeleton "
                f"({', '.join(lay.names[:3])}, ...): it was trained on another skeleton"
            )
        return [self.primitives.get(n, empty) for n in lay.names]


def training_segments(motion: Motion, max_segment: int) -> tuple[quatseg.Layout, np.ndarray, np.ndarray]:
    """(layout, normalised segments ``(n, 16, 4)``, their joints ``(n,)``) of a clip."""
    lay = quatseg.layout(motion.skeleton)
    q = quatseg.joint_quaternions(lay, motion.channels)
    g = quatseg.speed_change(q, motion.fps)
    segs = np.array(quatseg.chop(g, np.zeros(lay.count, dtype=np.int64), max_segment, final=True), dtype=np.int64)
    segs = segs.reshape(-1, 3)
    return lay, quatseg.normalise(q, segs), segs[:, 0]


def train(
    clips: list[Motion],
    max_segment: int = 32,
    seed: int = 0,
    threshold: float = ERROR_THRESHOLD,
    max_clusters: int = MAX_CLUSTERS,
    names: list[str] | None = None,
) -> PrimitiveDB:
    """A database from ``clips`` (one frame rate; skeletons may differ, joints go by name)."""
    if not clips:
        raise CodecError("no clips to train a primitive database on")
    fps = clips[0].fps
    by_joint: dict[str, list[np.ndarray]] = {}
    for clip in clips:
        if abs(clip.fps - fps) > 1e-6 * fps:
            raise CodecError(f"primitive database clips must share one frame rate ({fps:g} and {clip.fps:g} Hz)")
        lay, normal, joints = training_segments(clip, max_segment)
        for r, name in enumerate(lay.names):
            by_joint.setdefault(name, []).append(normal[joints == r])
    prims, errors, counts = {}, {}, {}
    for r, name in enumerate(by_joint):
        segs = np.concatenate(by_joint[name])
        counts[name] = len(segs)
        if len(segs) == 0:
            continue
        segs = segs[np.linspace(0, len(segs) - 1, min(len(segs), MAX_SEGMENTS)).astype(np.int64)]
        centres, errors[name] = cluster(segs, np.random.default_rng([seed, r]), threshold, max_clusters)
        prims[name] = centres.astype("<f4").astype(np.float64)  # as the file holds them
    return PrimitiveDB(
        prims,
        errors,
        {n: counts[n] for n in prims},
        max_segment,
        seed,
        threshold,
        max_clusters,
        float(fps),
        list(names or []),
    )
