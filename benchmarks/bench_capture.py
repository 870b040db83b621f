"""Capture (003 ch. 4): conversion speed on one core and the round-trip errors, from random poses
of the human model through simulated trackers (transmitter anywhere, trackers strapped on
askew) back to joint angles. Run: `.venv/bin/python benchmarks/bench_capture.py`."""

from __future__ import annotations

import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from common import best_of, options  # noqa: E402
from mocodec import rotations  # noqa: E402
from mocodec.capture.converter import Converter  # noqa: E402
from mocodec.capture.simulate import random_poses, simulate  # noqa: E402
from mocodec.kinematics import forward_kinematics  # noqa: E402

FRAMES = 20_000


def main() -> None:
    options(__doc__)
    t0 = time.perf_counter()
    small = random_poses(10, seed=0)
    Converter().convert(simulate(small, seed=0))
    first = time.perf_counter() - t0
    poses = random_poses(FRAMES, seed=1)
    log = simulate(poses, seed=1)
    conv = Converter()
    seconds = best_of(lambda: conv.convert(log), 3)
    print(
        f"convert {FRAMES:,} sensor frames: {seconds:.3f} s = {FRAMES / seconds:,.0f} frames/s on one core "
        f"(first call, imports and compilation included: {first:.2f} s)"
    )
    sk = poses.skeleton
    truth_p, truth_q = forward_kinematics(sk, poses.channels)
    print(f"{'trackers':24s} {'head top cm':>16s} {'wrists cm':>16s} {'ankles cm':>16s} {'forearms deg':>16s}")
    for label, noise in (
        ("exact", (0.0, 0.0, 0.0)),
        ("0.5 deg, 0.3 cm", (0.5, 0.3, 0.016)),
        ("1 deg, 0.5 cm", (1.0, 0.5, 0.016)),
        ("2 deg, 1 cm", (2.0, 1.0, 0.016)),
    ):
        got = conv.convert(simulate(poses, noise[0], noise[1], seed=2, glove_noise=noise[2]))
        p, q = forward_kinematics(sk, got.channels)

        def cm(*joints):
            e = np.concatenate([np.linalg.norm(p[:, sk.index(j)] - truth_p[:, sk.index(j)], axis=1) for j in joints])
            return f"{100 * e.mean():6.2f} / {100 * e.max():5.2f}"

        deg = np.concatenate(
            [
                np.degrees(rotations.quat_distance(q[:, sk.index(j)], truth_q[:, sk.index(j)]))
                for j in ("left_elbow", "right_elbow")
            ]
        )
        print(
            f"{label:24s} {cm('head_top'):>16s} {cm('left_wrist', 'right_wrist'):>16s} "
            f"{cm('left_ankle', 'right_ankle'):>16s} {f'{np.median(deg):6.2f} / {deg.max():5.1f}':>16s}"
        )
    print("(mean / max; forearms: median / max of the orientation error)")


if __name__ == "__main__":
    main()
