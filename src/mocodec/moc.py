"""Coded motion files: ``encode(motion, path, codec)`` writes a .moc container, ``decode(path,
frames=(a, b))`` reads back the whole clip or only the chunks a frame range needs.

Each chunk of ``chunk_frames`` frames (:func:`chunk_spans`) is coded on its own by the codec (so chunks decode
independently and a range costs only its chunks); the container stores the codec's config and
the skeleton, so a file decodes without anything else. A lossy codec's file stores the
skeleton's offsets rounded to 0.001 cm (:func:`stored_skeleton`) and decodes on that skeleton;
the codec is told, so an error bound it verifies holds on the decoded joints.
"""

from __future__ import annotations

import io
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocodec import limits, sandbox
from mocodec.codecs import DEFAULT_CODEC, Codec, codec_from_untrusted, get_codec
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.formats import container
from mocodec.formats.fileio import atomic_write_bytes
from mocodec.formats.skeleton_bin import round_offsets
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

CHUNK_FRAMES = 1024
SKELETON_PRECISION_CM = 0.001  # offsets of a lossy file: joints move by 0.003 cm at most on the shared clips


def stored_skeleton(
    motion: Motion, codec: Codec, embed_skeleton: bool = True, exact_skeleton: bool = False
) -> Skeleton:
    """The skeleton a file of ``motion`` coded by ``codec`` holds, and decodes on: a lossy
    codec's file rounds the offsets to :data:`SKELETON_PRECISION_CM` (docs/codecs.md); a
    lossless codec's, a file that holds only the skeleton's id, or
    ``exact_skeleton`` keep it bit for bit."""
    if codec.lossless or not embed_skeleton or exact_skeleton:
        return motion.skeleton
    return round_offsets(motion.skeleton, SKELETON_PRECISION_CM)


def chunk_spans(motion: Motion, chunk_frames: int) -> list[tuple[int, int]]:
    """The chunks' frames ``[a, b)``: ``chunk_frames`` each, counted from frame 1 where frame 0
    is a rest pose (:attr:`Motion.starts_at_rest`; the first chunk takes it along), so a bind
    pose before a take leaves the take's chunks as they were."""
    lead = 1 if motion.starts_at_rest else 0
    ends = list(range(lead + chunk_frames, motion.num_frames, chunk_frames)) + [motion.num_frames]
    return list(zip([0, *ends[:-1]], ends)) if motion.num_frames else []


def pack(
    motion: Motion,
    codec: Codec | None = None,
    chunk_frames: int = CHUNK_FRAMES,
    embed_skeleton: bool = True,
    exact_skeleton: bool = False,
    jobs: int = 1,
) -> bytes:
    """The .moc bytes of ``motion`` coded by ``codec`` (default: the default codec); with
    ``embed_skeleton=False`` the file holds only the skeleton's id. The codec is told the
    :func:`stored_skeleton`, so an error bound it verifies holds on what the file decodes to.
    ``jobs`` processes code the chunks at once: the same bytes as one, as each chunk is coded
    on its own."""
    codec = codec or get_codec(DEFAULT_CODEC)
    if chunk_frames < 1:
        raise CodecError(f"chunk_frames must be at least 1, got {chunk_frames}")
    if jobs < 1:
        raise CodecError(f"jobs must be at least 1, got {jobs}")
    skeleton = stored_skeleton(motion, codec, embed_skeleton, exact_skeleton)
    output = None if skeleton is motion.skeleton else skeleton
    spans = chunk_spans(motion, chunk_frames)
    bodies = _encode_chunks(codec, [motion[a:b] for a, b in spans], output, jobs)
    chunks = [container.Chunk(a, b - a, body) for (a, b), body in zip(spans, bodies)]
    header = {
        "codec": codec.get_config(),
        "fps": float(motion.fps),
        "frames": motion.num_frames,
        "chunk_frames": chunk_frames,
        "skeleton": skeleton,
    }
    return container.pack(header, chunks, embed_skeleton)


def _encode_chunks(codec: Codec, parts: list[Motion], output: Skeleton | None, jobs: int) -> list[bytes]:
    """Each part's body, in order; with ``jobs`` > 1 (and more than one part) in that many
    worker processes."""
    jobs = min(jobs, len(parts))
    if jobs <= 1:
        return [codec.encode(part, output) for part in parts]
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(jobs, mp_context=sandbox.process_context()) as pool:
        return list(pool.map(_encode_part, [(codec, part, output) for part in parts]))


def _encode_part(task: tuple[Codec, Motion, Skeleton | None]) -> bytes:
    codec, part, output = task
    return codec.encode(part, output)


def encode(
    motion: Motion,
    path: str | os.PathLike,
    codec: Codec | None = None,
    chunk_frames: int = CHUNK_FRAMES,
    embed_skeleton: bool = True,
    exact_skeleton: bool = False,
    jobs: int = 1,
) -> int:
    """Write ``motion`` to ``path`` (atomically), its chunks coded by ``jobs`` processes; return
    the file size in bytes."""
    data = pack(motion, codec, chunk_frames, embed_skeleton, exact_skeleton, jobs)
    atomic_write_bytes(path, data)
    return len(data)


def unpack(
    data: bytes,
    frames: tuple[int, int] | None = None,
    name: str = "<bytes>",
    skeleton: Skeleton | None = None,
    max_values: int = limits.MAX_DECODED_VALUES,
    codec: Codec | None = None,
) -> Motion:
    """Decode .moc bytes (all frames, or ``frames=(first, stop)``); ``skeleton`` for a file
    that holds only its skeleton's id; ``max_values`` caps frames x channels
    (:mod:`mocodec.limits`). ``codec``: the codec that wrote ``data`` in this process (a round
    trip), which then decodes it as trusted (:meth:`Codec.decode`), its model files included."""
    return _decode(
        container.open_container(io.BytesIO(data), len(data), name, skeleton),
        frames,
        max_values=max_values,
        codec=codec,
    )


@dataclass(frozen=True)
class RoundTrip:
    data: bytes  # the .moc bytes
    decoded: Motion
    encode_s: float  # wall time of pack, seconds
    decode_s: float  # wall time of unpack


def round_trip(motion: Motion, codec: Codec) -> RoundTrip:
    """Pack and unpack in memory, timing each: what ``eval`` and ``bench`` measure."""
    t0 = time.perf_counter()
    data = pack(motion, codec)
    t1 = time.perf_counter()
    decoded = unpack(data, codec=codec)
    return RoundTrip(data, decoded, t1 - t0, time.perf_counter() - t1)


def decode(
    path: str | os.PathLike,
    frames: tuple[int, int] | None = None,
    skeleton: Skeleton | None = None,
    local_files: dict | None = None,
    max_values: int = limits.MAX_DECODED_VALUES,
) -> Motion:
    """Decode a .moc file, reading only the chunks that ``frames=(first, stop)`` needs.
    ``local_files``: the model files the caller allows (``{"db": path}``); a file never
    chooses what is opened (:func:`codec_from_untrusted`). ``max_values`` caps frames x
    channels (:mod:`mocodec.limits`)."""
    path = Path(path)
    with open(path, "rb") as f:
        return _decode(
            container.open_container(f, path.stat().st_size, str(path), skeleton), frames, local_files, max_values
        )


def info(path: str | os.PathLike, skeleton: Skeleton | None = None) -> container.Container:
    """The header and index of a .moc file (the file is closed; chunks cannot be read)."""
    path = Path(path)
    with open(path, "rb") as f:
        return container.open_container(f, path.stat().st_size, str(path), skeleton)


def _decode(
    c: container.Container,
    frames: tuple[int, int] | None,
    local_files: dict | None = None,
    max_values: int = limits.MAX_DECODED_VALUES,
    codec: Codec | None = None,
) -> Motion:
    first, stop = (0, c.frames) if frames is None else frames
    if not 0 <= first <= stop <= c.frames:
        raise CodecError(f"{c.name}: frames {first}:{stop} are outside 0:{c.frames}")
    wanted = c.chunks_for(first, stop)
    values = sum(c.index[k].count for k in wanted) * c.skeleton.num_channels
    if values > max_values:
        raise CorruptStreamError(
            f"{c.name}: decoding frames {first}:{stop} makes {values:,} values, over the limit of "
            f"{max_values:,} (raise it with --max-values, or decode a frame range)"
        )
    trusted = codec is not None
    codec = codec or codec_from_untrusted(c.header["codec"], f"{c.name}: header", local_files)
    parts = []
    for k in wanted:
        e = c.index[k]
        try:
            motion = codec.decode(c.read_chunk(k), c.skeleton, e.count, c.fps, max_values, trusted)
        except CorruptStreamError as err:
            raise CorruptStreamError(f"{c.name}: chunk {k} at byte {e.offset}: {err}") from None
        if motion.num_frames != e.count:
            raise CorruptStreamError(
                f"{c.name}: chunk {k} at byte {e.offset} decodes to {motion.num_frames} "
                f"frames, the index says {e.count}"
            )
        parts.append(motion.channels[max(first - e.first, 0) : stop - e.first])
    channels = np.concatenate(parts) if parts else np.zeros((0, c.skeleton.num_channels))
    return Motion(c.skeleton, c.fps, channels)


def truncate(
    data: bytes,
    ratio: float | None = None,
    bitrate: float | None = None,
    name: str = "<bytes>",
    tolerance: float = 0.02,
    skeleton: Skeleton | None = None,
) -> bytes:
    """A smaller .moc from an embedded one (``spiht``) without re-encoding: every chunk's
    streams are cut to the rate that makes the file ``ratio`` : 1 (vs 32-bit floats) or
    ``bitrate`` bits per second, within ``tolerance`` below the target size."""
    if (ratio is None) == (bitrate is None):
        raise CodecError("truncate needs exactly one of ratio and bitrate")
    c = container.open_container(io.BytesIO(data), len(data), name, skeleton)
    embedded = "skeleton_id" not in c.header
    codec = codec_from_untrusted(c.header["codec"], f"{name}: header")
    if not codec.embedded:
        raise CodecError(f"{name}: codec {codec.id} is not embedded; encode again with a smaller target")
    cutters = [codec.truncator(c.read_chunk(k), c.skeleton, e.count, c.fps) for k, e in enumerate(c.index)]
    duration = c.frames / c.fps
    raw = c.frames * c.skeleton.num_channels * 4
    target = raw / ratio if ratio is not None else float(bitrate or 0.0) * duration / 8
    if not target > 0:
        raise CodecError(f"truncate target must be positive, got {ratio if ratio is not None else bitrate}")

    def at(bps: float) -> bytes:
        cut = [cutter(bps) for cutter in cutters]
        chunks = [container.Chunk(e.first, e.count, body) for e, (_, body) in zip(c.index, cut)]
        new_codec = cut[0][0] if cut else codec
        header = {k: v for k, v in c.header.items() if k != "skeleton_id"}
        return container.pack(dict(header, codec=new_codec.get_config(), skeleton=c.skeleton), chunks, embedded)

    if len(data) <= target:
        return data
    high = codec.config["bits_per_second"]
    least = next(k.low for k in codec.knobs if k.name == "bits_per_second") or 0.0  # the knob's floor
    low, best = least, None
    for _ in range(40):
        mid = (low + high) / 2
        out = at(mid)
        if len(out) <= target:
            low, best = mid, out
            if len(out) >= target * (1 - tolerance):
                break
        else:
            high = mid
    if best is None:
        raise CodecError(f"{name}: cannot cut to {target:.0f} bytes (the skeleton and side data alone are larger)")
    return best
