"""The fuzz suite (slow tier): every target of tests/fuzzing.py in a child process under an
address-space limit, so an unbounded allocation fails as a MemoryError there instead of taking
the machine, seeded so a failure reproduces (``python tests/fuzzing.py TARGET SEED SECONDS``)."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from fuzzing import TARGETS

pytestmark = pytest.mark.slow
MEMORY_LIMIT = 4 << 30
SECONDS = 20


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_fuzz_target_ends_only_in_clean_errors(target):
    script = Path(__file__).with_name("fuzzing.py")
    done = subprocess.run(
        [sys.executable, str(script), target, "2026", str(SECONDS)],
        capture_output=True,
        text=True,
        timeout=10 * SECONDS + 120,
        preexec_fn=_limit_memory,
    )
    assert done.returncode in (0, 1), f"the fuzzer died ({done.returncode}): {done.stderr[-2000:]}"
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary["cases"] > 100
    assert not summary["failures"], "\n\n".join(summary["failures"])
