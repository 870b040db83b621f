"""The relay's server (``mocodec serve``): one aiohttp application on one port around a
:class:`~mocodec.stream.relay.core.RelayCore`.

``/ws`` is the WebSocket (``?room=R&role=publish|subscribe``, the token in ``Authorization:
Bearer T`` or ``&token=T``), ``/status`` a JSON summary, and anything else the static files of
the viewer. The server greets an accepted connection with ``{"welcome": room, "role": role}``
and closes a refused one with code 4003 and the reason. A sender's messages go to the core's
ingest (and to the NATS bus, when there is one, to reach the other relays); a viewer's to its
settings and repairs; every tick the core fills each viewer's outbox and the server sends it.
Connections are counted before HTTP parses anything (:class:`ConnectionGuard`), and one is
closed when its token expires. The protocol and limits: :mod:`mocodec.stream.relay`.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import resource
import time
from collections.abc import Callable
from pathlib import Path

from aiohttp import WSMsgType, web
from aiohttp.abc import AbstractAccessLogger

from mocodec.data import PAGES, THREE
from mocodec.errors import MocodecError
from mocodec.formats.pagejson import Mannequins
from mocodec.stream import framing, tokens
from mocodec.stream.relay.core import RelayCore
from mocodec.stream.relay.limits import BAD_MESSAGE, BAD_TOKEN, RATE_LIMIT, TICK_HZ, Bucket, Closing, Limits
from mocodec.stream.relay.rooms import Room, Viewer

log = logging.getLogger("mocodec.relay")

STATIC = Path(__file__).parent.parent / "static"  # the relay's pages (and the decoder: a link to js/src in a checkout)
MANNEQUINS_KEPT = 16  # the watch page's mannequins kept, by their request
MANNEQUINS_PER_S = 2.0  # new mannequins made a second (each costs tens of ms of this process)


async def messages_of(ws: web.WebSocketResponse, kind: WSMsgType, refusal: str):
    """The data of a connection's messages until it closes; Closing(``refusal``) at the first
    message of another kind."""
    async for msg in ws:
        if msg.type == WSMsgType.ERROR:
            return
        if msg.type != kind:
            raise Closing(BAD_MESSAGE, refusal)
        yield msg.data


class Relay:
    """The relay's server: ``secret`` checks room tokens, ``bus`` (a :class:`~mocodec.stream.bus.NatsBus`)
    shares rooms with other relays."""

    def __init__(self, secret: str, limits: Limits | None = None, tick_hz: float = TICK_HZ, bus=None):
        if not secret:
            raise MocodecError("the relay needs a secret (--secret) to check room tokens")
        self.secret = secret
        self.core = RelayCore(limits, tick_hz)
        self.limits = self.core.limits
        self.bus = bus
        self.guard: ConnectionGuard | None = None  # set by start()
        self.started = time.monotonic()
        self._changed: asyncio.Event | None = None  # made while someone waits (until)
        self._mannequins = Mannequins(MANNEQUINS_KEPT)
        self._mannequin_budget = Bucket(MANNEQUINS_PER_S, 5.0)

    async def until(self, ready: Callable[[], bool], timeout_s: float = 10.0) -> None:
        """Wait until ``ready()`` holds, checked after every message the relay takes in and
        every tick (TimeoutError after ``timeout_s``): how tests wait for the relay."""
        async with asyncio.timeout(timeout_s):
            while not ready():
                if self._changed is None:
                    self._changed = asyncio.Event()
                await self._changed.wait()

    def _notify(self) -> None:
        """Wake whoever waits in :meth:`until` (nothing to do, on the hot path, when nobody does)."""
        if self._changed is not None:
            self._changed.set()
            self._changed = None

    # ----- the application -------------------------------------------------------------------
    def app(self) -> web.Application:
        app = web.Application(middlewares=[self._served])
        app.router.add_get("/ws", self.handle_ws)
        app.router.add_get("/status", self.handle_status)
        app.router.add_get("/", self.handle_index)
        app.router.add_get("/watch", self.handle_watch)
        app.router.add_post("/mannequin", self.handle_mannequin)
        for route, folder in (
            ("/static", STATIC),
            ("/decoder", STATIC / "decoder"),
            ("/vendor", THREE),
            ("/shared", PAGES),
        ):
            if folder.is_dir():
                app.router.add_static(route, folder.resolve())
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

    async def handle_mannequin(self, request: web.Request) -> web.Response:
        """The watch page's avatars' mannequins (:class:`~mocodec.formats.pagejson.Mannequins` of
        a stream header's skeleton), kept for the next avatar of the kind; new ones are made at
        MANNEQUINS_PER_S at most, so requests cannot take the relay's time from its streams."""
        text = await request.text()
        if text not in self._mannequins:
            if not self._mannequin_budget.take():
                return web.json_response({"error": "too many new mannequins: try again shortly"}, status=429)
            try:
                await asyncio.to_thread(self._mannequins.make, text)
            except MocodecError as e:
                return web.json_response({"error": str(e)}, status=400)
        return web.json_response(self._mannequins[text])

    async def handle_status(self, request: web.Request) -> web.Response:
        """Totals only: a room's name is what its tokens are issued for."""
        return web.json_response({"uptime_s": round(time.monotonic() - self.started, 1), **self.core.status()})

    async def handle_ws(self, request: web.Request) -> web.WebSocketResponse:
        room_name = request.query.get("room", "")
        role = request.query.get("role", "subscribe")
        auth = request.headers.get("Authorization", "")
        token = auth[7:] if auth.startswith("Bearer ") else request.query.get("token", "")
        ws = web.WebSocketResponse(max_msg_size=self.limits.max_message_bytes, heartbeat=20.0)
        await ws.prepare(request)
        counters = self.core.counters
        try:
            if role not in ("publish", "subscribe"):
                raise Closing(BAD_MESSAGE, f"role must be publish or subscribe, got {role!r}")
            try:
                claims = tokens.verify(self.secret, token, room_name, role)
            except tokens.TokenError as e:
                raise Closing(BAD_TOKEN, str(e)) from None
            room = self.core.room(room_name)
            expiry = asyncio.get_running_loop().call_later(
                max(float(claims["exp"]) - time.time(), 0.0), self._expire, ws
            )
            try:
                if role == "publish":
                    await self._publisher(ws, room_name, room)
                else:
                    await self._viewer(ws, room_name, room, request.transport)
            finally:
                expiry.cancel()
        except Closing as c:
            counters["closed_rate" if c.code == RATE_LIMIT else "closed_bad"] += 1
            log.info("closing a connection: %s", c.reason)
            await ws.close(code=c.code, message=c.reason[:120].encode())
        self._notify()
        return ws

    def _expire(self, ws: web.WebSocketResponse) -> None:
        """A connection's token has expired: close it (a viewer stops receiving, a sender's
        streams end)."""
        self.core.counters["closed_expired"] += 1
        log.info("closing a connection: token expired")
        asyncio.ensure_future(ws.close(code=BAD_TOKEN, message=b"token expired"))

    # ----- senders -----------------------------------------------------------------------------
    async def _publisher(self, ws: web.WebSocketResponse, room_name: str, room: Room) -> None:
        messages = Bucket(self.limits.publish_messages_per_s, self.limits.burst_s)
        volume = Bucket(self.limits.publish_bytes_per_s, self.limits.burst_s)
        room.publishers += 1
        try:
            await ws.send_json({"welcome": room_name, "role": "publish"})
            async for data in messages_of(ws, WSMsgType.BINARY, "a sender sends binary packet batches only"):
                if not messages.take() or not volume.take(len(data)):
                    raise Closing(
                        RATE_LIMIT,
                        f"rate limit: over {self.limits.publish_messages_per_s:g} messages "
                        f"or {self.limits.publish_bytes_per_s:g} bytes per second",
                    )
                self.core.ingest(room, data, owner=ws)
                self._notify()
                if self.bus is not None:
                    await self.bus.publish(room_name, data)
        finally:  # streams left without their end: end them for everyone
            room.publishers -= 1
            ends = self.core.sender_left(room, ws)
            if ends is not None and self.bus is not None:
                await self.bus.publish(room_name, ends)

    async def _from_bus(self, room_name: str, data: bytes) -> None:
        """A message another relay took in (the NATS bridge)."""
        try:
            self.core.ingest(self.core.room(room_name), data, owner=self.bus)
        except Closing as c:
            log.warning("a bus message for room %s was refused: %s", room_name, c.reason)
        self._notify()

    # ----- viewers -----------------------------------------------------------------------------
    async def _viewer(self, ws: web.WebSocketResponse, room_name: str, room: Room, transport) -> None:
        ready = asyncio.Event()
        viewer = Viewer(abort=transport.abort, wake=ready.set)
        self.core.join(room, viewer)  # before the welcome: a viewer let in misses nothing
        self._notify()
        sender = None
        control = Bucket(self.limits.control_messages_per_s, self.limits.burst_s)
        repairs = Bucket(self.limits.repair_packets_per_s, self.limits.burst_s)
        try:
            await ws.send_json({"welcome": room_name, "role": "subscribe"})
            sender = asyncio.create_task(self._send_loop(ws, viewer, ready))
            async for text in messages_of(ws, WSMsgType.TEXT, "a viewer sends JSON settings only"):
                if not control.take():
                    raise Closing(
                        RATE_LIMIT, f"rate limit: over {self.limits.control_messages_per_s:g} settings per second"
                    )
                self.core.control(room, viewer, text, repairs)
                self._notify()
        finally:
            self.core.leave(room, viewer)
            if sender is not None:
                sender.cancel()

    @staticmethod
    async def _send_loop(ws: web.WebSocketResponse, viewer: Viewer, ready: asyncio.Event) -> None:
        """Send a viewer's batches as the core queues them."""
        while True:
            await ready.wait()
            ready.clear()
            try:
                while viewer.outbox:
                    for batch in viewer.outbox.popleft():
                        await (ws.send_str(batch) if isinstance(batch, str) else ws.send_bytes(batch))
            except (ConnectionError, RuntimeError):
                return

    # ----- ticks -------------------------------------------------------------------------------
    async def _tick_loop(self) -> None:
        next_tick = time.monotonic()
        while True:
            next_tick += self.core.tick_s
            await asyncio.sleep(max(next_tick - time.monotonic(), 0.0))
            self.core.tick()
            self._notify()


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


async def start(
    relay: Relay, host: str, port: int, reuse_port: bool = False
) -> tuple[web.AppRunner, asyncio.AbstractServer]:
    """The relay listening on ``host:port`` (0: any free port) behind its
    :class:`ConnectionGuard` (``reuse_port``: beside other workers on the same port); stop with
    ``server.close()`` and ``runner.cleanup()``."""
    runner = web.AppRunner(relay.app(), access_log_class=PathOnlyAccessLogger)
    await runner.setup()
    relay.guard = ConnectionGuard(runner.server, relay.limits)
    server = await asyncio.get_running_loop().create_server(relay.guard, host, port, reuse_port=reuse_port or None)
    return runner, server


#: The cyclic collector's thresholds in a relay process: a young collection every 50,000
#: allocations, the older ones rarely (docs/streaming.md: a full collection over the packets a
#: room keeps paused every stream for 100 ms and more, which set the relay's p99 latency).
COLLECTOR_THRESHOLDS = (50_000, 20, 1000)


def quiet_collector() -> None:
    """What is alive at start-up (modules, compiled code) leaves the collector's view, and its
    collections come seldom: a relay's packets hold no cycles, reference counting frees them."""
    gc.freeze()
    gc.set_threshold(*COLLECTOR_THRESHOLDS)


def raise_descriptor_limit() -> None:
    """Raise the soft limit on open files to the hard one: every viewer holds a descriptor."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard == resource.RLIM_INFINITY or soft < hard:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard if hard != resource.RLIM_INFINITY else max(soft, 65536), hard))


def run(
    host: str,
    port: int,
    secret: str,
    limits: Limits | None = None,
    bus=None,
    tick_hz: float = TICK_HZ,
    reuse_port: bool = False,
    listening: Callable[[], None] | None = None,
) -> None:
    """Serve until interrupted (``mocodec serve``; a worker of ``--workers`` with ``reuse_port``);
    ``listening`` is called once the port takes connections."""
    raise_descriptor_limit()
    framing.warm()
    quiet_collector()

    async def serve() -> None:
        runner, server = await start(Relay(secret, limits, tick_hz, bus), host, port, reuse_port)
        if listening is not None:
            listening()
        try:
            await asyncio.Event().wait()
        finally:
            server.close()
            await runner.cleanup()

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(serve())
