"""The study's web server (``mocodec study run``): the study page and its trial API.

    GET  /                 the study page
    GET  /api/trial        the current trial (the motions as joint positions), or {"done", "saved"}
    POST /api/answer       the participant's answer; the next trial follows from /api/trial

The results file is written (atomically) when the last answer comes in.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

from aiohttp import web

from mocodec.data import PAGES, THREE, three_is_there
from mocodec.errors import MocodecError
from mocodec.viewer.server import STATIC, three_missing
from mocodec.viewer.study import Study


def make_study_app(study: Study, out_dir: str | Path) -> web.Application:
    if not three_is_there():
        raise three_missing()
    lock = asyncio.Lock()
    saved: list[Path] = []
    shown: dict = {}

    async def page(request: web.Request) -> web.FileResponse:
        return web.FileResponse(STATIC / "study.html")

    async def trial(request: web.Request) -> web.Response:
        async with lock:
            if study.done:
                return web.json_response({"done": True, "saved": str(saved[0]) if saved else None})
            if "trial" not in shown:  # prepare each trial once
                shown["trial"] = await asyncio.to_thread(study.trial)
            return web.json_response(shown["trial"])

    async def answer(request: web.Request) -> web.Response:
        try:
            reply = await request.json()
        except ValueError:
            return web.json_response({"error": "the answer must be JSON"}, status=400)
        async with lock:
            try:
                study.answer(reply)
            except MocodecError as e:
                return web.json_response({"error": str(e)}, status=400)
            shown.clear()
            if study.done and not saved:
                saved.append(study.save(out_dir))
            return web.json_response({"done": study.done, "saved": str(saved[0]) if saved else None})

    app = web.Application()
    app.router.add_get("/", page)
    app.router.add_get("/api/trial", trial)
    app.router.add_post("/api/answer", answer)
    app.router.add_static("/static", STATIC)
    app.router.add_static("/vendor", THREE)
    app.router.add_static("/shared", PAGES)
    return app
