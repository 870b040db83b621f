"""Shared test fixtures: the small clips in tests/data and, when present, ../shared/data."""

from __future__ import annotations

import os
import shutil
import socket
from pathlib import Path

import pytest
from hypothesis import settings

# No time limits in tests (shared machines, JIT compilation on first use); derandomised so a
# failure reproduces and CI time is bounded.
settings.register_profile("mocodec", deadline=None, derandomize=True, max_examples=60)
settings.load_profile("mocodec")

DATA = Path(__file__).parent / "data"
ROOT = Path(__file__).parent.parent


def _shared_data() -> Path | None:
    for candidate in (
        os.environ.get("MOCODEC_SHARED_DATA"),
        ROOT.parent / "shared" / "data",
        Path("/work/shared/data"),
    ):
        if candidate and (Path(candidate) / "cmu").is_dir():
            return Path(candidate)
    return None


SHARED = _shared_data()


def pytest_collection_modifyitems(items):
    """Tests that use the ``browser`` fixture are marked ``browser`` (and ``network``: they
    load pages from a server); those over every shared clip are ``slow``."""
    for item in items:
        if item.get_closest_marker("shared_data"):
            item.add_marker(pytest.mark.slow)
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.browser)
            item.add_marker(pytest.mark.network)
            item.add_marker(pytest.mark.xdist_group("browser"))  # one Chromium at a time (--dist loadgroup)


def free_port() -> int:
    """A loopback port nothing listens on (for servers the tests start)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def walk_bvh():
    from mocodec import load

    return load(DATA / "07_03.bvh")


@pytest.fixture(scope="session")
def walk_amc():
    from mocodec import load

    return load(DATA / "07_03.amc")


@pytest.fixture(scope="session")
def martial_amc():
    """Another subject and motion than the walk: training data for the walk's VQ codebooks."""
    from mocodec import load

    return load(DATA / "135_08.amc")


@pytest.fixture(scope="session")
def codebooks(martial_amc, tmp_path_factory):
    """{(codec id, predictive): codebook file} trained at 30 Hz on ``martial_amc`` (and, for the
    temporal ones, which serve any skeleton, on the BVH clip 09_02 too), never on the walk."""
    from mocodec import load
    from mocodec.codecs.shared import vqbook

    folder, out = tmp_path_factory.mktemp("codebooks"), {}
    clips = [martial_amc.resample(30.0), load(DATA / "09_02.bvh").resample(30.0)]
    for cid, kind, training in (("svq", "spatial", clips[:1]), ("tvq", "temporal", clips)):
        for predictive in (False, True):
            path = folder / f"{cid}_{int(predictive)}.mocvq"
            vqbook.train(kind, training, [16, 32, 64, 256], predictive=predictive).save(path)
            out[cid, predictive] = str(path)
    return out


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--enable-unsafe-swiftshader",
]


@pytest.fixture(scope="module")
def browser():
    """Debian's chromium, headless, driven by Playwright (skipped where either is missing)."""
    if CHROMIUM is None:
        pytest.skip("chromium is not installed (.ci/run installs Debian's chromium)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_FLAGS)
        yield b
        b.close()
