"""The viewer's live mode: a relay room watched from the page (``/?room=R&token=T``).

A browser cannot run the codecs, so the viewer's server joins the room as a viewer (with the
page's budget and camera), decodes every stream with the Python client, and sends the page,
at most 30 times a second, each avatar's newest pose as joint positions in metres and the bit
rate it has been getting over the last four seconds (a segment coder sends a packet about once
a second).
"""

from __future__ import annotations

import json
import time

import aiohttp
from aiohttp import web

from mocodec.errors import MocodecError
from mocodec.motion import Motion
from mocodec.stream.client import TICK_HZ, Watcher, connect

RATE_WINDOW_S = 4.0


def live_handler(relay_url: str | None):
    async def live(request: web.Request) -> web.WebSocketResponse:
        page = web.WebSocketResponse(heartbeat=20.0)
        await page.prepare(request)
        if relay_url is None:
            await page.send_json({"error": "this viewer has no relay: start it with --relay ws://HOST:PORT"})
            await page.close()
            return page
        room, token = request.query.get("room", ""), request.query.get("token", "")
        try:
            budget = float(request.query.get("budget", 0))
            camera = [float(v) for v in request.query.get("camera", "0,1.6,6").split(",")]
        except ValueError:
            await page.send_json({"error": "budget must be a number and camera x,y,z"})
            await page.close()
            return page
        try:
            async with connect(relay_url, room, token, "subscribe") as relay:
                await relay.send_str(json.dumps({"budget": budget, "camera": camera}))
                await _bridge(relay, page)
        except MocodecError as e:
            await page.send_json({"error": str(e)})
        await page.close()
        return page

    return live


async def _bridge(relay, page: web.WebSocketResponse) -> None:
    watcher = Watcher(keep=False)
    history: list[tuple[float, dict[int, int]]] = []
    last_sent = 0.0
    async for msg in relay:
        if page.closed:
            return
        if msg.type != aiohttp.WSMsgType.BINARY:
            if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.ERROR):
                return
            continue
        watcher.take(msg.data)
        now = time.monotonic()
        history = [(t, b) for t, b in history if now - t <= RATE_WINDOW_S] + [(now, dict(watcher.bytes))]
        if now - last_sent < 1.0 / TICK_HZ:
            continue
        last_sent = now
        await page.send_json(_update(watcher, history))


def _update(watcher: Watcher, history: list[tuple[float, dict[int, int]]]) -> dict:
    (t0, first), (t1, last) = history[0], history[-1]
    span = max(t1 - t0, 1e-3)
    streams = {}
    for k, dec in watcher.decoders.items():
        if not watcher.frames[k] or dec.ended:
            continue
        channels = watcher.pose(k)  # played out smoothly at the stream's frame rate
        motion = watcher.motion(k) if channels is None else Motion(dec.info.skeleton, dec.info.fps, channels[None])
        pose = motion.positions_m()[-1]
        streams[str(k)] = {
            "name": dec.info.name or f"stream {k}",
            "codec": dec.info.codec["codec"],
            "parents": [int(p) for p in dec.info.skeleton.parents],
            "positions": [round(float(v), 4) for v in pose.ravel()],
            "bits_per_second": 8 * (last.get(k, 0) - first.get(k, 0)) / span,
            "frames": watcher.counts[k],
            "in_sync": dec.in_sync,
        }
    return {"streams": streams}
