"""Parse and forward-kinematics speed against the Foundation targets.

Targets: a 10,000-frame 62-channel AMC loads in under 0.5 s; a 132-channel BVH parses at
20 MB/s or better; FK of 10,000 frames x 43 joints in under 0.2 s. Best of N runs (shared,
noisy machines: compare within one run). Run: ``make bench`` or
``python benchmarks/bench_foundation.py [--shared DIR]``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from common import DATA, ROOT, SHARED, best_of, tile
from mocodec import load, save
from mocodec.kinematics import forward_kinematics


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shared", type=Path, default=SHARED or ROOT.parent / "shared" / "data")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    tests = DATA
    amc_src = load(tests / "07_03.amc")
    bvh_src = load(tests / "07_03.bvh")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        amc10k = tile(amc_src, 10_000)
        save(amc10k, tmp / "big.amc")
        t = best_of(lambda: load(tmp / "big.amc"), args.repeats)
        print(f"AMC  10,000 frames x {amc10k.num_channels} channels: load {t:.3f} s   (target < 0.5 s)")
        bvh10k = tile(bvh_src, 10_000)
        save(bvh10k, tmp / "big.bvh")
        size = (tmp / "big.bvh").stat().st_size
        t = best_of(lambda: load(tmp / "big.bvh"), args.repeats)
        print(
            f"BVH  10,000 frames x {bvh10k.num_channels} channels ({size / 1e6:.1f} MB, written by mocodec): "
            f"{size / t / 1e6:.1f} MB/s   (target >= 20 MB/s)"
        )
    cmu = args.shared / "cmu" / "bvh" / "13_26.bvh"
    if cmu.exists():
        size = cmu.stat().st_size
        t = best_of(lambda: load(cmu), args.repeats)
        print(f"BVH  CMU 13_26.bvh ({size / 1e6:.1f} MB, 3029 frames): {size / t / 1e6:.1f} MB/s")
    sk = bvh10k.skeleton
    articulated = int((~sk.end_sites).sum())
    t = best_of(lambda: forward_kinematics(sk, bvh10k.channels), args.repeats)
    print(
        f"FK   10,000 frames x {len(sk)} pivots ({articulated} joints + {len(sk) - articulated} end sites): "
        f"{t:.3f} s   (target < 0.2 s for 43 joints)"
    )
    t = best_of(lambda: forward_kinematics(amc10k.skeleton, amc10k.channels), args.repeats)
    print(f"FK   10,000 frames x {len(amc10k.skeleton)} pivots (ASF, with bone axes): {t:.3f} s")


if __name__ == "__main__":
    main()
