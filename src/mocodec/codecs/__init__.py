"""Codecs, one module each, registered by id: ``get_codec(id, **knobs)``."""

from mocodec.codecs import (adpcm, dct, deadreckoning, dpcm, floats, gesture, hybrid, kinwave, lossless, posture,  # noqa: F401
                            primitives, pwavelet, quant, raw, rhythmic, spiht, subband, svq, tvq)  # noqa: F401
from mocodec.codecs.base import Codec, Knob, QualityKnob, StreamDecoder, StreamEncoder
from mocodec.codecs.registry import (DEFAULT_CODEC, codec_class, codec_from_config, codec_from_untrusted,
                                     codec_ids, get_codec, register)

__all__ = ["Codec", "Knob", "QualityKnob", "StreamDecoder", "StreamEncoder", "DEFAULT_CODEC", "codec_class",
           "codec_from_config", "codec_from_untrusted", "codec_ids", "get_codec", "register"]
