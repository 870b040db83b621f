"""The codec registry: ids to codec classes, and ``get_codec(id, **knobs)``."""

from __future__ import annotations

from mocodec.codecs.base import Codec
from mocodec.errors import CodecError

_CODECS: dict[str, type[Codec]] = {}
DEFAULT_CODEC = "kinwave"


def register(cls: type[Codec]) -> type[Codec]:
    """Class decorator: make a codec available by its ``id``."""
    if not cls.id or cls.id in _CODECS:
        raise ValueError(f"codec id {cls.id!r} is empty or taken")
    _CODECS[cls.id] = cls
    return cls


def codec_class(codec_id: str) -> type[Codec]:
    try:
        return _CODECS[codec_id]
    except KeyError:
        raise CodecError(f"unknown codec {codec_id!r} (available: {', '.join(sorted(_CODECS))})") from None


def get_codec(codec_id: str = DEFAULT_CODEC, **knobs) -> Codec:
    """A configured codec: ``get_codec("spiht", bits_per_second=4000)``."""
    return codec_class(codec_id)(**knobs)


def codec_from_config(config: dict) -> Codec:
    return codec_class(config.get("codec", "")).from_config(config)


def codec_ids() -> list[str]:
    return sorted(_CODECS)
