"""Shared test fixtures: the small clips in tests/data and, when present, ../shared/data."""

from __future__ import annotations

import os
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
    for candidate in (os.environ.get("MOCODEC_SHARED_DATA"), ROOT.parent / "shared" / "data",
                      Path("/work/shared/data")):
        if candidate and (Path(candidate) / "cmu").is_dir():
            return Path(candidate)
    return None


SHARED = _shared_data()


@pytest.fixture(scope="session")
def walk_bvh():
    from mocodec import load

    return load(DATA / "07_03.bvh")


@pytest.fixture(scope="session")
def walk_amc():
    from mocodec import load

    return load(DATA / "07_03.amc")
