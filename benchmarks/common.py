"""Pieces every benchmark script uses: where the shared clips are, timing, and long clips made
by repeating a short one."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mocodec import Motion

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
SHARED = next((p for p in (ROOT.parent / "shared" / "data", Path("/work/shared/data")) if (p / "cmu").is_dir()), None)


def shared_sources(clips: int = 0) -> dict[str, list[Path]]:
    """The shared clips of each source (CMU BVH, CMU ASF/AMC, Bandai Namco), sorted, the first
    ``clips`` of each (0: all); exits with a message where ../shared/data is absent."""
    if SHARED is None:
        raise SystemExit("../shared/data is absent")
    sources = {
        "CMU BVH": sorted((SHARED / "cmu" / "bvh").glob("*.bvh")),
        "CMU ASF/AMC": sorted((SHARED / "cmu" / "asf_amc").glob("*.amc")),
        "Bandai Namco": sorted((SHARED / "bandai").rglob("*.bvh")),
    }
    return {name: paths[:clips] if clips else paths for name, paths in sources.items()}


def best_of(fn, repeats: int = 5) -> float:
    """The fastest of ``repeats`` runs of ``fn``, in seconds (the least disturbed by others)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def tile(motion: Motion, frames: int) -> Motion:
    """``motion`` repeated to exactly ``frames`` frames."""
    reps = -(-frames // motion.num_frames)
    return motion.with_channels(np.tile(motion.channels, (reps, 1))[:frames])


def options(doc: str | None) -> argparse.Namespace:
    """The command line of a script that takes no options but ``--help`` (which prints ``doc``)."""
    return argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
