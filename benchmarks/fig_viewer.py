"""The viewer's screenshot in the docs (docs/figures/viewer.png): 07_03 coded by spiht at 60:1,
paused at frame 200, in Debian's chromium driven by Playwright. Run:
`.venv/bin/python benchmarks/fig_viewer.py`."""

from __future__ import annotations

import socket
import subprocess
import sys

from common import DATA, ROOT, options


def main() -> None:
    options(__doc__)
    from playwright.sync_api import sync_playwright

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mocodec",
            "view",
            str(DATA / "07_03.bvh"),
            "--codec",
            "spiht",
            "--ratio",
            "60",
            "--port",
            str(port),
            "--no-browser",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        server.stdout.readline()
        with sync_playwright() as pw:
            browser = pw.chromium.launch(
                executable_path="/usr/bin/chromium",
                headless=True,
                args=["--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader"],
            )
            page = browser.new_page(viewport={"width": 1300, "height": 820})
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function("window.viewerState && window.viewerState.ready")
            page.fill("#scrub", "200")
            page.dispatch_event("#scrub", "input")
            page.wait_for_timeout(300)
            out = ROOT / "docs" / "figures" / "viewer.png"
            page.screenshot(path=str(out))
            browser.close()
        print(out)
    finally:
        server.terminate()
        server.wait(10)


if __name__ == "__main__":
    main()
