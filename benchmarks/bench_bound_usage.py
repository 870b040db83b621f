"""How much of a max bound kinwave uses, and what its files weigh, on every shared clip.

    python benchmarks/bench_bound_usage.py [--clips N] [--jobs 2] [--effort E] [--save F] [--against F]

For the first N clips (sorted; 0 = all) of CMU BVH, CMU ASF/AMC and Bandai Namco, whole .moc
files (skeleton included) at max shell 1 cm, max shell 0.1 cm and max joint 0.5 cm: per source
and bound the total bytes, the median and least share of the bound the decoded file's measured
error uses, how many encodings use less than 85% of it (the issue's floor) and how many go over;
with every Bandai Namco clip, the sums over the issue's 22 (every fourth, sorted) at shell 1
and 0.1 cm; at kinwave's default effort, or at ``--effort E``. ``--save F`` writes every
clip's bytes per setting to F (JSON); ``--against F`` compares every clip with such a file
(another commit's: ``PYTHONPATH=<its src>``) and prints, per source, the median and largest
change and the clip-and-setting pairs more than 1% larger.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from functools import partial

import numpy as np

from common import shared_sources
from mocodec import load, moc
from mocodec.codecs import get_codec
from mocodec.formats.fileio import atomic_write
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors

SETTINGS = (("shell", 1.0), ("shell", 0.1), ("joint", 0.5))
FLOOR = 0.85
GREW = 0.01  # a clip this much larger than the saved run's is listed
ISSUE_SOURCE, ISSUE_CLIPS = "Bandai Namco", 22  # the issue's targets: every fourth clip from the first


def _clip(path, knobs: dict) -> list[tuple[int, float]]:
    """(bytes, measured error / bound) per setting, with kinwave's other ``knobs``."""
    motion = load(path)
    sk = motion.skeleton
    cm = 100.0 / sk.units_per_metre
    p0, q0 = forward_kinematics(sk, motion.channels)
    out = []
    for measure, bound in SETTINGS:
        data = moc.pack(motion, get_codec("kinwave", max_error_cm=bound, error_measure=measure, **knobs))
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
    parser.add_argument("--effort", type=int, help="kinwave's effort level (default: the codec's)")
    parser.add_argument("--save", help="write every clip's bytes per setting to this JSON file")
    parser.add_argument("--against", help="compare every clip with a --save file of another run")
    args = parser.parse_args()
    sizes_by_clip: dict[str, dict[str, list[int]]] = {}
    knobs = {} if args.effort is None else {"effort": args.effort}
    print("| source | clips | bound | bytes | median share of the bound | least | under 85% | over |")
    print("|---|---|---|---|---|---|---|---|")
    issue_sums = None  # bytes at shell 1 and 0.1 cm over the issue's clips
    with ProcessPoolExecutor(args.jobs) as pool:
        for name, paths in shared_sources(args.clips).items():
            rows = list(pool.map(partial(_clip, knobs=knobs), paths))
            sizes_by_clip[name] = {p.name: [r[0] for r in row] for p, row in zip(paths, rows)}
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
    if args.save:
        atomic_write(args.save, json.dumps(sizes_by_clip))
    if args.against:
        with open(args.against) as f:
            compare(sizes_by_clip, json.load(f))


def compare(now: dict[str, dict[str, list[int]]], before: dict[str, dict[str, list[int]]]) -> None:
    """Per source, every clip's change against ``before`` at each setting both runs have."""
    names = [f"{measure} {bound:g} cm" for measure, bound in SETTINGS]
    for source, clips in now.items():
        pairs = [
            (now_bytes / old[k] - 1.0, clip, names[k])
            for clip, sizes in clips.items()
            if (old := before.get(source, {}).get(clip))
            for k, now_bytes in enumerate(sizes[: len(old)])
        ]
        if not pairs:
            continue
        changes = np.array([c for c, _, _ in pairs])
        grew = sorted((p for p in pairs if p[0] > GREW), reverse=True)
        listed = "".join(f", {clip} {100 * c:+.1f}% ({setting})" for c, clip, setting in grew)
        print(
            f"{source} against the saved run: {len(pairs)} clip-and-setting pairs, "
            f"median {100 * np.median(changes):+.1f}%, largest {100 * changes.max():+.1f}%; "
            f"{len(grew)} more than {100 * GREW:g}% larger{listed}"
        )


if __name__ == "__main__":
    main()
