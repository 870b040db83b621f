"""Reading text files with clear errors, writing them atomically, and fast number parsing."""

from __future__ import annotations

import codecs
import os
import re
import stat
import tempfile
import time
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from mocodec.errors import FormatError, MocodecError


def read_bytes(path: str | os.PathLike, limit: int | None = None) -> bytes:
    """The whole file; FormatError if it is missing, not a file, unreadable or over ``limit`` bytes."""
    path = Path(path)
    try:
        if limit is not None and (size := path.stat().st_size) > limit:
            raise FormatError(path, None, f"{size} bytes, more than this kind of file may have ({limit})")
        return path.read_bytes()
    except FileNotFoundError:
        raise FormatError(path, None, "no such file") from None
    except IsADirectoryError:
        raise FormatError(path, None, "is a directory, expected a file") from None
    except OSError as e:
        raise FormatError(path, None, f"cannot read: {e.strerror}") from None


def read_text(path: str | os.PathLike) -> str:
    """The whole file as text (UTF-8, else Latin-1; UTF-16 after its byte-order mark, which a
    Windows editor writes; a UTF-8 byte-order mark dropped); FormatError if it is missing, empty
    or binary."""
    path = Path(path)
    data = read_bytes(path)
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            data = data.decode("utf-16").encode("utf-8")
        except UnicodeDecodeError as e:
            raise FormatError(path, None, f"not UTF-16 text after its byte-order mark (at byte {e.start})") from None
    data = data.removeprefix(codecs.BOM_UTF8)
    if not data.strip():
        raise FormatError(path, None, "empty file")
    if b"\0" in data[:65536]:
        raise FormatError(path, None, "binary data (NUL bytes), expected a text file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        try:
            return data.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes every byte
            raise FormatError(path, None, f"not text: undecodable byte at offset {e.start}") from None


def one_source_each(pairs: Iterable[tuple[object, object]]) -> None:
    """MocodecError naming the first two ``(source, target)`` pairs with one target, before
    anything is written: the later would replace the earlier (``walk.bvh`` and ``walk.amc``
    both make ``walk.moc``)."""
    first_of: dict[str, object] = {}
    for source, target in pairs:
        if str(target) in first_of:
            raise MocodecError(f"{first_of[str(target)]} and {source} would both be written to {target}")
        first_of[str(target)] = source


def atomic_write(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to a temporary file beside ``path``, then rename it into place, so a
    reader never sees a half-written file and a failed write leaves the old file intact."""
    atomic_write_bytes(path, text.encode("utf-8"))


#: A temporary file of an interrupted write older than this is removed by the next write
#: beside it (a younger one may belong to a write still running).
STALE_TEMP_S = 3600.0
_TEMP_NAME = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp$")


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """:func:`atomic_write` for bytes. A symbolic link is followed (its target is replaced);
    a device, FIFO or socket (``/dev/null``, ``/dev/stdout``, a pipe) is written through, as
    there is nothing to replace; a regular file keeps its mode, a new one takes the umask's.
    The data is on disk (fsync) before the rename; stale temporary files of interrupted writes
    in that directory are removed."""
    path = Path(path)
    try:
        existing = os.stat(path)  # through links, /proc's magic ones too
    except FileNotFoundError:
        existing = None
    except OSError as e:
        raise FormatError(path, None, f"cannot write: {e.strerror}") from None
    if existing is not None and stat.S_ISDIR(existing.st_mode):
        raise FormatError(path, None, "is a directory, expected a file to write")
    if existing is not None and not stat.S_ISREG(existing.st_mode):
        with open(path, "wb") as f:
            f.write(data)
        return
    target = Path(os.path.realpath(path))
    directory = target.parent
    if not directory.is_dir():
        raise FormatError(path, None, f"cannot write: the directory {directory} does not exist")
    _remove_stale_temps(directory)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    except OSError as e:
        raise FormatError(path, None, f"cannot write: {e.strerror}") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, stat.S_IMODE(existing.st_mode) if existing is not None else 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    _sync_directory(directory)


def _umask() -> int:
    """The process's umask (read from /proc, as setting it to read it races with threads)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _remove_stale_temps(directory: Path) -> None:
    """Remove temporary files that interrupted writes left in ``directory``."""
    now = time.time()
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return
    for entry in entries:
        if _TEMP_NAME.match(entry.name):
            try:
                if entry.is_file(follow_symlinks=False) and now - entry.stat().st_mtime > STALE_TEMP_S:
                    os.unlink(entry.path)
            except OSError:
                pass


def _sync_directory(directory: Path) -> None:
    """Make the rename durable (best effort: not every file system lets a directory be synced)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def parse_number(token: str, path, line: int, what: str = "a number") -> float:
    try:
        value = float(token)
    except ValueError:
        raise FormatError(path, line, f"{token!r} is not a number, expected {what}") from None
    if not np.isfinite(value):
        raise FormatError(path, line, f"{token!r} is not a finite number, expected {what}")
    return value


def parse_number_block(text: str, first_line: int, path, expected_per_line: int | None = None) -> np.ndarray:
    """All numbers of a block of whitespace-separated values, one record per line.

    With ``expected_per_line``, every non-blank line must hold exactly that many values; the
    result is then ``(lines, expected_per_line)``. Errors name the file line (``first_line`` is
    the line number of the block's first line).
    """
    raw = np.frombuffer(text.encode("latin-1", errors="replace"), dtype=np.uint8)
    is_space = (raw == 32) | (raw == 9) | (raw == 10) | (raw == 13) | (raw == 11) | (raw == 12)
    starts = ~is_space
    starts[1:] &= is_space[:-1]
    line_of_byte = np.concatenate(([0], np.cumsum(raw[:-1] == 10))) if raw.size else raw
    token_lines = line_of_byte[starts]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            values = np.fromstring(text, sep=" ") if token_lines.size else np.zeros(0)
    except ValueError:  # numpy raises (or warns and stops early) at the first non-number
        values = None
    if values is None or values.size != token_lines.size:
        for k, line in enumerate(text.split("\n")):
            for tok in line.split():
                parse_number(tok, path, first_line + k)
        raise FormatError(path, first_line, "malformed number block")
    if not np.all(np.isfinite(values)):
        bad_line = int(token_lines[np.flatnonzero(~np.isfinite(values))[0]])
        raise FormatError(path, first_line + bad_line, "non-finite value (nan or inf), expected a number")
    if expected_per_line is None:
        return values
    lines_with_tokens, counts = np.unique(token_lines, return_counts=True)
    wrong = np.flatnonzero(counts != expected_per_line)
    if wrong.size:
        k = wrong[0]
        raise FormatError(
            path,
            first_line + int(lines_with_tokens[k]),
            f"{counts[k]} values on the frame line, expected {expected_per_line}",
        )
    return values.reshape(-1, expected_per_line)


def format_rows(values: np.ndarray, decimals: int) -> str:
    """Rows of numbers, space separated, fixed decimals, ``-0`` written as ``0``."""
    values = np.where(np.abs(values) < 0.5 * 10.0**-decimals, 0.0, values)
    if values.size == 0:
        return "\n" * values.shape[0]
    fmt = " ".join([f"%.{decimals}f"] * values.shape[1])
    return "\n".join(fmt % tuple(row) for row in values.tolist()) + "\n"
