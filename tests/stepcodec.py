"""A minimal lossy codec for framework tests: each channel rounded to multiples of ``step``
(degrees or units), first differences range coded. Registered as ``test-step``."""

from __future__ import annotations

import numpy as np

from mocodec.codecs import Codec, Knob, QualityKnob, register
from mocodec.codecs.registry import codec_ids
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints


class StepCodec(Codec):
    id = "test-step"
    description = "test only: uniform rounding to a step"
    knobs = (Knob("step", float, 0.1, "rounding step", low=1e-4, high=100.0),)
    quality = QualityKnob("step", higher_is_better=False, log_scale=True)

    def _encode(self, motion) -> bytes:
        q = np.round(motion.channels / self.config["step"]).astype(np.int64)
        return encode_ints(np.diff(q, axis=0, prepend=0).T)

    def _decode(self, body, skeleton, frames, fps):
        d = decode_ints(body).reshape(skeleton.num_channels, frames).T
        return np.cumsum(d, axis=0) * self.config["step"]


if "test-step" not in codec_ids():
    register(StepCodec)
