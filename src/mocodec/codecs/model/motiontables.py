"""Posture and gesture tables of the model-based coders (000 §8.4.1, §8.4.2): training, the
similarity measure, and the versioned file encoder and decoder share.

A **posture table** per group holds the postures of the training motion spaced at least
``spacing`` apart, by the greedy O(N^2) search of 8.4.1: a frame's posture vector (the
positions its angles set, :func:`mocodec.codecs.model.modelgroups.posture_vectors`) is kept if it
lies at least ``spacing`` (Euclidean distance over all its coordinates, (8-11) with unit
weights, in metres) from every posture kept before it. The table stores the entries' joint
angles; their positions are computed on the coding skeleton, so a table trained on one
subject serves another with the same channel layout. Training frames are taken at 30 Hz at
most.

A **gesture table** per group holds the training clips' gesture segments
(:func:`mocodec.codecs.model.segmentation.gesture_samples`), each stretched in time to ``norm``
frames (the thesis: one second at 30 Hz), minus every segment within ``discard`` of one kept
before it by the similarity (8-12) with the weights (8-13). The thesis's (8-12) is a weighted
sum of squared differences; here it is the root of their weighted mean, so ``discard`` (and a
gesture coder's fit threshold e) are in degrees whatever the segment length and the number
of DOFs. (8-13) weighs the ends ``a`` = 1 and the middle ``b`` <= 1.

File layout: :mod:`mocodec.codecs.shared.modelfile` with magic ``MOCTB``; the JSON names every
group's channels and the training parameters; the numbers are the compact form a body
carries (angles in steps of :data:`ANGLE_STEP` degrees, range coded).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocodec.codecs.model.animate import stretch
from mocodec.codecs.model.modelgroups import Groups, entry_vectors, model_groups, posture_vectors
from mocodec.codecs.model.segmentation import GestureParams, gesture_samples
from mocodec.codecs.shared import modelfile
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.kernels import kernel
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

MAGIC = b"MOCTB"
VERSION = 1
ANGLE_STEP = 0.05  # degrees
NORM = 30  # frames of a normalised gesture
SPACING_CM = 5.0
DISCARD_DEG = 5.0
INTERIOR_WEIGHT = 0.5  # b of (8-13), the Appendix III value for most groups
TRAINING_RATE = 30.0


def similarity_weights(norm: int, interior: float, width: int) -> np.ndarray:
    """(8-13) for a ``norm``-frame gesture of ``width`` DOFs, flattened and scaled so the
    weighted sum of squares is the weighted mean square."""
    n = np.arange(1, norm + 1, dtype=np.float64)
    w = interior + (1.0 - interior) / np.where(n <= norm / 2, n, norm - n + 1)
    return np.repeat(w / (w.sum() * max(width, 1)), width)


@kernel
def _spaced(vectors, weights, limit):
    """Indices of the vectors kept by the greedy spacing search: each at a weighted distance
    of at least ``limit`` from every one kept before it."""
    n, dim = vectors.shape
    kept = np.empty(n, np.int64)
    m = 0
    limit2 = limit * limit
    for i in range(n):
        far = True
        for k in range(m):
            other = kept[k]
            s = 0.0
            for j in range(dim):
                d = vectors[i, j] - vectors[other, j]
                s += weights[j] * d * d
                if s >= limit2:
                    break
            if s < limit2:
                far = False
                break
        if far:
            kept[m] = i
            m += 1
    return kept[:m]


def nearest(
    vectors: np.ndarray, entries: np.ndarray, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(index of the closest entry, its weighted distance) for every row of ``vectors``."""
    w = np.ones(vectors.shape[1]) if weights is None else weights
    d2 = ((vectors * vectors) @ w)[:, None] + ((entries * entries) @ w)[None, :] - 2 * (vectors * w) @ entries.T
    best = np.argmin(d2, axis=1)
    return best, np.sqrt(np.maximum(d2[np.arange(len(vectors)), best], 0.0))


def gesture_segments(x: np.ndarray, frames: np.ndarray, norm: int) -> np.ndarray:
    """Every segment of ``x (frames, K)`` between consecutive sample ``frames`` (both ends
    included), stretched to ``norm`` frames: ``(S - 1, norm, K)``."""
    return (
        np.stack([stretch(x[a : b + 1], norm) for a, b in zip(frames[:-1], frames[1:])])
        if len(frames) > 1
        else np.zeros((0, norm, x.shape[1]))
    )


@dataclass
class Tables(modelfile.Model):
    """Posture and gesture tables of every group of one channel layout."""

    WHAT = "motion tables"

    groups: list[tuple[str, list[str]]]  # (group, its channel names)
    postures: list[np.ndarray]  # per group (M, K) degrees
    gestures: list[np.ndarray]  # per group (G, norm, K) degrees
    norm: int = NORM
    interior: float = INTERIOR_WEIGHT
    spacing_cm: float = SPACING_CM
    discard_deg: float = DISCARD_DEG
    trained_on: list[str] = field(default_factory=list)
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def fingerprint(self) -> int:
        """As :class:`modelfile.Model`'s, computed once (tables are not changed after training)."""
        if "fingerprint" not in self._cache:
            self._cache["fingerprint"] = modelfile.fingerprint(self.to_bytes())
        return self._cache["fingerprint"]

    def posture_vectors(self, skeleton: Skeleton, groups: Groups, k: int) -> np.ndarray:
        """The posture vectors of group ``k``'s entries on ``skeleton`` (computed once)."""
        key = (skeleton, k)
        if key not in self._cache:
            self._cache[key] = entry_vectors(skeleton, groups.parts[k], self.postures[k], groups)
        return self._cache[key]

    def weights(self, k: int) -> np.ndarray:
        return similarity_weights(self.norm, self.interior, self.postures[k].shape[1])

    def describe(self) -> str:
        sizes = ", ".join(
            f"{name} {len(p)}/{len(g)}" for (name, _), p, g in zip(self.groups, self.postures, self.gestures)
        )
        return f"postures/gestures per group: {sizes}"

    def check(self, skeleton: Skeleton, groups: Groups, where: str) -> None:
        names = groups.channel_names(skeleton)
        if [c for _, c in self.groups] != names:
            raise CodecError(
                f"{where} was trained on another channel layout ({len(self.groups)} groups, "
                f"first {self.groups[0][1][:2] if self.groups else []}; this skeleton has "
                f"{len(names)} groups, first {names[0][:2] if names else []})"
            )

    # ----- the compact form (the file's numbers, or what a body carries) -------------
    def compact(self) -> bytes:
        counts = [len(p) for p in self.postures] + [len(g) for g in self.gestures]
        parts = [encode_ints(np.array(counts + [self.norm]))]
        for p, g in zip(self.postures, self.gestures):
            q = np.round(p / ANGLE_STEP).astype(np.int64)
            parts.append(encode_ints(np.diff(q, axis=0, prepend=0)))
            q = np.round(g / ANGLE_STEP).astype(np.int64)
            parts.append(encode_ints(np.diff(q, axis=1, prepend=0)))
        return join_parts(parts)

    @classmethod
    def from_compact(cls, data: bytes, groups: list[tuple[str, list[str]]], where: str, **meta) -> Tables:
        n = len(groups)
        parts = split_parts(data, 1 + 2 * n, where)
        counts = decode_ints(parts[0])
        if counts.size != 2 * n + 1 or counts.min(initial=1) < 0 or counts[-1] < 2:
            raise CorruptStreamError(f"{where}: the table sizes do not match {n} groups")
        norm = int(counts[-1])
        postures, gestures = [], []
        for k, (_, names) in enumerate(groups):
            width, m, g = len(names), int(counts[k]), int(counts[n + k])
            p, s = decode_ints(parts[1 + 2 * k]), decode_ints(parts[2 + 2 * k])
            if p.size != m * width or s.size != g * norm * width:
                raise CorruptStreamError(f"{where}: the tables of group {groups[k][0]} do not fill their part")
            postures.append(np.cumsum(p.reshape(m, width), axis=0) * ANGLE_STEP)
            gestures.append(np.cumsum(s.reshape(g, norm, width), axis=1) * ANGLE_STEP)
        return cls(groups, postures, gestures, norm=norm, **meta)

    def quantised(self) -> Tables:
        """The tables as their compact form decodes (what both ends use)."""
        return Tables.from_compact(
            self.compact(),
            self.groups,
            "",
            interior=self.interior,
            spacing_cm=self.spacing_cm,
            discard_deg=self.discard_deg,
            trained_on=self.trained_on,
        )

    def to_bytes(self) -> bytes:
        meta = {
            "groups": [[name, names] for name, names in self.groups],
            "interior": self.interior,
            "spacing_cm": self.spacing_cm,
            "discard_deg": self.discard_deg,
            "trained_on": self.trained_on,
        }
        return modelfile.pack(MAGIC, VERSION, meta, self.compact())

    @classmethod
    def from_bytes(cls, data: bytes, where: str) -> Tables:
        meta, offset = modelfile.unpack(data, MAGIC, VERSION, cls.WHAT, where)
        try:
            groups = [(str(name), [str(c) for c in names]) for name, names in meta["groups"]]
            extra = {
                "interior": float(meta["interior"]),
                "spacing_cm": float(meta["spacing_cm"]),
                "discard_deg": float(meta["discard_deg"]),
                "trained_on": list(meta["trained_on"]),
            }
        except (KeyError, TypeError, ValueError) as e:
            raise CodecError(f"{where}: motion tables description does not parse ({e})") from None
        try:
            return cls.from_compact(data[offset:-4], groups, where, **extra)
        except CorruptStreamError as e:
            raise CodecError(str(e)) from None


def train(
    clips: list[Motion],
    spacing_cm: float = SPACING_CM,
    discard_deg: float = DISCARD_DEG,
    norm: int = NORM,
    interior: float = INTERIOR_WEIGHT,
    params: GestureParams = GestureParams(),
    names: list[str] | None = None,
    gestures: bool = True,
) -> Tables:
    """Posture and gesture tables (none without ``gestures``) of every group from ``clips``
    (one channel layout)."""
    if not clips:
        raise CodecError("no clips to train motion tables on")
    if not (spacing_cm > 0 and discard_deg >= 0 and norm >= 2 and 0 <= interior <= 1):
        raise CodecError("tables need spacing > 0, discard >= 0, norm >= 2 and 0 <= interior <= 1")
    skeleton = clips[0].skeleton
    groups = model_groups(skeleton)
    layout = groups.channel_names(skeleton)
    vectors: list[list[np.ndarray]] = [[] for _ in groups.parts]
    angles: list[list[np.ndarray]] = [[] for _ in groups.parts]
    segments: list[list[np.ndarray]] = [[] for _ in groups.parts]
    for clip in clips:
        if model_groups(clip.skeleton).channel_names(clip.skeleton) != layout:
            raise CodecError("motion tables clips must share one channel layout")
        clip = clip.continuous()
        step = max(1, round(clip.fps / TRAINING_RATE))
        frames = clip.channels[::step]
        for k, (g, v) in enumerate(zip(groups.parts, posture_vectors(clip.skeleton, frames, groups))):
            vectors[k].append(v)
            angles[k].append(frames[:, g.channels])
            x = clip.channels[:, g.channels]
            if gestures:
                segments[k].append(gesture_segments(x, gesture_samples(x, clip.fps, params).frames, norm))
    postures, moves = [], []
    for k, g in enumerate(groups.parts):
        v = np.concatenate(vectors[k])
        postures.append(np.concatenate(angles[k])[_spaced(v, np.ones(v.shape[1]), spacing_cm / 100.0)])
        s = np.concatenate(segments[k]) if segments[k] else np.zeros((0, norm, g.channels.size))
        flat = s.reshape(len(s), norm * g.channels.size)
        moves.append(s[_spaced(flat, similarity_weights(norm, interior, g.channels.size), discard_deg)])
    tables = Tables(
        [(g.name, names_) for g, names_ in zip(groups.parts, layout)],
        postures,
        moves,
        norm,
        interior,
        spacing_cm,
        discard_deg,
        list(names or []),
    )
    return tables.quantised()
