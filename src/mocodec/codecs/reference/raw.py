"""``raw``: every channel as a little-endian 32-bit float, frame by frame. The reference the
compression ratio is measured against (ratio 1 plus the envelope), and the simplest
streaming codec (one packet per push, no delay). Lossless relative to 32-bit floats."""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Codec, Coded, StreamDecoder, StreamEncoder
from mocodec.codecs.registry import register
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.skeleton import Skeleton


class _RawEncoder(StreamEncoder):
    def __init__(self, channels: int):
        self.channels = channels

    def code(self, frames: np.ndarray) -> list[Coded]:
        frames = np.atleast_2d(np.asarray(frames, dtype=np.float64))
        if frames.shape[1] != self.channels or not np.isfinite(frames).all():
            raise CodecError(f"raw stream: frames must be finite (n, {self.channels}) arrays")
        return [Coded(frames.astype("<f4").tobytes(), len(frames))] if len(frames) else []


class _RawDecoder(StreamDecoder):
    def __init__(self, channels: int):
        self.channels = channels

    def push(self, packet: bytes) -> np.ndarray:
        if len(packet) % (4 * self.channels):
            raise CorruptStreamError(f"raw packet of {len(packet)} bytes is not whole frames of {self.channels} floats")
        values = np.frombuffer(packet, dtype="<f4").reshape(-1, self.channels)
        if not np.isfinite(values).all():
            raise CorruptStreamError("raw packet holds a value that is not a finite number")
        return values.astype(np.float64)


@register
class RawCodec(Codec):
    id = "raw"
    packet_number = 0
    description = "32-bit floats, uncompressed: the reference for compression ratios"
    lossless = True

    def _encode(self, motion) -> bytes:
        return motion.channels.astype("<f4").tobytes()

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        need = 4 * frames * skeleton.num_channels
        if len(body) != need:
            raise CorruptStreamError(f"raw body holds {len(body)} bytes, {frames} frames need {need}")
        return np.frombuffer(body, dtype="<f4").reshape(frames, skeleton.num_channels).astype(np.float64)

    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return _RawEncoder(skeleton.num_channels)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return _RawDecoder(skeleton.num_channels)
