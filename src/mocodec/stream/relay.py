"""The relay: senders publish avatar streams into rooms, viewers watch rooms (``mocodec serve``).

One aiohttp server, one port: ``/ws`` is the WebSocket (``?room=R&role=publish|subscribe``,
the token in ``Authorization: Bearer T`` or ``&token=T``), ``/status`` a JSON summary, and
anything else the static files of the viewer. The relay greets an accepted connection with
``{"welcome": room, "role": role}`` and closes a refused one with code 4003 and the reason. A
sender's message is a batch of packets (:mod:`mocodec.stream.packets`); a viewer's messages
are JSON: settings, ``{"budget": bit/s, "camera": [x, y, z] (metres)}``, and requests to
resend packets it lost, ``{"repair": [[stream, sequence], ...]}``: the relay resends those it
still has (each stream's last REPAIR_PACKETS), up to ``repair_bytes_per_s`` (or the viewer's
budget), at its next tick, in a message before the
viewer's batch, with the layers the viewer gets now, so a receiver that holds the packets
after a gap decodes on in step instead of waiting for the next restart.

Every tick (TICK_HZ, 60 a second: a packet waits 17 ms at most) each viewer gets one batch with
everything new in its room. A viewer that declared a budget gets the scalable streams cut to
their shares by the crowd rule of 001: scores S = d_min / d (6.4), shares B S / sum S (6.5), d
the distance from its camera to each avatar's root. An embedded (``spiht``) stream is cut to its
share rounded down to a ladder of 4 rates per octave, so that viewers with nearly equal shares
share one cut; a layered (``kinwave-live`` with layers) stream keeps the most layers whose
measured rate fits the share (the base layer always), more only from a keyframe or a packet
where the layer restarts, since a layer's prediction needs its history: the share by distance is
spent as error bounds. Other streams pass whole. A viewer that joins late gets every stream
header and catches up from each stream's last keyframe (or restart point, where the codec
stream restarts its base layer on its own), paced at ``catchup_bytes_per_s`` (or its budget)
beyond the live packets (:mod:`mocodec.stream.retention` keeps them, capped in bytes per stream
and per room); a stream whose restart point is no longer kept starts live, and the viewer gets
a ``{"status": ...}`` message saying so. A stream ends with its END packet; if its sender
goes without one, the relay sends the END for it (and over the bus), so no viewer waits for a
stream that will not come back.

Limits: message size (the WebSocket refuses larger ones), per-connection rates of messages and
bytes (token buckets; over the limit closes that connection), streams per room, and at most
QUEUED_S of batches queued per viewer (two at 60 Hz): a slow viewer misses ticks and
resynchronises at the next keyframe, and missing ticks for ``slow_viewer_s`` drops it (its
connection is cut, as a close frame would wait behind the data its link cannot take), so memory
does not grow with slow links. A malformed message closes its connection only, with a close code
and the reason.
Connections are counted before HTTP parses anything (:class:`ConnectionGuard`): at most
``max_connections`` in all and ``max_connections_per_host`` from one address, and one that has
not made its request within ``request_timeout_s`` is cut. A connection is closed when its
token expires. ``/status`` shows totals only: room names are for token holders.
Threat model: docs/security.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import logging
import math
import resource
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import repeat
from pathlib import Path
from typing import Any

import numpy as np
from aiohttp import WSMsgType, web
from aiohttp.abc import AbstractAccessLogger

from mocodec.codecs.base import Embedded, Layered
from mocodec.coding.entropy.rangecoder import decode_ints
from mocodec.errors import CorruptStreamError, MocodecError
from mocodec.scene import bandwidth_scores, split_budget
from mocodec.stream import tokens
from mocodec.stream.packets import (
    CUTS,
    DATA,
    END,
    HEADER,
    MAX_REPAIRS,
    Cursor,
    Packet,
    StreamInfo,
    is_batch,
    layer_ends,
    pack_batch,
    parse,
    split_batch,
    truncated,
)
from mocodec.stream.retention import Caps, RoomHistory, StreamHistory

log = logging.getLogger("mocodec.relay")

#: Close codes (4000-4999 are the application's).
BAD_TOKEN, BAD_MESSAGE, RATE_LIMIT, TAKEN = 4003, 4400, 4429, 4409
STATIC = Path(__file__).with_name("static")
DECODER = STATIC / "decoder"
VENDOR = Path(__file__).parent.parent / "viewer" / "static" / "vendor"  # the pinned three.js
#: Shares are rounded down to this many rates per octave (19% apart), so cuts are shared.
LADDER_STEPS = 4
#: A layered stream's rate per layer is measured over about this long (an exponential average).
LAYER_RATE_S = 1.0


@dataclass
class Limits:
    max_message_bytes: int = 1 << 20
    publish_messages_per_s: float = 400.0
    publish_bytes_per_s: float = 8e6
    control_messages_per_s: float = 120.0  # settings and repair requests (one a tick, and some)
    max_control_bytes: int = 16384  # a viewer's message (MAX_REPAIRS pairs fit)
    repair_packets_per_s: float = 2000.0  # packets resent to one viewer; past it requests are ignored
    repair_bytes_per_s: float = 1e6  # bytes resent to one viewer (at most its budget)
    catchup_bytes_per_s: float = 2e6  # a late viewer's catch-up beyond the live packets (at most its budget)
    max_stream_kept_bytes: int = 4 << 20  # kept per stream for late viewers and repairs
    max_room_kept_bytes: int = 32 << 20  # kept per room
    burst_s: float = 2.0  # a bucket holds this many seconds of its rate
    slow_viewer_s: float = 5.0
    max_gop_packets: int = 512
    max_streams_per_room: int = 5000
    min_distance_m: float = 0.1
    max_connections: int = 2000
    max_connections_per_host: int = 200
    request_timeout_s: float = 10.0


class Bucket:
    """A token bucket: ``rate`` per second, up to ``rate * burst_s`` saved."""

    def __init__(self, rate: float, burst_s: float):
        self.rate, self.burst_s, self.capacity = rate, burst_s, rate * burst_s
        self.level, self.at = self.capacity, time.monotonic()

    def set_rate(self, rate: float) -> None:
        self.rate, self.capacity = rate, rate * self.burst_s
        self.level = min(self.level, self.capacity)

    def take(self, amount: float = 1.0) -> bool:
        now = time.monotonic()
        self.level = min(self.capacity, self.level + (now - self.at) * self.rate)
        self.at = now
        if self.level < amount:
            return False
        self.level -= amount
        return True


class Closing(Exception):
    """Close this connection with ``code`` and ``reason``."""

    def __init__(self, code: int, reason: str):
        super().__init__(reason)
        self.code, self.reason = code, reason


@dataclass
class Forward:
    """A packet on its way to viewers: the bytes as forwarded, and what cutting needs."""

    packet: Packet
    data: bytes  # without the cut table
    cuts: np.ndarray | None = None
    cutter: Callable[[float], bytes] | None = None  # the codec's packet cutter, made at the first cut
    layer_ends: list[int] | None = None  # a layered stream's data packet: where each layer ends
    layer_starts: list[bool] | None = None  # ... and which restart in it (read when a viewer may gain one)

    @property
    def scalable(self) -> bool:
        """Whether a viewer's budget may cut it (an embedded codec's cut table, or layers)."""
        return self.cuts is not None or self.layer_ends is not None


class _Cursors:
    """Reading a sender's packets against its room's streams: a compact packet follows on from
    its stream's state (the packets of one message follow on from each other)."""

    def __init__(self, room: Room):
        self.room = room
        self.pending: dict[int, Cursor] = {}

    def read(self, raw: memoryview, where: str) -> Packet:
        p = parse(raw, where, self._cursor)
        if p.kind == DATA:
            cursor = self._cursor(p.stream) or Cursor(p.codec)
            cursor.advance(p)
            self.pending[p.stream] = cursor
        else:
            self.pending[p.stream] = Cursor.of_header(p)
        return p

    def _cursor(self, stream: int) -> Cursor | None:
        if stream in self.pending:
            return self.pending[stream]
        state = self.room.streams.get(stream)
        if state is None:
            return None
        header = state.header.packet
        return Cursor(header.codec, state.next_sequence, state.next_frame, state.position, usual_frames=header.frames)


@dataclass
class StreamState:
    owner: object  # the sending connection, or the bus
    header: Forward
    info: StreamInfo
    codec: Any  # the stream's codec (an embedded one offers packet_cutter)
    history: StreamHistory  # what a late viewer catches up from and a repair resends
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    next_sequence: int = 0
    next_frame: int = 0
    ended: bool = False
    embedded: bool = field(init=False)  # cut by a cut table (spiht)
    layers: int = field(init=False)  # a layered stream's layers (1: none)
    layer_rates: list[float] = field(init=False)  # a layered stream: bit/s of its layers up to each

    def __post_init__(self) -> None:
        self.embedded = isinstance(self.codec, Embedded)
        self.layers = len(self.codec.layer_bounds) if isinstance(self.codec, Layered) else 1
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
        for k in range(self.layers):
            rate = ends[min(k, len(ends) - 1)] * scale
            self.layer_rates[k] += weight * (rate - self.layer_rates[k])

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


@dataclass
class _Crowd:
    """A tick's scalable streams (embedded or layered), worked out once for every viewer: each
    stream's row in ``where`` (its position) and in ``rates`` (the bit/s of its layers up to
    each, infinite past its own), and the tick's fresh layered packets, one per stream: their
    streams, rows, keyframe flags and their variants with 1, 2, ... layers (``variants[i *
    width + k - 1]``, and their lengths), and the tick's other fresh packets (``others``)."""

    row: dict[int, int]
    where: np.ndarray
    rates: np.ndarray
    layered: list[Forward]
    streams: list[int]
    rows: np.ndarray
    keyframes: np.ndarray
    width: int
    variants: list[bytes]
    lengths: np.ndarray
    together: set[int]
    others: list[Forward]


@dataclass
class Viewer:
    ws: web.WebSocketResponse
    transport: Any  # the connection (asyncio transport), aborted if the viewer stalls
    budget: float = 0.0  # bit/s for the scalable streams; 0: everything whole
    camera: tuple[float, float, float] = (0.0, 0.0, 0.0)
    layers: dict[int, int] = field(default_factory=dict)  # layered stream -> the layers it gets now
    pending: list[Forward] = field(default_factory=list)  # stream headers it has still to get
    behind: dict[int, tuple[StreamState, int]] = field(default_factory=dict)  # catching up: the next ordinal
    credit: float = 0.0  # bytes of catch-up it may get now
    notes: list[str] = field(default_factory=list)  # status messages it has still to get
    resends: list[Forward] = field(default_factory=list)  # packets it asked for again
    repair_volume: Bucket = field(default_factory=lambda: Bucket(Limits.repair_bytes_per_s, Limits.burst_s))
    queue: asyncio.Queue = field(default_factory=lambda: asyncio.Queue(maxsize=1))
    missed_since: float | None = None
    missed: int = 0
    sent: int = 0
    dropped: bool = False


@dataclass
class Room:
    history: RoomHistory = field(default_factory=lambda: RoomHistory(caps_of(Limits())))
    streams: dict[int, StreamState] = field(default_factory=dict)
    viewers: list[Viewer] = field(default_factory=list)
    fresh: list[Forward] = field(default_factory=list)
    publishers: int = 0  # connected senders (a room with one is kept, streams or not)

    @property
    def idle(self) -> bool:
        return not (self.streams or self.viewers or self.publishers)


def caps_of(limits: Limits) -> Caps:
    return Caps(limits.max_stream_kept_bytes, limits.max_room_kept_bytes, limits.max_gop_packets)


async def messages_of(ws: web.WebSocketResponse, kind: WSMsgType, refusal: str):
    """The data of a connection's messages until it closes; Closing(``refusal``) at the first
    message of another kind."""
    async for msg in ws:
        if msg.type == WSMsgType.ERROR:
            return
        if msg.type != kind:
            raise Closing(BAD_MESSAGE, refusal)
        yield msg.data


@functools.lru_cache(maxsize=256)
def stream_setup(header_payload: bytes) -> tuple[StreamInfo, object]:
    """A stream header's contents and codec, parsed once for every avatar that sends the same
    header (a crowd of one kind joins at the cost of one)."""
    info = StreamInfo.from_payload(header_payload)
    return info, info.stream_codec()


TICK_HZ = 60.0  # batches a second to each viewer: twice the senders' packet rate halves the wait
QUEUED_S = 1.0 / 30.0  # batches a viewer may have queued, in seconds (one at 30 Hz, two at 60)


class Relay:
    def __init__(self, secret: str, limits: Limits | None = None, tick_hz: float = TICK_HZ, bus=None):
        if not secret:
            raise MocodecError("the relay needs a secret (--secret) to check room tokens")
        self.secret, self.limits, self.tick_s = secret, limits or Limits(), 1.0 / tick_hz
        self.queued = max(1, round(QUEUED_S * tick_hz))  # batches a viewer may have queued
        self.rooms: dict[str, Room] = {}
        self.bus = bus
        self.guard: ConnectionGuard | None = None  # set by start()
        self.started = time.monotonic()
        self.counters = {
            "packets_in": 0,
            "batches_out": 0,
            "missed_ticks": 0,
            "closed_bad": 0,
            "closed_rate": 0,
            "closed_expired": 0,
            "dropped_slow": 0,
            "repairs": 0,
            "repairs_missed": 0,
            "catchups_partial": 0,
        }

    # ----- the application -------------------------------------------------------------------
    def app(self) -> web.Application:
        app = web.Application(middlewares=[self._served])
        app.router.add_get("/ws", self.handle_ws)
        app.router.add_get("/status", self.handle_status)
        if STATIC.is_dir():
            app.router.add_get("/", self.handle_index)
            app.router.add_get("/watch", self.handle_watch)
            app.router.add_static("/static", STATIC)
            if DECODER.is_dir():  # the JavaScript decoder (a link to js/src in a checkout)
                app.router.add_static("/decoder", DECODER.resolve())
            if VENDOR.is_dir():
                app.router.add_static("/vendor", VENDOR)
        app.on_startup.append(self._start)
        app.on_cleanup.append(self._stop)
        return app

    @web.middleware
    async def _served(self, request: web.Request, handler):
        """Every request that reaches a handler marks its connection as past the guard's timeout."""
        if self.guard is not None:
            self.guard.mark_served(request.transport)
        return await handler(request)

    async def _start(self, app: web.Application) -> None:
        self._ticker = asyncio.create_task(self._tick_loop())
        if self.bus is not None:
            await self.bus.start(self._from_bus)

    async def _stop(self, app: web.Application) -> None:
        self._ticker.cancel()
        if self.bus is not None:
            await self.bus.stop()

    async def handle_index(self, request: web.Request) -> web.FileResponse:
        return web.FileResponse(STATIC / "index.html")

    async def handle_watch(self, request: web.Request) -> web.FileResponse:
        """A page that joins a room itself and decodes it in the browser (/decoder)."""
        return web.FileResponse(STATIC / "watch.html")

    async def handle_status(self, request: web.Request) -> web.Response:
        """Totals only: a room's name is what its tokens are issued for."""
        rooms = self.rooms.values()
        return web.json_response(
            {
                "rooms": len(self.rooms),
                "streams": sum(len(r.streams) for r in rooms),
                "viewers": sum(len(r.viewers) for r in rooms),
                "uptime_s": round(time.monotonic() - self.started, 1),
                **self.counters,
            }
        )

    async def handle_ws(self, request: web.Request) -> web.WebSocketResponse:
        room_name = request.query.get("room", "")
        role = request.query.get("role", "subscribe")
        auth = request.headers.get("Authorization", "")
        token = auth[7:] if auth.startswith("Bearer ") else request.query.get("token", "")
        ws = web.WebSocketResponse(max_msg_size=self.limits.max_message_bytes, heartbeat=20.0)
        await ws.prepare(request)
        try:
            if role not in ("publish", "subscribe"):
                raise Closing(BAD_MESSAGE, f"role must be publish or subscribe, got {role!r}")
            try:
                claims = tokens.verify(self.secret, token, room_name, role)
            except tokens.TokenError as e:
                raise Closing(BAD_TOKEN, str(e)) from None
            room = self._room(room_name)
            expiry = asyncio.get_running_loop().call_later(
                max(float(claims["exp"]) - time.time(), 0.0), self._expire, ws
            )
            await ws.send_json({"welcome": room_name, "role": role})
            try:
                if role == "publish":
                    await self._publisher(ws, room_name, room)
                else:
                    await self._viewer(ws, room, request.transport)
            finally:
                expiry.cancel()
        except Closing as c:
            self.counters["closed_rate" if c.code == RATE_LIMIT else "closed_bad"] += 1
            log.info("closing a connection: %s", c.reason)
            await ws.close(code=c.code, message=c.reason[:120].encode())
        return ws

    def _room(self, name: str) -> Room:
        room = self.rooms.get(name)
        if room is None:
            room = self.rooms[name] = Room(RoomHistory(caps_of(self.limits)))
        return room

    def _expire(self, ws: web.WebSocketResponse) -> None:
        """A connection's token has expired: close it (a viewer stops receiving, a sender's
        streams end)."""
        self.counters["closed_expired"] += 1
        log.info("closing a connection: token expired")
        asyncio.ensure_future(ws.close(code=BAD_TOKEN, message=b"token expired"))

    # ----- senders -----------------------------------------------------------------------------
    async def _publisher(self, ws: web.WebSocketResponse, room_name: str, room: Room) -> None:
        messages = Bucket(self.limits.publish_messages_per_s, self.limits.burst_s)
        volume = Bucket(self.limits.publish_bytes_per_s, self.limits.burst_s)
        room.publishers += 1
        try:
            async for data in messages_of(ws, WSMsgType.BINARY, "a sender sends binary packet batches only"):
                if not messages.take() or not volume.take(len(data)):
                    raise Closing(
                        RATE_LIMIT,
                        f"rate limit: over {self.limits.publish_messages_per_s:g} messages "
                        f"or {self.limits.publish_bytes_per_s:g} bytes per second",
                    )
                self._ingest(room, data, owner=ws)
                if self.bus is not None:
                    await self.bus.publish(room_name, data)
        finally:  # streams left without their end: end them for everyone
            room.publishers -= 1
            ends = [s.end_packet(k).to_bytes() for k, s in room.streams.items() if s.owner is ws and not s.ended]
            if ends:
                self._ingest(room, pack_batch(ends), owner=ws)
                if self.bus is not None:
                    await self.bus.publish(room_name, pack_batch(ends))

    def _ingest(self, room: Room, data: bytes, owner: object) -> None:
        """The packets of one sender message into the room; Closing if it is malformed."""
        try:
            raw = split_batch(data) if is_batch(data) else [memoryview(data)]
            cursors = _Cursors(room)
            packets = [cursors.read(r, f"packet {k}") for k, r in enumerate(raw)]
        except MocodecError as e:
            raise Closing(BAD_MESSAGE, f"bad message: {e}") from None
        for p, r in zip(packets, raw):
            self.counters["packets_in"] += 1
            state = room.streams.get(p.stream)
            if state is not None and state.owner is not owner:
                raise Closing(TAKEN, f"stream {p.stream} is published by another sender")
            if p.kind == HEADER:
                try:
                    info, codec = stream_setup(p.payload)
                except MocodecError as e:
                    raise Closing(BAD_MESSAGE, f"stream {p.stream}: {e}") from None
                if state is None and len(room.streams) >= self.limits.max_streams_per_room:
                    raise Closing(RATE_LIMIT, f"room is full ({self.limits.max_streams_per_room} streams)")
                if state is not None:
                    state.history.close()
                room.streams[p.stream] = StreamState(owner, Forward(p, bytes(r)), info, codec, room.history.stream())
                room.fresh.append(room.streams[p.stream].header)
                continue
            if state is None:
                raise Closing(BAD_MESSAGE, f"stream {p.stream}: data before its header")
            forward = self._forward(p, r, state.layered)
            if p.dropped:
                raise Closing(BAD_MESSAGE, f"stream {p.stream}: packet {p.sequence}: a sender's packet is whole")
            if state.layered and p.frames:
                try:
                    forward.layer_ends = layer_ends(p, state.layers)
                except CorruptStreamError as e:
                    raise Closing(BAD_MESSAGE, f"stream {p.stream}: packet {p.sequence}: {e}") from None
                state.measure_layers(p, forward.layer_ends)
            state.position = p.position
            state.next_sequence, state.next_frame = (p.sequence + 1) & 0xFFFFFFFF, p.first_frame + p.frames
            state.history.add(forward, p.restart)  # a late joiner starts at the last keyframe or restart
            room.fresh.append(forward)
            state.ended = state.ended or p.end  # removed after this tick's dispatch

    @staticmethod
    def _forward(p: Packet, raw: memoryview, layered: bool) -> Forward:
        """The packet as forwarded, its cut table stripped: an embedded codec's read here, a
        layered one's by :func:`~mocodec.stream.packets.layer_ends`."""
        if not p.flags & CUTS:
            return Forward(p, bytes(raw))
        plain = p.without_cuts()
        if layered:
            return Forward(plain, plain.to_bytes())
        try:
            cuts = decode_ints(p.cuts)
        except Exception:  # noqa: BLE001 - a cut table that does not parse
            raise Closing(BAD_MESSAGE, f"stream {p.stream}: packet {p.sequence}: bad cut table") from None
        return Forward(plain, plain.to_bytes(), cuts)

    async def _from_bus(self, room_name: str, data: bytes) -> None:
        try:
            self._ingest(self._room(room_name), data, owner=self.bus)
        except Closing as c:
            log.warning("a bus message for room %s was refused: %s", room_name, c.reason)

    # ----- viewers -----------------------------------------------------------------------------
    async def _viewer(self, ws: web.WebSocketResponse, room: Room, transport) -> None:
        viewer = Viewer(ws, transport, queue=asyncio.Queue(maxsize=self.queued))
        self._join(viewer, room)
        sender = asyncio.create_task(self._send_loop(viewer))
        control = Bucket(self.limits.control_messages_per_s, self.limits.burst_s)
        repairs = Bucket(self.limits.repair_packets_per_s, self.limits.burst_s)
        try:
            async for text in messages_of(ws, WSMsgType.TEXT, "a viewer sends JSON settings only"):
                if not control.take():
                    raise Closing(
                        RATE_LIMIT, f"rate limit: over {self.limits.control_messages_per_s:g} settings per second"
                    )
                if len(text) > self.limits.max_control_bytes:
                    raise Closing(BAD_MESSAGE, f"a viewer's message is at most {self.limits.max_control_bytes} bytes")
                doc = self._settings(viewer, text)
                viewer.repair_volume.set_rate(self._pace(viewer, self.limits.repair_bytes_per_s))
                if "repair" in doc:
                    self._resend(viewer, room, doc["repair"], repairs)
        finally:
            room.viewers.remove(viewer)
            sender.cancel()

    def _join(self, viewer: Viewer, room: Room) -> None:
        """A viewer joins: it gets every stream's header and catches up from its last restart
        point (:meth:`_catch_up`), or starts a stream live where that point is no longer kept."""
        viewer.repair_volume = Bucket(self.limits.repair_bytes_per_s, self.limits.burst_s)
        for key, state in room.streams.items():
            if state.ended:
                continue
            viewer.pending.append(state.header)
            if state.history.partial:
                self._starts_live(viewer, key, "its last restart point is no longer kept")
            else:
                viewer.behind[key] = (state, state.history.restart)
        room.viewers.append(viewer)

    @staticmethod
    def _settings(viewer: Viewer, text: str) -> dict:
        """Apply a viewer's settings; the message, parsed."""
        try:
            doc = json.loads(text)
            budget = float(doc.get("budget", viewer.budget))
            camera = tuple(float(x) for x in doc.get("camera", viewer.camera))
        except (ValueError, TypeError, AttributeError, OverflowError, RecursionError):
            raise Closing(BAD_MESSAGE, 'settings must be JSON like {"budget": 8000, "camera": [0, 1.6, 5]}') from None
        if not (math.isfinite(budget) and budget >= 0) or len(camera) != 3 or not all(map(math.isfinite, camera)):
            raise Closing(BAD_MESSAGE, "budget must be >= 0 bit/s and camera three finite numbers")
        viewer.budget, viewer.camera = budget, camera
        return doc

    def _pace(self, viewer: Viewer, rate: float) -> float:
        """Bytes a second of catch-up or repairs for a viewer: ``rate``, or its budget if lower."""
        return rate if viewer.budget <= 0 else min(rate, viewer.budget / 8.0)

    def _starts_live(self, viewer: Viewer, stream: int, why: str) -> None:
        """A late viewer gets ``stream`` from its latest packets on, decodable from its next
        restart point; it is told so in a status message."""
        self.counters["catchups_partial"] += 1
        status = f"stream {stream}: {why}; live from its latest packets, decoded from its next restart"
        viewer.notes.append(json.dumps({"status": status}))

    def _resend(self, viewer: Viewer, room: Room, pairs: object, bucket: Bucket) -> None:
        """Queue the packets a viewer asks for again (``[[stream, sequence], ...]``) that the
        relay still has (the last REPAIR_PACKETS of each stream), while its repair buckets last,
        ``bucket`` in packets and the viewer's own in bytes (past them, requests are ignored:
        the viewer's receivers wait for the next restart)."""
        if not (isinstance(pairs, list) and len(pairs) <= MAX_REPAIRS):
            raise Closing(BAD_MESSAGE, f"repair must be a list of at most {MAX_REPAIRS} [stream, sequence] pairs")
        for pair in pairs:
            if not (
                isinstance(pair, list) and len(pair) == 2 and all(type(x) is int and 0 <= x <= 0xFFFFFFFF for x in pair)
            ):
                raise Closing(BAD_MESSAGE, "a repair pair is [stream, sequence], two integers 0 to 2**32 - 1")
            state = room.streams.get(pair[0])
            found = None if state is None else state.history.find(pair[1])
            if found is None or not bucket.take() or not viewer.repair_volume.take(len(found.data)):
                self.counters["repairs_missed"] += 1
                continue
            viewer.resends.append(found)
            self.counters["repairs"] += 1

    async def _send_loop(self, viewer: Viewer) -> None:
        while True:
            batches = await viewer.queue.get()
            try:
                for batch in batches:
                    await (viewer.ws.send_str(batch) if isinstance(batch, str) else viewer.ws.send_bytes(batch))
            except (ConnectionError, RuntimeError):
                return

    # ----- ticks -------------------------------------------------------------------------------
    async def _tick_loop(self) -> None:
        next_tick = time.monotonic()
        while True:
            next_tick += self.tick_s
            await asyncio.sleep(max(next_tick - time.monotonic(), 0.0))
            for name, room in list(self.rooms.items()):
                try:
                    self._dispatch(room)
                except Exception:  # noqa: BLE001 - one room's fault must not stop the others
                    log.exception("dispatching room %s failed", name)
            for name in [n for n, r in self.rooms.items() if r.idle]:
                del self.rooms[name]

    def _dispatch(self, room: Room) -> None:
        fresh, room.fresh = room.fresh, []
        shared: bytes | None = None  # the batch of every viewer with nothing of its own
        cut_cache: dict[tuple[int, float], bytes] = {}
        crowd = None  # the scalable streams and where they are, this tick
        viewers = [v for v in room.viewers if not v.dropped]
        shares: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        scalable = any(f.scalable for f in fresh)
        for viewer in viewers:
            pending, viewer.pending = viewer.pending, []
            resends, viewer.resends = viewer.resends, []
            notes, viewer.notes = viewer.notes, []
            caught, live = self._catch_up(room, viewer, fresh) if viewer.behind else ([], fresh)
            pending += caught
            items = pending + live
            # status, and what it asked for again, go first, in messages of their own: the tick's batch stays shared
            batches: list[bytes | str] = [*notes]
            if resends:
                batches.append(pack_batch([self._resent(viewer, f) for f in resends]))
            if viewer.budget > 0 and (scalable or any(f.scalable for f in pending)):
                if crowd is None:
                    crowd = self._crowd(room, fresh)
                    shares = self._shares(crowd, [v for v in viewers if v.budget > 0])
                own = len(items) - len(fresh) if live is fresh else len(items)  # the tick's fresh packets go together
                cut = self._cut(room, crowd, viewer, *shares[id(viewer)], items, own, cut_cache)
                batches.append(pack_batch(*cut))
            elif pending or live is not fresh:  # joined late: its streams' last packets before the tick's
                if items:
                    batches.append(pack_batch([f.data for f in items]))
            elif fresh:
                shared = shared or pack_batch([f.data for f in fresh])
                batches.append(shared)
            if batches:
                self._offer(viewer, tuple(batches), items)
        for key in [k for k, state in room.streams.items() if state.ended]:
            room.streams.pop(key).history.close()  # over: late joiners will not see it
            for viewer in room.viewers:
                viewer.layers.pop(key, None)

    def _catch_up(self, room: Room, viewer: Viewer, fresh: list[Forward]) -> tuple[list[Forward], list[Forward]]:
        """A late viewer's catch-up this tick: the kept packets of each stream it is behind on,
        from where it got to, paced at :meth:`_pace` beyond the live packets of those streams
        (which the history holds too, in order); and the tick's fresh packets it gets as they
        are (the other streams', and new streams' headers)."""
        for key, (state, _) in list(viewer.behind.items()):
            if room.streams.get(key) is not state:  # ended, or a new header: that comes fresh
                del viewer.behind[key]
        live: list[Forward] = []
        out: list[Forward] = []
        owed = 0
        for f in fresh:
            if f.packet.kind == HEADER or f.packet.stream not in viewer.behind:
                live.append(f)
            else:
                owed += len(f.data)
        rate = self._pace(viewer, self.limits.catchup_bytes_per_s)
        viewer.credit = min(viewer.credit + rate * self.tick_s, rate * self.limits.burst_s) + owed
        for key, (state, at) in list(viewer.behind.items()):
            history = state.history
            if at < history.first:  # dropped before it got there (it was too slow)
                del viewer.behind[key]
                self._starts_live(viewer, key, "its catch-up fell out of what the relay keeps")
                continue
            if viewer.credit <= 0 and not state.ended:
                continue
            got, at = history.since(at, math.inf if state.ended else viewer.credit)
            viewer.credit -= sum(len(f.data) for f in got)
            out += got
            if at >= history.end:
                del viewer.behind[key]
            else:
                viewer.behind[key] = (state, at)
        if not viewer.behind:
            viewer.credit = 0.0
        return out, live

    def _offer(self, viewer: Viewer, batches: tuple[bytes | str, ...], items: list[Forward]) -> None:
        """Queue a viewer's batches, or miss the tick if the last are still on their way:
        it keeps the stream headers for the next tick and drops the rest (its receivers
        resynchronise at the next keyframe)."""
        try:
            viewer.queue.put_nowait(batches)
            viewer.missed_since = None
            viewer.sent += 1
            self.counters["batches_out"] += 1
        except asyncio.QueueFull:
            viewer.missed += 1
            self.counters["missed_ticks"] += 1
            viewer.pending = [f for f in items if f.packet.kind == HEADER]
            now = time.monotonic()
            viewer.missed_since = viewer.missed_since or now
            if now - viewer.missed_since > self.limits.slow_viewer_s and not viewer.dropped:
                # its link is full, so a close frame would wait behind the data: cut the connection
                self.counters["dropped_slow"] += 1
                viewer.dropped = True
                log.info("dropping a viewer that missed ticks for %.1f s", now - viewer.missed_since)
                viewer.transport.abort()

    @staticmethod
    def _crowd(room: Room, fresh: list[Forward]) -> _Crowd:
        scalable = [k for k, s in room.streams.items() if s.embedded or s.layered]
        where = np.array([room.streams[k].position for k in scalable], dtype=np.float64).reshape(-1, 3)
        width = max((room.streams[k].layers for k in scalable), default=1)
        rates = np.full((len(scalable), width), np.inf)
        for i, k in enumerate(scalable):
            state = room.streams[k]
            rates[i, : state.layers] = state.layer_rates
        row = {k: i for i, k in enumerate(scalable)}
        count = Counter(f.packet.stream for f in fresh)  # a stream's packets keep their order: one by one
        alone = [f for f in fresh if count[f.packet.stream] < 2]
        layered = [f for f in alone if f.layer_ends is not None and f.packet.stream in row]
        streams = [f.packet.stream for f in layered]
        variants: list[bytes] = []
        for f in layered:
            own = Relay._layer_variants(f)
            variants += own + own[-1:] * (width - len(own))
        together = {id(f) for f in layered}
        return _Crowd(
            row,
            where,
            rates,
            layered,
            streams,
            np.array([row[k] for k in streams], dtype=np.int64),
            np.array([f.packet.keyframe for f in layered], dtype=bool),
            width,
            variants,
            np.fromiter(map(len, variants), dtype="<u4", count=len(variants)),
            together,
            [f for f in fresh if id(f) not in together],
        )

    def _shares(self, crowd: _Crowd, viewers: list[Viewer]) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """For every viewer with a budget (by id), its shares of the crowd's streams (6.4, 6.5:
        ``split_budget`` of its budget by the distance scores from its camera) and the layers of
        each stream within its share (at least one), worked out for all viewers at once."""
        streams = len(crowd.row)
        if not streams or not viewers:
            return {id(v): (np.zeros(streams), np.ones(streams, dtype=np.int64)) for v in viewers}
        cameras = np.array([v.camera for v in viewers], dtype=np.float64)
        d = np.linalg.norm(crowd.where[:, None, :] - cameras[None, :, :], axis=2)
        scores = bandwidth_scores(np.maximum(d, self.limits.min_distance_m))  # (streams, viewers)
        shares = split_budget(np.array([int(v.budget) for v in viewers]), scores)
        fits = np.maximum((crowd.rates[:, None, :] <= shares[:, :, None]).sum(axis=2), 1)
        return {id(v): (shares[:, k], fits[:, k]) for k, v in enumerate(viewers)}

    def _cut(
        self,
        room: Room,
        crowd: _Crowd,
        viewer: Viewer,
        shares: np.ndarray,
        fits: np.ndarray,
        items: list[Forward],
        pending: int,
        cache: dict,
    ) -> tuple[list[bytes], np.ndarray | None]:
        """The viewer's packets, the scalable streams cut to its ``shares`` of the crowd (bit/s
        per stream; ``fits``: the layers within each), and their lengths (None: not worked
        out). The tick's fresh layered packets (``crowd.layered``) go at once, in arrays; the
        rest, and what the viewer has pending, one by one."""
        together = pending < len(items) and bool(crowd.together)
        out = []
        for f in items[:pending] + (crowd.others if together else items[pending:]):
            r = crowd.row.get(f.packet.stream)
            if r is None or (f.cuts is None and f.layer_ends is None):
                out.append(f.data)
            elif f.layer_ends is not None:
                keep = self._layers_for(viewer, f, room.streams[f.packet.stream], int(fits[r]))
                key: tuple[int, float] = (id(f), -keep)
                if key not in cache:
                    cache[key] = self._drop_layers(f, keep)
                out.append(cache[key])
            else:
                rate = on_ladder(float(shares[r]))
                key = (id(f), rate)
                if key not in cache:
                    cache[key] = self._cut_one(f, room.streams[f.packet.stream], rate)
                out.append(cache[key])
        if not together:
            return out, None
        chosen = self._cut_layered(room, crowd, viewer, fits[crowd.rows])
        lengths = np.concatenate((np.fromiter(map(len, out), dtype="<u4", count=len(out)), crowd.lengths[chosen]))
        return out + list(map(crowd.variants.__getitem__, chosen.tolist())), lengths

    def _cut_layered(self, room: Room, crowd: _Crowd, viewer: Viewer, fits: np.ndarray) -> np.ndarray:
        """Which variant of each of the tick's fresh layered packets a viewer gets (indices
        into ``crowd.variants``; :meth:`_layers_for`, in arrays): the only packet of its stream
        this tick, so its layers depend only on what the viewer had."""
        count = len(crowd.streams)
        had = np.fromiter(map(viewer.layers.get, crowd.streams, repeat(0, count)), dtype=np.int64, count=count)
        keep = np.where(crowd.keyframes | (had == 0), fits, np.minimum(fits, had))
        for i in np.nonzero(keep < fits)[0].tolist():  # a layer may come back where it restarts
            f = crowd.layered[i]
            keep[i] = self._layers_for(viewer, f, room.streams[f.packet.stream], int(fits[i]))
        viewer.layers.update(zip(crowd.streams, keep.tolist()))
        return np.arange(count) * crowd.width + keep - 1

    @staticmethod
    def _layers_for(viewer: Viewer, f: Forward, state: StreamState, fits: int) -> int:
        """The layers of a layered stream's packet a viewer gets: the ``fits`` whose rate fits
        its share (at least the base), more than it had only from a keyframe or a packet where
        the next layer restarts (a layer it missed has lost its prediction's history)."""
        stream = f.packet.stream
        had = viewer.layers.get(stream)
        keep = fits if f.packet.keyframe or had is None else min(fits, had)
        if keep < fits:
            if f.layer_starts is None:
                try:
                    f.layer_starts = state.codec.layer_starts(f.packet.payload)
                except MocodecError:
                    f.layer_starts = []
            starts = f.layer_starts
            while keep < min(fits, len(starts)) and starts[keep]:
                keep += 1
        viewer.layers[stream] = keep
        return keep

    @staticmethod
    def _resent(viewer: Viewer, f: Forward) -> bytes:
        """A packet a viewer asked for again: a layered one with the layers the viewer gets now
        (all, without a budget), anything else whole."""
        if f.layer_ends is None or viewer.budget <= 0:
            return f.data
        return Relay._drop_layers(f, min(viewer.layers.get(f.packet.stream, 1), len(f.layer_ends)))

    @staticmethod
    def _drop_layers(f: Forward, keep: int) -> bytes:
        assert f.layer_ends is not None
        if keep >= len(f.layer_ends):
            return f.data
        return truncated(f.packet, f.data, f.layer_ends[keep - 1], len(f.layer_ends) - keep)

    @staticmethod
    def _layer_variants(f: Forward) -> list[bytes]:
        """A layered packet with 1, 2, ... of its layers (all of them: the packet)."""
        assert f.layer_ends is not None
        return [Relay._drop_layers(f, keep) for keep in range(1, len(f.layer_ends) + 1)]

    @staticmethod
    def _cut_one(f: Forward, state: StreamState, rate: float) -> bytes:
        try:
            if f.cutter is None:
                f.cutter = state.codec.packet_cutter(f.packet.payload, state.info.skeleton, f.cuts, state.info.fps)
            payload = f.cutter(rate)
        except Exception as e:  # noqa: BLE001 - a cut table that does not fit the payload: pass it whole
            log.warning("stream %d: packet %d not cut: %s", f.packet.stream, f.packet.sequence, e)
            f.cuts = None
            return f.data
        return f.data if payload is f.packet.payload else f.packet.with_payload(payload).to_bytes()


def on_ladder(bits_per_second: float) -> float:
    """A share rounded down to a ladder of LADDER_STEPS rates per octave, so viewers with
    nearly equal shares share one cut packet."""
    if bits_per_second < 1:
        return 0.0
    return 2.0 ** (math.floor(math.log2(bits_per_second) * LADDER_STEPS) / LADDER_STEPS)


class ConnectionGuard:
    """The relay's protocol factory around aiohttp's: counts connections before HTTP parses
    a byte, refuses those over ``max_connections`` (or ``max_connections_per_host`` from one
    address), and cuts one whose request has not reached a handler within
    ``request_timeout_s`` (slow openers hold a descriptor each; 300 of them once exhausted a
    relay's 256). Handlers mark their connection as served (:meth:`mark_served`)."""

    def __init__(self, factory, limits: Limits):
        self.factory, self.limits = factory, limits
        self.open: dict[object, str] = {}  # transport -> peer host
        self.per_host: dict[str, int] = {}
        self._served: set = set()  # the open transports whose request reached a handler
        self.refused = 0

    def __call__(self) -> asyncio.Protocol:
        return _Guarded(self, self.factory())

    def admit(self, transport) -> None:
        """Count a new connection, or refuse it (abort it) over a limit."""
        peer = transport.get_extra_info("peername")
        host = str(peer[0]) if isinstance(peer, tuple) and peer else "?"
        if (
            len(self.open) >= self.limits.max_connections
            or self.per_host.get(host, 0) >= self.limits.max_connections_per_host
        ):
            self.refused += 1
            transport.abort()
            return
        self.open[transport] = host
        self.per_host[host] = self.per_host.get(host, 0) + 1
        asyncio.get_running_loop().call_later(self.limits.request_timeout_s, self._check, transport)

    def mark_served(self, transport) -> None:
        if transport in self.open:
            self._served.add(transport)

    def release(self, transport) -> None:
        host = self.open.pop(transport, None)
        if host is None:
            return
        self._served.discard(transport)
        self.per_host[host] -= 1
        if not self.per_host[host]:
            del self.per_host[host]

    def _check(self, transport) -> None:
        if transport in self.open and transport not in self._served:
            self.refused += 1
            transport.abort()


class _Guarded(asyncio.Protocol):
    """aiohttp's protocol for one connection, admitted and released by the guard."""

    def __init__(self, guard: ConnectionGuard, inner: asyncio.Protocol):
        self.guard, self.inner, self.transport = guard, inner, None

    def connection_made(self, transport) -> None:
        self.transport = transport
        self.inner.connection_made(transport)
        self.guard.admit(transport)

    def data_received(self, data: bytes) -> None:
        self.inner.data_received(data)

    def eof_received(self):
        return self.inner.eof_received()

    def pause_writing(self) -> None:
        self.inner.pause_writing()

    def resume_writing(self) -> None:
        self.inner.resume_writing()

    def connection_lost(self, exc) -> None:
        self.guard.release(self.transport)
        self.inner.connection_lost(exc)


class PathOnlyAccessLogger(AbstractAccessLogger):
    """The access log without query strings: a token in ``?token=`` must not reach a log."""

    def log(self, request, response, time_s: float) -> None:
        self.logger.info("%s %s %s %d %.3fs", request.remote, request.method, request.path, response.status, time_s)


async def start(relay: Relay, host: str, port: int) -> tuple[web.AppRunner, asyncio.AbstractServer]:
    """The relay listening on ``host:port`` (0: any free port) behind its
    :class:`ConnectionGuard`; stop with ``server.close()`` and ``runner.cleanup()``."""
    runner = web.AppRunner(relay.app(), access_log_class=PathOnlyAccessLogger)
    await runner.setup()
    relay.guard = ConnectionGuard(runner.server, relay.limits)
    server = await asyncio.get_running_loop().create_server(relay.guard, host, port)
    return runner, server


def raise_descriptor_limit() -> None:
    """Raise the soft limit on open files to the hard one: every viewer holds a descriptor."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard == resource.RLIM_INFINITY or soft < hard:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard if hard != resource.RLIM_INFINITY else max(soft, 65536), hard))


def run(host: str, port: int, secret: str, limits: Limits | None = None, bus=None, tick_hz: float = TICK_HZ) -> None:
    """Serve until interrupted (``mocodec serve``)."""
    raise_descriptor_limit()

    async def serve() -> None:
        runner, server = await start(Relay(secret, limits, tick_hz, bus), host, port)
        try:
            await asyncio.Event().wait()
        finally:
            server.close()
            await runner.cleanup()

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(serve())
