"""Codecs by family (waveform, model, motionprimitives, perceptual, kinwave, reference), each
registered by id: ``get_codec(id, **knobs)`` imports the one asked for."""

from mocodec.codecs.registry import (
    DEFAULT_CODEC,
    checked_config,
    codec_class,
    codec_from_config,
    codec_from_untrusted,
    codec_ids,
    get_codec,
    packet_codecs,
    register,
)

_BASE = ("Codec", "Coded", "Knob", "QualityKnob", "StreamDecoder", "StreamEncoder")


def __getattr__(name: str):
    if name in _BASE:  # the interface, loaded with the first codec that needs it
        from mocodec.codecs import base

        return getattr(base, name)
    raise AttributeError(f"module 'mocodec.codecs' has no attribute {name!r}")


__all__ = [
    *_BASE,
    "DEFAULT_CODEC",
    "checked_config",
    "codec_class",
    "codec_from_config",
    "codec_from_untrusted",
    "codec_ids",
    "get_codec",
    "packet_codecs",
    "register",
]
