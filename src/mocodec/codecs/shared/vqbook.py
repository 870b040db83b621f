"""VQ codebooks of the spatial and temporal coders (000 §7.9): which vectors a skeleton's
motion gives, training them from clips, and the versioned codebook file encoder and decoder
share.

Vectors are in degrees and centimetres (translations converted from the skeleton's units), so
one temporal codebook serves any skeleton; a spatial codebook has one book per body-part group
(Table 5-1, the root's translation a group of its own) and names the channels of each group,
so it serves skeletons with that channel layout (the hand groups of a skeleton with fingers
are the thesis's hand-gesture case). ``predictive`` codebooks hold differences from the last
decoded sample (temporal) or frame (spatial); plain ones hold the values themselves.

File layout (little-endian): ``MOCVQ``, a version byte, the length of a JSON description
(kind, predictive, length, fps, sizes, groups with their channels, entries per size and group,
the training clips), the JSON, then per size and group the code vectors as float32, then a
CRC-32 of everything before it. The CRC is also the codebook's fingerprint, which a body
coded with it carries.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from mocodec.codecs.base import Knob
from mocodec.codecs.shared import modelfile
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.quantisation import vq
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.metrics.groups import group_channels
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

#: svq's and tvq's knob naming a trained codebook file
CODEBOOK_KNOB = Knob(
    "codebook",
    str,
    "",
    "a codebook file (mocodec model train codebook); empty: train on the clip, send in-band",
    path=True,
)

MAGIC = b"MOCVQ"
VERSION = 1
KINDS = ("temporal", "spatial")
MAX_TRAINING_VECTORS = 200_000


def channel_units(skeleton: Skeleton) -> np.ndarray:
    """Per channel the factor to degrees (rotations) or centimetres (translations)."""
    return np.where(skeleton.rotation_mask, 1.0, 100.0 / skeleton.units_per_metre)


def spatial_groups(skeleton: Skeleton) -> list[tuple[str, np.ndarray]]:
    """(name, channels) of every group: the body parts, the root's translation apart."""
    translation = np.flatnonzero(~skeleton.rotation_mask)
    groups = [("root_position", translation)] if translation.size else []
    for name, cols in group_channels(skeleton).items():
        cols = np.setdiff1d(cols, translation)
        if cols.size:
            groups.append((name, cols))
    return groups


def temporal_vectors(x: np.ndarray, length: int, predictive: bool) -> np.ndarray:
    """The ``length``-sample vectors of every channel of ``x (frames, C)`` (minus the sample
    before each, when ``predictive``)."""
    m = (len(x) - int(predictive)) // length
    if m <= 0:
        return np.zeros((0, length))
    start = int(predictive)
    blocks = x[start : start + m * length].reshape(m, length, -1)
    if predictive:
        blocks = blocks - x[length * np.arange(m)][:, None, :]
    return blocks.transpose(0, 2, 1).reshape(-1, length)


def spatial_vectors(x: np.ndarray, cols: np.ndarray, predictive: bool) -> np.ndarray:
    """The group's vectors, one per frame (frame-to-frame differences when ``predictive``)."""
    v = x[:, cols]
    return np.diff(v, axis=0) if predictive else v


@dataclass
class Codebook(modelfile.Model):
    WHAT = "codebook"

    kind: str  # temporal | spatial
    predictive: bool
    length: int  # temporal vector length (1 for spatial)
    fps: float  # the rate it was trained at
    groups: list[tuple[str, list[str]]]  # (name, channel names); temporal: one group, no names
    books: dict[int, list[np.ndarray]]  # size -> one (entries, dim) array per group
    trained_on: list[str] = field(default_factory=list)

    def to_bytes(self) -> bytes:
        sizes = sorted(self.books)
        meta = {
            "kind": self.kind,
            "predictive": self.predictive,
            "length": self.length,
            "fps": self.fps,
            "sizes": sizes,
            "groups": [{"name": n, "channels": c} for n, c in self.groups],
            "entries": {str(s): [len(b) for b in self.books[s]] for s in sizes},
            "trained_on": self.trained_on,
        }
        return modelfile.pack(
            MAGIC, VERSION, meta, b"".join(np.asarray(b, dtype="<f4").tobytes() for s in sizes for b in self.books[s])
        )

    @classmethod
    def from_bytes(cls, data: bytes, where: str) -> Codebook:
        meta, offset = modelfile.unpack(data, MAGIC, VERSION, "VQ codebook", where)
        try:
            groups = [(g["name"], list(g["channels"])) for g in meta["groups"]]
            dims = [meta["length"]] if meta["kind"] == "temporal" else [len(c) for _, c in groups]
            books: dict[int, list[np.ndarray]] = {}
            for s in meta["sizes"]:
                books[int(s)] = []
                for entries, dim in zip(meta["entries"][str(s)], dims):
                    n = entries * dim
                    books[int(s)].append(np.frombuffer(data, "<f4", n, offset).reshape(entries, dim).astype(np.float64))
                    offset += 4 * n
            if offset != len(data) - 4 or meta["kind"] not in KINDS:
                raise ValueError(f"{len(data) - 4 - offset} bytes left after the code vectors")
            return cls(
                meta["kind"],
                bool(meta["predictive"]),
                int(meta["length"]),
                float(meta["fps"]),
                groups,
                books,
                list(meta.get("trained_on", [])),
            )
        except (ValueError, KeyError, TypeError) as e:
            raise CodecError(f"{where}: codebook description does not parse ({e})") from None

    def book(self, size: int) -> list[np.ndarray]:
        if size not in self.books:
            raise CodecError(f"this {self.kind} codebook has sizes {sorted(self.books)}, not {size}")
        return self.books[size]

    def check_skeleton(self, skeleton: Skeleton) -> None:
        """A spatial codebook's groups must be the skeleton's, channel for channel."""
        if self.kind != "spatial":
            return
        names = list(skeleton.channel_names)
        mine = [(n, [names[c] for c in cols]) for n, cols in spatial_groups(skeleton)]
        if mine != [(n, list(c)) for n, c in self.groups]:
            raise CodecError(
                f"the spatial codebook's groups ({', '.join(n for n, _ in self.groups)}) do not match "
                f"this skeleton's channels ({', '.join(n for n, _ in mine)})"
            )


_SOURCE = struct.Struct("<BII")  # 0: the books travel in the header (float16); 1: a file's: fingerprint, size


def shared_books(
    path: str, kind: str, predictive: bool, length: int, size: int, skeleton: Skeleton
) -> tuple[list[np.ndarray], bytes]:
    """The books of ``size`` in the codebook file at ``path``, checked against the coder's
    settings, and the header part that names them."""
    book = Codebook.load(path)
    if book.kind != kind:
        raise CodecError(f"codebook {path} is a {book.kind} codebook, this coder needs a {kind} one")
    if book.predictive != predictive or (kind == "temporal" and book.length != length):
        raise CodecError(
            f"codebook {path} was trained with predictive={book.predictive}, length={book.length}; "
            f"the coder has predictive={predictive}, length={length}"
        )
    book.check_skeleton(skeleton)
    if size not in book.books:
        raise CodecError(f"codebook {path} has sizes {sorted(book.books)}, not {size} (the codec's size knob)")
    return book.book(size), _SOURCE.pack(1, book.fingerprint, size)


def inband_books(books: list[np.ndarray]) -> tuple[list[np.ndarray], bytes]:
    """Books that travel in the header: rounded to float16, and that header part."""
    half = [b.astype("<f2") for b in books]
    counts = struct.pack(f"<{len(half)}I", *[len(b) for b in half])
    return [h.astype(np.float64) for h in half], _SOURCE.pack(0, 0, 0) + counts + b"".join(h.tobytes() for h in half)


def read_books(part: bytes, dims: list[int], path: str, where: str) -> list[np.ndarray]:
    """The books a header part names or holds (``path``: the decoder's codebook file, if any)."""
    if len(part) < _SOURCE.size:
        raise CorruptStreamError(f"{where}: codebook part of {len(part)} bytes")
    mode, fingerprint, size = _SOURCE.unpack_from(part)
    if mode == 1 and len(part) == _SOURCE.size:
        if not path:
            raise CodecError(
                f"{where}: the body was coded with a shared codebook (fingerprint {fingerprint:08x}); "
                "give the file with --codebook FILE"
            )
        book = Codebook.load(path)
        if book.fingerprint != fingerprint:
            raise CodecError(
                f"{where}: the body was coded with codebook {fingerprint:08x}, {path} is {book.fingerprint:08x}"
            )
        books = book.book(size)
        if [b.shape[1] for b in books] != dims:
            raise CodecError(f"{where}: codebook {path} does not fit this skeleton's groups")
        return books
    if mode != 0 or len(part) < _SOURCE.size + 4 * len(dims):
        raise CorruptStreamError(f"{where}: codebook part does not parse")
    counts = struct.unpack_from(f"<{len(dims)}I", part, _SOURCE.size)
    offset, books = _SOURCE.size + 4 * len(dims), []
    for n, d in zip(counts, dims):
        if offset + 2 * n * d > len(part):
            raise CorruptStreamError(f"{where}: codebook part is shorter than its {n} x {d} entries")
        books.append(np.frombuffer(part, "<f2", n * d, offset).reshape(n, d).astype(np.float64))
        offset += 2 * n * d
    if offset != len(part) or any(len(b) == 0 or not np.isfinite(b).all() for b in books):
        raise CorruptStreamError(f"{where}: codebook part does not parse")
    return books


def pack_header(source: bytes, x: np.ndarray) -> tuple[bytes, np.ndarray]:
    """A VQ coder's header (the codebook part and the first frame ``x[0]`` in float32, where a
    predictive loop starts) and that first frame as both ends have it."""
    first = x[0].astype("<f4")
    return join_parts([source, first.tobytes()]), first.astype(np.float64)


def read_header(
    header: bytes, dims: list[int], path: str, skeleton: Skeleton, where: str
) -> tuple[list[np.ndarray], np.ndarray]:
    """The books and first frame of a header made by :func:`pack_header`."""
    source, first_bytes = split_parts(header, 2, where)
    books = read_books(source, dims, path, where)
    first = np.frombuffer(first_bytes, "<f4").astype(np.float64)
    if first.size != skeleton.num_channels or not np.isfinite(first).all():
        raise CorruptStreamError(f"{where}: the first frame does not match the skeleton")
    return books, first


def train(
    kind: str,
    clips: list[Motion],
    sizes: list[int],
    predictive: bool = True,
    length: int = 6,
    names: list[str] | None = None,
) -> Codebook:
    """LBG codebooks of every size in ``sizes`` from ``clips`` (same frame rate; for spatial,
    the same channel layout), at most :data:`MAX_TRAINING_VECTORS` vectors per group, evenly
    taken."""
    if kind not in KINDS:
        raise CodecError(f"codebook kind must be one of {KINDS}, got {kind!r}")
    if not clips:
        raise CodecError("no clips to train a codebook on")
    first = clips[0]
    units = [channel_units(c.skeleton) * c.continuous().channels for c in clips]
    if kind == "temporal":
        layout: list[tuple[str, list[str]]] = [("all", [])]
        vectors = [np.vstack([temporal_vectors(u, length, predictive) for u in units])]
    else:
        groups = spatial_groups(first.skeleton)
        for c in clips[1:]:
            if list(c.skeleton.channel_names) != list(first.skeleton.channel_names):
                raise CodecError("spatial codebooks need clips with one channel layout")
        layout = [(n, [first.skeleton.channel_names[i] for i in cols]) for n, cols in groups]
        vectors = [np.vstack([spatial_vectors(u, cols, predictive) for u in units]) for _, cols in groups]
    books: dict[int, list[np.ndarray]] = {s: [] for s in sizes}
    for v in vectors:
        if len(v) == 0:
            raise CodecError("the clips are too short to give any training vector")
        v = v[np.linspace(0, len(v) - 1, min(len(v), MAX_TRAINING_VECTORS)).astype(np.int64)]
        for s, b in vq.lbg(v, sorted(sizes)).items():
            books[s].append(b)
    return Codebook(
        kind, predictive, length if kind == "temporal" else 1, float(first.fps), layout, books, list(names or [])
    )
