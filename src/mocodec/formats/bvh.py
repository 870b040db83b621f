"""BVH (Biovision hierarchy) reader and writer.

Any channel order per joint, position channels on any joint, ``End Site`` blocks (read as
channel-less joints named ``<parent>_end``), tabs or spaces, CRLF or LF, ``#`` comment lines
in the hierarchy. ``Frame Time`` gives the frame rate; a rate within 1e-4 of a whole number is
taken as that number (0.00833333 s is 120 fps). The frame block is parsed by numpy in one pass,
so big files load at tens of MB/s.

BVH states no unit of length. The writer states it in a comment line after ``HIERARCHY``
(``# unit: 100 per metre``) when a reader's guess from the skeleton's size
(:func:`guess_units_per_metre`) would get it wrong; Blender's importer skips such a line,
three.js's BVHLoader does not, which is why it is written only then. The motion rows follow
the hierarchy as written (depth first), whatever the order of the motion's joints.

A position channel holds the joint's position in its parent's frame, in place of its OFFSET
(as MotionBuilder writes them, every joint's position channels equal to its offset, and as
Blender's importer reads them); a :class:`~mocodec.motion.Motion` holds the change from the
offset, so the reader subtracts the offset and the writer adds it back (:func:`mocodec.kinematics.position_offsets`).
three.js's BVHLoader adds the offset to the channel instead, which doubles such a skeleton's
bones; the two agree on a root at offset 0, as most files have.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import replace

import numpy as np

from mocodec import limits
from mocodec.errors import FormatError
from mocodec.formats.fileio import atomic_write, format_rows, parse_number, parse_number_block, read_text
from mocodec.kinematics import position_offsets
from mocodec.motion import Motion
from mocodec.skeleton import CHANNEL_NAMES, Joint, Skeleton

_CHANNEL_LOOKUP = {c.lower(): c for c in CHANNEL_NAMES}
_HIERARCHY_KEYWORDS = "ROOT, JOINT, End Site, OFFSET, CHANNELS, { or }"
#: The comment line that states a file's unit of length.
_UNIT_LINE = re.compile(r"^#\s*unit:\s*(\S+)\s+per\s+metre\b", re.IGNORECASE)


def _snap_fps(frame_time: float) -> float:
    fps = 1.0 / frame_time
    nearest = round(fps)
    return float(nearest) if nearest > 0 and abs(fps - nearest) < 1e-4 * nearest else fps


class _HierarchyParser:
    def __init__(self, lines: list[str], path):
        self.lines = lines
        self.path = path
        self.joints: list[dict] = []
        self.stated_units: float | None = None  # from a '# unit: N per metre' line

    def error(self, lineno: int, message: str) -> FormatError:
        return FormatError(self.path, lineno + 1, message)

    def tokens(self, lineno: int) -> list[str]:
        return self.lines[lineno].replace("{", " { ").replace("}", " } ").split()

    def parse(self) -> int:
        """Parse from HIERARCHY to MOTION; returns the index of the MOTION line."""
        n = 0
        while n < len(self.lines) and not self.lines[n].strip():
            n += 1
        if n == len(self.lines) or self.tokens(n)[0].upper() != "HIERARCHY":
            raise self.error(n if n < len(self.lines) else 0, "expected 'HIERARCHY' at the start of a BVH file")
        n += 1
        stack: list[int] = []  # open joint indices; -2 marks an End Site block
        pending: tuple[str | None, int, bool] | None = None  # (name, parent, is_end) awaiting '{'
        root_seen = False
        while n < len(self.lines):
            if self.lines[n].lstrip().startswith("#"):
                self._comment(n)
                n += 1
                continue
            toks = self.tokens(n)
            while toks:
                word = toks[0]
                key = word.upper()
                if pending is not None:
                    if word != "{":
                        raise self.error(n, f"expected '{{' after the joint name, found {word!r}")
                    name, parent, is_end = pending
                    self.joints.append(
                        {"name": name, "parent": parent, "end": is_end, "line": n, "offset": None, "channels": ()}
                    )
                    stack.append(len(self.joints) - 1)
                    pending = None
                    toks = toks[1:]
                elif key in ("ROOT", "JOINT"):
                    if key == "ROOT" and (root_seen or stack):
                        raise self.error(n, "a second ROOT: only one skeleton per BVH file is supported")
                    if key == "JOINT" and not stack:
                        raise self.error(n, "JOINT outside the ROOT block")
                    if stack and self.joints[stack[-1]]["end"]:
                        raise self.error(n, "End Site blocks cannot contain joints")
                    rest = toks[1:]
                    name_toks = rest[: rest.index("{")] if "{" in rest else rest
                    if not name_toks:
                        raise self.error(n, f"{word} needs a name")
                    root_seen = True
                    pending = (" ".join(name_toks), stack[-1] if stack else -1, False)
                    toks = rest[len(name_toks) :]
                elif key == "END":
                    if len(toks) < 2 or toks[1].upper() != "SITE":
                        raise self.error(n, f"expected 'End Site', found {' '.join(toks[:2])!r}")
                    if not stack:
                        raise self.error(n, "End Site outside the ROOT block")
                    pending = (None, stack[-1], True)
                    toks = toks[2:]
                elif key == "OFFSET":
                    if not stack:
                        raise self.error(n, "OFFSET outside a joint block")
                    if len(toks) < 4:
                        raise self.error(n, f"OFFSET needs 3 numbers, found {len(toks) - 1}")
                    self.joints[stack[-1]]["offset"] = tuple(parse_number(t, self.path, n + 1) for t in toks[1:4])
                    toks = toks[4:]
                elif key == "CHANNELS":
                    toks = self._channels(n, toks, stack)
                elif word == "}":
                    if not stack:
                        raise self.error(n, "unmatched '}'")
                    j = self.joints[stack.pop()]
                    if j["offset"] is None:
                        raise self.error(j["line"], f"joint {j['name'] or 'End Site'} has no OFFSET")
                    toks = toks[1:]
                elif key == "MOTION":
                    if stack or pending:
                        raise self.error(n, "MOTION before the hierarchy is closed (missing '}')")
                    if not root_seen:
                        raise self.error(n, "no ROOT joint in the hierarchy")
                    return n
                else:
                    raise self.error(n, f"unknown keyword {word!r}, expected {_HIERARCHY_KEYWORDS}")
            n += 1
        raise self.error(len(self.lines) - 1, "file ends before the MOTION section")

    def _comment(self, n: int) -> None:
        """A comment line: the file's unit when it states one."""
        m = _UNIT_LINE.match(self.lines[n].strip())
        if m:
            units = parse_number(m.group(1), self.path, n + 1, "the units per metre")
            if not 0 < units <= 1e9:
                raise self.error(n, f"unit {m.group(1)} per metre out of range (0, 1e9]")
            self.stated_units = units

    def _channels(self, n: int, toks: list[str], stack: list[int]) -> list[str]:
        if not stack:
            raise self.error(n, "CHANNELS outside a joint block")
        joint = self.joints[stack[-1]]
        if joint["end"]:
            raise self.error(n, "End Site cannot have CHANNELS")
        if len(toks) < 2:
            raise self.error(n, "CHANNELS needs a count")
        try:
            count = int(toks[1])
        except ValueError:
            raise self.error(n, f"{toks[1]!r} is not a channel count") from None
        names = toks[2 : 2 + count]
        if len(names) != count or count < 0:
            raise self.error(n, f"CHANNELS {count} lists {len(names)} channel names")
        channels = []
        for name in names:
            canon = _CHANNEL_LOOKUP.get(name.lower())
            if canon is None:
                raise self.error(n, f"unknown channel {name!r}, expected one of {', '.join(CHANNEL_NAMES)}")
            channels.append(canon)
        if len(set(channels)) != len(channels):
            raise self.error(n, f"repeated channel in {' '.join(names)}")
        joint["channels"] = tuple(channels)
        return toks[2 + count :]

    def skeleton(self, units_per_metre: float) -> Skeleton:
        names: set[str] = {j["name"] for j in self.joints if j["name"]}
        suffix: dict[str, int] = {}  # the last number given to each end site base name
        joints = []
        for j in self.joints:
            name = j["name"]
            if name is None:
                base = f"{self.joints[j['parent']]['name']}_end"
                name, k = base, suffix.get(base, 1)
                while name in names:
                    k += 1
                    name = f"{base}{k}"
                suffix[base] = k
                names.add(name)
                j["name"] = name
            order = "".join(c[0] for c in j["channels"] if c.endswith("rotation"))
            joints.append(
                Joint(name=name, parent=j["parent"], offset=j["offset"], channels=j["channels"], rotation_order=order)
            )
        dup = len({j.name for j in joints}) != len(joints)
        if dup:
            seen = set()
            for joint, raw in zip(joints, self.joints):
                if joint.name in seen:
                    raise self.error(raw["line"], f"joint name {joint.name!r} is used twice")
                seen.add(joint.name)
        return Skeleton(tuple(joints), units_per_metre=units_per_metre)


def read_bvh(path: str | os.PathLike, units_per_metre: float | None = None) -> Motion:
    """Read a BVH file; ``units_per_metre`` is the file's stated unit, or guessed from the
    skeleton's size (see :func:`guess_units_per_metre`), unless given."""
    text = read_text(path)
    lines = text.split("\n")
    parser = _HierarchyParser(lines, path)
    motion_line = parser.parse()
    skeleton_units = units_per_metre or parser.stated_units
    n = motion_line + 1
    header: dict[str, tuple[str, int]] = {}
    while n < len(lines) and len(header) < 2:
        line = lines[n].strip()
        if line:
            m = re.match(r"^(Frames|Frame\s+Time)\s*:\s*(\S*)\s*$", line, re.IGNORECASE)
            if not m:
                want = "Frames:" if "frames" not in header else "Frame Time:"
                raise FormatError(path, n + 1, f"expected '{want} <number>', found {line[:40]!r}")
            header["frames" if m.group(1).lower() == "frames" else "time"] = (m.group(2), n + 1)
        n += 1
    if "frames" not in header or "time" not in header:
        raise FormatError(path, n, "the MOTION section needs 'Frames:' and 'Frame Time:' lines")
    token, at = header["frames"]
    try:
        frames = int(token)
        if frames < 0:
            raise ValueError
    except ValueError:
        raise FormatError(path, at, f"{token!r} is not a frame count") from None
    token, at = header["time"]
    frame_time = parse_number(token, path, at, "the frame time in seconds")
    if frame_time <= 0:
        raise FormatError(path, at, f"frame time {token} must be positive")
    if not limits.fps_ok(1.0 / frame_time):
        raise FormatError(path, at, f"frame time {token} s: a frame rate outside {limits.FPS_RANGE} per second")
    try:
        skeleton = parser.skeleton(1.0)
    except ValueError as e:
        raise FormatError(path, None, str(e)) from None
    if skeleton_units is None:
        skeleton_units = guess_units_per_metre(skeleton.span())
    skeleton = replace(skeleton, units_per_metre=skeleton_units)
    width = skeleton.num_channels
    block = "\n".join(lines[n:])
    values = parse_number_block(block, n + 1, path, expected_per_line=width) if width else np.zeros((0, 0))
    if width == 0:
        values = np.zeros((frames, 0))
    if values.shape[0] != frames:
        raise FormatError(path, header["frames"][1], f"'Frames: {frames}' but {values.shape[0]} frame lines follow")
    return Motion(skeleton, _snap_fps(frame_time), values - position_offsets(skeleton))


_UNIT_CANDIDATES = (("metres", 1.0), ("inches", 1.0 / 0.0254), ("centimetres", 100.0), ("millimetres", 1000.0))
#: The span (metres, :meth:`~mocodec.skeleton.Skeleton.span`) a person's skeleton has:
#: fingertip or toe to fingertip or toe along the bones, 1.2 m for a child to 2.6 m for a
#: tall adult with fingers; the range is narrower than one unit's ratio to the next (2.54).
PERSON_SPAN_M = (1.1, 2.8)


def guess_units_per_metre(span: float) -> float:
    """Units per metre of a BVH skeleton whose file does not state it, from its span (the
    longest path along its bones, in file units).

    We pick the unit among metres, inches, centimetres and millimetres that puts the span in
    :data:`PERSON_SPAN_M`, centimetres when none or several do. The span does not depend on
    the rest pose, which is not always upright. On the CMU BVH set (236 units) this gives
    centimetres, which the same takes in ASF/AMC confirm (``docs/units.md``).
    """
    low, high = PERSON_SPAN_M
    fits = [upm for _, upm in _UNIT_CANDIDATES if low <= span / upm <= high]
    return fits[0] if len(fits) == 1 else 100.0


def write_bvh(motion: Motion, path: str | os.PathLike, decimals: int | None = None) -> None:
    """Write ``motion`` as BVH, atomically (see :func:`bvh_text`)."""
    atomic_write(path, bvh_text(motion, decimals))


def bvh_text(motion: Motion, decimals: int | None = None) -> str:
    """``motion`` as BVH text. Channel-less leaf joints become End Sites; the hierarchy and the
    motion rows go depth first; the unit is stated when a reader would guess another. Values
    have ``decimals`` places, by default enough for 1e-8 m (at least 6)."""
    sk = motion.skeleton
    for j in sk.joints:
        if j.rotation_order != "".join(c[0] for c in j.channels if c.endswith("rotation")):
            raise ValueError(
                f"joint {j.name!r}: BVH applies rotations in channel order; "
                f"rotation order {j.rotation_order!r} differs (convert the motion first)"
            )
        if j.has_axis:
            raise ValueError(f"joint {j.name!r} has an ASF axis; convert the motion to BVH form first")
    if decimals is None:
        decimals = max(6, math.ceil(8.0 - math.log10(sk.units_per_metre) - 1e-9))
    out = ["HIERARCHY"]
    if guess_units_per_metre(sk.span()) != sk.units_per_metre:
        out.append(f"# unit: {sk.units_per_metre!r} per metre")
    order: list[int] = []
    kids = sk.children
    stack: list[tuple[int, int]] = [(0, 0)]  # (joint, depth); (-1, depth) closes a block
    while stack:
        i, depth = stack.pop()
        indent = "  " * depth
        if i < 0:
            out.append(f"{indent}}}")
            continue
        j = sk.joints[i]
        order.append(i)
        end_site = i != 0 and sk.end_sites[i]
        out.append(f"{indent}End Site" if end_site else f"{indent}{'ROOT' if i == 0 else 'JOINT'} {j.name}")
        out.append(f"{indent}{{")
        out.append(f"{indent}  OFFSET {' '.join(_number(v, decimals) for v in j.offset)}")
        if not end_site:
            out.append(f"{indent}  CHANNELS {len(j.channels)}{''.join(' ' + c for c in j.channels)}")
        stack.append((-1, depth))
        stack.extend((k, depth + 1) for k in reversed(kids[i]))
    out.append("MOTION")
    out.append(f"Frames: {motion.num_frames}")
    out.append(f"Frame Time: {1.0 / motion.fps:.10g}")
    offsets = sk.channel_offsets
    columns = np.concatenate([np.arange(offsets[i], offsets[i + 1]) for i in order]).astype(np.int64)
    values = motion.channels + position_offsets(sk)
    return "\n".join(out) + "\n" + format_rows(values[:, columns], decimals)


def _number(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text
