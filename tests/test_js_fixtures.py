"""The fixtures the JavaScript tests decode (tests/formats/live/) are what the live encoder and the
Python decoder make now: a change to the live format shows here first (then run
tests/js/make_fixtures.py, and the Node tests check the JavaScript decoder against it)."""

from __future__ import annotations

import sys

import pytest

from conftest import DATA

sys.path.insert(0, str(DATA.parent / "js"))
from make_fixtures import LIVE_CASES, live_fixture  # noqa: E402

LIVE = DATA.parent / "formats" / "live"


@pytest.mark.parametrize("case", LIVE_CASES, ids=[c[0] for c in LIVE_CASES])
def test_live_fixtures_are_current(case):
    for name, data in live_fixture(*case).items():
        assert (LIVE / name).read_bytes() == data, f"{name} is stale: run tests/js/make_fixtures.py"


def test_the_javascript_package_has_mocodecs_version():
    import json

    from mocodec.version import __version__

    package = json.loads((DATA.parent.parent / "js" / "package.json").read_text())
    assert package["version"] == __version__
