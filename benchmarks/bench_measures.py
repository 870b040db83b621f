"""Time every error measure together on a 10,000-frame, 62-channel CMU clip (FK included).

Target (issue 3): under 0.3 s for `compare` on 10k frames x 62 channels. Prints the time of
each part so regressions are easy to place. Run: `.venv/bin/python benchmarks/bench_measures.py`.
"""

from __future__ import annotations

import numpy as np

from common import DATA, best_of, options, tile
from mocodec import load
from mocodec.kinematics import forward_kinematics
from mocodec.metrics import compare, dof_errors, visual_errors
from mocodec.metrics.waveform import channel_error

FRAMES = 10_000


def main() -> None:
    options(__doc__)
    clip = load(DATA / "135_08.amc")
    original = tile(clip, FRAMES)
    noise = np.random.default_rng(0).normal(0, 0.3, original.channels.shape)
    decoded = original.with_channels(original.channels + noise)
    sk = original.skeleton
    print(f"clip 135_08 tiled to {original.num_frames} frames x {sk.num_channels} channels, {len(sk)} joints")
    err = channel_error(original.channels, decoded.channels, sk.rotation_mask)
    rng = dof_errors(original.channels, decoded.channels, sk.rotation_mask).range
    parts = {
        "waveform (6-1..6-8)": lambda: dof_errors(original.channels, decoded.channels, sk.rotation_mask),
        "visual (6-15..6-17)": lambda: visual_errors(err, rng, original.fps),
        "forward kinematics x2": lambda: (
            forward_kinematics(sk, original.channels),
            forward_kinematics(sk, decoded.channels),
        ),
    }
    for name, fn in parts.items():
        print(f"  {name:<24}{best_of(fn) * 1e3:8.1f} ms")
    total = best_of(lambda: compare(original, decoded))
    print(f"compare (all measures)    {total * 1e3:8.1f} ms   target < 300 ms")


if __name__ == "__main__":
    main()
