"""What each kinwave technique is worth: payload bytes at equal error bounds, one knob changed
at a time, relative to the default (geometric mean over the clips).

    python benchmarks/bench_kinwave_ablation.py [--clips N]
"""

from __future__ import annotations

import argparse

import numpy as np

from common import SHARED
from mocodec import load
from mocodec.codecs import get_codec

VARIANTS = {
    "open loop (closed_loop=False)": {"closed_loop": False},
    "one step for all angles (allocation=uniform)": {"allocation": "uniform"},
    "D4 instead of CDF 9/7": {"wavelet": "d4"},
    "Haar instead of CDF 9/7": {"wavelet": "haar"},
    "plain rounding (deadzone=0.5)": {"deadzone": 0.5},
    "stronger dead zone (deadzone=0.3)": {"deadzone": 0.3},
    "no keyframes apart (keyframes=False)": {"keyframes": False},
    "model steps only (joint_feedback=False)": {"joint_feedback": False},
    "time-adaptive steps (segment_steps=True, window 256)": {"segment_steps": True, "window": 256},
    "Euler angles only (rotation_vectors=False)": {"rotation_vectors": False},
    "window 128": {"window": 128},
    "window 256 (the default before 2026-12-06)": {"window": 256},
    "4 levels": {"levels": 4},
    "6 levels": {"levels": 6},
}
BOUNDS = (("mean", 0.5), ("joint", 0.5), ("shell", 0.1))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=4, help="clips per set (BVH and AMC)")
    args = ap.parse_args()
    clips = (
        sorted((SHARED / "cmu" / "bvh").glob("*.bvh"))[::8][: args.clips]
        + sorted((SHARED / "cmu" / "asf_amc").glob("*.amc"))[::4][: args.clips]
    )
    motions = [load(p) for p in clips]
    print(f"{len(motions)} clips: {', '.join(p.name for p in clips)}")
    print(f"| variant | {' | '.join(f'{m} {b} cm' for m, b in BOUNDS)} |\n|---|" + "---|" * len(BOUNDS))
    base = {
        mb: [len(get_codec("kinwave", max_error_cm=mb[1], error_measure=mb[0]).encode(m)) for m in motions]
        for mb in BOUNDS
    }
    for name, knobs in VARIANTS.items():
        cells = []
        for mb in BOUNDS:
            sizes = [
                len(get_codec("kinwave", max_error_cm=mb[1], error_measure=mb[0], **knobs).encode(m)) for m in motions
            ]
            cells.append(f"{np.exp(np.mean(np.log(np.array(sizes) / base[mb]))) - 1:+.1%}")
        print(f"| {name} | {' | '.join(cells)} |", flush=True)


if __name__ == "__main__":
    main()
