"""Scenes: several characters coded under one bit budget (001 §6.5).

The budget of every segment of W frames is split between the characters present in it by
their bandwidth score S_C = d_m / d_C (6.4), d_C the character's distance from the camera in
that segment and d_m the nearest character's, times an optional per-character weight:
B_k = S_k B / sum_i S_i (6.5). Each character is then coded by ``spiht`` with its own
segment budgets (split again between its channels by the perceptual factors), so the split
follows the scene as characters come closer or move away. A scene file holds one .moc per
character; every part decodes on its own.
"""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np

from mocodec import moc
from mocodec.codecs.perceptual.spiht import SpihtCodec
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.crowd import bandwidth_scores, split_budget
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.formats import container
from mocodec.motion import Motion

MAGIC = b"MOCS"
VERSION = 1
_HEAD = struct.Struct("<4sHI")
_U32 = struct.Struct("<I")


def allocate(motions: list[Motion], bits_per_second: float, distances, weights=None, window: int = 128) -> np.ndarray:
    """Per character and segment, the SPIHT budget in bits: ``(characters, segments)``."""
    fps = motions[0].fps
    n_seg = max(-(-m.num_frames // window) for m in motions)
    d = np.asarray(distances, dtype=np.float64)
    if d.ndim == 1:
        d = np.repeat(d[:, None], n_seg, axis=1)
    if d.shape != (len(motions), n_seg):
        raise CodecError(f"distances must be ({len(motions)},) or ({len(motions)}, {n_seg}), got {d.shape}")
    present = np.array([[k * window < m.num_frames for k in range(n_seg)] for m in motions])
    d = np.where(present, d, np.nan)
    scores = bandwidth_scores(d, weights)
    out = np.zeros((len(motions), n_seg), dtype=np.int64)
    for k in range(n_seg):
        out[:, k] = split_budget(int(np.floor(bits_per_second * window / fps)), scores[:, k])
    return out


def encode_scene(
    motions: list[Motion],
    bits_per_second: float,
    distances,
    weights=None,
    chunk_frames: int = moc.CHUNK_FRAMES,
    **spiht_knobs,
) -> bytes:
    """One file for all characters under ``bits_per_second`` of SPIHT bits in total."""
    if not motions:
        raise CodecError("a scene needs at least one character")
    if len({m.fps for m in motions}) != 1:
        raise CodecError("every character of a scene needs the same frame rate")
    codec = SpihtCodec(bits_per_second=bits_per_second, **spiht_knobs)
    window = codec.segment_frames()
    if chunk_frames % window:
        raise CodecError(f"chunk_frames ({chunk_frames}) must be a multiple of the window ({window})")
    budgets = allocate(motions, bits_per_second, distances, weights, window)
    parts = []
    for motion, row in zip(motions, budgets):
        chunks = []
        for first in range(0, motion.num_frames, chunk_frames):
            part = motion[first : first + chunk_frames]
            seg = row[first // window : first // window + -(-part.num_frames // window)]
            chunks.append(container.Chunk(first, part.num_frames, codec.encode_with_budgets(part, seg)))
        header = {
            "codec": codec.get_config(),
            "fps": float(motion.fps),
            "frames": motion.num_frames,
            "chunk_frames": chunk_frames,
            "skeleton": motion.skeleton,
        }
        parts.append(container.pack(header, chunks))
    body = _HEAD.pack(MAGIC, VERSION, len(parts)) + join_parts(parts)
    return body + _U32.pack(zlib.crc32(body))


def scene_parts(data: bytes, name: str = "<bytes>") -> list[bytes]:
    """The .moc bytes of every character of a scene file, with the file's CRC checked."""
    if len(data) < _HEAD.size + 4 or data[:4] != MAGIC:
        raise CorruptStreamError(f"{name}: not a mocodec scene file")
    if zlib.crc32(data[:-4]) != _U32.unpack(data[-4:])[0]:
        raise CorruptStreamError(f"{name}: scene CRC mismatch, the file is damaged")
    _, version, count = _HEAD.unpack_from(data)
    if version != VERSION:
        raise CorruptStreamError(f"{name}: scene version {version}; this mocodec reads {VERSION}")
    return split_parts(data[:-4], count, f"{name}: scene", start=_HEAD.size)


def decode_scene(data: bytes, name: str = "<bytes>") -> list[Motion]:
    """Every character of a scene file."""
    return [moc.unpack(p, name=f"{name}[{k}]") for k, p in enumerate(scene_parts(data, name))]


def scene_sizes(data: bytes) -> list[int]:
    """Bytes of every character's coded motion (chunk payloads), for reports."""
    out = []
    for p in scene_parts(data):
        c = container.open_container(io.BytesIO(p), len(p), "<part>")
        out.append(sum(len(c.read_chunk(k)) for k in range(len(c.index))))
    return out
