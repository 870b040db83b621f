"""The JavaScript .moc decoder on both sources: exactness against the Python decoder and speed.

    python benchmarks/bench_js_moc.py [--clips N] [--seconds S]

For the first N clips (sorted; 0 = all) of CMU BVH, CMU ASF/AMC and Bandai Namco, each coded by
kinwave at a max joint error of 1 cm: the Python decoder's channels are written beside the .moc
and ``node js/bench/moc.mjs`` decodes every file, reports its largest difference from them and
its speed (frames/s, one core, whole files with their header and skeleton, with and without
forward kinematics). The table gives per source the worst difference and median speeds, the
Python decoder's beside them (numba kernels, warmed up).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from common import ROOT, shared_sources
from mocodec import load, moc
from mocodec.codecs import get_codec


def _prepare(paths: list[Path], folder: Path) -> list[float]:
    """Code each clip into ``folder`` with the Python decode beside it; Python's frames/s."""
    speeds = []
    for k, path in enumerate(paths):
        motion = load(path)
        target = folder / f"{k:03d}-{path.stem}.moc"
        data = moc.pack(motion, get_codec("kinwave", max_error_cm=1.0))
        target.write_bytes(data)
        moc.unpack(data)  # warm
        t0 = time.perf_counter()
        decoded = moc.unpack(data)
        speeds.append(motion.num_frames / (time.perf_counter() - t0))
        decoded.channels.astype("<f8").tofile(f"{target}.f64")
    return speeds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clips", type=int, default=8, help="clips per source (0 = all)")
    parser.add_argument("--seconds", type=float, default=0.5, help="seconds of decoding per file and mode")
    args = parser.parse_args()
    sources = shared_sources(args.clips)
    print(
        "| source | clips | median frames | worst JS - Python channel difference | JS decode (frames/s) "
        "| JS decode + FK | Python decode |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, paths in sources.items():
        with tempfile.TemporaryDirectory() as tmp:
            python = _prepare(paths, Path(tmp))
            files = sorted(str(p) for p in Path(tmp).glob("*.moc"))
            run = subprocess.run(
                ["node", str(ROOT / "js" / "bench" / "moc.mjs"), "--seconds", str(args.seconds), *files],
                capture_output=True,
                text=True,
                check=True,
                env={**os.environ, "MOCODEC_BENCH_JSON": "1"},
            )
            rows = json.loads(run.stdout.strip().splitlines()[-1])
        print(
            f"| {name} | {len(rows)} | {np.median([r['frames'] for r in rows]):.0f} | "
            f"{max(r['worst'] for r in rows):.1e} | {np.median([r['decode'] for r in rows]):,.0f} | "
            f"{np.median([r['posed'] for r in rows]):,.0f} | {np.median(python):,.0f} |"
        )


if __name__ == "__main__":
    main()
