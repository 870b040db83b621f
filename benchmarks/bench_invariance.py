"""kinwave on the same motion in other pipelines' layouts: file size and bound under each
re-expression of :mod:`mocodec.reexpress` (every joint position unchanged).

    python benchmarks/bench_invariance.py [--clips N] [--bounds 1 0.1] [--jobs 2]

For every clip (the first N of CMU BVH, CMU ASF/AMC and Bandai Namco, sorted) and every max
shell bound, the whole .moc file (skeleton included) of each transformed clip is compared with
the clip's own; frame-rate rows compare the resampled clip's file with the original's (the same motion in fewer
frames) and check the bound against the resampled clip itself. Beyond the issue's list: the
rows "h" cut the clip one to three frames later (about the same motion, on another frame
grid), the row "i" puts a bind pose that is not the rest pose (a keyframe) before frame 0.
Prints one row per transform (median and worst growth, encodings over the bound), then the
median and worst over the rows a-f and over a-f, h and i.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from common import shared_sources
from mocodec import load, moc, reexpress
from mocodec.codecs import get_codec
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors

SEED = 28


def dummy_root(motion, rotation=(0.0, 0.0, 0.0), position_channels=False):
    """:func:`reexpress.with_dummy_root` under a name the skeleton does not use (a game export
    has a dummy root already)."""
    names = {j.name for j in motion.skeleton.joints}
    name = next(f"dummy_root{k or ''}" for k in range(len(names) + 1) if f"dummy_root{k or ''}" not in names)
    return reexpress.with_dummy_root(motion, rotation, name=name, position_channels=position_channels)


def transforms(motion, rng):
    """``(name, motion)`` for every re-expression the issue lists."""
    turn = tuple(float(v) for v in rng.uniform(-180, 180, 3))
    yield "a dummy root, random rotation", dummy_root(motion, turn)
    yield "a dummy root (0, -90, 0)", dummy_root(motion, (0.0, -90.0, 0.0))
    yield "a dummy root (0, 90, 0)", dummy_root(motion, (0.0, 90.0, 0.0))
    for order in reexpress.EULER_ORDERS:
        yield f"b Euler order {order}", reexpress.with_euler_orders(motion, order)
    yield "c 6-channel joints", reexpress.with_position_channels(motion)
    yield "d units x 0.01", reexpress.with_units(motion, 0.01)
    yield "d units x 2.54", reexpress.with_units(motion, 2.54)
    yield "e translation on a dummy root's child", dummy_root(motion, position_channels=True)
    yield "f bind pose in frame 0", reexpress.with_bind_frame(motion)
    for frames in (1, 2, 3):
        yield f"h cut {frames} frame{'s' if frames > 1 else ''} later", motion[frames:]
    bind = reexpress.with_bind_frame(motion)
    channels = bind.channels.copy()
    channels[0, motion.skeleton.rotation_mask] = 5.0
    yield "i a bind pose not at rest (every angle 5 degrees)", bind.with_channels(channels)
    for fps in (24.0, 30.0, 60.0):
        if fps < motion.fps:
            yield f"g {fps:g} fps", motion.resample(fps)


def shell_max(motion, decoded) -> float:
    """Max shell error (cm) of ``decoded`` (on its stored skeleton) against ``motion``."""
    sk = motion.skeleton
    cm = 100.0 / sk.units_per_metre
    p0, q0 = forward_kinematics(sk, motion.channels)
    p1, q1 = forward_kinematics(decoded.skeleton, decoded.channels)
    return shell_errors(sk, p0 * cm, q0, p1 * cm, q1).max


def measure(path: str, bounds: tuple[float, ...]) -> list[tuple[str, float, float, int, int, bool]]:
    """(transform, bound, growth, bytes, base bytes, over the bound) rows for one clip."""
    motion = load(path)
    rng = np.random.default_rng([SEED, sum(map(ord, path.split("/")[-1]))])
    rows = []
    for bound in bounds:
        codec = get_codec("kinwave", max_error_cm=bound, error_measure="shell")
        base = len(moc.pack(motion, codec))
        for name, moved in transforms(motion, rng):
            data = moc.pack(moved, codec)
            over = shell_max(moved, moc.unpack(data)) > bound
            rows.append((name, bound, len(data) / base - 1.0, len(data), base, over))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=4, help="clips per source (0: all)")
    ap.add_argument("--bounds", type=float, nargs="+", default=[1.0, 0.1])
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    chosen = shared_sources(args.clips)
    with ProcessPoolExecutor(args.jobs) as pool:
        results = {
            name: list(pool.map(measure, map(str, files), [tuple(args.bounds)] * len(files)))
            for name, files in chosen.items()
        }
    print(f"kinwave, max shell bounds {args.bounds} cm; growth of the whole file against the clip's own")
    print(f"{'transform':42s} {'source':13s} {'median':>8s} {'worst':>8s} {'over':>5s}")
    everything = []
    for source, clips in results.items():
        rows = [r for clip in clips for r in clip]
        everything += rows
        for name in dict.fromkeys(r[0] for r in rows):
            growth = np.array([r[2] for r in rows if r[0] == name])
            over = sum(r[5] for r in rows if r[0] == name)
            print(f"{name:42s} {source:13s} {100 * np.median(growth):+7.1f}% {100 * growth.max():+7.1f}% {over:5d}")
    for rows, what in (
        (lambda name: name < "g", "the issue's transforms a-f"),
        (lambda name: name[0] != "g", "a-f, h, i"),
    ):
        growth = np.array([r[2] for r in everything if rows(r[0])])
        print(f"{what}: median {100 * np.median(growth):+.1f}%, worst {100 * growth.max():+.1f}%")
    print(f"{sum(r[5] for r in everything)} of {len(everything)} encodings over the bound")


if __name__ == "__main__":
    main()
