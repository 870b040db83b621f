"""What the ``spiht`` codec's bodies and stream packets hold, shared by its codec, cutting and
stream modules: the quanta, the importance levels and their weights, the anchors, and the
stream packet's head and segment budget."""

from __future__ import annotations

import struct

import numpy as np

from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton

QUANTUM = 1.0 / 256  # degrees, or cm for translations: the finest SPIHT plane
ANCHOR_QUANTUM = 0.1  # degrees, or cm: the root is pinned to within 0.05 cm
N0_BITS = 6  # each channel stream starts with its top plane + 1 (0: all zero)
SEAM_LIMIT = 2.0  # a seam step is removed up to twice the two sides' coding uncertainty
F_LEVELS = 16  # importance sent as half-octave levels 1..15 below the segment's top; 0 = none
U32 = struct.Struct("<I")


def channel_scale(skeleton: Skeleton) -> np.ndarray:
    """Per channel, skeleton units (or degrees) per cm (or degree)."""
    return np.where(skeleton.rotation_mask, 1.0, skeleton.units_per_metre / 100.0)


def importance_levels(f: np.ndarray) -> np.ndarray:
    """F as levels: 15 for the largest, one less per half octave below it, 1 at least; 0 for 0."""
    top = f.max() if f.size else 0.0
    if top <= 0:
        return np.zeros(f.size, dtype=np.int64)
    with np.errstate(divide="ignore"):
        level = F_LEVELS - 1 + np.round(2 * np.log2(f / top))
    return np.where(f > 0, np.clip(level, 1, F_LEVELS - 1), 0).astype(np.int64)


def level_weights(levels: np.ndarray) -> np.ndarray:
    return np.where(levels > 0, 2.0 ** ((levels - (F_LEVELS - 1)) / 2.0), 0.0)


def anchor_frames(frames: int, window: int) -> np.ndarray:
    starts = np.arange(0, frames, window)
    return starts if frames - 1 in starts else np.append(starts, frames - 1)


PACKET = struct.Struct("<BI")  # flags (1: carries the start anchors, 2: last segment), frames


def packet_total(part: bytes) -> int:
    """A stream packet's segment budget B_T (a plain u32, so a relay rewrites it cheaply)."""
    if len(part) != U32.size:
        raise CorruptStreamError(f"spiht packet: a {len(part)}-byte segment budget, expected {U32.size}")
    return U32.unpack(part)[0]


def line(start: np.ndarray, end: np.ndarray, frames: int, span: int) -> np.ndarray:
    t = np.arange(frames)[:, None] / max(span, 1)
    return start + (end - start) * t
