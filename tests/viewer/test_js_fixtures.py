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
    still_rig_fixture,
)

LIVE = DATA / "live"
MOC = DATA / "moc"


def _assert_current(path, made: bytes) -> None:
    """The stored fixture is what the code makes now: bytes and integers exactly; decoded floats
    and joint positions to the last bits the platform's sin, cos and arctan2 leave open (they
    differ by an ulp between CPUs: tests/codecs/test_golden.py)."""
    import gzip
    import json

    import numpy as np

    stale = f"{path.name} is stale: run tests/js/make_fixtures.py"
    stored = path.read_bytes()
    if path.name.endswith(".f64.gz"):
        old, new = (np.frombuffer(gzip.decompress(b), "<f8") for b in (stored, made))
        assert old.shape == new.shape and np.allclose(old, new, rtol=1e-14, atol=1e-12), stale
    elif path.suffix == ".json":
        old, new = json.loads(stored), json.loads(made)
        for key in ("positions", "original_positions"):
            if key in old or key in new:
                assert old[key].keys() == new[key].keys(), stale
                for frame, rows in old.pop(key).items():
                    assert np.allclose(rows, new[key][frame], rtol=0, atol=2e-9), stale
                new.pop(key)
        assert old == new, stale
    else:
        assert stored == made, stale


@pytest.mark.parametrize("case", LIVE_CASES, ids=[c[0] for c in LIVE_CASES])
def test_live_fixtures_are_current(case):
    for name, data in live_fixture(*case).items():
        _assert_current(LIVE / name, data)


@pytest.mark.parametrize("case", MOC_CASES, ids=[c[0] for c in MOC_CASES])
def test_moc_fixtures_are_current(case):
    for name, data in moc_fixture(*case).items():
        _assert_current(MOC / name, data)


def test_the_javascript_step_table_and_header_dictionary_are_current():
    assert (MOC / "steps.json").read_bytes() == steps_table()
    for name, data in still_rig_fixture().items():
        assert (MOC / name).read_bytes() == data, name
    module = DATA.parent.parent / "js" / "src" / "header-dict.js"
    assert module.read_text() == header_dictionary_module(), "js/src/header-dict.js is stale"


def test_the_javascript_package_has_mocodecs_version():
    import json

    from mocodec.version import __version__

    package = json.loads((DATA.parent.parent / "js" / "package.json").read_text())
    assert package["version"] == __version__


def test_the_javascript_packet_table_is_the_codecs_packet_numbers():
    """js/src/packets.js names codecs by the numbers of their classes' ``packet_number``."""
    import re

    from mocodec.codecs import packet_codecs

    source = (DATA.parent.parent / "js" / "src" / "packets.js").read_text()
    table = re.search(r"export const CODECS = \[([^\]]*)\]", source).group(1)
    assert tuple(re.findall(r"'([^']+)'", table)) == packet_codecs()
