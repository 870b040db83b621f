"""The live page with a crowd: the JavaScript time of each animation frame (decoding since the
last frame, posing with the skin matrices; with --draw, drawing too) when the viewer's page
(`mocodec view --relay`, with `render=0` unless --draw) watches N kinwave-live avatars, as
bodies and then as stick figures, in headless Chromium.

    python benchmarks/bench_live_page.py [--avatars 100] [--seconds 6] [--draw]

The avatars replay the live stream of tests/data/07_03.bvh at random phases
(`relay_load.py`'s publishers, in two processes) through a relay on this machine. Prints the
median, 95th percentile and largest frame time over the last --seconds, and the avatars drawn
at each level of detail.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import subprocess
import sys
import time

import numpy as np

from common import free_port
from relay_load import publisher, templates, wait_port

SECRET = "bench-live-page-relay-secret"
PUBLISHERS = 2


def frame_times(page, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's JavaScript time (ms) over ``seconds``, and its parts: decoding, posing (with
    the skin matrices), drawing."""
    page.evaluate("window.viewerState.live.frameMs.length = 0; window.viewerState.live.partsMs.length = 0")
    page.wait_for_timeout(seconds * 1000)
    live = page.evaluate("({frames: viewerState.live.frameMs, parts: viewerState.live.partsMs})")
    return np.array(live["frames"]), np.array(live["parts"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--avatars", type=int, default=100)
    ap.add_argument("--seconds", type=float, default=6.0, help="measured time per rendering")
    ap.add_argument(
        "--draw",
        action="store_true",
        help="draw too (Chromium's software renderer then takes both cores here: the frame rate falls, "
        "and every frame decodes more)",
    )
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    from mocodec.stream import tokens

    relay_port, viewer_port = free_port(), free_port()
    serve = [sys.executable, "-m", "mocodec", "serve", "--port", str(relay_port), "--secret", SECRET]
    procs = [subprocess.Popen(serve)]
    try:
        wait_port(relay_port)
        url, token = f"ws://127.0.0.1:{relay_port}", tokens.issue(SECRET, "load")
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "mocodec", "view", "--relay", url, "--port", str(viewer_port), "--no-browser"],
                stdout=subprocess.DEVNULL,
            )
        )
        wait_port(viewer_port)
        template = templates(("kinwave-live", 0.0, 1, 0.0), 0.5)
        total = 3 * args.seconds + 30.0
        out = mp.get_context("spawn").Queue()
        senders = [
            mp.get_context("spawn").Process(
                target=publisher, args=(url, token, list(range(k, args.avatars, PUBLISHERS)), total, template, out)
            )
            for k in range(PUBLISHERS)
        ]
        for s in senders:
            s.start()
        with sync_playwright() as pw:
            browser = pw.chromium.launch(
                executable_path="/usr/bin/chromium", args=["--no-sandbox", "--enable-unsafe-swiftshader"]
            )
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.goto(f"http://127.0.0.1:{viewer_port}/?room=load&token={token}&render={int(args.draw)}")
            page.wait_for_function("window.viewerState && window.viewerState.ready", timeout=60_000)
            started = time.monotonic()
            page.wait_for_function(f"window.viewerState.live.bodies >= {args.avatars}", timeout=60_000, polling=200)
            print(f"{args.avatars} avatars drawn as bodies after {time.monotonic() - started:.1f} s")
            for rendering in ("bodies", "sticks"):
                page.evaluate(f"document.getElementById('figures').value = '{rendering}'")
                page.wait_for_timeout(500)
                ms, parts = frame_times(page, args.seconds)
                decode, pose, draw = np.median(parts, axis=0)
                print(
                    f"{rendering:7s}: {ms.size} frames, JavaScript per frame median {np.median(ms):.2f} ms "
                    f"(decoding {decode:.2f}, posing with the skin matrices {pose:.2f}, drawing {draw:.2f}), "
                    f"p95 {np.percentile(ms, 95):.2f} ms, max {ms.max():.2f} ms"
                )
            browser.close()
        for s in senders:
            s.terminate()
    finally:
        for p in procs:
            p.terminate()
            p.wait(10)


if __name__ == "__main__":
    main()
