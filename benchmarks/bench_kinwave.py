"""kinwave against SZ3 (pysz, one channel at a time, absolute bound) at equal max shell error,
its ratio at a mean joint error bound, the guarantee on every clip (and how much of a max
bound it uses), and its speed; every figure per source (CMU BVH, CMU ASF/AMC, Bandai Namco, the
game-export stand-in set), side by side.

    python benchmarks/bench_kinwave.py [--set bvh|amc|bandai|game|all] [--limit N]

SZ3's bound (degrees, and cm for translations) is bisected per clip to the largest one whose
decoded max shell error is within the target; kinwave is given the target as its bound. Sizes
are the coded motion (payload bytes, no container); ratios at a mean error include the whole
.moc file with its skeleton.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from baselines import sz3_per_channel
from common import GAME_EXPORT, shared_sources
from mocodec import load, moc
from mocodec.codecs import get_codec
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors

SETS = {"bvh": "CMU BVH", "amc": "CMU ASF/AMC", "bandai": "Bandai Namco", "game": GAME_EXPORT}


def errors(motion, channels):
    sk = motion.skeleton
    cm = 100.0 / sk.units_per_metre
    p0, q0 = forward_kinematics(sk, motion.channels)
    p1, q1 = forward_kinematics(sk, channels)
    joint = np.linalg.norm((p1 - p0) * cm, axis=2)
    return {"shell": shell_errors(sk, p0 * cm, q0, p1 * cm, q1).max, "joint": joint.max(), "mean": joint.mean()}


def sz3_at_shell(motion, target):
    lo, hi, best = 1e-5, 100.0, None
    for _ in range(30):
        mid = np.sqrt(lo * hi)
        size, out = sz3_per_channel(motion, mid)
        if errors(motion, out)["shell"] <= target:
            lo, best = mid, size
        else:
            hi = mid
        if hi / lo < 1.02:
            break
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", choices=(*SETS, "all"), default="all")
    ap.add_argument("--limit", type=int, default=0, help="only the first N clips of each set")
    args = ap.parse_args()
    clips = [
        (name, p)
        for name, paths in shared_sources(args.limit).items()
        if args.set == "all" or SETS[args.set] == name
        for p in paths
    ]
    rel, ratio, over, used, enc_fps, dec_fps = {}, {}, {}, {}, [], []
    print(f"{'clip':36s} {'frames':>6s} | shell 0.1: kinwave/SZ3 | shell 1.0: kinwave/SZ3 | mean 0.5 / 1.0 ratio")
    for source, path in clips:
        motion = load(path)
        row = [f"{path.name[:36]:36s} {motion.num_frames:6d}"]
        for bound in (0.1, 1.0):
            codec = get_codec("kinwave", max_error_cm=bound, error_measure="shell")
            payload = codec.encode(motion)
            err = errors(motion, codec.decode(payload, motion.skeleton, motion.num_frames, motion.fps).channels)[
                "shell"
            ]
            over.setdefault((source, "shell", bound), []).append(err > bound)
            used.setdefault((source, "shell", bound), []).append(err / bound)
            ref = sz3_at_shell(motion, bound)
            rel.setdefault((source, bound), []).append(len(payload) / ref)
            row.append(f"{len(payload):7d}/{ref:7d} = {len(payload) / ref:.2f}")
        for bound in (0.5, 1.0):
            data = moc.pack(motion, get_codec("kinwave", max_error_cm=bound, error_measure="mean"))
            ratio.setdefault((source, bound), []).append(motion.raw_bits / 8 / len(data))
            row.append(f"{ratio[(source, bound)][-1]:6.1f}")
        for bound in (0.1, 0.5, 1.0):
            codec = get_codec("kinwave", max_error_cm=bound, error_measure="joint")
            t0 = time.perf_counter()
            payload = codec.encode(motion)
            t1 = time.perf_counter()
            decoded = codec.decode(payload, motion.skeleton, motion.num_frames, motion.fps)
            t2 = time.perf_counter()
            err = errors(motion, decoded.channels)["joint"]
            over.setdefault((source, "joint", bound), []).append(err > bound)
            used.setdefault((source, "joint", bound), []).append(err / bound)
            if motion.num_channels == 62 and bound == 0.5:
                enc_fps.append(motion.num_frames / (t1 - t0))
                dec_fps.append(motion.num_frames / (t2 - t1))
        print(" | ".join(row), flush=True)
    names = list(dict.fromkeys(name for name, _ in clips))
    print(f"\n{len(clips)} clips; per source: " + ", ".join(f"{n} ({sum(s == n for s, _ in clips)})" for n in names))
    print(f"{'':44s}" + "".join(f"{n:>16s}" for n in names))

    def line(label, values):
        print(f"{label:44s}" + "".join(f"{v:>16s}" for v in values))

    for bound in (0.1, 1.0):
        line(
            f"kinwave / SZ3 bytes, max shell {bound} cm (median)",
            [f"{np.median(rel[(n, bound)]):.2f}" if (n, bound) in rel else "-" for n in names],
        )
    for bound in (0.5, 1.0):
        line(
            f"whole-file ratio, mean joint {bound} cm (median)",
            [f"{np.median(ratio[(n, bound)]):.0f}:1" if (n, bound) in ratio else "-" for n in names],
        )
    for measure, bound in sorted({(m, b) for _, m, b in over}):
        line(
            f"clips over the bound, {measure} {bound} cm",
            [
                f"{sum(over[(n, measure, bound)])} of {len(over[(n, measure, bound)])}"
                if (n, measure, bound) in over
                else "-"
                for n in names
            ],
        )
        line(
            f"share of the bound used, {measure} {bound} cm (least)",
            [f"{min(used[(n, measure, bound)]):.2f}" if (n, measure, bound) in used else "-" for n in names],
        )
    if enc_fps:
        print(
            f"62-channel clips, joint 0.5 cm: encode median {np.median(enc_fps):,.0f} frames/s, "
            f"decode {np.median(dec_fps):,.0f} frames/s (one core, after compilation)"
        )


if __name__ == "__main__":
    main()
