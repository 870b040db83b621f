"""Packets read and cut in compiled calls: a relay checks a sender's message of hundreds of
packets (full or compact: their checks, fields and cut tables, a compact packet placed by its
stream's cursor) and makes their layered variants (a packet's lowest layers,
docs/streaming.md) at once, each one's header kept or written anew, its payload cut and its
check made anew, where a call per packet cost a row of small Python steps.

The checks are zlib's CRC-32 (:func:`zlib.crc32`, a full packet's) and binascii's CRC-CCITT
(:func:`binascii.crc_hqx`, a compact packet's), table-driven, the same values bit for bit.
"""

from __future__ import annotations

import numba
import numpy as np

from mocodec.kernels import kernel


def _crc32_table() -> np.ndarray:
    table = np.arange(256, dtype=np.int64)
    for _ in range(8):
        table = np.where(table & 1, (table >> 1) ^ 0xEDB88320, table >> 1)
    return table


def _crc16_table() -> np.ndarray:
    table = np.arange(256, dtype=np.int64) << 8
    for _ in range(8):
        table = np.where(table & 0x8000, ((table << 1) ^ 0x1021) & 0xFFFF, (table << 1) & 0xFFFF)
    return table


CRC32_TABLE = _crc32_table()
CRC16_TABLE = _crc16_table()


@kernel
def crc32(data, start, a, b):
    """:func:`zlib.crc32` of ``data[a:b]`` (uint8) continued from ``start``."""
    crc = start ^ 0xFFFFFFFF
    for i in range(a, b):
        crc = CRC32_TABLE[(crc ^ data[i]) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


@kernel
def crc16(data, start, a, b):
    """:func:`binascii.crc_hqx` of ``data[a:b]`` (uint8) from ``start``."""
    crc = start
    for i in range(a, b):
        crc = ((crc << 8) & 0xFFFF) ^ CRC16_TABLE[((crc >> 8) ^ data[i]) & 0xFF]
    return crc


@kernel
def cut_packets(source, starts, heads, skips, sizes, full, checks, flags):
    """Each cut ``k`` of a packet at ``source[starts[k]:]`` whose header takes ``heads[k]``
    bytes: the header, ``sizes[k]`` bytes of the payload from its byte ``skips[k]``, and a check
    of all before it started from ``checks[k]``. A ``full`` packet's header is followed by its
    payload length (u32, set anew), its flags byte (byte 4) becomes ``flags[k]`` where that is
    not negative, and its check is a CRC-32; a compact one's a CRC-16. Returns the cuts end to
    end and where each ends."""
    ends = np.empty(starts.size + 1, dtype=np.int64)
    ends[0] = 0
    for k in range(starts.size):
        ends[k + 1] = ends[k] + heads[k] + sizes[k] + (8 if full[k] else 2)  # (a full one's length and CRC-32)
    out = np.empty(ends[-1], dtype=np.uint8)
    for k in range(starts.size):
        at, o, h, n = starts[k], ends[k], heads[k], sizes[k]
        out[o : o + h] = source[at : at + h]
        body = at + h + (4 if full[k] else 0) + skips[k]  # where the kept payload starts in the source
        if full[k]:
            if flags[k] >= 0:
                out[o + 4] = flags[k]
            for i in range(4):
                out[o + h + i] = (n >> (8 * i)) & 0xFF
            h += 4
        out[o + h : o + h + n] = source[body : body + n]
        e = o + h + n
        if full[k]:
            crc = crc32(out, checks[k], o, e)
            for i in range(4):
                out[e + i] = (crc >> (8 * i)) & 0xFF
        else:
            crc = crc16(out, checks[k], o, e)
            out[e], out[e + 1] = crc & 0xFF, crc >> 8
    return out, ends


#: The most ends :func:`read_full` and :func:`read_compact` read of a cut table (a longer one
#: is left to the caller).
MAX_TABLE = 8


@numba.njit(inline="always")
def _cut_table(source, p, length, values, k):
    """The cut table at the start of the payload ``source[p:p + length]``: its ends in
    ``values[k]`` (varints of at most 4 bytes, in order, within the codec payload, ending where
    the table's u16 length says) and (their count, where the codec payload starts in the
    payload); the count -1 where it is not so, or longer than MAX_TABLE."""
    if length < 2:
        return -1, 0
    size = np.int64(source[p]) | np.int64(source[p + 1]) << 8
    end, whole = 2 + size, length - 2 - size
    if whole < 0:
        return -1, 0
    pos, n, last, ok = 2, 0, 0, True
    while pos < end and ok:
        value, shift, done = 0, 0, False
        for _ in range(4):
            if pos >= length:
                break
            byte = source[p + pos]
            pos += 1
            value |= np.int64(byte & 0x7F) << shift
            shift += 7
            if byte < 0x80:
                done = True
                break
        ok = done and n < MAX_TABLE and last <= value <= whole
        if ok:
            values[k, n] = value
            n += 1
            last = value
    if ok and pos == end:
        return n, end
    return -1, 0


@kernel
def read_full(source, starts, stops, head_size, crc_starts, tables):
    """Full packets ``source[starts[k]:stops[k]]`` (their frames checked by the caller), their
    checks and cut tables: per packet the CRC-32 start its check was made from (its index in
    ``crc_starts``; -1: none, a damaged packet) and, where ``tables[k]``, its cut table's ends
    (:func:`_cut_table`; -1 ends where it does not read) and where the codec payload starts in
    the payload."""
    count = starts.size
    dropped = np.full(count, -1, dtype=np.int64)
    table_ends = np.full(count, -1, dtype=np.int64)
    values = np.zeros((count, MAX_TABLE), dtype=np.int64)
    codec_at = np.zeros(count, dtype=np.int64)
    for k in range(count):
        a, e = starts[k], stops[k] - 4
        stored = 0
        for i in range(4):
            stored |= np.int64(source[e + i]) << (8 * i)
        for c in range(crc_starts.size):
            if crc32(source, crc_starts[c], a, e) == stored:
                dropped[k] = c
                break
        if tables[k]:
            table_ends[k], codec_at[k] = _cut_table(source, a + head_size, e - a - head_size, values, k)
    return dropped, table_ends, values, codec_at


#: A compact packet's tag bits (docs/formats.md; :data:`mocodec.stream.packets.C_EXPLICIT` and
#: the rest), its cut table flag, and the short tag's sequence bits.
_CUTS, _EXPLICIT, _POSITION, _SHORT, _SHORT_SEQUENCE = 4, 8, 16, 64, 63


@numba.njit(inline="always")
def _varint(source, pos, end, max_bytes):
    """(value, next position) of the varint at ``source[pos:end]``; the position -1 where it
    ends inside the number or runs past ``max_bytes``."""
    value, shift = 0, 0
    for k in range(max_bytes):
        if pos + k >= end:
            return 0, -1
        byte = source[pos + k]
        value |= np.int64(byte & 0x7F) << shift
        if byte < 0x80:
            return value, pos + k + 1
        shift += 7
    return 0, -1


@kernel
def read_compact(source, starts, stops, crc_starts):
    """Compact data packets ``source[starts[k]:stops[k]]`` (docs/formats.md), as
    ``packets.parse`` reads them up to what their streams' cursors give: per packet its check's
    CRC-16 start (its index in ``crc_starts``; -1: damaged, or a field runs past the packet),
    ``fields`` (tag, stream id, the sequence number's low bits, frame count or -1 for a short
    packet's usual one, sequence number and first frame or -1 where not given), the position
    in cm where given (``positions``, else zeros), where the payload starts, and the cut table
    of one flagged so, as :func:`read_full` gives it."""
    count = starts.size
    dropped = np.full(count, -1, dtype=np.int64)
    fields = np.full((count, 6), -1, dtype=np.int64)
    positions = np.zeros((count, 3), dtype=np.int64)
    payload_at = np.zeros(count, dtype=np.int64)
    table_ends = np.full(count, -1, dtype=np.int64)
    values = np.zeros((count, MAX_TABLE), dtype=np.int64)
    codec_at = np.zeros(count, dtype=np.int64)
    for k in range(count):
        a, e = starts[k], stops[k] - 2
        if e - a < 2:
            continue
        stored = np.int64(source[e]) | np.int64(source[e + 1]) << 8
        crc = -1
        for c in range(crc_starts.size):
            if crc16(source, crc_starts[c], a, e) == stored:
                crc = c
                break
        tag = np.int64(source[a])
        stream, pos = _varint(source, a + 1, e, 5)
        if crc < 0 or pos < 0:
            continue
        low, frames, sequence, first = tag & _SHORT_SEQUENCE, -1, -1, -1
        if not tag & _SHORT:
            if pos >= e:
                continue
            low = np.int64(source[pos])
            frames, pos = _varint(source, pos + 1, e, 3)
            if pos >= 0 and tag & _EXPLICIT:
                sequence, pos = _varint(source, pos, e, 5)
                if pos >= 0:
                    first, pos = _varint(source, pos, e, 5)
            if pos >= 0 and tag & _POSITION:
                if pos + 6 > e:
                    continue
                for i in range(3):
                    v = np.int64(source[pos + 2 * i]) | np.int64(source[pos + 2 * i + 1]) << 8
                    positions[k, i] = v - 65536 if v >= 32768 else v
                pos += 6
            if pos < 0:
                continue
            if tag & _CUTS:
                table_ends[k], codec_at[k] = _cut_table(source, pos, e - pos, values, k)
        dropped[k] = crc
        fields[k, 0], fields[k, 1], fields[k, 2], fields[k, 3] = tag, stream, low, frames
        fields[k, 4], fields[k, 5] = sequence, first
        payload_at[k] = pos
    return dropped, fields, positions, payload_at, table_ends, values, codec_at


@kernel
def follow_cursors(cursor, explicit, short, low, frames, given, next_sequence, next_frame, with_position):
    """The sequence numbers and first frames of compact packets read in order (``cursor[k]``:
    their stream's cursor, whose ``next_sequence`` and ``next_frame`` they move as
    ``packets.Cursor.advance`` does), as ``packets.parse`` gives them: given (``given[k]``:
    sequence, first frame) where ``explicit``, else placed from the sequence number's low bits
    ``low`` (6 of a short packet, 8 of another) nearest to where the cursor is; and which
    packet's position each has (its own ``with_position``, the last one of its stream's before
    it, or -1: its cursor's)."""
    count = cursor.size
    sequence = np.empty(count, dtype=np.int64)
    first = np.empty(count, dtype=np.int64)
    position_of = np.empty(count, dtype=np.int64)
    last = np.full(next_sequence.size, -1, dtype=np.int64)
    for k in range(count):
        u = cursor[k]
        if explicit[k]:
            s, f = given[k, 0], given[k, 1]
        else:
            window = _SHORT_SEQUENCE + 1 if short[k] else 256
            ahead = ((low[k] - next_sequence[u] + window // 2) % window) - window // 2
            s, f = (next_sequence[u] + ahead) & 0xFFFFFFFF, max(next_frame[u] + ahead * frames[k], 0)
        sequence[k], first[k] = s, f
        position_of[k] = k if with_position[k] else last[u]
        if (s - next_sequence[u]) & 0xFFFFFFFF < 1 << 31:  # (one behind moves no cursor)
            next_sequence[u], next_frame[u], last[u] = (s + 1) & 0xFFFFFFFF, f + frames[k], position_of[k]
    return sequence, first, position_of


@numba.njit(inline="always")
def _put_varint(out, o, value):
    while value >= 0x80:
        out[o] = (value & 0x7F) | 0x80
        o += 1
        value >>= 7
    out[o] = value
    return o + 1


@numba.njit(inline="always")
def _compact_head(out, o, head):
    """Write :func:`cut_compact`'s header ``head`` at ``out[o:]``; its length."""
    tag = head[0]
    out[o] = tag
    at = _put_varint(out, o + 1, head[1])
    if tag & _SHORT:
        return at - o
    out[at] = head[2] & 0xFF
    at = _put_varint(out, at + 1, head[3])
    if tag & _EXPLICIT:
        at = _put_varint(out, at, head[4])
        at = _put_varint(out, at, head[5])
    if tag & _POSITION:
        for i in range(3):
            v = head[6 + i] & 0xFFFF
            out[at], out[at + 1] = v & 0xFF, v >> 8
            at += 2
    return at - o


@kernel
def cut_compact(source, payload_at, skips, sizes, checks, heads):
    """Compact packets made anew, as ``Packet.to_compact`` writes them: per cut ``k`` the header
    of ``heads[k]`` (tag, stream id, the sequence number's low byte, frame count, sequence
    number, first frame, and three i16 position values; a short tag's packet (``_SHORT``) takes
    only the stream id after it, one without ``_EXPLICIT`` not the two numbers, one without
    ``_POSITION`` not the position), then ``sizes[k]`` bytes of the payload at
    ``source[payload_at[k] + skips[k]:]`` and a CRC-16 of all of it from ``checks[k]``. Returns
    the cuts end to end and where each ends."""
    count = payload_at.size
    scratch = np.empty(40, dtype=np.uint8)
    ends = np.empty(count + 1, dtype=np.int64)
    ends[0] = 0
    for k in range(count):
        ends[k + 1] = ends[k] + _compact_head(scratch, 0, heads[k]) + sizes[k] + 2
    out = np.empty(ends[-1], dtype=np.uint8)
    for k in range(count):
        o = ends[k]
        h = o + _compact_head(out, o, heads[k])
        n, at = sizes[k], payload_at[k] + skips[k]
        out[h : h + n] = source[at : at + n]
        crc = crc16(out, checks[k], o, h + n)
        out[h + n], out[h + n + 1] = crc & 0xFF, crc >> 8
    return out, ends


def warm() -> None:
    """Compile (or load from numba's cache) the kernels before a relay takes
    connections, so that its first tick does not pay for it."""
    one = np.zeros(1, dtype=np.int64)
    source = np.frombuffer(bytes(8), dtype=np.uint8)  # (read-only, as a relay passes it)
    cut_packets(source, one * 0, one, one * 0, one, np.ones(1, dtype=np.bool_), one, -one)
    read_full(source, one * 0, one * 8, 2, one, np.ones(1, dtype=np.bool_))
    read_compact(source, one * 0, one * 8, one)
    cut_compact(source, one * 0, one * 0, one * 0, one, np.zeros((1, 9), dtype=np.int64))
    no = np.zeros(1, dtype=np.bool_)
    follow_cursors(one * 0, no, no, one, one, np.zeros((1, 2), dtype=np.int64), one * 0, one * 0, no)
