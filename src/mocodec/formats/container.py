"""The .moc container: a coded motion that decodes on its own, with random access.

Layout (little-endian; version 3, docs/formats.md gives it byte by byte; versions 1 and 2
are read as well)::

    "MOC1"  u16 version  varint flags (bit 0: the header holds a compact skeleton; bit 1: one
        chunk, without framing or index)
    varint header length, header (zlib, deflated with the version's preset dictionary of
        :mod:`mocodec.formats.header_dict`), holding JSON with the codec
        config, fps, frame count, chunk size and, without flag 0, the skeleton's id; with
        flag 0, a zero byte and the compact skeleton of :mod:`mocodec.formats.skeleton_bin`
        follow the JSON;
        u32 CRC32 of the header bytes
    with flag 1, the one chunk: the codec's body of every frame, u32 CRC32 of the body, to the
        end of the file; else
    chunks: varint body length, the codec's body (:meth:`Codec.encode`: its frame count and
            rate are the index's and the header's), u32 CRC32 of the length and the body
    index:  varint chunk count, per chunk (varint frame count, varint bytes of the chunk),
            u32 CRC32 of the index
    footer: u32 index length, "MOCX"

Versions 1 and 2 have a u16 flags and a u32 header length, and no flag 1; each version has
its header dictionary (:data:`~mocodec.formats.header_dict.DICTIONARIES`). A clip of one
chunk (up to ``chunk_frames`` frames) pays 17 bytes of framing, the smallest that still checks
each part (38 in version 2, which a short clip feels). Chunks follow the header back to back,
so the index's sizes give every chunk's offset and its frame counts every chunk's first frame.
The index at the end lets a reader fetch only the chunks that cover a frame range. Every part
is length-checked and CRC-checked before it is used, and a failure raises
:class:`~mocodec.errors.CorruptStreamError` naming the part (chunk number) and byte offset.

A file can hold its skeleton (self-contained: about 250 bytes for the 57 joints of the CMU BVH
skeletons in a lossy file, 460 for CMU ASF ones) or only the skeleton's id, a hash of its
canonical form: a library of clips on one skeleton, or a stream whose receiver already has it,
then pays 32 bytes instead; the reader must be given the skeleton, and a skeleton with another
id is refused.

This module handles bytes and the skeleton only; codecs are applied by :mod:`mocodec.moc`.
"""

from __future__ import annotations

import hashlib
import json
import math
import struct
import zlib
from dataclasses import dataclass
from typing import BinaryIO

from mocodec import limits
from mocodec.errors import CorruptStreamError, SkeletonMismatchError
from mocodec.formats import varint
from mocodec.formats.header_dict import DICTIONARIES
from mocodec.formats.skeleton_bin import pack_skeleton, unpack_skeleton
from mocodec.skeleton import Joint, Skeleton

MAGIC = b"MOC1"
FOOTER_MAGIC = b"MOCX"
VERSION = 3  # what is written; every version of DICTIONARIES is read (3: varint start, one-chunk files)
VARINT_START = 3  # the first version whose flags and header length are varints
MAX_HEADER = 1 << 24
MAX_CHUNKS = 1 << 20
#: The smallest chunk: a one-byte length, no body, a CRC-32.
MIN_CHUNK_BYTES = 5
FLAG_SKELETON = 1
FLAG_ONE_CHUNK = 2
START = struct.Struct("<4sHHI")  # versions 1 and 2: magic, version, flags, header length
OPENING = struct.Struct("<4sH")  # every version: magic, version
FOOTER = struct.Struct("<I4s")  # index length, footer magic
_U32 = struct.Struct("<I")


# ----- skeleton <-> JSON ------------------------------------------------------------------------
def _number(x: float):
    """A float (never an int, so equal skeletons have equal ids) or "inf"/"-inf" for JSON."""
    x = float(x)
    return x if math.isfinite(x) else ("inf" if x > 0 else "-inf")


def _from_number(x) -> float:
    return float(x)


def skeleton_to_dict(skeleton: Skeleton) -> dict:
    return {
        "name": skeleton.name,
        "units_per_metre": float(skeleton.units_per_metre),
        "joints": [
            {
                "name": j.name,
                "parent": j.parent,
                "offset": [_number(x) for x in j.offset],
                "channels": list(j.channels),
                "rotation_order": j.rotation_order,
                "axis": [_number(x) for x in j.axis],
                "axis_order": j.axis_order,
                "limits": [[_number(a), _number(b)] for a, b in j.limits],
                "body_part": j.body_part,
            }
            for j in skeleton.joints
        ],
    }


def skeleton_id(skeleton: Skeleton) -> str:
    """A 128-bit hash (hex) of the skeleton's canonical JSON form."""
    text = json.dumps(skeleton_to_dict(skeleton), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def skeleton_from_dict(data: dict) -> Skeleton:
    joints = [
        Joint(
            j["name"],
            int(j["parent"]),
            tuple(map(float, j["offset"])),
            tuple(j["channels"]),
            j["rotation_order"],
            tuple(map(float, j["axis"])),
            j["axis_order"],
            tuple((_from_number(a), _from_number(b)) for a, b in j["limits"]),
            j["body_part"],
        )
        for j in data["joints"]
    ]
    return Skeleton(tuple(joints), float(data["units_per_metre"]), data.get("name", ""))


# ----- writing --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Chunk:
    first: int
    count: int
    body: bytes


def pack(header: dict, chunks: list[Chunk], embed_skeleton: bool = True, version: int = VERSION) -> bytes:
    """The whole container as bytes. ``header`` holds codec, fps, frames, chunk_frames and
    ``skeleton`` (a :class:`Skeleton`), which is stored whole or, with ``embed_skeleton=False``,
    as its id. ``version``: an older one for an older reader (a one-chunk file then keeps
    its index)."""
    if version not in DICTIONARIES:
        raise ValueError(f".moc version {version} is not one this mocodec writes")
    skeleton = header["skeleton"]
    meta = {k: v for k, v in header.items() if k != "skeleton"}
    if not embed_skeleton:
        meta["skeleton_id"] = skeleton_id(skeleton)
    text = json.dumps(meta, separators=(",", ":"), allow_nan=False).encode()
    if embed_skeleton:
        text += b"\0" + pack_skeleton(skeleton)
    deflate = zlib.compressobj(9, zdict=DICTIONARIES[version])
    head = deflate.compress(text) + deflate.flush()
    expected = 0
    for chunk in chunks:
        if chunk.first != expected or chunk.count < 1:
            raise ValueError(f"chunk of frames {chunk.first}+{chunk.count} does not follow frame {expected}")
        expected += chunk.count
    one_chunk = len(chunks) == 1 and version >= VARINT_START
    flags = (FLAG_SKELETON if embed_skeleton else 0) | (FLAG_ONE_CHUNK if one_chunk else 0)
    out = bytearray(opening(version, flags, len(head)) + head + _U32.pack(zlib.crc32(head)))
    if flags & FLAG_ONE_CHUNK:
        return bytes(out + chunks[0].body + _U32.pack(zlib.crc32(chunks[0].body)))
    index = bytearray(varint.pack(len(chunks)))
    for chunk in chunks:
        framed = varint.pack(len(chunk.body)) + chunk.body
        index += varint.pack(chunk.count) + varint.pack(len(framed) + 4)
        out += framed + _U32.pack(zlib.crc32(framed))
    index += _U32.pack(zlib.crc32(index))
    out += index + FOOTER.pack(len(index), FOOTER_MAGIC)
    return bytes(out)


def opening(version: int, flags: int, head_len: int) -> bytes:
    """A file's first bytes, up to its header: magic, version, flags and header length (fixed
    widths before VARINT_START, varints from it)."""
    if version < VARINT_START:
        return START.pack(MAGIC, version, flags, head_len)
    return OPENING.pack(MAGIC, version) + varint.pack(flags) + varint.pack(head_len)


def inflate_capped(data: bytes, zdict: bytes, limit: int) -> bytes:
    """``data`` inflated (with the preset dictionary ``zdict``), refusing output over ``limit``
    bytes before it is made (a deflate bomb turns a megabyte into a gigabyte) and input that
    ends early; ValueError says which."""
    inflate = zlib.decompressobj(zdict=zdict) if zdict else zlib.decompressobj()
    text = inflate.decompress(data, limit + 1)
    if not inflate.unconsumed_tail:
        text += inflate.flush()
    if len(text) > limit or inflate.unconsumed_tail:
        raise ValueError(f"it inflates to over {limit:,} bytes")
    if not inflate.eof:
        raise ValueError("the compressed header is cut short")
    return text


def _read_varint(data: bytes, pos: int, where: str) -> tuple[int, int]:
    """(value, next position) of the varint at ``pos``."""
    try:
        return varint.unpack(data, pos)
    except ValueError as e:
        raise CorruptStreamError(f"{where}: {e}") from None


# ----- reading --------------------------------------------------------------------------------
@dataclass(frozen=True)
class IndexEntry:
    offset: int
    first: int
    count: int
    size: int  # bytes of the chunk with its framing


@dataclass(frozen=True)
class Container:
    """An open container: its header and index; chunks are read on demand."""

    source: BinaryIO
    size: int
    name: str
    header: dict
    skeleton: Skeleton
    index: tuple[IndexEntry, ...]
    one_chunk: bool = False  # the file's one chunk is the body and its CRC, without a length

    @property
    def frames(self) -> int:
        return int(self.header["frames"])

    @property
    def fps(self) -> float:
        return float(self.header["fps"])

    def chunks_for(self, first: int, stop: int) -> list[int]:
        """Numbers of the chunks that cover frames first..stop-1."""
        return [k for k, e in enumerate(self.index) if e.first < stop and e.first + e.count > first]

    def read_chunk(self, k: int) -> bytes:
        """The codec body of chunk ``k``, length- and CRC-checked."""
        e = self.index[k]
        where = f"{self.name}: chunk {k} at byte {e.offset}"
        body = _read_at(self.source, e.offset, e.size, self.size, where)
        length, start = (e.size - 4, 0) if self.one_chunk else _read_varint(body, 0, where)
        if start + length + 4 != e.size:
            raise CorruptStreamError(
                f"{where}: a {length}-byte body does not fill the {e.size} bytes the index gives the chunk"
            )
        if zlib.crc32(body[:-4]) != _U32.unpack(body[-4:])[0]:
            raise CorruptStreamError(f"{where}: CRC mismatch, the chunk is damaged")
        return body[start:-4]


def _read_at(source: BinaryIO, offset: int, length: int, size: int, where: str) -> bytes:
    if offset < 0 or offset + length > size:
        raise CorruptStreamError(f"{where}: needs bytes {offset}..{offset + length} but the file has {size}")
    source.seek(offset)
    data = source.read(length)
    if len(data) != length:
        raise CorruptStreamError(f"{where}: file ends at byte {offset + len(data)}")
    return data


def open_container(source: BinaryIO, size: int, name: str, skeleton: Skeleton | None = None) -> Container:
    """Read and check the header, footer and index of a container. ``skeleton`` is needed for
    a file that holds only its skeleton's id (and is ignored for one that holds the skeleton)."""
    version, flags, head_at, head_len = read_opening(source, size, name)
    if head_len > MAX_HEADER:
        raise CorruptStreamError(f"{name}: header length {head_len} before byte {head_at} is implausible")
    head = _read_at(source, head_at, head_len + 4, size, f"{name}: header")
    if zlib.crc32(head[:-4]) != _U32.unpack(head[-4:])[0]:
        raise CorruptStreamError(f"{name}: header CRC mismatch at byte {head_at}, the header is damaged")
    try:
        text = inflate_capped(head[:-4], DICTIONARIES[version], limits.MAX_HEADER_TEXT)
        if flags & FLAG_SKELETON:
            text, _, compact = text.partition(b"\0")
        header = json.loads(text)
        embedded: Skeleton | None
        if flags & FLAG_SKELETON:
            embedded = unpack_skeleton(compact)
        else:
            embedded = skeleton_from_dict(header.pop("skeleton")) if "skeleton" in header else None
        wanted = None if embedded else str(header["skeleton_id"])
        frames, fps = int(header["frames"]), float(header["fps"])
        if not isinstance(header["codec"], dict):
            raise ValueError("the codec config is not an object")
    except (ValueError, KeyError, TypeError, AttributeError, OverflowError, RecursionError, zlib.error) as e:
        raise CorruptStreamError(f"{name}: header at byte {head_at} does not parse ({e})") from None
    if embedded is None:
        if skeleton is None:
            raise SkeletonMismatchError(
                f"{name}: the file refers to skeleton {wanted} without holding it; "
                "give the skeleton it was coded with (decode --skeleton FILE)"
            )
        if skeleton_id(skeleton) != wanted:
            raise SkeletonMismatchError(
                f"{name}: the file was coded for skeleton {wanted}, the one given is {skeleton_id(skeleton)}"
            )
    skeleton = embedded or skeleton
    assert skeleton is not None  # a file without its skeleton was given one above
    if frames < 0 or not limits.fps_ok(fps):
        raise CorruptStreamError(f"{name}: header says {frames} frames at {fps} fps")
    chunks_at = head_at + head_len + 4
    if flags & FLAG_ONE_CHUNK:
        if not 0 < frames <= limits.MAX_PAYLOAD_FRAMES or size - chunks_at < 4:
            raise CorruptStreamError(
                f"{name}: a chunk of {frames} frames in the {size - chunks_at} bytes from byte {chunks_at} is invalid"
            )
        whole = IndexEntry(chunks_at, 0, frames, size - chunks_at)
        return Container(source, size, name, header, skeleton, (whole,), one_chunk=True)
    index = _index(source, size, name, chunks_at)
    if sum(e.count for e in index) != frames:
        raise CorruptStreamError(
            f"{name}: the index's chunks cover {sum(e.count for e in index)} frames, the header says {frames}"
        )
    return Container(source, size, name, header, skeleton, index)


def read_opening(source: BinaryIO, size: int, name: str) -> tuple[int, int, int, int]:
    """(version, flags, where the header starts, its length) from a file's first bytes, checked."""
    magic, version = OPENING.unpack(_read_at(source, 0, OPENING.size, size, f"{name}: header"))
    if magic != MAGIC:
        raise CorruptStreamError(f"{name}: not a .moc file (starts with {magic!r}, expected {MAGIC!r})")
    if version not in DICTIONARIES:
        known = ", ".join(map(str, DICTIONARIES))
        raise CorruptStreamError(f"{name}: .moc version {version}; this mocodec reads versions {known}")
    if version < VARINT_START:
        _, _, flags, head_len = START.unpack(_read_at(source, 0, START.size, size, f"{name}: header"))
        head_at, defined = START.size, FLAG_SKELETON
    else:
        where = f"{name}: start"
        start = _read_at(source, 0, min(size, OPENING.size + 8), size, where)
        flags, pos = _read_varint(start, OPENING.size, where)
        head_len, head_at = _read_varint(start, pos, where)
        defined = FLAG_SKELETON | FLAG_ONE_CHUNK
    if flags & ~defined:
        raise CorruptStreamError(
            f"{name}: flags {flags:#06x} at byte {OPENING.size} set bits version {version} does not define"
        )
    return version, flags, head_at, head_len


def _index(source: BinaryIO, size: int, name: str, chunks_at: int) -> tuple[IndexEntry, ...]:
    """The index, checked against the file's layout."""
    foot_at = size - FOOTER.size
    length, foot_magic = FOOTER.unpack(_read_at(source, foot_at, FOOTER.size, size, f"{name}: footer"))
    if foot_magic != FOOTER_MAGIC:
        raise CorruptStreamError(f"{name}: footer at byte {foot_at} is damaged or the file is truncated")
    index_at = foot_at - length
    where = f"{name}: index at byte {index_at}"
    if length < 5 or index_at < chunks_at:
        raise CorruptStreamError(f"{where}: an index of {length} bytes does not fit in the file")
    raw = _read_at(source, index_at, length, size, where)
    if zlib.crc32(raw[:-4]) != _U32.unpack(raw[-4:])[0]:
        raise CorruptStreamError(f"{where}: CRC mismatch, the index is damaged")
    n, pos = _read_varint(raw, 0, where)
    if n > min(MAX_CHUNKS, (index_at - chunks_at) // MIN_CHUNK_BYTES):
        raise CorruptStreamError(f"{where}: {n} chunks do not fit in {index_at - chunks_at} bytes of chunks")
    entries, offset, first = [], chunks_at, 0
    for k in range(n):
        count, pos = _read_varint(raw, pos, where)
        chunk_size, pos = _read_varint(raw, pos, where)
        if not 0 < count <= limits.MAX_PAYLOAD_FRAMES or chunk_size < 5:
            raise CorruptStreamError(f"{where}: entry {k} ({count} frames in {chunk_size} bytes) is invalid")
        entries.append(IndexEntry(offset, first, count, chunk_size))
        offset, first = offset + chunk_size, first + count
    if pos != length - 4 or offset != index_at:
        raise CorruptStreamError(f"{where}: the entries do not match the file's layout")
    return tuple(entries)
