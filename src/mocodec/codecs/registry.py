"""The codec registry: ids to codec classes, and ``get_codec(id, **knobs)``.

The built-in codecs are imported when first asked for (:data:`BUILT_IN` names each one's
module below ``mocodec.codecs``), so a command that codes with one codec loads only that one; :func:`register` adds
any other codec class.
"""

from __future__ import annotations

import functools
import importlib
from typing import TYPE_CHECKING

from mocodec.errors import CodecError, CorruptStreamError

if TYPE_CHECKING:
    from mocodec.codecs.base import Codec

_CODECS: dict[str, type[Codec]] = {}
DEFAULT_CODEC = "kinwave"
BUILT_IN = {
    **{c: f"waveform.{c}" for c in ("adpcm", "dct", "deadreckoning", "dpcm", "quant", "subband", "svq", "tvq")},
    **{c: f"model.{c}" for c in ("gesture", "hybrid", "posture")},
    **{c: f"motionprimitives.{c}" for c in ("primitives", "rhythmic")},
    **{c: f"perceptual.{c}" for c in ("pwavelet", "spiht")},
    "kinwave": "kinwave.codec",
    "kinwave-live": "kinwave.live",
    "raw": "reference.raw",
    "lossless": "reference.lossless",
    **dict.fromkeys(("zstd", "sz3", "zfp", "fpzip"), "reference.floats"),
}


def register(cls: type[Codec]) -> type[Codec]:
    """Class decorator: make a codec available by its ``id``."""
    if not cls.id or cls.id in _CODECS:
        raise ValueError(f"codec id {cls.id!r} is empty or taken")
    _CODECS[cls.id] = cls
    packet_codecs.cache_clear()
    return cls


def codec_class(codec_id: str) -> type[Codec]:
    if codec_id not in _CODECS and codec_id in BUILT_IN:
        importlib.import_module(f"mocodec.codecs.{BUILT_IN[codec_id]}")
    try:
        return _CODECS[codec_id]
    except KeyError:
        raise CodecError(f"unknown codec {codec_id!r} (available: {', '.join(codec_ids())})") from None


@functools.cache
def packet_codecs() -> tuple[str, ...]:
    """The ids of the codecs that stream live, by their packet number (each class's
    ``packet_number``; the table is part of the wire format). Imports every built-in codec the
    first time."""
    for codec_id in BUILT_IN:
        codec_class(codec_id)
    numbered = {cls.packet_number: cls.id for cls in _CODECS.values() if cls.packet_number is not None}
    if len(numbered) != sum(cls.packet_number is not None for cls in _CODECS.values()):
        raise CodecError("two codecs have the same packet number")
    if sorted(numbered) != list(range(len(numbered))):
        raise CodecError(f"packet numbers must run from 0 without gaps, got {sorted(numbered)}")
    return tuple(numbered[n] for n in range(len(numbered)))


def get_codec(codec_id: str = DEFAULT_CODEC, **knobs) -> Codec:
    """A configured codec: ``get_codec("spiht", bits_per_second=4000)``."""
    return codec_class(codec_id)(**knobs)


def codec_from_config(config: dict) -> Codec:
    return codec_class(config.get("codec", "")).from_config(config)


def checked_config(config: object, where: str) -> dict:
    """The knobs of a config from a file or a stream once its shape is checked: an object
    naming a codec, its knobs an object of strings, numbers and booleans (CorruptStreamError
    naming ``where`` otherwise)."""
    if not isinstance(config, dict) or not isinstance(config.get("codec"), str):
        raise CorruptStreamError(f"{where}: the codec config must be an object naming a codec")
    knobs = config.get("knobs", {})
    if not isinstance(knobs, dict) or not all(
        isinstance(k, str) and isinstance(v, (str, int, float, bool)) for k, v in knobs.items()
    ):
        raise CorruptStreamError(f"{where}: the codec's knobs must be an object of strings, numbers and booleans")
    return knobs


def codec_from_untrusted(config: object, where: str, local_files: dict[str, str] | None = None) -> Codec:
    """A codec from the config a file or a stream carries, which may be hostile: it must be a
    dict naming a codec, with knobs a dict of strings, numbers and booleans, each parsed by its
    knob. A knob that names a local file (:attr:`Knob.path`) is never taken from the config
    (a file could make the reader open ``/dev/zero``, or learn which paths exist): it is the
    caller's ``local_files`` entry, or empty; the body names the model it needs by content
    hash, and the codec checks the one given against it. CorruptStreamError names ``where``."""
    knobs = checked_config(config, where)
    assert isinstance(config, dict)  # checked_config refuses anything else
    try:
        cls = codec_class(config["codec"])
        cls.check_revision(config)
        paths = {k.name for k in cls.knobs if k.path}
        chosen = {k: v for k, v in knobs.items() if k not in paths}
        chosen.update({k: v for k, v in (local_files or {}).items() if k in paths and v})
        return cls(**chosen)
    except CodecError as e:
        raise CorruptStreamError(f"{where}: names a codec this mocodec cannot build ({e})") from None


def codec_ids() -> list[str]:
    return sorted(set(_CODECS) | set(BUILT_IN))
