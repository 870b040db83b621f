"""The wire format of live motion: packets and batches.

A packet is one codec packet with what a network needs around it::

    magic "MP", version u8, kind u8 (0 stream header, 1 data), flags u8 (1 keyframe, 2 end,
    4 cut table: the payload starts with a u16 length and the table),
    codec u8, stream id u32, sequence u32, timestamp u64 (µs since the epoch),
    first frame u32, frames u16, position 3 x f32 (the avatar's root, for crowd allocation),
    payload length u32, payload, CRC32 over everything before it (started from a value that
    says how many top layers a relay cut off a layered stream's packet: CRC32_STARTS)

All integers little-endian; 48 bytes around the payload. A *stream header* packet (kind 0)
carries the skeleton, frame rate and codec configuration as compressed JSON, so a receiver
needs nothing else. A *batch* (one WebSocket message) is "Mb", the packet count and each
packet's length as varints, then the packets: the relay sends each viewer one per tick.

An embedded (truncatable) codec's packets travel from the sender to the relay with a *cut
table*: where each channel's stream ends, so the relay cuts every viewer's share by slicing,
without decoding; a layered codec's, where each layer ends. The relay strips the table before
it forwards a packet.

Parsing never trusts a length: a short, oversized or damaged packet raises
:class:`~mocodec.errors.CorruptStreamError` naming the byte offset and what was expected.
"""

from __future__ import annotations

import binascii
import json
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mocodec import limits
from mocodec.codecs import codec_from_untrusted, packet_codecs
from mocodec.codecs.base import Codec
from mocodec.errors import CorruptStreamError, OutOfStepError
from mocodec.formats import varint
from mocodec.formats.container import inflate_capped, skeleton_from_dict, skeleton_to_dict
from mocodec.skeleton import Skeleton
from mocodec.stream import framing

MAGIC = b"MP"
BATCH_MAGIC = b"Mb"  # a batch of format 2 (varint lengths)
OLD_BATCH_MAGIC = b"MB"  # format 1 (u32 lengths), no longer read
VERSION = 2  # 2: compact packets of an ongoing stream carry their sequence number in the tag
HEADER, DATA = 0, 1
KEYFRAME, END, CUTS, RESTART = 1, 2, 4, 8  # RESTART: the codec stream's base restarts here

_FIELDS = struct.Struct("<2sBBBBIIQIH3fI")
_CRC = _U32 = struct.Struct("<I")
_U16 = struct.Struct("<H")
_POSITION = struct.Struct("<3h")
COMPACT = 0x80  # the tag bit of a compact data packet (a full packet starts with "M")
# a compact tag with SHORT: an ongoing packet of the stream's usual frame count, flagged nothing,
# the sequence number's low 6 bits in the tag; without: the flags (KEYFRAME, END, CUTS), the
# full sequence number and first frame follow (EXPLICIT), the position follows, flag RESTART
C_EXPLICIT, C_POSITION, C_RESTART, C_SHORT = 8, 16, 32, 64
SHORT_SEQUENCE = 63  # the sequence bits a short tag carries
COMPACT_MIN = 4
#: A packet's check starts from one of these, the top layers a relay cut off it (0 to 3): a cut
#: costs no byte, and the receiver learns it with the check (docs/formats.md).
CRC16_STARTS = (0xFFFF, 0x5A5A, 0xA5A5, 0x0F0F)
CRC32_STARTS = (0, 0x5A5A5A5A, 0xA5A5A5A5, 0x0F0F0F0F)
OVERHEAD = _FIELDS.size + _CRC.size
_CRC_STARTS = np.array(CRC32_STARTS, dtype=np.int64)
_CRC16_STARTS = np.array(CRC16_STARTS, dtype=np.int64)
MAX_REPAIRS = 256  # packets a viewer's repair request may name (docs/streaming.md)
#: Where the timestamp, stream id and sequence number sit in a packet (read in bulk by the load test).
STREAM_OFFSET, SEQUENCE_OFFSET, TIMESTAMP_OFFSET = 6, 10, 14


@dataclass(frozen=True)
class Packet:
    stream: int
    sequence: int
    timestamp_us: int
    codec: str
    first_frame: int
    frames: int
    payload: bytes
    kind: int = DATA
    flags: int = 0
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    compact: bool = False  # a data packet's wire form: compact (to_compact) or full
    sends_position: bool = True  # a compact packet carries ``position`` (else the receiver keeps the last)
    usual_frames: int = 0  # a data packet: its stream's usual frame count, which its header gives
    dropped: int = 0  # a layered stream's data packet: the top layers a relay cut off it

    @property
    def keyframe(self) -> bool:
        return bool(self.flags & KEYFRAME)

    @property
    def end(self) -> bool:
        return bool(self.flags & END)

    @property
    def restart(self) -> bool:
        """A receiver may start decoding here (a keyframe, or a point where the codec stream
        restarts its base layer on its own)."""
        return bool(self.flags & (KEYFRAME | RESTART))

    @property
    def codec_payload(self) -> bytes:
        """The codec's packet, without the cut table."""
        return self.payload[_U16.size + self._cuts_size() :] if self.flags & CUTS else self.payload

    @property
    def cuts(self) -> bytes:
        return self.payload[_U16.size : _U16.size + self._cuts_size()] if self.flags & CUTS else b""

    def _cuts_size(self) -> int:
        size = _U16.unpack_from(self.payload)[0] if len(self.payload) >= _U16.size else -1
        if not 0 <= size <= len(self.payload) - _U16.size:
            raise CorruptStreamError(f"packet {self.sequence} of stream {self.stream}: its cut table overruns it")
        return size

    def with_payload(self, payload: bytes, flags: int | None = None) -> Packet:
        """The packet with another payload (and flags): ``replace`` without its checks, as a
        relay makes one of every packet it takes in."""
        other = object.__new__(Packet)
        fields = other.__dict__
        fields.update(self.__dict__)
        fields["payload"] = payload
        if flags is not None:
            fields["flags"] = flags
        return other

    def without_cuts(self) -> Packet:
        return self.with_payload(self.codec_payload, self.flags & ~CUTS) if self.flags & CUTS else self

    def to_bytes(self) -> bytes:
        if self.compact and self.kind == DATA:
            return self.to_compact()
        head = _FIELDS.pack(
            MAGIC,
            VERSION,
            self.kind,
            self.flags,
            codec_number(self.codec),
            self.stream,
            self.sequence,
            self.timestamp_us,
            self.first_frame,
            self.frames,
            *self.position,
            len(self.payload),
        )
        return head + self.payload + _CRC.pack(zlib.crc32(self.payload, zlib.crc32(head, CRC32_STARTS[self.dropped])))

    def to_compact(self) -> bytes:
        """The compact wire form of a data packet (docs/formats.md). An ongoing packet that
        codes the usual frame count its stream's header gives, flagged nothing and sending no
        position, is *short*: a tag holding the sequence number's low 6 bits, the stream id (a
        varint), the payload and a CRC-16 (CCITT) of all of it, 4 bytes around the payload.
        Any other is a tag of flags, the stream id and frame count (varints), the sequence
        number's low byte, on keyframes, restarts and a stream's first packet the full sequence
        number and first frame, the root position when it is sent (3 x i16, cm), the payload
        and the CRC. The receiver keeps, per stream, what the omitted fields follow from
        (:class:`Cursor`)."""
        explicit = self.restart or self.sequence == 0
        usual = self.usual_frames > 0 and self.frames == self.usual_frames
        if usual and not (explicit or self.sends_position or self.flags):
            out = bytearray([COMPACT | C_SHORT | (self.sequence & SHORT_SEQUENCE)]) + varint.pack(self.stream)
            out += self.payload
            return bytes(out) + _U16.pack(binascii.crc_hqx(out, CRC16_STARTS[self.dropped]))
        tag = COMPACT | (self.flags & 7) | (C_EXPLICIT if explicit else 0) | (C_POSITION if self.sends_position else 0)
        tag |= C_RESTART if self.flags & RESTART else 0
        out = bytearray([tag]) + varint.pack(self.stream) + bytes([self.sequence & 0xFF]) + varint.pack(self.frames)
        if explicit:
            out += varint.pack(self.sequence) + varint.pack(self.first_frame)
        if self.sends_position:
            out += _POSITION.pack(*(int(np.clip(round(v * 100.0), -32768, 32767)) for v in self.position))
        out += self.payload
        return bytes(out) + _U16.pack(binascii.crc_hqx(out, CRC16_STARTS[self.dropped]))


def _parsed(stream, sequence, timestamp_us, codec, first_frame, frames, payload, kind, flags, position, wire) -> Packet:
    """A :class:`Packet` as the parsers make one per packet a relay takes in: its fields set at
    once rather than one by one through the frozen dataclass's ``__init__``. ``wire``:
    compact, sends_position, usual_frames and dropped."""
    packet = object.__new__(Packet)
    packet.__dict__.update(
        {
            "stream": stream,
            "sequence": sequence,
            "timestamp_us": timestamp_us,
            "codec": codec,
            "first_frame": first_frame,
            "frames": frames,
            "payload": payload,
            "kind": kind,
            "flags": flags,
            "position": position,
            "compact": wire[0],
            "sends_position": wire[1],
            "usual_frames": wire[2],
            "dropped": wire[3],
        }
    )
    return packet


@dataclass
class Cursor:
    """What a receiver keeps per stream to read its compact packets: the codec and the usual
    frame count (from the stream header), the next sequence number and frame, the last root
    position."""

    codec: str
    next_sequence: int = 0
    next_frame: int = 0
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    synced: bool = True  # a receiver that joined mid-stream waits for a keyframe
    usual_frames: int = 0  # the header's frame count of a full packet (0: every packet says its own)

    @classmethod
    def of_header(cls, header: Packet, synced: bool = True) -> Cursor:
        """The cursor a stream's header packet starts (its frames field: the usual frame count)."""
        return cls(header.codec, synced=synced, usual_frames=header.frames)

    def advance(self, p: Packet) -> None:
        """Past ``p``, unless it lies behind (a duplicate or a late packet)."""
        if self.synced and (p.sequence - self.next_sequence) & 0xFFFFFFFF >= 1 << 31:
            return
        self.next_sequence, self.next_frame = (p.sequence + 1) & 0xFFFFFFFF, p.first_frame + p.frames
        self.position, self.synced = p.position, True


def _parse_compact(data: bytes, where: str, cursor_of: Callable[[int], Cursor | None] | None) -> Packet:
    if len(data) < COMPACT_MIN:
        raise CorruptStreamError(f"{where}: {len(data)} bytes, shorter than a compact packet")
    (crc,) = _U16.unpack_from(data, len(data) - 2)
    dropped = next((k for k, start in enumerate(CRC16_STARTS) if binascii.crc_hqx(data[:-2], start) == crc), None)
    if dropped is None:
        raise CorruptStreamError(f"{where}: byte {len(data) - 2}: CRC mismatch (damaged packet)")
    tag, body = data[0], data[:-2]
    short = bool(tag & C_SHORT)
    flags = 0 if short else tag  # every bit of a tag is defined: a short one's low bits are the sequence's
    try:
        stream, pos = varint.unpack(body, 1, 5)
        if not short and pos >= len(body):
            raise ValueError(f"ends at byte {pos}")
        cursor = cursor_of(stream) if cursor_of is not None else None
        if cursor is None:
            raise CorruptStreamError(f"{where}: a compact packet of stream {stream} before its stream header")
        if short:
            if not cursor.usual_frames:
                raise CorruptStreamError(
                    f"{where}: byte 0: a short packet of stream {stream}, whose header gives no usual frame count"
                )
            frames, low, window = cursor.usual_frames, tag & SHORT_SEQUENCE, SHORT_SEQUENCE + 1
        else:
            low, window = body[pos], 256
            frames, pos = varint.unpack(body, pos + 1, 3)
        if flags & C_EXPLICIT:
            sequence, pos = varint.unpack(body, pos, 5)
            first, pos = varint.unpack(body, pos, 5)
    except ValueError as e:
        raise CorruptStreamError(f"{where}: {e}") from None
    if not flags & C_EXPLICIT and not cursor.synced:
        raise OutOfStepError(f"{where}: stream {stream}: a packet before the first keyframe received")
    if flags & C_EXPLICIT:
        if sequence & 0xFF != low or sequence > 0xFFFFFFFF:
            raise CorruptStreamError(f"{where}: sequence {sequence} does not end in byte {low}")
    else:  # packets lost since the last one received had this one's frame count; a packet up to
        # half the window (32 or 128 packets) behind (a duplicate, a late one) is placed behind
        ahead = ((low - cursor.next_sequence + window // 2) % window) - window // 2
        sequence = (cursor.next_sequence + ahead) & 0xFFFFFFFF
        first = max(cursor.next_frame + ahead * frames, 0)
    position = cursor.position
    if flags & C_POSITION:
        if pos + _POSITION.size > len(body):
            raise CorruptStreamError(f"{where}: byte {pos}: the position runs past the packet")
        position = tuple(v / 100.0 for v in _POSITION.unpack_from(body, pos))
        pos += _POSITION.size
    if frames > limits.MAX_PAYLOAD_FRAMES or first > 1 << 40:
        raise CorruptStreamError(f"{where}: {frames} frames from frame {first} is not plausible")
    return _parsed(
        stream,
        sequence,
        0,
        cursor.codec,
        first,
        frames,
        bytes(body[pos:]),
        DATA,
        (flags & 7) | (RESTART if flags & C_RESTART else 0),
        position,
        (True, bool(flags & C_POSITION), cursor.usual_frames, dropped),
    )


def with_cuts(payload: bytes, cuts: bytes) -> bytes:
    """A payload carrying a cut table (flag CUTS)."""
    return _U16.pack(len(cuts)) + cuts + payload


def with_cut_table(payload: bytes, ends) -> bytes:
    """A payload carrying its cut table (flag CUTS): where a relay may cut it, as varints (an
    embedded codec's: where each channel's stream ends; a layered codec's: where each layer
    but the top one ends). Read by :func:`cut_table` and :func:`layer_ends`."""
    return with_cuts(payload, varint.pack_array(np.asarray(ends, dtype=np.int64)))


def cut_table(p: Packet) -> np.ndarray:
    """The ends in a packet's cut table (:func:`with_cut_table`); CorruptStreamError if it
    does not parse."""
    table = p.cuts
    try:
        values, end = varint.unpack_array(table, 0, int(np.count_nonzero(np.frombuffer(table, np.uint8) < 0x80)))
    except ValueError as e:
        raise CorruptStreamError(f"bad cut table: {e}") from None
    if end != len(table):
        raise CorruptStreamError("bad cut table: it ends inside a number")
    return values


def layer_ends(p: Packet, layers: int) -> list[int]:
    """Where each of the ``layers`` layers of a layered stream's packet ends, from its cut table
    (:func:`with_cut_table`), the top one at the codec payload's end; CorruptStreamError if it
    has no table or the table does not fit (read a varint at a time: a relay reads every one)."""
    payload = p.payload
    size = _U16.unpack_from(payload)[0] if p.flags & CUTS and len(payload) >= _U16.size else -1
    end = _U16.size + size
    whole = len(payload) - end  # the codec payload's size
    ends: list[int] = []
    pos, last = _U16.size, 0
    try:
        while 0 <= whole and pos < end and len(ends) < layers:
            value, after = varint.unpack(payload, pos, 4)
            if not last <= value <= whole:
                break  # (before it moves on: a table with an end out of order does not read)
            ends.append(value)
            last, pos = value, after
    except ValueError:
        pass
    if size < 0 or whole < 0 or pos != end or len(ends) != layers - 1:
        raise CorruptStreamError(
            f"a layered stream's packet needs a cut table of {layers - 1} ends in order, within its "
            f"{max(whole, 0)} bytes"
        )
    ends.append(whole)
    return ends


def codec_number(codec_id: str) -> int:
    """A streaming codec's number in packets (its class's ``packet_number``)."""
    try:
        return packet_codecs().index(codec_id)
    except ValueError:
        raise CorruptStreamError(
            f"codec {codec_id!r} has no packet number (streaming codecs: {', '.join(packet_codecs())})"
        ) from None


def parse(
    data: bytes | memoryview, where: str = "packet", cursor_of: Callable[[int], Cursor | None] | None = None
) -> Packet:
    """The packet in ``data`` (exactly one), its CRC checked. A compact data packet needs its
    stream's :class:`Cursor`, from ``cursor_of(stream)``."""
    data = bytes(data)
    if data[:1] and data[0] & COMPACT:
        return _parse_compact(data, where, cursor_of)
    if len(data) < OVERHEAD:
        raise CorruptStreamError(f"{where}: {len(data)} bytes, shorter than the {OVERHEAD}-byte packet frame")
    (magic, version, kind, flags, number, stream, seq, ts, first, frames, x, y, z, length) = _FIELDS.unpack_from(data)
    if magic != MAGIC:
        raise CorruptStreamError(f"{where}: byte 0: expected the packet magic {MAGIC!r}, got {magic!r}")
    if version != VERSION:
        raise CorruptStreamError(f"{where}: byte 2: packet version {version}, this mocodec reads {VERSION}")
    if kind not in (HEADER, DATA) or number >= len(packet_codecs()):
        raise CorruptStreamError(f"{where}: bytes 3-5: unknown packet kind {kind} or codec number {number}")
    if len(data) != OVERHEAD + length:
        raise CorruptStreamError(
            f"{where}: byte {_FIELDS.size - 4}: payload of {length} bytes announced, {len(data) - OVERHEAD} present"
        )
    end = _FIELDS.size + length
    (crc,) = _CRC.unpack_from(data, end)
    checked = data[:end]
    if crc == zlib.crc32(checked):
        dropped: int | None = 0
    else:
        dropped = next((k for k, start in enumerate(CRC32_STARTS) if crc == zlib.crc32(checked, start)), None)
    if dropped is None or (dropped and kind != DATA):
        raise CorruptStreamError(f"{where}: byte {end}: CRC mismatch (damaged packet)")
    return _parsed(
        stream,
        seq,
        ts,
        packet_codecs()[number],
        first,
        frames,
        data[_FIELDS.size : end],
        kind,
        flags,
        (x, y, z),
        (False, True, 0, dropped),
    )


#: A full packet's fields before its payload, as numpy reads them from many packets at once.
_HEAD = np.dtype(
    [
        ("magic", "S2"), ("version", "u1"), ("kind", "u1"), ("flags", "u1"), ("codec", "u1"),
        ("stream", "<u4"), ("sequence", "<u4"), ("timestamp", "<u8"), ("first", "<u4"),
        ("frames", "<u2"), ("position", "<f4", (3,)), ("length", "<u4"),
    ]
)  # fmt: skip
#: A layered packet read together with its batch (:func:`read_batch`): where each of its
#: layers ends in its payload (the top one at its end: :func:`layer_ends`), and its wire bytes
#: with its lowest 1, 2, ... layers, the last the whole packet (what :func:`stripped` and
#: :func:`truncated` make of it): a relay's viewers get one of them each.
Prepared = tuple[list[int], tuple[bytes, ...]]


def read_batch(
    data: bytes,
    offsets: np.ndarray,
    layers: Callable[[list[int]], list[int]] | None = None,
    cursor_of: Callable[[int], Cursor | None] | None = None,
) -> tuple[list[Packet], dict[int, Prepared]] | None:
    """The packets of a batch (``offsets``: :func:`batch_offsets`) all in the full form, or all
    compact data packets of streams ``cursor_of`` knows, read together: their frames and
    fields checked in arrays, their checks, cut tables and layers in compiled calls
    (:mod:`.framing`). The packets are those :func:`parse` gives, except the layered ones
    (``layers``: the layer count of each packet's stream, from their stream ids; 1 where not
    layered) whose cut table reads with that count less one: those come stripped of it
    (:func:`stripped`), and by their place in the batch with their layers (:data:`Prepared`).
    None where the forms mix, or a packet does not parse: the caller reads them one at a time,
    which says what is wrong where."""
    data = data if isinstance(data, bytes) else bytes(data)
    starts, stops = offsets[:-1], offsets[1:]
    raw = np.frombuffer(data, dtype=np.uint8)
    if not starts.size or (stops - starts < COMPACT_MIN).any():
        return None
    compact = (raw[starts] & COMPACT) != 0
    if compact.all() and cursor_of is not None:
        return _read_compact(data, raw, starts, stops, layers, cursor_of)
    if compact.any() or (stops - starts < OVERHEAD).any():
        return None
    heads = raw[starts[:, None] + np.arange(_FIELDS.size)].view(_HEAD).ravel()
    codecs = packet_codecs()
    if not (
        (heads["magic"] == MAGIC).all()
        and (heads["version"] == VERSION).all()
        and (heads["kind"] <= DATA).all()
        and (heads["codec"] < len(codecs)).all()
        and (heads["length"].astype(np.int64) + OVERHEAD == stops - starts).all()
    ):
        return None
    kinds, flags = heads["kind"].astype(np.int64), heads["flags"].astype(np.int64)
    dropped, table_ends, values, codec_at = framing.read_full(
        raw, starts, stops, _FIELDS.size, _CRC_STARTS, (flags & CUTS) != 0
    )
    if (dropped < 0).any() or ((dropped > 0) & (kinds != DATA)).any():
        return None
    streams = heads["stream"].tolist()
    counts = np.asarray(layers(streams) if layers is not None else np.ones(len(streams)), dtype=np.int64)
    peeled = (
        (counts > 1)
        & (counts <= _CRC_STARTS.size)
        & (table_ends + 1 == counts)
        & (dropped == 0)
        & (kinds == DATA)
        & (heads["frames"] > 0)
    )
    skips = np.where(peeled, codec_at, 0)
    flags = np.where(peeled, flags & ~CUTS, flags)
    packets = [
        _parsed(stream, seq, ts, codecs[number], first, frames, data[a + _FIELDS.size + skip : b - _CRC.size], kind,
                f, tuple(position), (False, True, 0, d))
        for stream, seq, ts, number, first, frames, a, b, skip, kind, f, position, d in zip(
            streams, heads["sequence"].tolist(), heads["timestamp"].tolist(), heads["codec"].tolist(),
            heads["first"].tolist(), heads["frames"].tolist(), starts.tolist(), stops.tolist(), skips.tolist(),
            kinds.tolist(), flags.tolist(), heads["position"].tolist(), dropped.tolist(),
        )
    ]  # fmt: skip
    layered = np.flatnonzero(peeled)
    if not layered.size:
        return packets, {}
    head = _FIELDS.size - _U32.size  # (cut_packets sets the payload length after it)
    return packets, _layers_of(
        layered, counts[layered], values, heads["length"].astype(np.int64) - skips, _CRC_STARTS,
        lambda rows, sizes, checks: framing.cut_packets(
            raw, starts[rows], np.full(rows.size, head), skips[rows], sizes, np.ones(rows.size, dtype=np.bool_),
            checks, flags[rows],
        ),
    )  # fmt: skip


def _read_compact(data, raw, starts, stops, layers, cursor_of) -> tuple[list[Packet], dict[int, Prepared]] | None:
    """:func:`read_batch` of compact data packets: their fields and checks read in one compiled
    call (:func:`.framing.read_compact`), then placed by their streams' cursors in order
    (:func:`.framing.follow_cursors`, the cursors as the batch leaves them not kept)."""
    dropped, fields, cm, payload_at, table_ends, values, codec_at = framing.read_compact(
        raw, starts, stops, _CRC16_STARTS
    )
    if (dropped < 0).any():
        return None
    tags, streams, frames = fields[:, 0], fields[:, 1], fields[:, 3]
    keys, local = np.unique(streams, return_inverse=True)
    cursors = [cursor_of(k) for k in keys.tolist()]
    if any(c is None or not c.synced for c in cursors):
        return None
    short, explicit = (tags & C_SHORT) != 0, (tags & (C_SHORT | C_EXPLICIT)) == C_EXPLICIT
    usual = np.array([c.usual_frames for c in cursors], dtype=np.int64)[local]
    frames = np.where(short, usual, frames)
    given = fields[:, 4:6]
    misplaced = ((given[:, 0] & 0xFF) != fields[:, 2]) | (given[:, 0] > 0xFFFFFFFF)  # (a sequence number given)
    if (short & (usual == 0)).any() or misplaced[explicit].any():
        return None
    with_position = ~short & ((tags & C_POSITION) != 0)
    sequence, first, position_of = framing.follow_cursors(
        local, explicit, short, fields[:, 2], frames, np.ascontiguousarray(given),
        np.array([c.next_sequence for c in cursors], dtype=np.int64),
        np.array([c.next_frame for c in cursors], dtype=np.int64), with_position,
    )  # fmt: skip
    if (frames > limits.MAX_PAYLOAD_FRAMES).any() or (first > 1 << 40).any():
        return None
    kept = np.array([c.position for c in cursors], dtype=np.float64).reshape(-1, 3)[local]
    where = np.where((position_of >= 0)[:, None], cm[np.maximum(position_of, 0)] / 100.0, kept)
    flags = np.where(short, 0, (tags & 7) | np.where(tags & C_RESTART, RESTART, 0))
    counts = np.asarray(layers(keys.tolist()) if layers is not None else np.ones(keys.size), dtype=np.int64)[local]
    peeled = (counts > 1) & (counts <= len(CRC16_STARTS)) & (table_ends + 1 == counts) & (dropped == 0) & (frames > 0)
    skips = np.where(peeled, codec_at, 0)
    flags = np.where(peeled, flags & ~CUTS, flags)
    codecs = [c.codec for c in cursors]
    packets = [
        _parsed(stream, seq, 0, codecs[u], f0, n, data[a + skip : b - _U16.size], DATA, f, tuple(xyz),
                (True, sends, usual_frames, d))
        for stream, seq, u, f0, n, a, b, skip, f, xyz, sends, usual_frames, d in zip(
            streams.tolist(), sequence.tolist(), local.tolist(), first.tolist(), frames.tolist(),
            payload_at.tolist(), stops.tolist(), skips.tolist(), flags.tolist(), where.tolist(),
            with_position.tolist(), usual.tolist(), dropped.tolist(),
        )
    ]  # fmt: skip
    layered = np.flatnonzero(peeled)
    if not layered.size:
        return packets, {}
    tags = _compact_tags(flags, sequence, frames, usual, with_position)  # (of the packets stripped)
    heads = np.column_stack((tags, streams, sequence, frames, sequence, first, cm))
    lengths = stops - _U16.size - payload_at
    return packets, _layers_of(
        layered, counts[layered], values, lengths - skips, _CRC16_STARTS,
        lambda rows, sizes, checks: framing.cut_compact(raw, payload_at[rows], skips[rows], sizes, checks, heads[rows]),
    )  # fmt: skip


def _compact_tags(flags, sequence, frames, usual, with_position) -> np.ndarray:
    """The tags :meth:`Packet.to_compact` writes for packets of these fields (arrays): a short
    one where the frame count is the usual one and nothing is flagged, given or sent."""
    explicit = ((flags & (KEYFRAME | RESTART)) != 0) | (sequence == 0)
    short = (usual > 0) & (frames == usual) & ~(explicit | with_position | (flags != 0))
    return np.where(
        short,
        COMPACT | C_SHORT | (sequence & SHORT_SEQUENCE),
        COMPACT
        | (flags & 7)
        | np.where(explicit, C_EXPLICIT, 0)
        | np.where(with_position, C_POSITION, 0)
        | np.where(flags & RESTART, C_RESTART, 0),
    )


def _layers_of(layered, counts, values, wholes, crc_starts, cut) -> dict[int, Prepared]:
    """:func:`read_batch`'s layered packets' layers: every packet's variants (its lowest 1, 2,
    ... layers, the ones above dropped: its cut table's ends ``values``, then its codec
    payload's size ``wholes``) made in one compiled call, ``cut(rows, sizes, checks)``, with
    the check of each started from ``crc_starts``, by the layers it drops."""
    rows = np.repeat(layered, counts)
    firsts = np.cumsum(counts) - counts
    keep = np.arange(rows.size) - np.repeat(firsts, counts) + 1  # layers kept, 1 to the packet's count
    top = np.repeat(counts, counts)
    sizes = np.where(keep < top, values[rows, np.minimum(keep, top - 1) - 1], wholes[rows])
    out, bounds = cut(rows, sizes, crc_starts[top - keep])
    wire, at, ends = out.tobytes(), bounds.tolist(), sizes.tolist()
    cuts = [wire[a:b] for a, b in zip(at, at[1:])]
    return {
        i: (ends[first : first + n], tuple(cuts[first : first + n]))
        for i, first, n in zip(layered.tolist(), firsts.tolist(), counts.tolist())
    }


class Reader:
    """A receiver's reading of packets, full or compact: it keeps every stream's
    :class:`Cursor`, made by the stream's header and moved by each data packet read."""

    def __init__(self):
        self.cursors: dict[int, Cursor] = {}

    def read(self, data: bytes | memoryview, where: str = "packet") -> Packet:
        p = parse(data, where, self.cursors.get)
        if p.kind == HEADER:
            self.cursors.setdefault(p.stream, Cursor.of_header(p, synced=False))
        else:
            cursor = self.cursors.setdefault(p.stream, Cursor(p.codec))
            cursor.advance(p)
        return p


# ----- stream headers ---------------------------------------------------------------------------
@dataclass(frozen=True)
class StreamInfo:
    """What a receiver needs before the first data packet of a stream."""

    skeleton: Skeleton
    fps: float
    codec: dict  # Codec.get_config()
    name: str = ""
    extra: dict = field(default_factory=dict)

    def to_payload(self) -> bytes:
        doc = {
            "skeleton": skeleton_to_dict(self.skeleton),
            "fps": float(self.fps),
            "codec": self.codec,
            "name": self.name,
            "extra": self.extra,
        }
        return zlib.compress(json.dumps(doc, sort_keys=True, separators=(",", ":")).encode(), 9)

    @classmethod
    def from_payload(cls, payload: bytes, where: str = "stream header") -> StreamInfo:
        """The header's contents, every field checked: inflated to at most
        :data:`~mocodec.limits.MAX_HEADER_TEXT` bytes, a skeleton of at most
        :data:`~mocodec.limits.MAX_JOINTS` joints, a finite positive frame rate up to
        :data:`~mocodec.limits.MAX_FPS`, the codec config an object (its knobs are checked when
        a codec is made of it: :func:`~mocodec.codecs.codec_from_untrusted`)."""
        try:
            doc = json.loads(inflate_capped(payload, b"", limits.MAX_HEADER_TEXT))
            if (
                not isinstance(doc, dict)
                or not isinstance(doc.get("codec"), dict)
                or not isinstance(doc["codec"].get("codec"), str)
            ):
                raise ValueError("expected an object with a codec config naming a codec")
            if not isinstance(doc.get("skeleton"), dict) or len(doc["skeleton"].get("joints", ())) > limits.MAX_JOINTS:
                raise ValueError(f"expected a skeleton of at most {limits.MAX_JOINTS} joints")
            fps = float(doc["fps"])
            if not limits.fps_ok(fps):
                raise ValueError(f"frame rate {fps} is outside {limits.FPS_RANGE}")
            extra = doc.get("extra", {})
            skeleton = skeleton_from_dict(doc["skeleton"])
            if not skeleton.num_channels:
                raise ValueError("a skeleton without channels has nothing to stream")
            return cls(
                skeleton,
                fps,
                doc["codec"],
                str(doc.get("name", "")),
                extra if isinstance(extra, dict) else {},
            )
        except Exception as e:  # noqa: BLE001 - anything malformed in a header
            raise CorruptStreamError(f"{where}: does not parse ({type(e).__name__}: {e})") from None

    def stream_codec(self, local_files: dict[str, str] | None = None) -> Codec:
        """The codec of the stream, bound to the tables the header carries for its decoders
        (``extra["decoder"]``, :meth:`~mocodec.codecs.base.Codec.for_stream`); the config and
        tables are hostile, checked (CorruptStreamError), and a knob naming a local file is the
        caller's ``local_files`` entry (:func:`~mocodec.codecs.codec_from_untrusted`)."""
        codec = codec_from_untrusted(self.codec, "stream header", local_files)
        return codec.for_stream(self.skeleton, self.extra.get("decoder", {}))


def header_packet(stream: int, info: StreamInfo, timestamp_us: int = 0, usual_frames: int = 0) -> Packet:
    """A stream's header packet; its frames field is the frame count of the stream's full
    packets (0: they vary), which compact packets then need not send."""
    return Packet(stream, 0, timestamp_us, info.codec["codec"], 0, usual_frames, info.to_payload(), kind=HEADER)


# ----- batches ----------------------------------------------------------------------------------
def length_varint(n: int) -> bytes:
    """``varint.pack(n)``, spelled out for the one- and two-byte lengths a batch holds most (a
    packet under 16 KiB)."""
    if n < 0x80:
        return bytes((n,))
    if n < 0x4000:
        return bytes((n & 0x7F | 0x80, n >> 7))
    return varint.pack(n)


def pack_batch(packets: list[bytes]) -> bytes:
    """One message holding ``packets`` (already serialised)."""
    return batch_of(packets, [length_varint(len(p)) for p in packets])


def batch_of(packets: list[bytes], heads: list[bytes]) -> bytes:
    """:func:`pack_batch` of ``packets`` whose lengths' varints (``heads``, :func:`length_varint`)
    are made already: a relay keeps them beside the packets it serves many viewers."""
    return BATCH_MAGIC + varint.pack(len(packets)) + b"".join(heads) + b"".join(packets)


def is_batch(data: bytes | memoryview) -> bool:
    """Whether a message is a batch (of either format: a format 1 batch is refused as such)."""
    return bytes(data[:2]) in (BATCH_MAGIC, OLD_BATCH_MAGIC)


def stripped(p: Packet, data: bytes | memoryview) -> tuple[Packet, bytes]:
    """Packet ``p`` (whose wire bytes are ``data``) without its cut table, and its wire bytes:
    the same as ``p.without_cuts()`` and its ``to_bytes()``, a full packet's made from the bytes
    as they came (its header kept, the flag and payload length set anew) as a relay does for
    every packet it forwards."""
    plain = p.without_cuts()
    if plain is p:
        return p, bytes(data)
    if data[0] & COMPACT:
        return plain, plain.to_bytes()
    return plain, _reframed(data, plain.payload, p.dropped, plain.flags)


def truncated(p: Packet, data: bytes, size: int, dropped: int) -> bytes:
    """The wire bytes ``data`` of packet ``p`` with its payload cut to its first ``size``
    bytes (a layered packet cut after its ``dropped`` top layers): the same as
    ``replace(p, payload=p.payload[:size], dropped=dropped).to_bytes()``, made from the bytes as
    they came, the header kept (the full form's payload length set anew) and the check
    recomputed from the start that says the cut."""
    body = p.payload[:size]
    if data[0] & COMPACT:
        head = data[: len(data) - _U16.size - len(p.payload)]
        out = head + body
        return out + _U16.pack(binascii.crc_hqx(out, CRC16_STARTS[dropped]))
    return _reframed(data, body, dropped)


def _reframed(data: bytes | memoryview, body: bytes, dropped: int, flags: int | None = None) -> bytes:
    """A full packet's wire bytes ``data`` with the payload ``body`` (and ``flags``): its header
    kept, the payload length set anew, the check made from the start that says ``dropped``."""
    head = bytes(data[: _FIELDS.size - _U32.size])
    if flags is not None:
        head = head[:4] + bytes((flags,)) + head[5:]
    head += _U32.pack(len(body))
    return b"".join((head, body, _CRC.pack(zlib.crc32(body, zlib.crc32(head, CRC32_STARTS[dropped])))))


def split_batch(data: bytes | memoryview, where: str = "batch") -> list[memoryview]:
    """The packets of a batch, unparsed (views into ``data``)."""
    return packet_views(data, batch_offsets(data, where))


def packet_views(data: bytes | memoryview, offsets: np.ndarray) -> list[memoryview]:
    """Views into ``data`` of the packets starting at ``offsets`` (:func:`batch_offsets`)."""
    view, at = memoryview(data), offsets.tolist()
    return [view[a:b] for a, b in zip(at, at[1:])]


def batch_offsets(data: bytes | memoryview, where: str = "batch") -> np.ndarray:
    """Where each packet of a batch starts, and where the last ends: ``(count + 1,)``."""
    magic = bytes(data[:2])
    if magic == OLD_BATCH_MAGIC:
        raise CorruptStreamError(f"{where}: byte 0: a batch of format 1 (u32 lengths); this mocodec reads format 2")
    if magic != BATCH_MAGIC:
        raise CorruptStreamError(f"{where}: byte 0: expected the batch magic {BATCH_MAGIC!r}, got {magic!r}")
    try:
        count, pos = varint.unpack(data, 2, 5)
        if count > len(data) - pos:  # a length takes a byte at least
            raise ValueError(f"{count} packets announced, the message is {len(data)} bytes")
        lengths, start = varint.unpack_array(data, pos, count)
    except ValueError as e:
        raise CorruptStreamError(f"{where}: {e}") from None
    offsets = start + np.concatenate(([0], np.cumsum(lengths)))
    if offsets[-1] != len(data):
        raise CorruptStreamError(f"{where}: packet lengths add up to {offsets[-1]} bytes, the message is {len(data)}")
    return offsets


def read_u32(data: bytes | memoryview, offsets: np.ndarray, at: int) -> np.ndarray:
    """The u32 at byte ``at`` of every packet starting at ``offsets`` (vectorised)."""
    raw = np.frombuffer(data, dtype=np.uint8)
    idx = offsets[:, None] + at + np.arange(4)
    return raw[idx].copy().view("<u4").ravel()


def read_u64(data: bytes | memoryview, offsets: np.ndarray, at: int) -> np.ndarray:
    raw = np.frombuffer(data, dtype=np.uint8)
    idx = offsets[:, None] + at + np.arange(8)
    return raw[idx].copy().view("<u8").ravel()
