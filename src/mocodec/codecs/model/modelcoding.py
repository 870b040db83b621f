"""What the model-based codecs of 000 ch. 8 share: the sample frames of a group (sent as
lags), the root group as quantised Hermite samples, and where the tables come from.

The root (translation in centimetres, rotation in degrees) is segmented by posture distance
(8-1) every ``d`` units, its samples quantised to ``step`` units, delta coded and Hermite
interpolated (8-5 to 8-8) on decoding.

Tables are a file both ends load (named in the body by fingerprint) or, without one, are
trained on the clip itself and carried in the body in compact form, so the body stands
alone (and pays for its tables).
"""

from __future__ import annotations

import os
import struct
from functools import lru_cache

import numpy as np

from mocodec.codecs.model import animate, motiontables, segmentation
from mocodec.codecs.model.modelgroups import Groups
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

CARRIED, EXTERNAL = b"c", b"x"  # first byte of the tables part


def encode_lags(samples: list[np.ndarray]) -> bytes:
    """The sample frames of several groups as one stream of lags."""
    return encode_ints(np.concatenate([np.diff(f) for f in samples]) if samples else np.zeros(0, np.int64))


def decode_lags(data: bytes, n: int, count: int, where: str) -> list[np.ndarray]:
    """``count`` groups' sample frames from their lags, each checked to run from 0 to the
    last of ``n`` frames."""
    lags = decode_ints(data)
    if lags.min(initial=1) < 1:
        raise CorruptStreamError(f"{where}: a segment lag is not positive")
    ends = np.cumsum(lags)
    out, start = [], 0
    for k in range(count):
        # the group's lags are those up to where they sum to n - 1
        stop = start + int(np.searchsorted(ends[start:] - (ends[start - 1] if start else 0), n - 1, side="right"))
        frames = np.concatenate([[0], np.cumsum(lags[start:stop])]).astype(np.int64)
        if frames[-1] != max(n - 1, 0):
            raise CorruptStreamError(f"{where}: the lags of group {k} do not add up to the {n} frames of the header")
        out.append(frames)
        start = stop
    if start != lags.size:
        raise CorruptStreamError(f"{where}: {lags.size - start} lags left over")
    return out


def encode_root(x: np.ndarray, d: float, step: float, max_lag: int) -> tuple[bytes, segmentation.Samples]:
    """The root channels ``x (frames, R)`` (cm, degrees) as quantised samples (and the samples,
    whose lags the caller sends)."""
    samples = segmentation.posture_samples(x, d, max_lag)
    q = np.round(x[samples.frames] / step).astype(np.int64)
    return encode_ints(np.diff(q, axis=0, prepend=0)), samples


def decode_root(data: bytes, frames: np.ndarray, n: int, width: int, step: float, where: str) -> np.ndarray:
    q = decode_ints(data)
    if q.size != frames.size * width:
        raise CorruptStreamError(f"{where}: {q.size} root values for {frames.size} samples of {width} channels")
    return animate.hermite(frames, np.cumsum(q.reshape(frames.size, width), axis=0) * step, n)


def tables_for(
    motion: Motion,
    groups: Groups,
    path: str,
    spacing_cm: float,
    discard_deg: float,
    params: segmentation.GestureParams | None,
) -> tuple[motiontables.Tables, bytes]:
    """(the tables, the body part naming or carrying them) for coding ``motion``; tables
    trained on the clip hold gestures only if ``params`` (the gesture segmentation) is given."""
    if path:
        tables = load_tables(path, motion.skeleton, groups)
        return tables, EXTERNAL + struct.pack("<I", tables.fingerprint)
    tables = motiontables.train(
        [motion], spacing_cm, discard_deg, params=params or segmentation.GestureParams(), gestures=params is not None
    )
    return tables, CARRIED + tables.compact()


def load_tables(path: str, skeleton: Skeleton, groups: Groups) -> motiontables.Tables:
    """The tables in ``path``, checked against ``skeleton``; read once while the file is unchanged."""
    try:
        stat = os.stat(path)
    except OSError as e:
        raise CodecError(f"motion tables {path}: {e.strerror}") from None
    tables = _load_cached(os.path.abspath(path), stat.st_mtime_ns, stat.st_size)
    tables.check(skeleton, groups, f"motion tables {path}")
    return tables


@lru_cache(maxsize=8)
def _load_cached(path: str, mtime_ns: int, size: int) -> motiontables.Tables:
    return motiontables.Tables.load(path)


def read_tables(part: bytes, path: str, skeleton: Skeleton, groups: Groups, where: str) -> motiontables.Tables:
    """The tables a body's tables part carries or names (then loaded from ``path``)."""
    kind, rest = part[:1], part[1:]
    if kind == CARRIED:
        if path:
            raise CodecError(f"{where}: the motion carries its own tables; drop --tables")
        names = groups.channel_names(skeleton)
        return motiontables.Tables.from_compact(rest, [(g.name, c) for g, c in zip(groups.parts, names)], where)
    if kind != EXTERNAL or len(rest) != 4:
        raise CorruptStreamError(f"{where}: the tables part is neither tables nor a fingerprint")
    (fingerprint,) = struct.unpack("<I", rest)
    if not path:
        raise CodecError(
            f"{where}: the motion was coded with motion tables {fingerprint:08x}; none is given (--tables FILE)"
        )
    tables = load_tables(path, skeleton, groups)
    if tables.fingerprint != fingerprint:
        raise CodecError(
            f"{where}: the motion was coded with motion tables {fingerprint:08x}; {path} is {tables.fingerprint:08x}"
        )
    return tables


def worst_delays(n: int, runs: list[tuple[segmentation.Samples, int]]) -> np.ndarray:
    """Per frame the longest wait over all groups' segmentations (samples, lookahead)."""
    out = np.zeros(n, dtype=np.int64)
    for samples, lookahead in runs:
        out = np.maximum(out, segmentation.frame_delays(samples, n, lookahead))
    return out
