"""kinwave as a zarr format 3 codec: the array-to-bytes step ("serializer") of an array of
motion, registered under the name ``mocodec.kinwave`` through zarr's entry point.

The chunks and the configuration are those of :class:`mocodec.numcodecs.Kinwave`
(docs/formats.md); this class only adapts it to zarr 3's codec interface. Format 2 arrays take
:class:`mocodec.numcodecs.Kinwave` itself as their compressor.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from mocodec.extras import require
from mocodec.motion import Motion
from mocodec.numcodecs import Kinwave as NumcodecsKinwave
from mocodec.skeleton import Skeleton

require("zarr", "zarr", "the zarr format 3 codec")
from zarr.abc.codec import ArrayBytesCodec  # noqa: E402 - after the one-line message of a missing extra
from zarr.core.common import parse_named_configuration  # noqa: E402

NAME = "mocodec.kinwave"


@dataclass(frozen=True)
class Kinwave(ArrayBytesCodec):
    """``zarr.create_array(..., serializer=Kinwave.for_motion(motion, max_error_cm=1),
    compressors=None)``: each chunk of ``(frames, channels)`` coded by kinwave."""

    configuration: dict
    is_fixed_size = False

    @classmethod
    def for_motion(cls, motion: Motion | Skeleton, fps: float | None = None, **knobs) -> Kinwave:
        config = NumcodecsKinwave.for_motion(motion, fps, **knobs).get_config()
        config.pop("id")
        return cls(config)

    @cached_property
    def codec(self) -> NumcodecsKinwave:
        return NumcodecsKinwave.from_config(self.configuration)

    @classmethod
    def from_dict(cls, data: dict) -> Kinwave:
        _, configuration = parse_named_configuration(data, NAME)
        return cls(dict(configuration or {}))

    def to_dict(self) -> dict:
        return {"name": NAME, "configuration": dict(self.configuration)}

    async def _decode_single(self, chunk_bytes, chunk_spec):
        decoded = self.codec.decode(chunk_bytes.as_array_like(), frames=chunk_spec.shape[0])
        array = np.ascontiguousarray(decoded, dtype=chunk_spec.dtype.to_native_dtype()).reshape(chunk_spec.shape)
        return chunk_spec.prototype.nd_buffer.from_ndarray_like(array)

    async def _encode_single(self, chunk_array, chunk_spec):
        return chunk_spec.prototype.buffer.from_bytes(self.codec.encode(chunk_array.as_ndarray_like()))

    def compute_encoded_size(self, input_byte_length: int, chunk_spec) -> int:
        raise NotImplementedError("a kinwave chunk's size depends on its motion")
