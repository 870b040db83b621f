"""The fixtures the JavaScript tests decode (tests/data/live/, tests/data/moc/) and the
JavaScript copy of the .moc header dictionary are what the encoders and the Python decoders make
now: a change to the live or kinwave format shows here first (then run tests/js/make_fixtures.py,
and the Node tests check the JavaScript decoders against it)."""

from __future__ import annotations

import sys

import pytest

from conftest import DATA

sys.path.insert(0, str(DATA.parent / "js"))
from make_fixtures import (  # noqa: E402
    LIVE_CASES,
    MOC_CASES,
    header_dictionary_module,
    live_fixture,
    moc_fixture,
    steps_table,
)

LIVE = DATA / "live"
MOC = DATA / "moc"


@pytest.mark.parametrize("case", LIVE_CASES, ids=[c[0] for c in LIVE_CASES])
def test_live_fixtures_are_current(case):
    for name, data in live_fixture(*case).items():
        assert (LIVE / name).read_bytes() == data, f"{name} is stale: run tests/js/make_fixtures.py"


@pytest.mark.parametrize("case", MOC_CASES, ids=[c[0] for c in MOC_CASES])
def test_moc_fixtures_are_current(case):
    for name, data in moc_fixture(*case).items():
        assert (MOC / name).read_bytes() == data, f"{name} is stale: run tests/js/make_fixtures.py"


def test_the_javascript_step_table_and_header_dictionary_are_current():
    assert (MOC / "steps.json").read_bytes() == steps_table()
    module = DATA.parent.parent / "js" / "src" / "header-dict.js"
    assert module.read_text() == header_dictionary_module(), "js/src/header-dict.js is stale"


def test_the_javascript_package_has_mocodecs_version():
    import json

    from mocodec.version import __version__

    package = json.loads((DATA.parent.parent / "js" / "package.json").read_text())
    assert package["version"] == __version__
