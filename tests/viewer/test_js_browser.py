"""A page the relay serves (/watch) joins a room with two live kinwave-live avatars, decodes them
in the page with mocodec's JavaScript decoder (no Python decoding anywhere in the loop) and draws
them; every decoded pose it shows is within the codec's bound of the clip that was published. A
page decodes a kinwave .moc file as the Python decoder does (the browser's own inflate, the
header's preset dictionary)."""

from __future__ import annotations

import asyncio
import subprocess
import sys
import threading

import numpy as np
import pytest

from conftest import DATA, free_port
from mocodec import load
from mocodec.motion import Motion

MOC_CASE = DATA / "moc" / "dummy-root-bind"
SECRET = "browser-tests-relay-secret"  # at least the 16 characters serve asks for


@pytest.fixture
def relay_port():
    """A relay (secret SECRET) on a free port, stopped after the test."""
    port = free_port()
    serve = [sys.executable, "-m", "mocodec", "serve", "--port", str(port), "--secret", SECRET]
    relay = subprocess.Popen(serve, stdout=subprocess.PIPE, text=True)
    try:
        assert "relay on" in relay.stdout.readline()
        yield port
    finally:
        relay.terminate()
        relay.wait(10)


def test_a_relay_page_decodes_and_draws_two_live_avatars(browser, relay_port):
    from mocodec.codecs import get_codec
    from mocodec.stream import tokens
    from mocodec.stream.client import publish_clip

    token = tokens.issue(SECRET, "lobby")
    page = browser.new_page(viewport={"width": 800, "height": 600})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"http://127.0.0.1:{relay_port}/watch?room=lobby&token={token}")
    page.wait_for_function("window.watch && window.watch.ready", timeout=30_000)
    clip = load(DATA / "07_03.bvh")
    walk = Motion(clip.skeleton, clip.fps, np.vstack([clip.channels] * 3))  # 10 s: still live when checked
    codecs = {0: get_codec("kinwave-live"), 1: get_codec("kinwave-live", layers=2, max_error_cm=0.5)}

    async def publish():
        await asyncio.gather(
            *(
                publish_clip(f"ws://127.0.0.1:{relay_port}", "lobby", token, walk, c, stream=s)
                for s, c in codecs.items()
            )
        )

    sender = threading.Thread(target=asyncio.run, args=(publish(),))
    sender.start()
    page.wait_for_function(
        "window.watch.avatars().length === 2 && window.watch.avatars().every(a => a.frames > 240)", timeout=30_000
    )
    avatars = page.evaluate("window.watch.avatars()")
    assert all(a["joints"] == len(walk.skeleton) and a["errors"] == 0 for a in avatars), avatars
    truth = walk.positions_m()
    for stream, bound_cm in ((0, 1.0), (1, 0.5)):
        frames = page.evaluate(f"window.watch.frames({stream})")
        assert len(frames) > 100
        for frame in frames[:: max(len(frames) // 12, 1)]:
            shown = np.array(page.evaluate(f"window.watch.positions({stream}, {frame})")).reshape(-1, 3)
            error_cm = np.linalg.norm(shown - truth[frame], axis=1).max() * 100
            assert error_cm <= bound_cm + 1e-6, (stream, frame, error_cm)
    page.wait_for_function("window.watch.bodies() === 2", timeout=30_000)  # each a body, from the relay's mannequin
    assert page.evaluate("window.watch.drawnPixels()") > 200
    assert not errors
    sender.join()
    page.close()


def test_a_page_decodes_a_moc_file_as_python_does(browser, relay_port):
    import base64
    import gzip
    import json

    page = browser.new_page()
    page.goto(f"http://127.0.0.1:{relay_port}/")
    data = base64.b64encode(MOC_CASE.with_suffix(".moc").read_bytes()).decode()
    decoded = page.evaluate(
        """async (text) => {
            const { decodeMoc } = await import('/decoder/index.js');
            const out = await decodeMoc(Uint8Array.from(atob(text), (c) => c.charCodeAt(0)));
            return { frames: out.frames, channels: Array.from(out.channels) };
        }""",
        data,
    )
    python = np.frombuffer(gzip.decompress(MOC_CASE.with_suffix(".f64.gz").read_bytes()), "<f8")
    meta = json.loads(MOC_CASE.with_suffix(".json").read_text())
    assert decoded["frames"] == meta["frames"] and python.size == meta["frames"] * meta["channels"]
    assert np.abs(np.array(decoded["channels"]) - python).max() <= 1e-9
    page.close()
