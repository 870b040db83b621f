"""What the relay holds: rooms, the streams published into them (each with its header, its
codec, where it is and what is kept of it), the packets on their way to viewers, and the
viewers themselves (their budget, camera, the layers they get and what they still owe or are
owed). Plain state: no network code."""

from __future__ import annotations

import functools
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocodec.stream.packets import (
    COMPACT,
    DATA,
    END,
    Cursor,
    Packet,
    Prepared,
    StreamInfo,
    batch_offsets,
    is_batch,
    packet_views,
    parse,
    read_batch,
)
from mocodec.stream.relay.limits import Bucket, Limits
from mocodec.stream.relay.retention import Caps, RoomHistory, StreamHistory

#: A layered stream's rate per layer is measured over about this long (an exponential average).
LAYER_RATE_S = 1.0


@dataclass(slots=True)
class Forward:
    """A packet on its way to viewers: the bytes as forwarded, and what cutting needs."""

    packet: Packet
    data: bytes  # without the cut table
    cuts: np.ndarray | None = None
    cutter: Callable[[float], bytes] | None = None  # the codec's packet cutter, made at the first cut
    layer_ends: list[int] | None = None  # a layered stream's data packet: where each layer ends
    layer_variants: tuple[bytes, ...] = ()  # ... and its bytes with its lowest 1, 2, ... layers (the last: data)
    layer_starts: list[bool] | None = None  # which of its layers restart in it (read when a viewer may gain one)

    @property
    def scalable(self) -> bool:
        """Whether a viewer's budget may cut it (an embedded codec's cut table, or layers)."""
        return self.cuts is not None or self.layer_ends is not None


@functools.lru_cache(maxsize=256)
def stream_setup(header_payload: bytes) -> tuple[StreamInfo, Any]:
    """A stream header's contents and codec, parsed once for every avatar that sends the same
    header (a crowd of one kind joins at the cost of one)."""
    info = StreamInfo.from_payload(header_payload)
    return info, info.stream_codec()


@dataclass(slots=True)
class StreamState:
    owner: object  # the sending connection, or the bus
    header: Forward
    info: StreamInfo
    codec: Any  # the stream's codec (an embedded one offers packet_cutter)
    history: StreamHistory  # what a late viewer catches up from and a repair resends
    slot: int = 0  # its place in each viewer's table of layers (Room.take_slot)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    next_sequence: int = 0
    next_frame: int = 0
    ended: bool = False
    embedded: bool = field(init=False)  # cut by a cut table (spiht)
    layers: int = field(init=False)  # a layered stream's layers (1: none)
    layer_rates: list[float] = field(init=False)  # a layered stream: bit/s of its layers up to each

    def __post_init__(self) -> None:
        self.embedded = self.codec.embedded
        self.layers = self.codec.layers
        self.layer_rates = [0.0] * self.layers

    @property
    def layered(self) -> bool:
        return self.layers > 1

    def measure_layers(self, p: Packet, ends: list[int]) -> None:
        """Fold a data packet's layer sizes into the stream's rates per layer (each with the
        layers below it), an exponential average over LAYER_RATE_S that starts from zero: a
        stream's first keyframe counts for its frames' share of that time, so a new stream's
        viewers start with more layers and drop those that do not fit."""
        scale = 8.0 * self.info.fps / p.frames
        weight = min(p.frames / (self.info.fps * LAYER_RATE_S), 1.0)
        rates = self.layer_rates
        for k, end in enumerate(ends):  # (one end a layer: layer_ends)
            rates[k] += weight * (end * scale - rates[k])

    def end_packet(self, stream: int) -> Packet:
        """The packet that ends this stream for its receivers when its sender vanishes."""
        return Packet(
            stream,
            self.next_sequence,
            time.time_ns() // 1000,
            self.header.packet.codec,
            self.next_frame,
            0,
            b"",
            flags=END,
            position=self.position,
        )


@dataclass(eq=False)  # each viewer is itself: it leaves its room by identity
class Viewer:
    """One viewer of a room. Its batches wait in ``outbox`` (at most ``capacity``) until the
    server sends them; ``wake`` tells the server there are some, ``abort`` cuts its connection."""

    abort: Callable[[], None] = lambda: None
    wake: Callable[[], None] = lambda: None
    capacity: int = 1
    budget: float = 0.0  # bit/s for the scalable streams; 0: everything whole
    camera: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # by stream slot (StreamState.slot): the layers it gets now of each layered stream (0: none yet)
    layers: np.ndarray = field(default_factory=lambda: np.zeros(64, dtype=np.int8))
    pending: list[Forward] = field(default_factory=list)  # stream headers it has still to get
    behind: dict[int, tuple[StreamState, int]] = field(default_factory=dict)  # catching up: the next ordinal
    credit: float = 0.0  # bytes of catch-up it may get now
    notes: list[str] = field(default_factory=list)  # status messages it has still to get
    resends: list[Forward] = field(default_factory=list)  # packets it asked for again
    repair_volume: Bucket = field(default_factory=lambda: Bucket(Limits.repair_bytes_per_s, Limits.burst_s))
    outbox: deque[tuple[bytes | str, ...]] = field(default_factory=deque)
    missed_since: float | None = None
    missed: int = 0
    sent: int = 0
    dropped: bool = False

    def hold_slot(self, slot: int) -> None:
        """Make room in its table of layers for the stream in ``slot``."""
        if slot >= self.layers.size:
            self.layers = np.concatenate((self.layers, np.zeros(2 * slot + 2 - self.layers.size, np.int8)))

    def layer_of(self, slot: int) -> int:
        """The layers it gets now of the stream in ``slot`` (0: none yet)."""
        return int(self.layers[slot]) if slot < self.layers.size else 0

    def set_layer(self, slot: int, layers: int) -> None:
        self.hold_slot(slot)
        self.layers[slot] = layers


def caps_of(limits: Limits) -> Caps:
    return Caps(limits.max_stream_kept_bytes, limits.max_room_kept_bytes, limits.max_gop_packets)


@dataclass
class Room:
    history: RoomHistory = field(default_factory=lambda: RoomHistory(caps_of(Limits())))
    streams: dict[int, StreamState] = field(default_factory=dict)
    viewers: list[Viewer] = field(default_factory=list)
    fresh: list[Forward] = field(default_factory=list)
    publishers: int = 0  # connected senders (a room with one is kept, streams or not)
    free_slots: list[int] = field(default_factory=list)
    slots: int = 0  # slots handed out so far
    layout: object = None  # the cutting.Layout of the last few ticks

    @property
    def idle(self) -> bool:
        return not (self.streams or self.viewers or self.publishers)

    def take_slot(self) -> int:
        """A place in the viewers' tables of layers for a new stream."""
        if self.free_slots:
            return self.free_slots.pop()
        self.slots += 1
        return self.slots - 1

    def end_stream(self, key: int) -> None:
        """The stream is over: late joiners will not see it, and its slot is free again."""
        state = self.streams.pop(key)
        state.history.close()
        for viewer in self.viewers:
            viewer.set_layer(state.slot, 0)
        self.free_slots.append(state.slot)


def read_message(room: Room, data: bytes) -> tuple[list[Packet], list[memoryview], dict[int, Prepared]]:
    """The packets of one sender message in order, each one's bytes, and by their place the
    layered packets read with their layers (:data:`~mocodec.stream.packets.Prepared`: those
    come stripped of their cut tables). A batch of full packets, or of compact ones of the
    room's streams, is read together (:func:`read_batch`, the layer counts and cursors of the
    room's streams); where the forms mix (a new stream's header before its packets) or a
    packet does not parse, they are read one at a time, a compact packet following on from its
    stream's state (:class:`Cursors`), which says what is wrong where (CorruptStreamError)."""
    if not is_batch(data):
        raw = [memoryview(data)]
    else:
        offsets = batch_offsets(data)
        raw = packet_views(data, offsets)
        streams = room.streams
        together = read_batch(
            data,
            offsets,
            lambda keys: [s.layers if (s := streams.get(k)) is not None else 1 for k in keys],
            Cursors(room).cursor,
        )
        if together is not None:
            return together[0], raw, together[1]
    if any(r[:1] and r[0] & COMPACT for r in raw):
        cursors = Cursors(room)
        return [cursors.read(r, f"packet {k}") for k, r in enumerate(raw)], raw, {}
    return [parse(r, f"packet {k}") for k, r in enumerate(raw)], raw, {}


class Cursors:
    """Reading a sender's packets against its room's streams: a compact packet follows on from
    its stream's state (the packets of one message follow on from each other)."""

    def __init__(self, room: Room):
        self.room = room
        self.pending: dict[int, Cursor] = {}

    def read(self, raw: memoryview, where: str) -> Packet:
        p = parse(raw, where, self.cursor)
        if p.kind == DATA:
            cursor = self.cursor(p.stream) or Cursor(p.codec)
            cursor.advance(p)
            self.pending[p.stream] = cursor
        else:
            self.pending[p.stream] = Cursor.of_header(p)
        return p

    def cursor(self, stream: int) -> Cursor | None:
        if stream in self.pending:
            return self.pending[stream]
        state = self.room.streams.get(stream)
        if state is None:
            return None
        header = state.header.packet
        return Cursor(header.codec, state.next_sequence, state.next_frame, state.position, usual_frames=header.frames)
