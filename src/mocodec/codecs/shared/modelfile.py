"""The file layout of trained models that encoder and decoder share (VQ codebooks, primitive
databases): a magic, a version byte, the length of a JSON description, the JSON, the model's
numbers, and a CRC-32 of everything before it. The CRC is also the model's fingerprint, which
a body coded with it carries.
"""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path
from typing import ClassVar

from mocodec.errors import CodecError
from mocodec.formats.fileio import atomic_write_bytes

_HEAD = struct.Struct("<BI")  # version, JSON length


def pack(magic: bytes, version: int, meta: dict, numbers: bytes) -> bytes:
    text = json.dumps(meta, sort_keys=True).encode()
    body = magic + _HEAD.pack(version, len(text)) + text + numbers
    return body + struct.pack("<I", zlib.crc32(body))


def fingerprint(data: bytes) -> int:
    """The fingerprint of a model's bytes (from :func:`pack`)."""
    return zlib.crc32(data[:-4])


def unpack(data: bytes, magic: bytes, version: int, what: str, where: str) -> tuple[dict, int]:
    """(the JSON description, where the numbers start) of a model file, its magic, version and
    checksum checked; ``what`` names the kind of model in errors, ``where`` the file."""
    head = len(magic) + _HEAD.size
    if len(data) < head + 4 or not data.startswith(magic):
        raise CodecError(f"{where}: not a mocodec {what} (expected {magic!r} at byte 0)")
    found, size = _HEAD.unpack_from(data, len(magic))
    if found != version:
        raise CodecError(f"{where}: {what} version {found}, this mocodec reads version {version}")
    if zlib.crc32(data[:-4]) != struct.unpack_from("<I", data, len(data) - 4)[0]:
        raise CodecError(f"{where}: checksum mismatch (the file is damaged or truncated)")
    try:
        return json.loads(data[head : head + size]), head + size
    except (ValueError, RecursionError) as e:
        raise CodecError(f"{where}: {what} description does not parse ({e})") from None


def read(path: str | Path, what: str) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as e:
        raise CodecError(f"{what} {path}: {e.strerror}") from None


class Model:
    """What every model class shares: its fingerprint, saving and loading, from the class's
    ``to_bytes()`` and ``from_bytes(data, where)``; ``WHAT`` names the kind of model in errors."""

    WHAT: ClassVar[str] = "model"

    def to_bytes(self) -> bytes:
        raise NotImplementedError

    @classmethod
    def from_bytes(cls, data: bytes, where: str):
        raise NotImplementedError

    @property
    def fingerprint(self) -> int:
        return fingerprint(self.to_bytes())

    def save(self, path: str | Path) -> None:
        atomic_write_bytes(path, self.to_bytes())

    @classmethod
    def load(cls, path: str | Path):
        return cls.from_bytes(read(path, cls.WHAT), f"{cls.WHAT} {path}")
