"""How much of a max bound kinwave uses, and what its files weigh, on every shared clip.

    python benchmarks/bench_bound_usage.py [--clips N] [--jobs 2]

For the first N clips (sorted; 0 = all) of CMU BVH, CMU ASF/AMC and Bandai Namco, whole .moc
files (skeleton included) at max shell 1 cm, max shell 0.1 cm and max joint 0.5 cm: per source
and bound the total bytes, the median and least share of the bound the decoded file's measured
error uses, how many encodings use less than 85% of it (the issue's floor) and how many go over;
with every Bandai Namco clip, the sums over the issue's 22 (every fourth, sorted) at shell 1
and 0.1 cm.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from common import shared_sources
from mocodec import load, moc
from mocodec.codecs import get_codec
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors

SETTINGS = (("shell", 1.0), ("shell", 0.1), ("joint", 0.5))
FLOOR = 0.85
ISSUE_SOURCE, ISSUE_CLIPS = "Bandai Namco", 22  # the issue's targets: every fourth clip from the first


def _clip(path) -> list[tuple[int, float]]:
    """(bytes, measured error / bound) per setting."""
    motion = load(path)
    sk = motion.skeleton
    cm = 100.0 / sk.units_per_metre
    p0, q0 = forward_kinematics(sk, motion.channels)
    out = []
    for measure, bound in SETTINGS:
        data = moc.pack(motion, get_codec("kinwave", max_error_cm=bound, error_measure=measure))
        decoded = moc.unpack(data)
        p1, q1 = forward_kinematics(decoded.skeleton, decoded.channels)
        if measure == "shell":
            error = shell_errors(sk, p0 * cm, q0, p1 * cm, q1).max
        else:
            error = float(np.linalg.norm((p1 - p0) * cm, axis=2).max())
        out.append((len(data), error / bound))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clips", type=int, default=0, help="clips per source (0 = all)")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    print("| source | clips | bound | bytes | median share of the bound | least | under 85% | over |")
    print("|---|---|---|---|---|---|---|---|")
    issue_sums = None  # bytes at shell 1 and 0.1 cm over the issue's clips
    with ProcessPoolExecutor(args.jobs) as pool:
        for name, paths in shared_sources(args.clips).items():
            rows = list(pool.map(_clip, paths))
            for k, (measure, bound) in enumerate(SETTINGS):
                sizes = np.array([r[k][0] for r in rows])
                shares = np.array([r[k][1] for r in rows])
                print(
                    f"| {name} | {len(rows)} | {measure} {bound:g} cm | {sizes.sum():,} | {np.median(shares):.3f} | "
                    f"{shares.min():.3f} | {(shares < FLOOR).sum()} | {(shares > 1.0).sum()} |"
                )
            if name == ISSUE_SOURCE and not args.clips:
                every_fourth = rows[::4][:ISSUE_CLIPS]  # the paths are sorted
                issue_sums = [sum(r[k][0] for r in every_fourth) for k in range(2)]
    if issue_sums:
        one_cm, tenth = issue_sums
        print(
            f"the issue's {ISSUE_CLIPS} {ISSUE_SOURCE} clips (every fourth, sorted): "
            f"{one_cm:,} bytes at shell 1 cm, {tenth:,} at 0.1 cm"
        )


if __name__ == "__main__":
    main()
