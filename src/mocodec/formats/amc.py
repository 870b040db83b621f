"""Acclaim AMC motions (reader and writer) against an ASF skeleton (:mod:`.asf`).

``:DEGREES`` / ``:RADIANS`` apply to AMC values; motion channels are always degrees. AMC has no
frame rate: 120 fps (CMU) unless given.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from mocodec.errors import FormatError
from mocodec.formats.asf import asf_bone_vectors, read_asf, write_asf
from mocodec.formats.fileio import atomic_write, parse_number, parse_number_block, read_text
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

CMU_FPS = 120.0


# ----------------------------------------------------------------------------- AMC reading
def read_amc(
    path: str | os.PathLike, skeleton: Skeleton | str | os.PathLike | None = None, fps: float = CMU_FPS
) -> Motion:
    """Read an AMC motion against its ASF skeleton.

    ``skeleton`` is a Skeleton or an ASF path; by default the ASF named by the subject part of
    the file name (``05_01.amc`` -> ``05.asf``) or the only ``.asf`` in the same folder.
    """
    path = Path(path)
    if skeleton is None:
        skeleton = find_asf(path)
    if not isinstance(skeleton, Skeleton):
        skeleton = read_asf(skeleton)
    text = read_text(path)
    lines = text.split("\n")
    angle_scale = 1.0
    n = 0
    while n < len(lines):
        s = lines[n].strip()
        if not s or s.startswith("#"):
            n += 1
            continue
        if s.startswith(":"):
            key = s.split()[0].upper()
            if key == ":RADIANS":
                angle_scale = float(np.rad2deg(1.0))
            elif key not in (":FULLY-SPECIFIED", ":DEGREES"):
                raise FormatError(
                    path,
                    n + 1,
                    f"unknown AMC keyword {s.split()[0]!r}, expected :FULLY-SPECIFIED, :DEGREES or :RADIANS",
                )
            n += 1
            continue
        break
    if n == len(lines):  # a header alone: a motion of no frames, as a BVH of "Frames: 0"
        return Motion(skeleton, fps, np.zeros((0, skeleton.num_channels)))
    layout = _frame_layout(skeleton)
    channels = _fast_frames(lines, n, layout, path)
    if channels is None:
        channels = _slow_frames(lines, n, layout, skeleton, path)
    channels[:, skeleton.rotation_mask] *= angle_scale
    return Motion(skeleton, fps, channels)


def _frame_number(token: str) -> int | None:
    """The frame number ``token`` is (ASCII digits, at most 9 of them), or None."""
    return int(token) if token.isascii() and token.isdigit() and len(token) <= 9 else None


def _frame_layout(skeleton: Skeleton) -> dict[str, tuple[int, int]]:
    """Bone name -> (first channel, channel count) for every joint with channels."""
    return {
        j.name: (int(skeleton.channel_offsets[i]), len(j.channels)) for i, j in enumerate(skeleton.joints) if j.channels
    }


def _fast_frames(lines: list[str], start: int, layout: dict, path) -> np.ndarray | None:
    """Parse frames that all list the same bones in the same order as the first frame.

    Returns None when the file does not have that regular shape (the slow path then parses it
    line by line and reports exactly what is wrong).
    """
    end = len(lines)
    while end > start and not lines[end - 1].strip():
        end -= 1
    order = []
    k = start + 1
    while k < end and _frame_number(lines[k].strip()) is None:
        name = lines[k].split(None, 1)[0] if lines[k].strip() else ""
        if name not in layout or name in order:
            return None
        order.append(name)
        k += 1
    if set(order) != set(layout):
        return None
    block = len(order) + 1
    if (end - start) % block:
        return None
    frames = (end - start) // block
    f0 = _frame_number(lines[start].strip())
    if f0 is None:
        return None
    if [s.strip() for s in lines[start:end:block]] != [str(f0 + i) for i in range(frames)]:
        return None
    width = sum(c for _, c in layout.values())
    out = np.empty((frames, width))
    for b, name in enumerate(order):
        rows = lines[start + 1 + b : end : block]
        prefix = len(name)
        if not all(r.startswith(name) and (len(r) == prefix or r[prefix] in " \t") for r in rows):
            return None
        first_channel, count = layout[name]
        body = "\n".join(r[prefix:] for r in rows)
        try:
            values = parse_number_block(body, 0, path, expected_per_line=count) if count else np.zeros((frames, 0))
        except FormatError:
            return None
        if values.shape[0] != frames:
            return None
        out[:, first_channel : first_channel + count] = values
    return out


def _slow_frames(lines: list[str], start: int, layout: dict, skeleton: Skeleton, path) -> np.ndarray:
    rows: list[np.ndarray] = []
    current: np.ndarray | None = None
    seen: set[str] = set()
    frame_line = start
    expected_frame = None

    def close() -> None:
        if current is not None:
            missing = [b for b in layout if b not in seen]
            if missing:
                raise FormatError(path, frame_line + 1, f"frame {expected_frame} has no line for bone {missing[0]!r}")
            rows.append(current)

    for n in range(start, len(lines)):
        toks = lines[n].split()
        if not toks:
            continue
        if len(toks) == 1 and (number := _frame_number(toks[0])) is not None:
            close()
            if expected_frame is not None and number != expected_frame + 1:
                raise FormatError(path, n + 1, f"frame number {number}, expected {expected_frame + 1}")
            expected_frame = number
            current = np.zeros(skeleton.num_channels)
            seen = set()
            frame_line = n
            continue
        if current is None:
            raise FormatError(path, n + 1, f"expected a frame number, found {toks[0][:40]!r}")
        name = toks[0]
        if name not in layout:
            if name in skeleton.names:
                raise FormatError(path, n + 1, f"bone {name!r} has no dof in the ASF but has values here")
            raise FormatError(path, n + 1, f"bone {name!r} is not defined in the ASF skeleton")
        if name in seen:
            raise FormatError(path, n + 1, f"bone {name!r} appears twice in frame {expected_frame}")
        first_channel, count = layout[name]
        if len(toks) - 1 != count:
            raise FormatError(path, n + 1, f"bone {name!r} has {len(toks) - 1} values, expected {count}")
        current[first_channel : first_channel + count] = [parse_number(t, path, n + 1) for t in toks[1:]]
        seen.add(name)
    close()
    if not rows:
        raise FormatError(path, None, "no frames in the AMC file")
    return np.array(rows)


def find_asf(amc_path: str | os.PathLike) -> Path:
    """The ASF for an AMC: ``<subject>.asf`` for ``<subject>_<trial>.amc``, else the only
    ``.asf`` beside it."""
    amc_path = Path(amc_path)
    subject = amc_path.stem.split("_")[0]
    candidate = amc_path.with_name(f"{subject}.asf")
    if candidate.exists():
        return candidate
    found = sorted(amc_path.parent.glob("*.asf"))
    if len(found) == 1:
        return found[0]
    if not found:
        raise FormatError(amc_path, None, f"no ASF skeleton found (looked for {candidate.name}); pass it explicitly")
    raise FormatError(
        amc_path,
        None,
        f"{len(found)} ASF files beside it and none named {candidate.name}; pass the skeleton explicitly",
    )


def amc_text(motion: Motion, asf_name: str = "") -> str:
    sk = motion.skeleton
    asf_bone_vectors(sk)
    parts = []
    for i, j in enumerate(sk.joints):
        if j.channels:
            parts.append(("root" if i == 0 else j.name) + " %.6f" * len(j.channels) + "\n")
    frame_fmt = "%d\n" + "".join(parts)
    values = np.where(np.abs(motion.channels) < 5e-7, 0.0, motion.channels)
    header = f"#!OML:ASF {asf_name}\n:FULLY-SPECIFIED\n:DEGREES\n"
    return header + "".join(frame_fmt % (f + 1, *row) for f, row in enumerate(values.tolist()))


def write_amc(motion: Motion, path: str | os.PathLike, asf_path: str | os.PathLike | None = None) -> None:
    """Write the AMC of ``motion`` and, when ``asf_path`` is given, its ASF, both atomically."""
    text = amc_text(motion, Path(asf_path).name if asf_path else "")
    if asf_path is not None:
        write_asf(motion.skeleton, asf_path)
    atomic_write(path, text)
