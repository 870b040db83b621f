"""A wheel built from a clean checkout (``pip wheel .``, the way ``pip install`` builds one from a
repository or an index) installs into a fresh venv and serves a working viewer: three.js and the
JavaScript decoder are inside the package, and the page draws both figures in Chromium."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile

import pytest

from conftest import ROOT, free_port

pytestmark = [pytest.mark.slow, pytest.mark.network]


def clean_checkout(to) -> None:
    """The files git tracks (what a fresh clone has), nothing built or fetched."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        source, target = ROOT / name, to / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if source.is_symlink():
            target.symlink_to(source.readlink())
        elif source.is_file():
            shutil.copy2(source, target)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(the fresh venv's python, the wheel's file names)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    work = tmp_path_factory.mktemp("wheel")
    clean_checkout(work / "src")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", ".", "--no-deps", "-q", "-w", str(work / "dist")],
        cwd=work / "src",
        check=True,
    )
    (wheel,) = (work / "dist").glob("mocodec-*.whl")
    subprocess.run([sys.executable, "-m", "venv", str(work / "venv")], check=True)
    python = work / "venv" / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", f"{wheel}[view]"], check=True)
    return python, zipfile.ZipFile(wheel).namelist()


def test_the_wheel_carries_three_js_with_its_licence_and_the_decoder(installed):
    _, names = installed
    for name in (
        "mocodec/data/three/three.module.js",
        "mocodec/data/three/three.core.js",
        "mocodec/data/three/LICENSE",
        "mocodec/data/three/addons/controls/OrbitControls.js",
        "mocodec/viewer/static/decoder/index.js",
        "mocodec/stream/static/decoder/kinwave-live.js",
        "mocodec/data/sample_walk_02_02.bvh",
    ):
        assert name in names


def test_the_installed_viewer_draws_both_figures(installed, browser, tmp_path):
    from test_viewer import figure_pixels

    python, _ = installed
    where = subprocess.run(
        [str(python), "-c", "import mocodec; print(mocodec.__file__)"], capture_output=True, text=True, check=True
    )
    assert str(python.parent.parent) in where.stdout  # the wheel's copy, not the checkout
    clip = tmp_path / "walk.bvh"
    shutil.copy(ROOT / "src" / "mocodec" / "data" / "sample_walk_02_02.bvh", clip)
    port = free_port()
    proc = subprocess.Popen(
        [str(python), "-m", "mocodec", "view", str(clip), "--codec", "dpcm", "--port", str(port), "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    try:
        assert "viewer on" in proc.stdout.readline(), proc.stderr.read()
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"http://127.0.0.1:{port}/")
        page.wait_for_function("window.viewerState && window.viewerState.ready", timeout=60_000)
        left, right = figure_pixels(page.locator("#view canvas").screenshot())
        assert left > 200 and right > 200, (left, right)
        assert not errors, errors
        page.close()
    finally:
        proc.terminate()
        proc.wait(10)
