"""mocodec's kinwave as a numcodecs codec, so a zarr array of motion is coded with a guaranteed
error and stays self-describing.

A chunk is a ``(frames, channels)`` float array of one skeleton's channels (degrees and
skeleton units, as :class:`~mocodec.motion.Motion` holds them); the skeleton (its compact form,
base64) and the frame rate live in the codec's config, which zarr stores in the array's
metadata. An encoded chunk is a varint frame count, the kinwave body and a CRC-32 of both
(docs/formats.md). Registered under the id ``mocodec.kinwave`` through numcodecs' entry point,
so ``numcodecs.get_codec({"id": "mocodec.kinwave", ...})`` finds it once mocodec is installed
with the ``[zarr]`` extra. Decoding treats the config and the chunk as hostile: sizes are
checked before anything is allocated.
"""

from __future__ import annotations

import base64
import binascii
import zlib

import numpy as np

from mocodec import limits
from mocodec.codecs.registry import codec_from_untrusted
from mocodec.errors import CorruptStreamError
from mocodec.extras import require
from mocodec.formats import varint
from mocodec.formats.skeleton_bin import pack_skeleton, unpack_skeleton
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

_numcodecs = require("numcodecs", "zarr", "the numcodecs codec")
from numcodecs.abc import Codec  # noqa: E402 - after the one-line message of a missing extra
from numcodecs.compat import ensure_bytes, ensure_ndarray_like, ndarray_copy  # noqa: E402

#: Bytes the base64 skeleton of a config may have.
MAX_SKELETON_TEXT = 1 << 22


class Kinwave(Codec):
    """kinwave on ``(frames, channels)`` chunks of one skeleton's motion.

    ``skeleton``: the compact skeleton, base64 (:meth:`for_motion` makes it); ``fps``: the
    frame rate; ``dtype``: the zarr array's dtype, which decoded chunks take; ``knobs``:
    kinwave's knobs (``max_error_cm``, ``error_measure``, ...); ``chunk_frames``: the array's
    chunk length in frames, which a chunk must have (a zarr format 2 array tells its compressor
    nothing else; format 3 and an ``out`` buffer give the chunk's shape anyway). Every field is
    checked as hostile (zarr metadata is a file): a wrong type or value is a CorruptStreamError."""

    codec_id = "mocodec.kinwave"

    def __init__(
        self,
        skeleton: str,
        fps: float,
        dtype: str = "<f4",
        knobs: dict | None = None,
        chunk_frames: int | None = None,
    ):
        where = f"{self.codec_id} config"
        self.skeleton_text = skeleton
        self.fps = _number(fps, f"{where}: fps")
        if not limits.fps_ok(self.fps):
            raise CorruptStreamError(f"{where}: fps {self.fps!r} out of range {limits.FPS_RANGE}")
        self.dtype = _float_dtype(dtype, where)
        if knobs is not None and not isinstance(knobs, dict):
            raise CorruptStreamError(f"{where}: knobs must be an object, got {type(knobs).__name__}")
        self.knobs = dict(knobs or {})
        if chunk_frames is not None and not (
            type(chunk_frames) is int and 0 < chunk_frames <= limits.MAX_PAYLOAD_FRAMES
        ):
            raise CorruptStreamError(f"{where}: chunk_frames must be an integer 1 to {limits.MAX_PAYLOAD_FRAMES}")
        self.chunk_frames = chunk_frames
        self.skeleton = _skeleton(skeleton, where)
        self.codec = codec_from_untrusted({"codec": "kinwave", "knobs": self.knobs}, where)

    @classmethod
    def from_config(cls, config: dict) -> Kinwave:
        """The codec of a config from an array's metadata: unknown fields are refused."""
        fields = {k: v for k, v in dict(config).items() if k != "id"}
        unknown = sorted(set(fields) - {"skeleton", "fps", "dtype", "knobs", "chunk_frames"})
        if unknown or not {"skeleton", "fps"} <= set(fields):
            raise CorruptStreamError(f"{cls.codec_id} config: needs skeleton and fps, and has no field {unknown}")
        return cls(**fields)

    @classmethod
    def for_motion(
        cls,
        motion: Motion | Skeleton,
        fps: float | None = None,
        dtype: str = "<f4",
        chunk_frames: int | None = None,
        **knobs,
    ) -> Kinwave:
        """The codec for chunks of ``motion``'s channels (or of a skeleton's, at ``fps``)."""
        skeleton = motion.skeleton if isinstance(motion, Motion) else motion
        rate = fps if fps is not None else getattr(motion, "fps", None)
        if rate is None:
            raise ValueError("give the frame rate (fps) with a skeleton")
        text = base64.b64encode(pack_skeleton(skeleton)).decode("ascii")
        return cls(text, rate, dtype, knobs, chunk_frames)

    def get_config(self) -> dict:
        config = {
            "id": self.codec_id,
            "skeleton": self.skeleton_text,
            "fps": self.fps,
            "dtype": self.dtype,
            "knobs": dict(self.knobs),
        }
        return config | ({"chunk_frames": self.chunk_frames} if self.chunk_frames else {})

    def __repr__(self) -> str:
        return f"Kinwave({len(self.skeleton)} joints, {self.fps:g} fps, {self.dtype}, knobs={self.knobs})"

    def _frames(self, buf) -> np.ndarray:
        array = ensure_ndarray_like(buf)
        channels = self.skeleton.num_channels
        if array.ndim == 1 and channels and array.size % channels == 0:
            array = array.reshape(-1, channels)
        if array.ndim != 2 or array.shape[1] != channels:
            raise ValueError(
                f"{self.codec_id}: a chunk must be (frames, {channels}) with every channel of the skeleton, "
                f"got {array.shape}"
            )
        return np.asarray(array, dtype=np.float64)

    def encode(self, buf) -> bytes:
        channels = self._frames(buf)
        body = self.codec.encode(Motion(self.skeleton, self.fps, channels))
        framed = varint.pack(len(channels)) + body
        return framed + zlib.crc32(framed).to_bytes(4, "little")

    def decode(self, buf, out=None, *, frames: int | None = None):
        """A chunk's ``(frames, channels)``; ``frames``: the chunk shape's (else ``out``'s, else
        ``chunk_frames``), which the chunk must declare before anything is decoded."""
        data = ensure_bytes(buf)
        if len(data) < 5:
            raise CorruptStreamError(f"{self.codec_id} chunk of {len(data)} bytes: too short")
        framed, crc = data[:-4], int.from_bytes(data[-4:], "little")
        if zlib.crc32(framed) != crc:
            raise CorruptStreamError(f"{self.codec_id} chunk: CRC-32 mismatch (the data is damaged)")
        try:
            declared, start = varint.unpack(framed, 0)
        except ValueError as e:
            raise CorruptStreamError(f"{self.codec_id} chunk: frame count {e}") from None
        expected = self._chunk_frames(out) if frames is None else frames
        if expected is not None and declared != expected:
            raise CorruptStreamError(
                f"{self.codec_id} chunk: {declared} frames, but its array's chunks have {expected}"
            )
        motion = self.codec.decode(framed[start:], self.skeleton, declared, self.fps)
        decoded = np.ascontiguousarray(motion.channels, dtype=self.dtype)  # C order: zarr flattens in "A" order
        return ndarray_copy(decoded, out) if out is not None else decoded

    def _chunk_frames(self, out) -> int | None:
        if out is None:
            return self.chunk_frames
        size, channels = ensure_ndarray_like(out).size, self.skeleton.num_channels
        return size // channels if channels else 0


def _number(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CorruptStreamError(f"{where} must be a number, got {type(value).__name__}")
    try:
        return float(value)
    except OverflowError:
        raise CorruptStreamError(f"{where} is out of range") from None


def _float_dtype(value: object, where: str) -> str:
    dtype = None
    if isinstance(value, (str, np.dtype)) or (isinstance(value, type) and issubclass(value, np.generic)):
        try:
            dtype = np.dtype(value)
        except (TypeError, ValueError):
            pass
    if dtype is None or dtype.kind != "f" or dtype.subdtype is not None:
        raise CorruptStreamError(f"{where}: dtype {str(value)[:40]!r} is not a float type")
    return dtype.str


def _skeleton(text: object, where: str) -> Skeleton:
    if not isinstance(text, str) or len(text) > MAX_SKELETON_TEXT:
        raise CorruptStreamError(f"{where}: the skeleton must be base64 text of at most {MAX_SKELETON_TEXT} bytes")
    try:
        return unpack_skeleton(base64.b64decode(text, validate=True))
    except (binascii.Error, ValueError):
        raise CorruptStreamError(f"{where}: the skeleton is not valid base64") from None
