"""Errors a user can cause. Each carries a one-line message the CLI prints as it is."""

from __future__ import annotations


class MocodecError(Exception):
    """Base of every error mocodec raises on purpose."""


class FormatError(MocodecError):
    """A motion file is malformed: names the file, the line (when known) and what was expected."""

    def __init__(self, path: object, line: int | None, message: str):
        self.path = str(path)
        self.line = line
        self.message = message
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")


class ConversionError(MocodecError):
    """A motion cannot be expressed in the requested format (e.g. BVH translations -> ASF)."""


class SkeletonMismatchError(MocodecError):
    """Two motions (or a motion and a skeleton) that must match do not."""


class CorruptStreamError(MocodecError):
    """A coded stream or .moc file is truncated or damaged; the message says where."""


class CodecError(MocodecError):
    """A codec cannot do what was asked: unknown id, bad knob, unencodable input, unmet target."""


class OutOfStepError(CorruptStreamError):
    """A stream packet that cannot be decoded yet: its receiver lost packets, or joined after
    the stream's start, and has not reached a packet it can go on from (a keyframe or a
    restart point)."""
