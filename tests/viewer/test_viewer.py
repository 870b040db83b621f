"""The viewer: its JSON API, and the page in a real browser (Debian's chromium, Playwright)."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from aiohttp import web

from conftest import DATA, free_port
from mocodec import Motion, load
from mocodec.viewer.server import make_app
from mocodec.viewer.session import ViewSession

SECRET = "viewer-tests-relay-secret"  # at least the 16 characters serve asks for


def positions(b64: str, frames: int, joints: int) -> np.ndarray:
    return np.frombuffer(base64.b64decode(b64), dtype="<f4").reshape(frames, joints, 3)


@pytest.fixture(scope="module")
def session():
    s = ViewSession(load(DATA / "07_03.bvh")[:240], "07_03.bvh")
    s.code("dpcm", {"levels": 32})
    return s


def test_state_has_both_motions_errors_and_numbers(session):
    st = session.state()
    n, j = st["frames"], len(st["joints"])
    orig, dec = positions(st["original"], n, j), positions(st["decoded"], n, j)
    np.testing.assert_allclose(orig, session.motion.positions_m(), atol=1e-5)
    err = np.frombuffer(base64.b64decode(st["error_cm"]), dtype="<f4").reshape(n, j)
    np.testing.assert_allclose(err, np.linalg.norm(dec - orig, axis=2) * 100, rtol=1e-4, atol=1e-3)
    assert abs(err.max() - st["numbers"]["max_joint_error_cm"]) < 0.01
    assert st["numbers"]["ratio"] > 1 and st["config"]["codec"] == "dpcm"


@contextlib.asynccontextmanager
async def app_url(app: web.Application):
    """The app served on a free loopback port: its http:// address."""
    runner = web.AppRunner(app)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    try:
        yield f"http://127.0.0.1:{runner.addresses[0][1]}"
    finally:
        await runner.cleanup()


def test_encode_api_re_encodes_and_reports_bad_requests(session):
    async def go():
        import aiohttp

        async with app_url(make_app(session)) as url, aiohttp.ClientSession() as http:
            ok = await (await http.post(f"{url}/api/encode", json={"codec": "spiht", "target": ["ratio", 40]})).json()
            bad = await http.post(f"{url}/api/encode", json={"codec": "dpcm", "knobs": {"levels": "many"}})
            junk = await http.post(f"{url}/api/encode", data=b"not json")
            menu = await (await http.get(f"{url}/api/codecs")).json()
            return ok, bad.status, (await bad.json())["error"], junk.status, menu

    ok, bad_status, bad_error, junk_status, menu = asyncio.run(go())
    assert ok["config"]["codec"] == "spiht" and abs(ok["numbers"]["ratio"] - 40) < 0.02 * 40
    assert bad_status == 400 and "levels" in bad_error and junk_status == 400
    assert {"kinwave", "spiht", "dpcm"} <= {c["id"] for c in menu}


@contextlib.contextmanager
def viewer_process(*args):
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "mocodec", "view", *args, "--port", str(port), "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        assert "viewer on" in line, proc.stderr.read()
        yield f"http://127.0.0.1:{port}/"
    finally:
        proc.terminate()
        proc.wait(10)


def figure_pixels(png: bytes) -> tuple[int, int]:
    """Dark (figure) pixels in the left and right halves of a screenshot of the 3-D view."""
    from io import BytesIO

    from matplotlib import image

    img = image.imread(BytesIO(png), format="png")[:, :, :3]
    dark = img.sum(axis=2) < 1.6  # bones and joints on the light background and grid
    half = img.shape[1] // 2
    return int(dark[:, :half].sum()), int(dark[:, half:].sum())


def opened(browser, url: str):
    """The viewer's page at ``url``, ready: the page, the list its errors go to, and its state."""
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_function("window.viewerState && window.viewerState.ready", timeout=30_000)
    return page, errors, page.evaluate("fetch('/api/state').then(r => r.json())")


def test_the_page_plays_both_figures_and_shows_the_servers_numbers(browser, tmp_path):
    with viewer_process(str(DATA / "07_03.bvh"), "--codec", "dpcm", "--levels", "32") as url:
        page, errors, state = opened(browser, url)
        numbers = state["numbers"]
        assert page.inner_text("#n-ratio") == f"{numbers['ratio']:.2f} : 1"
        assert page.inner_text("#n-max") == f"{numbers['max_joint_error_cm']:.3f} cm"
        assert page.inner_text("#n-vpsnr") == f"{numbers['vpsnr_db']:.2f} dB"
        page.click("#play")
        page.wait_for_timeout(600)
        assert page.evaluate("window.viewerState.playing") and page.evaluate("window.viewerState.frame") > 0
        shot = page.locator("#view canvas").screenshot()
        (tmp_path / "viewer.png").write_bytes(shot)
        left, right = figure_pixels(shot)
        assert left > 200 and right > 200, (left, right)  # the original and the decoded figure
        page.click("#play")
        frame = page.evaluate("window.viewerState.frame")
        page.wait_for_timeout(300)
        assert page.evaluate("window.viewerState.frame") == frame  # paused
        page.fill("#scrub", "100")
        page.dispatch_event("#scrub", "input")
        assert page.evaluate("window.viewerState.frame") == 100
        # another codec and target from the page: the server re-encodes, the numbers follow
        page.select_option("#codec", "spiht")
        page.select_option("#target-kind", "ratio")
        page.fill("#target-value", "40")
        page.click("#apply")
        page.wait_for_function(
            "window.viewerState.ready && window.viewerState.numbers.codec.startsWith('spiht')", timeout=60_000
        )
        ratio = float(page.inner_text("#n-ratio").split()[0])
        assert abs(ratio - 40) < 0.8
        assert not errors, errors
        page.close()


def test_view_refuses_a_bad_file_with_one_line(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT hip\n{\n")
    out = subprocess.run(
        [sys.executable, "-m", "mocodec", "view", str(bad), "--no-browser"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and "bad.bvh" in out.stderr and "Traceback" not in out.stderr


def test_the_page_watches_a_relay_room_live(browser):
    """The page joins the relay itself and decodes in the browser: two kinwave-live avatars (one
    with two layers) are drawn with their bit rates; a dpcm stream, which has no decoder there, is
    listed as such. Both avatars are drawn as bodies, their mannequin made once by the viewer's
    server, which has no route that decodes."""
    from mocodec.codecs import get_codec
    from mocodec.stream import tokens
    from mocodec.stream.client import publish_clip

    relay_port = free_port()
    relay = subprocess.Popen(
        [sys.executable, "-m", "mocodec", "serve", "--port", str(relay_port), "--secret", SECRET],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert "relay on" in relay.stdout.readline()
        relay_url = f"ws://127.0.0.1:{relay_port}"
        tok = tokens.issue(SECRET, "lobby")
        with viewer_process("--relay", relay_url) as url:
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{url}?room=lobby&token={tok}")
            page.wait_for_function("window.viewerState && window.viewerState.ready", timeout=30_000)
            clip = load(DATA / "07_03.bvh")
            walk = Motion(clip.skeleton, clip.fps, np.vstack([clip.channels] * 3))  # 10 s: still live when checked
            codecs = {0: get_codec("kinwave-live"), 1: get_codec("kinwave-live", layers=2), 2: get_codec("dpcm")}

            async def publish():
                await asyncio.gather(
                    *(
                        publish_clip(relay_url, "lobby", tok, walk, codec, speed=1.0, stream=s, name=f"walker {s}")
                        for s, codec in codecs.items()
                    )
                )

            import threading

            sender = threading.Thread(target=asyncio.run, args=(publish(),))
            sender.start()
            page.wait_for_function("window.viewerState.live.streams === 2", timeout=30_000)
            page.wait_for_function("window.viewerState.live.bodies === 2", timeout=30_000)  # as bodies
            page.wait_for_timeout(1500)
            bits = page.evaluate("window.viewerState.live.bits")
            assert len(bits) == 2 and all(b > 0 for b in bits.values()), bits
            assert page.evaluate("window.viewerState.live.others") == {"2": "dpcm"}
            table = page.inner_text("#avatars")
            assert "walker 0" in table and "kinwave-live" in table and "not decodable in the browser" in table
            assert "(resync)" not in table  # nothing is lost on the way: both decoders follow their streams
            shot = page.locator("#view canvas").screenshot()
            assert sum(figure_pixels(shot)) > 300
            assert page.evaluate("fetch('/api/live').then(r => r.status)") == 404
            sender.join()
            assert not errors, errors
            page.close()
        bad = subprocess.run(
            [sys.executable, "-m", "mocodec", "view", "--no-browser"], capture_output=True, text=True, timeout=60
        )
        assert bad.returncode == 2 and "needs a FILE" in bad.stderr
    finally:
        relay.terminate()
        relay.wait(10)


def _pixels(png: bytes) -> np.ndarray:
    from io import BytesIO

    from matplotlib import image

    return image.imread(BytesIO(png), format="png")[:, :, :3]


def test_the_page_shows_bodies_painted_with_the_error(browser):
    """By default the page draws the mannequin: the bodies cover several times the screen area
    of the stick figures, and at the frame of the clip's largest error the decoded body is red
    where that joint is (the heatmap on its surface) and the original nowhere."""
    with viewer_process(str(DATA / "07_03.bvh"), "--codec", "dpcm", "--levels", "8") as url:
        page, errors, state = opened(browser, url)
        n, j = state["frames"], len(state["joints"])
        error = np.frombuffer(base64.b64decode(state["error_cm"]), dtype="<f4").reshape(n, j)
        frame, joint = np.unravel_index(int(error.argmax()), error.shape)
        page.fill("#scrub", str(frame))
        page.dispatch_event("#scrub", "input")
        canvas = page.locator("#view canvas")
        bodies = _pixels(canvas.screenshot())
        page.select_option("#figures", "sticks")
        sticks = _pixels(canvas.screenshot())
        page.select_option("#figures", "bodies")

        def covered(img):
            return int((np.abs(img - img[2, 2]).sum(axis=2) > 0.25).sum())  # off the background colour

        assert covered(bodies) > 3 * covered(sticks), (covered(bodies), covered(sticks))
        shift = np.array([page.evaluate("viewerState.decodedShift()"), 0.0, 0.0])
        where = positions(state["decoded"], n, j)[frame, joint] + shift
        x, y = page.evaluate("([x, y, z]) => viewerState.project(x, y, z)", [float(v) for v in where])
        red = (bodies[:, :, 0] > 0.55) & (bodies[:, :, 1] < 0.35) & (bodies[:, :, 2] < 0.35)
        rows, cols = np.nonzero(red)
        assert rows.size, "no red on the decoded body"
        assert np.hypot(cols - x, rows - y).min() < 40  # red at the worst joint
        roots = positions(state["original"], n, j)[frame, 0], positions(state["decoded"], n, j)[frame, 0] + shift
        left, right = (
            page.evaluate("([x, y, z]) => viewerState.project(x, y, z)[0]", [float(v) for v in r]) for r in roots
        )
        assert not red[:, : int((left + right) / 2)].any()  # none on the original, on the left
        assert not errors, errors
        page.close()


def test_a_live_avatars_mannequin_is_made_from_its_stream_header(walk_bvh):
    """What the live page asks of the viewer's server: the mannequin of a stream header's
    skeleton, every level of detail, the same mesh as the file viewer's; a request that is not
    such a skeleton gets a one-line error and status 400."""
    from mocodec.formats.container import skeleton_to_dict
    from mocodec.formats.pagejson import body_of

    doc = {"skeleton": skeleton_to_dict(walk_bvh.skeleton), "frame": [0.0] * walk_bvh.num_channels}

    async def go():
        import aiohttp

        async with app_url(make_app(None)) as base, aiohttp.ClientSession() as http:
            url = f"{base}/api/mannequin"
            ok = await (await http.post(url, json=doc)).json()
            bad = [
                await http.post(url, data=body)
                for body in (b"not json", b"[1, 2]", b'{"skeleton": {"joints": 7}}', b"[" * 100_000)
            ]
            short = await http.post(url, json={**doc, "frame": [0.0, 1.0]})
            return ok, [(r.status, (await r.json())["error"]) for r in [*bad, short]]

    with ThreadPoolExecutor(1) as thread:  # a thread of its own: the browser tests' loop may run in this one
        ok, refused = thread.submit(asyncio.run, go()).result()
    assert len(ok["levels"]) == 3 and ok["levels"][0] == body_of(walk_bvh.skeleton, np.zeros(walk_bvh.num_channels))
    assert all(status == 400 and "\n" not in error for status, error in refused), refused
    assert "frame must be" in refused[-1][1]


def test_a_skeleton_without_bones_is_shown_as_dots():
    """A motion whose skeleton has no bone to build a body on (a single joint) still opens: the
    page gets no mannequin and draws its stick figure."""
    from mocodec.skeleton import POSITION_CHANNELS, Joint, Skeleton

    point = Skeleton((Joint(name="marker", parent=-1, offset=(0.0, 0.0, 0.0), channels=POSITION_CHANNELS),), 100.0)
    motion = Motion(point, 30.0, np.cumsum(np.ones((20, 3)), axis=0))
    state = ViewSession(motion, "marker").state()
    assert state["body"] is None and state["frames"] == 20
