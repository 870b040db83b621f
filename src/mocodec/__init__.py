"""mocodec: coding (compression) of human motion capture.

The data model (:class:`Skeleton`, :class:`Motion`), motion files (:func:`load`,
:func:`save`), the built-in human model, the codecs (:func:`get_codec`) and .moc files
(:mod:`mocodec.moc`: ``pack``, ``unpack``, ``encode``, ``decode``). Names are imported when
first used, so ``import mocodec`` is quick.
"""

from importlib import import_module
from typing import TYPE_CHECKING

from mocodec.version import __version__

if TYPE_CHECKING:  # what the names below resolve to, for type checkers
    from mocodec import moc
    from mocodec.codecs import codec_ids, get_codec
    from mocodec.errors import CodecError, ConversionError, CorruptStreamError, FormatError, MocodecError
    from mocodec.formats import load, save
    from mocodec.human import human_model
    from mocodec.motion import Motion
    from mocodec.skeleton import BODY_PARTS, Joint, Skeleton

_WHERE = {
    "Skeleton": "mocodec.skeleton",
    "Joint": "mocodec.skeleton",
    "BODY_PARTS": "mocodec.skeleton",
    "Motion": "mocodec.motion",
    "load": "mocodec.formats",
    "save": "mocodec.formats",
    "human_model": "mocodec.human",
    "get_codec": "mocodec.codecs",
    "codec_ids": "mocodec.codecs",
    **dict.fromkeys(
        ("MocodecError", "FormatError", "ConversionError", "CodecError", "CorruptStreamError"), "mocodec.errors"
    ),
}


def __getattr__(name: str):
    if name == "moc":
        return import_module("mocodec.moc")
    if name in _WHERE:
        return getattr(import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'mocodec' has no attribute {name!r}")


__all__ = [
    "Skeleton",
    "Joint",
    "Motion",
    "load",
    "save",
    "human_model",
    "BODY_PARTS",
    "get_codec",
    "codec_ids",
    "moc",
    "MocodecError",
    "FormatError",
    "ConversionError",
    "CodecError",
    "CorruptStreamError",
    "__version__",
]
