"""mocodec: coding (compression) of human motion capture.

The data model (:class:`Skeleton`, :class:`Motion`), motion files (:func:`load`,
:func:`save`), the built-in human model, the codecs (:func:`get_codec`) and .moc files
(:mod:`mocodec.moc`: ``pack``, ``unpack``, ``encode``, ``decode``). Names are imported when
first used, so ``import mocodec`` is quick.
"""

from importlib import import_module

from mocodec.version import __version__

_WHERE = {
    "Skeleton": "mocodec.skeleton", "Joint": "mocodec.skeleton", "BODY_PARTS": "mocodec.skeleton",
    "Motion": "mocodec.motion", "load": "mocodec.formats", "save": "mocodec.formats",
    "human_model": "mocodec.human", "get_codec": "mocodec.codecs", "codec_ids": "mocodec.codecs",
    **dict.fromkeys(("MocodecError", "FormatError", "ConversionError", "CodecError", "CorruptStreamError"),
                    "mocodec.errors"),
}


def __getattr__(name: str):
    if name == "moc":
        return import_module("mocodec.moc")
    if name in _WHERE:
        return getattr(import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'mocodec' has no attribute {name!r}")


__all__ = ["Skeleton", "Joint", "Motion", "load", "save", "human_model", "BODY_PARTS", "get_codec", "codec_ids",
           "moc", "MocodecError", "FormatError", "ConversionError", "CodecError", "CorruptStreamError",
           "__version__"]
