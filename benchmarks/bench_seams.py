"""Jerk where segments meet: spiht's, with and without the decoder's seam smoothing, and
kinwave's (its segments join at shared knots, so nothing is smoothed).

For a few shared clips and rates: the mean third difference of the joint positions (cm per
frame^3) over the 4 frames ending at each seam and over the rest, for the original and the
decoded motion, and the mean joint error. Run: `.venv/bin/python benchmarks/bench_seams.py`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common import SHARED, options
from mocodec import load
from mocodec.codecs import get_codec
from mocodec.kinematics import forward_kinematics
from mocodec.metrics import compare

CLIPS = ("asf_amc/131_04.amc", "asf_amc/05_02.amc", "bvh/61_04.bvh", "bvh/02_02.bvh")


def jerk(motion, channels):
    sk = motion.skeleton
    p = forward_kinematics(sk, channels)[0] * (100.0 / sk.units_per_metre)
    return np.linalg.norm(np.diff(p, n=3, axis=0), axis=2).mean(axis=1)


def main() -> None:
    options(__doc__)
    if SHARED is None:
        print("../shared/data is not here; skipped")
        return
    print(f"{'clip':<12}{'setting':>22}{'seam jerk':>11}{'elsewhere':>11}{'original':>10}{'mean cm':>9}")
    for name in CLIPS:
        motion = load(SHARED / "cmu" / name)
        seam = np.zeros(motion.num_frames - 3, dtype=bool)
        for k in range(128, motion.num_frames, 128):
            seam[max(k - 3, 0) : k + 1] = True
        original = jerk(motion, motion.channels)
        settings = [
            (
                f"spiht {bps // 1000} kbit/s{' smooth' if smooth else ''}",
                get_codec("spiht", bits_per_second=bps, smooth_seams=smooth),
            )
            for bps in (4000, 15000)
            for smooth in (False, True)
        ]
        settings += [
            (f"kinwave mean {bound} cm", get_codec("kinwave", max_error_cm=bound, error_measure="mean", window=128))
            for bound in (0.5, 1.0)
        ]
        for label, codec in settings:
            decoded = codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)
            j = jerk(motion, decoded.channels)
            print(
                f"{Path(name).name:<12}{label:>22}{j[seam].mean():>11.3f}{j[~seam].mean():>11.3f}"
                f"{original[seam].mean():>10.3f}{compare(motion, decoded).joints.mean:>9.3f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
