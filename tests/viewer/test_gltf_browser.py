"""A glTF mocodec writes plays in Chromium through three.js's GLTFLoader: the bone count, the
clip's duration and the pose at one frame are what mocodec computes, and the skeleton is drawn."""

from __future__ import annotations

import functools
import json
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest

from conftest import DATA
from mocodec.data import THREE

FORMATS = DATA.parent / "formats"
FILES = {
    "/": DATA.parent / "js" / "gltf_page.html",
    "/walk.glb": FORMATS / "walk.glb",
    "/walk_mannequin.glb": FORMATS / "walk_mannequin.glb",
}


class _Handler(SimpleHTTPRequestHandler):
    """The page, the fixture, and the vendored three.js under /vendor/; nothing else."""

    def translate_path(self, path):
        path = path.split("?")[0]
        if path in FILES:
            return str(FILES[path])
        if path.startswith("/vendor/") and ".." not in path:
            return str(THREE / path[len("/vendor/") :])
        return str(THREE / "missing")

    def log_message(self, *args):
        pass


@pytest.fixture
def page_url():
    handler = functools.partial(_Handler, directory=str(THREE))
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()


def test_a_written_gltf_plays_in_chromium_with_its_bones_duration_and_pose(browser, page_url):
    expected = json.loads((FORMATS / "walk.glb.json").read_text())
    page = browser.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(page_url)
        page.wait_for_function("window.gltfCheck && window.gltfCheck.frames() > 5", timeout=30_000)
        assert not errors
        assert page.evaluate("window.gltfCheck.bones") == expected["joints"]
        assert page.evaluate("window.gltfCheck.duration") == pytest.approx(expected["duration_s"], abs=1e-6)
        assert page.evaluate("window.gltfCheck.mixerTime()") > 0  # it plays
        pose = page.evaluate(f"window.gltfCheck.poseAt({expected['pose_frame'] / expected['fps']})")
        worst = max(np.linalg.norm(np.subtract(pose[name], p)) for name, p in expected["positions_m"].items())
        assert worst < 1e-5
        assert page.evaluate("window.gltfCheck.drawnPixels()") > 50  # the skeleton is on the canvas
    finally:
        page.close()


def test_a_gltf_with_the_mannequin_plays_in_chromium_as_a_body(browser, page_url):
    """Written with --mesh mannequin, the same walk loads with one skinned mesh on its bones and
    covers many times the pixels of its skeleton's lines as it plays."""
    page = browser.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        drawn = {}
        for name in ("walk.glb", "walk_mannequin.glb"):
            page.goto(f"{page_url}?file={name}")
            page.wait_for_function("window.gltfCheck && window.gltfCheck.frames() > 5", timeout=30_000)
            drawn[name] = (page.evaluate("window.gltfCheck.skinned"), page.evaluate("window.gltfCheck.drawnPixels()"))
        assert not errors, errors
        assert drawn["walk.glb"][0] == 0 and drawn["walk_mannequin.glb"][0] == 1
        assert page.evaluate("window.gltfCheck.mixerTime()") > 0  # it plays
        assert drawn["walk_mannequin.glb"][1] > 5 * drawn["walk.glb"][1], drawn
    finally:
        page.close()
