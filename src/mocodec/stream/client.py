"""Python clients of the relay: publish a clip as a live stream, watch a room and record it.

    async with connect(url, room, token, "publish") as ws: ...
    await publish_clip(url, room, token, motion, get_codec("spiht").at_rate(8000))
    motions = await record(url, room, token, frames=600, budget=3000)

A refused connection (bad or expired token, wrong room) raises :class:`RelayRefused` with the
relay's reason; a relay that cannot be reached raises it too, with the address.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import aiohttp
import numpy as np

from mocodec.codecs.base import Codec
from mocodec.errors import MocodecError, OutOfStepError
from mocodec.motion import Motion
from mocodec.stream.jitter import JitterBuffer
from mocodec.stream.live import TICK_HZ, LiveDecoder, clip_encoder, tick_frames
from mocodec.stream.packets import HEADER, MAX_REPAIRS, Packet, Reader, StreamInfo, pack_batch, split_batch

WELCOME_S = 10.0  # seconds a client waits for the relay's welcome


class RelayRefused(MocodecError):
    """The relay refused the connection, closed it, or could not be reached."""


def ws_url(url: str, room: str, role: str) -> str:
    from urllib.parse import urlencode

    if not url.startswith(("ws://", "wss://")):
        raise RelayRefused(f"the relay address must start with ws:// or wss://, got {url!r}")
    return f"{url.rstrip('/')}/ws?{urlencode({'room': room, 'role': role})}"


@contextlib.asynccontextmanager
async def connect(url: str, room: str, token: str, role: str, max_msg_size: int = 64 << 20):
    """An open WebSocket to the relay, past its welcome (RelayRefused if none comes within
    WELCOME_S: a relay that took the connection but never answers would hold the client)."""
    async with aiohttp.ClientSession() as session:
        try:
            ws = await session.ws_connect(
                ws_url(url, room, role),
                headers={"Authorization": f"Bearer {token}"},
                max_msg_size=max_msg_size,
                heartbeat=20.0,
            )
        except (aiohttp.ClientError, OSError) as e:
            raise RelayRefused(f"cannot reach the relay at {url}: {e}") from None
        async with ws:
            try:
                msg = await ws.receive(timeout=WELCOME_S)
            except TimeoutError:
                raise RelayRefused(f"the relay at {url} sent no welcome within {WELCOME_S:g} s") from None
            if msg.type != aiohttp.WSMsgType.TEXT or "welcome" not in msg.data:
                raise RelayRefused(f"the relay at {url} refused room {room!r}: {closed_reason(ws, msg)}")
            yield ws


def closed_reason(ws, msg) -> str:
    reason = msg.extra if msg is not None and msg.type == aiohttp.WSMsgType.CLOSE and msg.extra else ""
    return f"{reason or 'connection closed'} (code {ws.close_code})"


@dataclass
class PublishStats:
    frames: int = 0
    packets: int = 0
    bytes: int = 0
    seconds: float = 0.0


async def publish_clip(
    url: str,
    room: str,
    token: str,
    motion: Motion,
    codec: Codec,
    speed: float = 1.0,
    stream: int = 0,
    keyframe_s: float = 1.0,
    name: str = "",
) -> PublishStats:
    """Play ``motion`` into ``room`` as a live stream at its frame rate (``speed`` times faster):
    the frames of one tick (1/30 s of the clip) are pushed when their time comes, and their
    packets sent as one batch; the last packet ends the stream. ``name`` labels the avatar. The packets are those of
    :func:`~mocodec.stream.live.stream_clip`, whatever the timing."""
    if not speed > 0:
        raise MocodecError(f"speed must be positive, got {speed}")
    enc = clip_encoder(motion, codec, stream, keyframe_s, name)
    step = tick_frames(motion.fps)
    stats = PublishStats()
    async with connect(url, room, token, "publish") as ws:
        start = time.monotonic()

        async def send(packets: list[Packet]) -> None:
            if ws.closed:
                raise RelayRefused(f"the relay closed the stream: {closed_reason(ws, None)}")
            data = [p.to_bytes() for p in packets]
            await ws.send_bytes(pack_batch(data))
            stats.packets += len(data)
            stats.bytes += sum(map(len, data))

        await send([enc.header()])
        for a in range(0, motion.num_frames, step):
            b = min(a + step, motion.num_frames)
            await asyncio.sleep(max(start + b / (motion.fps * speed) - time.monotonic(), 0.0))
            packets = enc.push(motion.channels[a:b])
            if packets:
                await send(packets)
        await send(enc.close())
        stats.frames, stats.seconds = motion.num_frames, time.monotonic() - start
        await _drain(ws)
    return stats


async def _drain(ws) -> None:
    """Wait briefly for the relay to close on us (a refused stream says why), then go."""
    try:
        msg = await ws.receive(timeout=2.0 / TICK_HZ)
    except TimeoutError:
        return
    if msg.type == aiohttp.WSMsgType.CLOSE and ws.close_code and ws.close_code >= 4000:
        raise RelayRefused(f"the relay closed the stream: {closed_reason(ws, msg)}")


REPAIR_HOLD_S = 0.2  # how long a watcher's decoder waits for a missing packet (four requests)
REPAIR_AGAIN_S = 0.05  # a request not answered in this time is made again, then after twice as long


class Watcher:
    """What a viewer holds: a decoder per stream, the frames received so far (or, with
    ``keep=False``, only each stream's newest frame, for watching without end), and the bytes
    each stream has brought. A message, packet or stream header that does not parse is
    skipped and counted (``refused``): one stream's damage never stops the others. Its
    decoders wait ``hold_s`` for a missing packet; :meth:`repairs` says which to ask for."""

    def __init__(self, conceal: str = "hold", keep: bool = True, hold_s: float = REPAIR_HOLD_S):
        self.conceal, self.keep, self.hold_s = conceal, keep, hold_s
        self.asked: dict[tuple[int, int], tuple[float, float]] = {}  # (stream, sequence) -> (when asked, wait)
        self.decoders: dict[int, LiveDecoder] = {}
        self.frames: dict[int, list[np.ndarray]] = {}
        self.counts: dict[int, int] = {}
        self.bytes: dict[int, int] = {}
        self.refused = 0
        self.reader = Reader()
        self.jitter: dict[int, JitterBuffer] = {}  # each stream's frames, for a smooth playout (pose)

    def take(self, data: bytes) -> None:
        try:
            raws = split_batch(data)
        except MocodecError:
            self.refused += 1
            return
        for raw in raws:
            try:
                p = self.reader.read(raw)
                if p.kind == HEADER and p.stream not in self.decoders:
                    decoder = LiveDecoder(StreamInfo.from_payload(p.payload), self.conceal, hold_s=self.hold_s)
                    self.decoders[p.stream] = decoder
                    self.frames[p.stream], self.counts[p.stream], self.bytes[p.stream] = [], 0, 0
            except OutOfStepError:  # joined mid-stream: the stream starts for us at its next keyframe
                continue
            except MocodecError:
                self.refused += 1
                continue
            if p.kind == HEADER:
                continue
            dec = self.decoders.get(p.stream)
            if dec is not None:
                out = dec.push(p)
                if len(out) and dec.next_frame is not None:
                    buffer = self.jitter.setdefault(p.stream, JitterBuffer(dec.info.fps, out.shape[1]))
                    buffer.push(out, dec.next_frame - len(out), time.monotonic())
                self.bytes[p.stream] += len(raw)
                self.counts[p.stream] += len(out)
                if self.keep:
                    self.frames[p.stream].append(out)
                elif len(out):
                    self.frames[p.stream] = [out[-1:]]

    def repairs(self, now_s: float | None = None) -> list[list[int]]:
        """The ``[stream, sequence]`` pairs to ask the relay for now (its ``repair`` request):
        the packets the decoders wait for, each asked for again after REPAIR_AGAIN_S, then
        after twice as long each time (a slow round trip is not answered with a flood); at most
        MAX_REPAIRS (by stream, then sequence), so that none is taken for asked that was not."""
        now = time.monotonic() if now_s is None else now_s
        wanted = {(stream, seq) for stream, dec in self.decoders.items() for seq in dec.wanted()}
        self.asked = {key: asked for key, asked in self.asked.items() if key in wanted}
        due: list[list[int]] = []
        for key in sorted(wanted):
            at, wait = self.asked.get(key, (-math.inf, REPAIR_AGAIN_S / 2))
            if now - at >= wait and len(due) < MAX_REPAIRS:
                self.asked[key] = (now, 2 * wait)
                due.append(list(key))
        return due

    def pose(self, stream: int, now_s: float | None = None) -> np.ndarray | None:
        """The channels of ``stream`` to show now: played out smoothly at the stream's frame rate
        a little behind the arrivals (:class:`~mocodec.stream.jitter.JitterBuffer`)."""
        buffer = self.jitter.get(stream)
        return None if buffer is None else buffer.pose(time.monotonic() if now_s is None else now_s)

    def motion(self, stream: int) -> Motion:
        info = self.decoders[stream].info
        chunks = self.frames[stream]
        channels = np.vstack(chunks) if chunks else np.zeros((0, info.skeleton.num_channels))
        return Motion(info.skeleton, info.fps, channels)


async def record(
    url: str,
    room: str,
    token: str,
    frames: int | None = None,
    stream: int | None = None,
    budget: float = 0.0,
    camera=(0.0, 0.0, 0.0),
    timeout_s: float | None = None,
    conceal: str = "hold",
    joined: Callable[[], None] | None = None,
) -> dict[int, Motion]:
    """Watch ``room`` and return what each stream delivered: until ``stream`` (or, without it,
    the first stream seen) has ``frames`` frames or ends, or ``timeout_s`` passes. ``joined``
    is called once the relay has let the viewer in."""
    watcher = Watcher(conceal)
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    async with connect(url, room, token, "subscribe") as ws:
        if budget or any(camera):
            await ws.send_str(json.dumps({"budget": budget, "camera": list(camera)}))
        if joined is not None:
            joined()
        while True:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                break
            try:
                msg = await ws.receive(timeout=left)
            except TimeoutError:
                break
            if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                if ws.close_code and ws.close_code >= 4000:
                    raise RelayRefused(f"the relay closed the connection: {closed_reason(ws, msg)}")
                break
            if msg.type != aiohttp.WSMsgType.BINARY:
                continue
            watcher.take(msg.data)
            if asks := watcher.repairs():
                await ws.send_str(json.dumps({"repair": asks}))
            target = stream if stream is not None else next(iter(watcher.decoders), None)
            if target is None or target not in watcher.decoders:
                continue
            if (frames is not None and watcher.counts[target] >= frames) or watcher.decoders[target].ended:
                break
    return {k: watcher.motion(k)[:frames] for k in watcher.decoders}
