"""Scale-out: relays share rooms over NATS (``mocodec serve --bus nats://host:4222``).

Each relay publishes what its senders send to the subject ``mocodec.room.<room>`` (the room
name base64url-coded, so any name is a valid subject token) and takes in what the other relays
publish there, as if a local sender had sent it. The connection is made with ``no_echo``, so a
relay never receives its own messages back.
"""

from __future__ import annotations

import asyncio
import base64
import logging
from collections.abc import Awaitable, Callable
from typing import Any

from mocodec.errors import MocodecError
from mocodec.extras import require

PREFIX = "mocodec.room."
CONNECT_S = 10.0  # seconds a relay tries to reach its NATS server at start (then it reconnects for ever)
log = logging.getLogger("mocodec.relay")


def subject(room: str) -> str:
    return PREFIX + base64.urlsafe_b64encode(room.encode()).rstrip(b"=").decode()


def room_of(subject_name: str) -> str:
    token = subject_name[len(PREFIX) :]
    return base64.urlsafe_b64decode(token + "=" * (-len(token) % 4)).decode()


class NatsBus:
    def __init__(self, url: str):
        if not url.startswith(("nats://", "tls://")):
            raise MocodecError(f"--bus must be a nats:// address, got {url!r}")
        self.url = url
        self.nc: Any = None
        self.stopping = False

    async def start(self, deliver: Callable[[str, bytes], Awaitable[None]]) -> None:
        nats = require("nats", "stream", "a relay with --bus")
        from nats.errors import NoServersError

        async def on_message(msg) -> None:
            try:
                room = room_of(msg.subject)
            except ValueError:
                log.warning("ignoring a bus message on %s", msg.subject)
                return
            await deliver(room, msg.data)

        async def on_error(e: Exception) -> None:
            log.warning("NATS %s: %s", self.url, e or type(e).__name__)

        async def on_disconnect() -> None:
            if not self.stopping:
                log.warning("NATS %s: disconnected, reconnecting", self.url)

        try:  # (the client applies its reconnect attempts, for ever, to the first connection too)
            async with asyncio.timeout(CONNECT_S):
                self.nc = await nats.connect(
                    servers=[self.url],
                    no_echo=True,
                    connect_timeout=5,
                    max_reconnect_attempts=-1,
                    allow_reconnect=True,
                    error_cb=on_error,
                    disconnected_cb=on_disconnect,
                )
        except TimeoutError:
            raise MocodecError(f"cannot reach the NATS server at {self.url} within {CONNECT_S:g} s") from None
        except (NoServersError, OSError) as e:
            raise MocodecError(f"cannot reach the NATS server at {self.url}: {e}") from None
        await self.nc.subscribe(PREFIX + "*", cb=on_message)

    async def publish(self, room: str, data: bytes) -> None:
        await self.nc.publish(subject(room), data)

    async def stop(self) -> None:
        if self.nc is None:
            return
        self.stopping = True
        try:
            await self.nc.drain()
        except Exception:  # noqa: BLE001 - the server is gone or reconnecting: just close
            await self.nc.close()
