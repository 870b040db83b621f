"""A compact, exact binary form of a skeleton for .moc headers (a few hundred bytes for a CMU
skeleton instead of 1-2 KB of JSON), so short clips stay small.

Every number is written as the shortest decimal ``n / 10^k`` (k = 0..12) that gives back the
very same float64 (BVH and ASF values come from decimal text, so almost all do), else as its
eight raw bytes; 0 and the infinities of unlimited joints have one-byte tags. Names, parents (as
the distance back to the parent), channel layouts, rotation and axis orders, limits and body
parts follow as small integers. A joint whose offset is an earlier joint's with some signs
flipped (the other side of a symmetric skeleton) refers to it instead, and one that is a
decimal length times a decimal direction (as ASF files give bones) is written as those. When
every offset has at most k decimals (a lossy file's, rounded by :func:`round_offsets`), they
are written as untagged integers / 10^k if that is shorter. The result is not compressed
here: the container compresses its whole header at once. docs/formats.md gives the layout
byte by byte. The round trip is exact, so :func:`~mocodec.formats.container.skeleton_id`
is unchanged.
"""

from __future__ import annotations

import dataclasses
import math
import struct
from functools import lru_cache

from mocodec.errors import CorruptStreamError
from mocodec.formats import varint
from mocodec.skeleton import BODY_PARTS, CHANNEL_NAMES, Joint, Skeleton

VERSION = 1  # the compact skeleton's format (docs/formats.md)
_AXES = "XYZ"
_ZERO, _POS_INF, _NEG_INF, _RAW = 0, 1, 2, 3
_DECIMAL = 4  # tags 4..16: decimal with k = tag - 4 places
_MAX_PLACES = 12
_PLAIN, _PRODUCT = 0, 1  # an offset's form; >= 8: a mirror reference (back << 3 | signs)


class _Writer:
    def __init__(self):
        self.out = bytearray()

    def uint(self, v: int) -> None:
        self.out += varint.pack(v)

    def sint(self, v: int) -> None:
        self.uint(2 * v if v >= 0 else -2 * v - 1)

    def text(self, s: str) -> None:
        raw = s.encode()
        self.uint(len(raw))
        self.out += raw

    def number(self, x: float) -> None:
        x = float(x)
        if x == 0.0 and math.copysign(1.0, x) > 0:
            self.out.append(_ZERO)
            return
        if math.isinf(x):
            self.out.append(_POS_INF if x > 0 else _NEG_INF)
            return
        if math.isfinite(x) and x != 0.0:  # -0.0 goes raw, keeping its sign
            for k in range(_MAX_PLACES + 1):
                n = round(x * 10**k)
                if abs(n) < 1 << 62 and n / 10**k == x:
                    self.out.append(_DECIMAL + k)
                    self.sint(n)
                    return
        self.out.append(_RAW)
        self.out += struct.pack("<d", x)


class _Reader:
    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def byte(self) -> int:
        if self.pos >= len(self.data):
            raise CorruptStreamError(f"compact skeleton ends early at byte {self.pos}")
        self.pos += 1
        return self.data[self.pos - 1]

    def uint(self) -> int:
        try:
            v, self.pos = varint.unpack(self.data, self.pos, max_bytes=11)
        except ValueError as e:
            raise CorruptStreamError(f"compact skeleton: {e}") from None
        return v

    def sint(self) -> int:
        v = self.uint()
        return v // 2 if v % 2 == 0 else -(v + 1) // 2

    def text(self) -> str:
        n = self.uint()
        if self.pos + n > len(self.data):
            raise CorruptStreamError(f"compact skeleton: a {n}-byte name runs past the end at byte {self.pos}")
        self.pos += n
        return self.data[self.pos - n : self.pos].decode()

    def number(self) -> float:
        tag = self.byte()
        if tag == _ZERO:
            return 0.0
        if tag in (_POS_INF, _NEG_INF):
            return math.inf if tag == _POS_INF else -math.inf
        if tag == _RAW:
            if self.pos + 8 > len(self.data):
                raise CorruptStreamError(f"compact skeleton ends early at byte {self.pos}")
            self.pos += 8
            return struct.unpack("<d", self.data[self.pos - 8 : self.pos])[0]
        if _DECIMAL <= tag <= _DECIMAL + _MAX_PLACES:
            return self.sint() / 10 ** (tag - _DECIMAL)
        raise CorruptStreamError(f"compact skeleton: unknown number tag {tag} at byte {self.pos - 1}")


def _default_order(channels: tuple[str, ...]) -> str:
    return "".join(c[0] for c in channels if c.endswith("rotation"))


def _numbers(values) -> bytes:
    w = _Writer()
    for x in values:
        w.number(x)
    return bytes(w.out)


def _as_product(offset: tuple[float, ...]) -> bytes | None:
    """The shortest ``length, direction`` (decimals) whose products are ``offset`` bit for bit
    (the ASF reader computes ``direction * length``), or None."""
    size = math.sqrt(sum(x * x for x in offset))
    if not math.isfinite(size) or size == 0.0:
        return None
    best = None
    for places in range(_MAX_PLACES + 1):
        length = round(size, places)
        if length == 0.0:
            continue
        direction: list[float] = []
        for x in offset:
            d = next((d for k in range(_MAX_PLACES + 1) if (d := round(x / length, k)) * length == x), None)
            if d is None:
                break
            direction.append(d)
        else:
            coded = _numbers([length, *direction])
            if best is None or len(coded) < len(best):
                best = coded
    return best


def mirrors(offsets: list[tuple[float, ...]]) -> list[int]:
    """Per joint ``i``, ``back << 3 | signs``: its offset is joint ``i - back``'s with the
    coordinates in ``signs`` (bit a for axis a) negated, bit for bit, the nearest such joint
    and then the fewest signs; 0 if no earlier joint's is (or the offset is zero). One pass with
    a table of the offsets seen, so a skeleton of thousands of joints packs in linear time."""
    last: dict[bytes, int] = {}  # an offset's exact bytes -> the last joint with it
    out = []
    for i, offset in enumerate(offsets):
        best = 0
        if any(offset):
            for signs in range(8):  # joint k's offset flipped by signs is mine: k's is mine flipped
                k = last.get(struct.pack("<3d", *(-x if signs >> a & 1 else x for a, x in enumerate(offset))))
                if k is not None and (not best or i - k < best >> 3):
                    best = (i - k) << 3 | signs
        out.append(best)
        last[struct.pack("<3d", *offset)] = i
    return out


def round_offsets(skeleton: Skeleton, precision_cm: float) -> Skeleton:
    """``skeleton`` with every offset rounded to the fewest decimal places (in its own units)
    whose step is at most ``precision_cm``: what a lossy file stores. The rounded values are
    short decimals, so :func:`pack_skeleton` writes them as integers at a fixed number of places:
    444 bytes to 313 (deflated) for the CMU BVH skeleton at 0.001 cm, 888 to 530 for a CMU ASF
    one. Joints move by at most about the
    step times half the chain's depth."""
    if not precision_cm > 0:
        raise ValueError(f"offset precision must be positive, got {precision_cm}")
    places = max(0, math.ceil(-math.log10(precision_cm * skeleton.units_per_metre / 100.0) - 1e-9))
    joints = [
        dataclasses.replace(j, offset=tuple(round(float(x), places) + 0.0 for x in j.offset)) for j in skeleton.joints
    ]
    return dataclasses.replace(skeleton, joints=tuple(joints))


def fixed_places(offsets: list[tuple[float, ...]]) -> int | None:
    """The fewest decimal places k at which every offset is an integer / 10^k, bit for bit."""
    values = [x for o in offsets for x in o]
    if not all(math.isfinite(x) for x in values):
        return None
    exact = struct.pack(f"<{len(values)}d", *values)  # bit for bit: -0.0 is not 0.0
    return next(
        (
            k
            for k in range(_MAX_PLACES + 1)
            if struct.pack(f"<{len(values)}d", *(round(x * 10**k) / 10**k for x in values)) == exact
        ),
        None,
    )


def offset_column(offsets: list[tuple[float, ...]], places: int | None) -> bytes:
    """The offsets, each as a reference to a mirrored earlier one or as its numbers: tagged
    decimals (or an ASF length times direction), or with ``places`` untagged
    integers / 10^places. The column opens with places + 1 (0: tagged)."""
    w = _Writer()
    w.uint(0 if places is None else places + 1)
    for offset, mirror in zip(offsets, mirrors(offsets)):
        if mirror:
            w.uint(mirror)
            continue
        w.uint(_PLAIN)
        if places is not None:
            for x in offset:
                w.sint(round(x * 10**places))
            continue
        plain, product = _numbers(offset), _as_product(offset)
        if product is not None and len(product) < len(plain):
            w.out[-1] = _PRODUCT
            w.out += product
        else:
            w.out += plain
    return bytes(w.out)


@lru_cache(maxsize=64)
def pack_skeleton(skeleton: Skeleton) -> bytes:
    """Column by column (all names, then all parents, ...), which compresses best; fields at
    their usual value (rotation order = channel order, axis order ZYX, no axis, no limits)
    cost one byte per joint. Kept per skeleton (the search for the shortest offsets takes a
    few milliseconds, and a library's files share their skeletons)."""
    w = _Writer()
    joints = skeleton.joints
    w.uint(VERSION)
    w.text(skeleton.name)
    w.number(skeleton.units_per_metre)
    w.uint(len(joints))
    for j in joints:
        w.text(j.name)
    for i, j in enumerate(joints):
        w.uint(i - j.parent if j.parent >= 0 else 0)
    for j in joints:
        w.uint(len(j.channels))
        for c in j.channels:
            w.uint(CHANNEL_NAMES.index(c))
    for j in joints:
        w.text("" if j.rotation_order == _default_order(j.channels) else j.rotation_order)
    for j in joints:
        w.text("" if j.axis_order == "ZYX" else j.axis_order)
    for j in joints:
        w.uint(BODY_PARTS.index(j.body_part) + 1 if j.body_part else 0)
    offsets = [tuple(float(x) for x in j.offset) for j in joints]
    w.out += min((offset_column(offsets, places) for places in (None, fixed_places(offsets))), key=len)
    for j in joints:
        w.uint(int(j.has_axis))
        if j.has_axis:
            for x in j.axis:
                w.number(x)
    for j in joints:
        limited = any(math.isfinite(x) for pair in j.limits for x in pair)
        w.uint(int(limited))
        if limited:
            for low, high in j.limits:
                w.number(low)
                w.number(high)
    return bytes(w.out)


def unpack_skeleton(data: bytes) -> Skeleton:
    r = _Reader(data)
    try:
        if (version := r.uint()) != VERSION:
            raise CorruptStreamError(f"compact skeleton version {version}, this mocodec reads {VERSION}")
        name, units = r.text(), r.number()
        n = r.uint()
        if n > len(data):
            raise CorruptStreamError(f"compact skeleton: {n} joints cannot fit in {len(data)} bytes")
        names = [r.text() for _ in range(n)]
        parents = [i - back if (back := r.uint()) else -1 for i in range(n)]
        channels = [tuple(CHANNEL_NAMES[r.uint()] for _ in range(r.uint())) for _ in range(n)]
        orders = [r.text() or _default_order(channels[i]) for i in range(n)]
        axis_orders = [r.text() or "ZYX" for _ in range(n)]
        parts = [BODY_PARTS[p - 1] if (p := r.uint()) else None for _ in range(n)]
        offsets = []
        places = r.uint() - 1
        if places > _MAX_PLACES:
            raise CorruptStreamError(f"compact skeleton: {places} decimal places at byte {r.pos}")
        for i in range(n):
            form = r.uint()
            back, signs = form >> 3, form & 7
            if form == _PLAIN and places >= 0:
                offsets.append(tuple(r.sint() / 10**places for _ in range(3)))
            elif form == _PLAIN:
                offsets.append(tuple(r.number() for _ in range(3)))
            elif form == _PRODUCT:
                length = r.number()
                offsets.append(tuple(r.number() * length for _ in range(3)))
            elif 0 < back <= i:
                offsets.append(tuple(-x if signs >> a & 1 else x for a, x in enumerate(offsets[i - back])))
            else:
                raise CorruptStreamError(f"compact skeleton: joint {i} has offset form {form} at byte {r.pos}")
        axes = [tuple(r.number() for _ in range(3)) if r.uint() else (0.0, 0.0, 0.0) for _ in range(n)]
        limits = [tuple((r.number(), r.number()) for _ in channels[i]) if r.uint() else () for i in range(n)]
        if r.pos != len(data):
            raise CorruptStreamError(f"compact skeleton: {len(data) - r.pos} bytes left over")
        joints = [
            Joint(
                names[i], parents[i], offsets[i], channels[i], orders[i], axes[i], axis_orders[i], limits[i], parts[i]
            )
            for i in range(n)
        ]
        return Skeleton(tuple(joints), units, name)
    except (IndexError, ValueError, UnicodeDecodeError) as e:
        raise CorruptStreamError(f"compact skeleton does not parse at byte {r.pos} ({e})") from None
