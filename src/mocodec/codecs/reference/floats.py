"""Generic float compressors a user might pick instead of a motion codec: ``zstd`` (lossless on
32-bit floats), ``sz3`` (absolute error bound), ``zfp`` (fixed accuracy) and ``fpzip``
(kept mantissa bits). They are the baselines of ``mocodec bench`` and go through the same
container, rate control and measures as every other codec.

Each codes the continuous angles (:meth:`Motion.continuous`: no 360-degree wraps, which would
cost these coders dearly and no motion codec pays for) as 32-bit floats in the time-contiguous
layout, one channel after another. Error bounds are in degrees for rotation channels and in
centimetres for translations. SZ3, ZFP and fpzip come with ``pip install mocodec[bench]``;
without them these codecs say so instead of failing later. Their C decoders are not safe on
damaged bytes, so a body that did not come from this process decodes in a child process
(:attr:`Codec.native_decoder`, :mod:`mocodec.sandbox`).
"""

from __future__ import annotations

import importlib
from typing import ClassVar

import numpy as np
import zstandard

from mocodec.codecs.base import Codec, Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton


def _module(name: str):
    try:
        return importlib.import_module(name)
    except ImportError:
        raise CodecError(f"this codec needs the {name} package: pip install 'mocodec[bench]'") from None


def _time_contiguous(motion: Motion) -> np.ndarray:
    """(channels, frames) 32-bit floats of the continuous angles."""
    return np.ascontiguousarray(motion.continuous().channels.T, dtype=np.float32)


def _channel_bounds(skeleton: Skeleton, bound: float) -> np.ndarray:
    """The bound per channel in file units: degrees, or cm converted to the skeleton's length unit."""
    return np.where(skeleton.rotation_mask, bound, bound * skeleton.units_per_metre / 100.0)


def _frames_from(values: np.ndarray, skeleton: Skeleton, frames: int, what: str) -> np.ndarray:
    values = np.asarray(values, dtype=np.float32).reshape(-1)
    if values.size != frames * skeleton.num_channels:
        raise CorruptStreamError(
            f"{what} body holds {values.size} values, {frames} frames of "
            f"{skeleton.num_channels} channels need {frames * skeleton.num_channels}"
        )
    return values.reshape(skeleton.num_channels, frames).T.astype(np.float64)


class _PerChannel(Codec):
    """An error-bounded compressor run on each channel's samples on its own."""

    baseline = True
    native_decoder = True
    knobs = (Knob("bound", float, 0.01, "absolute error bound per sample: degrees, cm for translations", 1e-6, 1000.0),)
    quality = QualityKnob("bound", higher_is_better=False, log_scale=True)
    package: ClassVar[str] = ""

    def _encode(self, motion: Motion) -> bytes:
        lib = _module(self.package)
        data = _time_contiguous(motion)
        bounds = _channel_bounds(motion.skeleton, self.config["bound"])
        return join_parts(self._compress(lib, row, float(b)) for row, b in zip(data, bounds))

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        lib = _module(self.package)
        parts = split_parts(body, skeleton.num_channels, f"{self.id} body")
        return _frames_from(
            np.concatenate([self._decompress(lib, p, frames) for p in parts]) if parts else np.zeros(0),
            skeleton,
            frames,
            self.id,
        )

    def _compress(self, lib, row: np.ndarray, bound: float) -> bytes:
        raise NotImplementedError

    def _decompress(self, lib, blob: bytes, frames: int) -> np.ndarray:
        raise NotImplementedError


@register
class ZstdCodec(Codec):
    id = "zstd"
    description = "baseline: zstandard on the 32-bit float channels (lossless at float precision)"
    knobs = (Knob("level", int, 19, "zstandard compression level", 1, 22),)
    baseline = True

    def _encode(self, motion: Motion) -> bytes:
        return zstandard.ZstdCompressor(level=self.config["level"]).compress(_time_contiguous(motion).tobytes())

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        raw = zstandard.ZstdDecompressor().decompress(body, max_output_size=4 * frames * skeleton.num_channels)
        return _frames_from(np.frombuffer(raw, dtype="<f4"), skeleton, frames, self.id)


@register
class Sz3Codec(_PerChannel):
    id = "sz3"
    description = "baseline: SZ3 (pysz) per channel with an absolute error bound"
    package = "pysz"

    def _compress(self, lib, row, bound):
        cfg = lib.szConfig()
        cfg.errorBoundMode = lib.szErrorBoundMode.ABS
        cfg.absErrorBound = bound
        return bytes(lib.sz.compress(row, cfg)[0])

    def _decompress(self, lib, blob, frames):
        return lib.sz.decompress(np.frombuffer(blob, dtype=np.uint8), np.float32, (frames,))[0]


@register
class ZfpCodec(_PerChannel):
    id = "zfp"
    description = "baseline: ZFP (zfpy) per channel in fixed-accuracy mode"
    package = "zfpy"

    def _compress(self, lib, row, bound):
        return lib.compress_numpy(row, tolerance=bound)

    def _decompress(self, lib, blob, frames):
        return lib.decompress_numpy(blob)


@register
class FpzipCodec(Codec):
    id = "fpzip"
    description = "baseline: fpzip on the (channels, frames) float array, keeping `precision` bits"
    knobs = (Knob("precision", int, 20, "bits kept of each 32-bit float (32 = lossless)", 2, 32),)
    quality = QualityKnob("precision", higher_is_better=True)
    package = "fpzip"
    baseline = True
    native_decoder = True

    def _encode(self, motion: Motion) -> bytes:
        fpzip = _module(self.package)
        precision = self.config["precision"]
        return fpzip.compress(_time_contiguous(motion), precision=0 if precision == 32 else precision, order="C")

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        fpzip = _module(self.package)
        return _frames_from(fpzip.decompress(body, order="C"), skeleton, frames, self.id)
