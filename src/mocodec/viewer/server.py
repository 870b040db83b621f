"""The viewer's web server (``mocodec view``): the page, its three.js, and a small JSON API.

    GET  /                 the page
    GET  /static/...       its script and style; /vendor/... the three.js in the package (no CDN: works offline); and
                           mocodec's JavaScript decoder (/static/decoder/, a link to js/src)
    GET  /api/state        the clip, its decoded version and the numbers (session.ViewSession.state)
    GET  /api/codecs       every codec and its knobs
    POST /api/encode       {"codec": id, "knobs": {...}, "target": ["ratio", 40] | null}: re-encode,
                           then the new state; a bad codec, knob or target answers 400 with the reason
    GET  /api/relay        {"relay": "ws://HOST:PORT" | null}: the relay the page joins itself to
                           watch a room (?room=R&token=T), decoding every stream in the browser

Encoding runs in a worker thread, so the page stays served while a slow codec works.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

from aiohttp import web

from mocodec.data import PAGES, THREE, three_is_there
from mocodec.errors import MocodecError
from mocodec.formats.pagejson import Mannequins
from mocodec.viewer.session import ViewSession, codec_menu

STATIC = Path(__file__).with_name("static")
DECODER = STATIC / "decoder"  # mocodec's JavaScript decoder (a link to js/src in a checkout)
BODIES_KEPT = 16  # live avatars' mannequins kept, by their request


def three_missing() -> MocodecError:
    return MocodecError(f"three.js is not in the package ({THREE}): reinstall mocodec, or run `make vendor`")


def make_app(session: ViewSession | None, relay_url: str | None = None) -> web.Application:
    """The viewer's application: of a clip (``session``), of a relay's rooms, or both."""
    if not three_is_there():
        raise three_missing()
    lock = asyncio.Lock()

    def no_clip() -> web.Response:
        return web.json_response({"error": "no clip: start the viewer with a FILE"}, status=404)

    async def index(request: web.Request) -> web.FileResponse:
        return web.FileResponse(STATIC / "index.html")

    async def state(request: web.Request) -> web.Response:
        return web.json_response(session.state()) if session else no_clip()

    async def relay(request: web.Request) -> web.Response:
        return web.json_response({"relay": relay_url})

    async def codecs(request: web.Request) -> web.Response:
        return web.json_response(codec_menu())

    async def encode(request: web.Request) -> web.Response:
        if session is None:
            return no_clip()
        try:
            body = await request.json()
            codec_id = str(body["codec"])
            knobs = {str(k): v for k, v in (body.get("knobs") or {}).items()}
            target = body.get("target")
            target = (str(target[0]), float(target[1])) if target else None
        except (ValueError, KeyError, TypeError, IndexError, json.JSONDecodeError):
            return web.json_response(
                {"error": 'expected {"codec": id, "knobs": {...}, "target": [kind, value]}'}, status=400
            )
        async with lock:  # one encode at a time; the session holds one result
            try:
                await asyncio.to_thread(session.code, codec_id, knobs, target)
            except MocodecError as e:
                return web.json_response({"error": str(e)}, status=400)
        return web.json_response(session.state())

    async def body(request: web.Request) -> web.Response:
        """A live avatar's mannequin, made here from its stream header's skeleton (the page
        decodes the motion itself); kept for the next avatar of the same kind."""
        text = await request.text()
        if text not in bodies:
            try:
                await asyncio.to_thread(bodies.make, text)
            except MocodecError as e:
                return web.json_response({"error": str(e)}, status=400)
        return web.json_response(bodies[text])

    bodies = Mannequins(BODIES_KEPT)
    app = web.Application()
    app.router.add_get("/", index)
    app.router.add_post("/api/mannequin", body)
    app.router.add_get("/api/state", state)
    app.router.add_get("/api/codecs", codecs)
    app.router.add_post("/api/encode", encode)
    app.router.add_get("/api/relay", relay)
    if DECODER.is_dir():  # before /static, whose files do not follow links out of it
        app.router.add_static("/static/decoder", DECODER.resolve())
    app.router.add_static("/static", STATIC)
    app.router.add_static("/vendor", THREE)
    app.router.add_static("/shared", PAGES)
    return app


def serve(app: web.Application, host: str, port: int, open_browser: bool, page: str = "") -> None:
    """Serve ``app`` until interrupted; open the default browser on the page (``page``: its
    query, such as ``?room=R&token=T``) unless told not to."""

    async def run() -> None:
        runner = web.AppRunner(app)
        await runner.setup()
        site = web.TCPSite(runner, host, port)
        await site.start()
        url = f"http://{host}:{runner.addresses[0][1]}/{page}"
        print(f"viewer on {url} (Ctrl-C to stop)", flush=True)
        if open_browser:
            import webbrowser

            webbrowser.open(url)
        try:
            await asyncio.Event().wait()
        finally:
            await runner.cleanup()

    try:
        asyncio.run(run())
    except KeyboardInterrupt:
        pass
