"""The motion-primitive coder (001 ch. 5) on the shared CMU clips, beside the thesis's tables.

Databases are trained on a few dev clips, as the thesis did (5.4: salsa 61_04, Indian dance
94_01 and walking 02_02; 94_01 is not in the shared set, so Indian dance 94_07 stands in): the
BVH database on 61_04, 94_07 and 02_02; the ASF/AMC clips use another skeleton, so they get a
database of their own, from dance 131_04, 05_02 and walk 07_03. Every other clip is coded at
t_L in {0.0025, 0.005, 0.01, 0.02} by the thesis's coder (``history 0``: database primitives
only) and by ours (``history 16``: the joint's earlier decoded segments and held pose offered
too), and measured: ratio vs 32-bit floats (payload only, as the thesis counts; the database
is on both ends), mean and max joint position error (cm). Then the S_M effect of table 5.4 on
61_06, table 5.1's clips we have (61_04, 135_04), the smoothing of 5.3.4 (knob ``smooth``) on
five clips, the database sizes and the speed of
table 5.3 (one core). Rows are means of ratios (the thesis averages its ratios) and medians
of errors over clips; every measurement goes to bench-out/primitives.csv.

Run: `.venv/bin/python benchmarks/bench_primitives.py [--quick]`.
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from common import ROOT, SHARED, best_of, tile  # noqa: E402
from mocodec import load  # noqa: E402
from mocodec.codecs import get_codec  # noqa: E402
from mocodec.codecs.motionprimitives import primdb
from mocodec.metrics import compare  # noqa: E402

TRAIN = {"bvh": ["61_04", "94_07", "02_02"], "amc": ["131_04", "05_02", "07_03"]}
THRESHOLDS = (0.0025, 0.005, 0.01, 0.02)
MODES = {"thesis": {"history": 0}, "ours": {"history": 16}}
THESIS_5_1 = {"61_04": 51, "135_04": 40}
THESIS_5_4 = {16: 46, 32: 49, 64: 50}
SMOOTH = (0, 2, 4)


def clip_path(kind: str, name: str):
    return SHARED / "cmu" / ("bvh" if kind == "bvh" else "asf_amc") / f"{name}.{kind}"


def measure(motion, knobs: dict) -> dict:
    codec = get_codec("primitives", **knobs)
    payload = codec.encode(motion)
    s = compare(motion, codec.decode(payload, motion.skeleton, motion.num_frames, motion.fps)).summary()
    return {
        "ratio": motion.raw_bits / 8 / len(payload),
        "mean_cm": s["mean_joint_error_cm"],
        "max_cm": s["max_joint_error_cm"],
        "bytes": len(payload),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="t_L = 0.01 only, every third clip")
    args = ap.parse_args()
    folder = tempfile.mkdtemp()
    dbs, rows = {}, []
    print("databases (5.3.3: K from 5 while the clustering error >= 0.01, at most 25 per joint):")
    for kind, names in TRAIN.items():
        clips = [load(clip_path(kind, n)) for n in names]
        t0 = time.perf_counter()
        db = primdb.train(clips, names=names)
        took = time.perf_counter() - t0
        dbs[kind] = os.path.join(folder, f"{kind}.mocdb")
        db.save(dbs[kind])
        print(
            f"  {kind}: {', '.join(names)} ({sum(c.num_frames for c in clips):,} frames): {db.count} primitives "
            f"for {len(db.primitives)} joints, {os.path.getsize(dbs[kind]):,} bytes, trained in {took:.1f} s "
            f"(the thesis: about 280 KB)"
        )
    thresholds = (0.01,) if args.quick else THRESHOLDS
    for kind in ("bvh", "amc"):
        paths = sorted(
            p
            for p in (SHARED / "cmu" / ("bvh" if kind == "bvh" else "asf_amc")).glob(f"*.{kind}")
            if p.stem not in TRAIN[kind]
        )
        for path in paths[::3] if args.quick else paths:
            motion = load(path)
            for mode, extra in MODES.items():
                for t in thresholds:
                    m = measure(motion, {"db": dbs[kind], "t_lower": t, **extra})
                    rows.append(
                        {"set": kind, "clip": path.stem, "mode": mode, "t_lower": t, "frames": motion.num_frames, **m}
                    )
    out = ROOT / "bench-out"
    out.mkdir(exist_ok=True)
    with open(out / "primitives.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("\nevaluation clips (not trained on): mean ratio, median mean / median max joint error (cm)")
    print(f"{'set':<5}{'mode':<8}" + "".join(f"{'t_L=' + format(t, 'g'):>26}" for t in thresholds))
    for kind in ("bvh", "amc"):
        for mode in MODES:
            cells = []
            for t in thresholds:
                sel = [r for r in rows if r["set"] == kind and r["mode"] == mode and r["t_lower"] == t]
                cells.append(
                    f"{np.mean([r['ratio'] for r in sel]):6.1f}:1 {np.median([r['mean_cm'] for r in sel]):5.2f}"
                    f" / {np.median([r['max_cm'] for r in sel]):5.2f} cm"
                )
            n = len({r["clip"] for r in rows if r["set"] == kind})
            print(f"{kind:<5}{mode:<8}" + "".join(f"{c:>26}" for c in cells) + f"   ({n} clips)")
    print("the thesis (table 5.1, t_L = 0.01, AMC, 7 clips): 48:1 on average")

    print("\ntable 5.1 clips we have, t_L = 0.01 (ratio, mean / max cm; the thesis's ratio):")
    for name, thesis in THESIS_5_1.items():
        for kind in ("bvh", "amc"):
            path = clip_path(kind, name)
            if not path.exists():
                continue
            motion = load(path)
            for mode, extra in MODES.items():
                m = measure(motion, {"db": dbs[kind], **extra})
                print(
                    f"  {name}.{kind} {mode:<7}{m['ratio']:6.1f}:1  {m['mean_cm']:.2f} / {m['max_cm']:.2f} cm"
                    f"   (thesis {thesis}:1{', a training clip' if name in TRAIN[kind] else ''})"
                )

    print("\ntable 5.4, S_M on 61_06 (BVH), t_L = 0.01:")
    motion = load(clip_path("bvh", "61_06"))
    for s_m, thesis in THESIS_5_4.items():
        cells = [
            f"{mode} {measure(motion, {'db': dbs['bvh'], 'max_segment': s_m, **extra})['ratio']:5.1f}:1"
            for mode, extra in MODES.items()
        ]
        print(f"  S_M = {s_m:<3} {'  '.join(cells)}   (thesis {thesis}:1)")

    print("\nsmoothing of consecutive segments (5.3.4), ours, t_L = 0.01 (mean / max joint error, jerk ratio):")
    for kind, name in (("bvh", "61_06"), ("bvh", "02_01"), ("bvh", "135_04"), ("amc", "131_04"), ("amc", "05_02")):
        motion = load(clip_path(kind, name))
        cells = []
        for m in SMOOTH:
            codec = get_codec("primitives", db=dbs[kind], smooth=m)
            s = compare(
                motion, codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)
            ).summary()
            cells.append(
                f"M={m}: {s['mean_joint_error_cm']:.3f} / {s['max_joint_error_cm']:5.2f} cm x{s['jerk_ratio']:.2f}"
            )
        print(f"  {name}.{kind:<4}" + "   ".join(cells))

    print("\nspeed, one core, 10,000 frames (table 5.3: 1,660-2,370 us per frame to encode, 110-140 to decode):")
    for kind, name in (("amc", "135_04"), ("bvh", "61_06")):
        motion = tile(load(clip_path(kind, name)), 10_000)
        for mode, extra in MODES.items():
            codec = get_codec("primitives", db=dbs[kind], **extra)
            payload = codec.encode(motion)
            enc = best_of(lambda: codec.encode(motion), 3)
            dec = best_of(lambda: codec.decode(payload, motion.skeleton, motion.num_frames, motion.fps), 3)
            print(
                f"  {name}.{kind} ({motion.num_channels} ch) {mode:<7}encode {10_000 / enc:7,.0f} frames/s "
                f"({enc / 10_000 * 1e6:5.0f} us/frame), decode {10_000 / dec:8,.0f} frames/s "
                f"({dec / 10_000 * 1e6:5.1f} us/frame)"
            )


if __name__ == "__main__":
    main()
