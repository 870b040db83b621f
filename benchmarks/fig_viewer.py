"""The pages' screenshots in the docs, in Debian's chromium driven by Playwright:

- docs/figures/viewer.png: the file viewer, 07_03 coded by spiht at 60:1, paused at frame 200;
- docs/figures/study.png: a 2AFC trial of the perceptual study (bodies side by side);
- docs/figures/live.png: the live page watching 20 kinwave-live avatars through a relay.

Run: `.venv/bin/python benchmarks/fig_viewer.py`."""

from __future__ import annotations

import contextlib
import json
import multiprocessing as mp
import subprocess
import sys
import tempfile
from pathlib import Path

from common import DATA, ROOT, free_port, options
from relay_load import publisher, templates, wait_port

FIGURES = ROOT / "docs" / "figures"
LIVE_AVATARS = 20
RELAY_SECRET = "figure-relay-secret"


@contextlib.contextmanager
def served(*args: str, page: bool = True):
    """``mocodec ARGS --port P`` running (``--no-browser`` too where it serves a page): its port."""
    port = free_port()
    quiet = ["--no-browser"] if page else []
    proc = subprocess.Popen(
        [sys.executable, "-m", "mocodec", *args, "--port", str(port), *quiet], stdout=subprocess.DEVNULL
    )
    try:
        wait_port(port)
        yield port
    finally:
        proc.terminate()
        proc.wait(10)


def viewer(browser) -> Path:
    with served("view", str(DATA / "07_03.bvh"), "--codec", "spiht", "--ratio", "60") as port:
        page = browser.new_page(viewport={"width": 1300, "height": 820})
        page.goto(f"http://127.0.0.1:{port}/")
        page.wait_for_function("window.viewerState && window.viewerState.ready", timeout=60_000)
        page.fill("#scrub", "200")
        page.dispatch_event("#scrub", "input")
        page.wait_for_timeout(300)
        page.screenshot(path=str(FIGURES / "viewer.png"))
    return FIGURES / "viewer.png"


def study(browser) -> Path:
    with tempfile.TemporaryDirectory() as folder:
        config = Path(folder) / "study.json"
        config.write_text(json.dumps({"kind": "2afc", "clips": [str(DATA / "07_03.bvh")], "max_frames": 240}))
        with served("study", "run", str(config), "--out", folder, "--participant", "figure") as port:
            page = browser.new_page(viewport={"width": 1100, "height": 700})
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function("window.studyState && window.studyState.phase === 'choosing'", timeout=60_000)
            page.wait_for_timeout(1500)
            page.screenshot(path=str(FIGURES / "study.png"))
    return FIGURES / "study.png"


def live(browser) -> Path:
    from mocodec.stream import tokens

    with served("serve", "--secret", RELAY_SECRET, page=False) as relay_port:
        url, token = f"ws://127.0.0.1:{relay_port}", tokens.issue(RELAY_SECRET, "load")
        context = mp.get_context("spawn")
        sent = context.Queue()  # kept here: the sender unpickles it after start()
        sender = context.Process(
            target=publisher,
            args=(
                url,
                token,
                list(range(LIVE_AVATARS)),
                60.0,
                templates(("kinwave-live", 0.0, 1, 0.0), 0.5),
                sent,
            ),
        )
        sender.start()
        try:
            with served("view", "--relay", url) as port:
                page = browser.new_page(viewport={"width": 1300, "height": 760})
                page.goto(f"http://127.0.0.1:{port}/?room=load&token={token}")
                page.wait_for_function(
                    f"window.viewerState.live && window.viewerState.live.bodies >= {LIVE_AVATARS}", timeout=60_000
                )
                page.wait_for_timeout(1500)
                page.screenshot(path=str(FIGURES / "live.png"))
        finally:
            sender.terminate()
    return FIGURES / "live.png"


def main() -> None:
    options(__doc__)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path="/usr/bin/chromium",
            headless=True,
            args=["--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader"],
        )
        for make in (viewer, study, live):
            print(make(browser))
        browser.close()


if __name__ == "__main__":
    main()
