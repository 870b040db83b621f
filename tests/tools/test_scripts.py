"""The scripts beside the package: every benchmark script is listed in docs/benchmarks.md, run by
``make bench`` (all but the one that needs Blender's Python) and answers ``--help``; the API
reference builds (``make api``)."""

from __future__ import annotations

import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import pytest

from conftest import ROOT

BENCHMARKS = ROOT / "benchmarks"
HELPERS = {"common", "baselines"}  # modules the scripts import
BY_HAND = {"blender_bvh_check"}  # runs in Blender's own Python
SCRIPTS = sorted(p.stem for p in BENCHMARKS.glob("*.py") if p.stem not in HELPERS)


def test_every_script_has_an_entry_and_a_place_in_make_bench():
    doc = (ROOT / "docs" / "benchmarks.md").read_text()
    table = doc[doc.index("## The scripts of `benchmarks/`") :]
    listed = set(re.findall(r"`([a-z0-9_]+)\.py`", table))
    make = (ROOT / "Makefile").read_text()
    recipe = make[make.index("\nbench:") : make.index("\nbench-suite:")]
    loop = set(re.search(r"for script in ([^;]*);", recipe, re.S).group(1).replace("\\", " ").split())
    run = {f"bench_{s}" for s in loop} | set(re.findall(r"benchmarks/([a-z0-9_]+)\.py", recipe))
    assert set(SCRIPTS) - listed == set()
    assert set(SCRIPTS) - BY_HAND - run == set()
    assert run <= set(SCRIPTS)  # nothing that is gone


@pytest.mark.slow
def test_every_script_answers_help():
    def help_of(name: str) -> tuple[str, int, str]:
        done = subprocess.run(
            [sys.executable, str(BENCHMARKS / f"{name}.py"), "--help"], capture_output=True, text=True, timeout=120
        )
        return name, done.returncode, done.stdout + done.stderr

    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(help_of, SCRIPTS))
    failed = [(name, out[-300:]) for name, code, out in results if code != 0 or "usage:" not in out]
    assert not failed


@pytest.mark.slow
def test_the_api_reference_builds(tmp_path):
    """``make api``: a page per public module, the codec interface's capabilities on its page."""
    pytest.importorskip("pdoc")
    done = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "api.py"), str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    base = (tmp_path / "mocodec" / "codecs" / "base.html").read_text()
    assert "packet_number" in base and "Coded" in base and "delay_frames" in base
    assert (tmp_path / "mocodec" / "stream" / "relay" / "core.html").is_file()
    assert "Warn" not in done.stderr and "UserWarning" not in done.stderr
