"""Packets cut in one compiled call: a relay makes a tick's layered variants (a packet's lowest
layers, docs/streaming.md) for hundreds of packets at once, each one's header kept, its payload
cut and its check made anew, where a call per packet cost a row of small Python steps.

The checks are zlib's CRC-32 (:func:`zlib.crc32`, a full packet's) and binascii's CRC-CCITT
(:func:`binascii.crc_hqx`, a compact packet's), table-driven, the same values bit for bit.
"""

from __future__ import annotations

import numba
import numpy as np


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


@numba.njit(cache=True)
def crc32(data, start, a, b):
    """:func:`zlib.crc32` of ``data[a:b]`` (uint8) continued from ``start``."""
    crc = start ^ 0xFFFFFFFF
    for i in range(a, b):
        crc = CRC32_TABLE[(crc ^ data[i]) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


@numba.njit(cache=True)
def crc16(data, start, a, b):
    """:func:`binascii.crc_hqx` of ``data[a:b]`` (uint8) from ``start``."""
    crc = start
    for i in range(a, b):
        crc = ((crc << 8) & 0xFFFF) ^ CRC16_TABLE[((crc >> 8) ^ data[i]) & 0xFF]
    return crc


@numba.njit(cache=True)
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


#: The most ends :func:`read_full` reads of a cut table (a longer one is left to the caller).
MAX_TABLE = 8


@numba.njit(cache=True)
def read_full(source, starts, stops, head_size, crc_starts, tables):
    """Full packets ``source[starts[k]:stops[k]]`` (their frames checked by the caller), their
    checks and cut tables: per packet the CRC-32 start its check was made from (its index in
    ``crc_starts``; -1: none, a damaged packet) and, where ``tables[k]``, its cut table's ends
    (varints of at most 4 bytes, in order, within the codec payload, ending where the table's
    u16 length says: -1 ends where it is not so, or longer than MAX_TABLE) and where the codec
    payload starts in the payload."""
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
        if not tables[k]:
            continue
        p, length = a + head_size, e - a - head_size  # the payload
        if length < 2:
            continue
        size = np.int64(source[p]) | np.int64(source[p + 1]) << 8
        end, whole = 2 + size, length - 2 - size
        if whole < 0:
            continue
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
            table_ends[k] = n
            codec_at[k] = end
    return dropped, table_ends, values, codec_at


def warm() -> None:
    """Compile (or load from numba's cache) the kernels before a relay takes
    connections, so that its first tick does not pay for it."""
    one = np.zeros(1, dtype=np.int64)
    source = np.frombuffer(bytes(8), dtype=np.uint8)  # (read-only, as a relay passes it)
    cut_packets(source, one * 0, one, one * 0, one, np.ones(1, dtype=np.bool_), one, -one)
    read_full(source, one * 0, one * 8, 2, one, np.ones(1, dtype=np.bool_))
