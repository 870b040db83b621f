"""The rhythmic framework of 001 ch. 4 measured: table 4.1's ratios by coding, not estimate.

Table 4.1 estimates the ratio of rhythmic motions of 3,000 to 7,500 frames coded as
references to 20 primitives, counting a 9 KB database sent along (89 KB raw, "wavelet
compression at 10:1"): 67:1 to 168:1. Here the Indian dance clips 61_04, 61_06, 61_09 and the
dance 60_04 (BVH, one skeleton, 8,093 frames) are laid end to end and cut to those lengths;
each is coded by ``rhythmic`` with 20 primitives made from the sequence itself and carried
in the payload (the thesis's setting), with both roots (ours: keys at every seam; the
thesis's: velocity), and with an external database trained on another dance (94_07) that
the receiver holds (not counted). Reported: ratio vs 32-bit floats, the carried database's
bytes, mean and max joint position error (cm), jerk ratio, with and without blending.

Run: `.venv/bin/python benchmarks/bench_rhythmic.py`.
"""

from __future__ import annotations

import os
import tempfile
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from common import SHARED, options  # noqa: E402
from mocodec import load  # noqa: E402
from mocodec.codecs import get_codec  # noqa: E402
from mocodec.codecs.motionprimitives import rhythmdb
from mocodec.metrics import compare  # noqa: E402

DANCE = ("61_04", "61_06", "61_09", "60_04")
LENGTHS = {3000: 67, 4500: 89, 6000: 134, 7500: 168}
OTHER = "94_07"


def bvh(name: str):
    return load(SHARED / "cmu" / "bvh" / f"{name}.bvh")


def measure(motion, **knobs) -> str:
    codec = get_codec("rhythmic", **knobs)
    t0 = time.perf_counter()
    payload = codec.encode(motion)
    t1 = time.perf_counter()
    decoded = codec.decode(payload, motion.skeleton, motion.num_frames, motion.fps)
    t2 = time.perf_counter()
    s = compare(motion, decoded).summary()
    n = motion.num_frames
    return (
        f"{motion.raw_bits / 8 / len(payload):6.1f}:1 {len(payload):7,} B  {s['mean_joint_error_cm']:6.2f} / "
        f"{s['max_joint_error_cm']:6.1f} cm  jerk x{s['jerk_ratio']:5.2f}  "
        f"enc {n / (t1 - t0):6,.0f} dec {n / (t2 - t1):7,.0f} f/s"
    )


def main() -> None:
    options(__doc__)
    clips = [bvh(n) for n in DANCE]
    whole = clips[0].with_channels(np.concatenate([c.channels for c in clips]))
    folder = tempfile.mkdtemp()
    other = os.path.join(folder, "other.mocrd")
    rhythmdb.train([bvh(OTHER)], names=[OTHER]).save(other)
    print(f"{' + '.join(DANCE)}: {whole.num_frames:,} frames, {whole.num_channels} channels at {whole.fps:g} Hz")
    print(f"external database: 20 primitives of {OTHER}, {os.path.getsize(other):,} bytes (float32, not counted)\n")
    for frames, thesis in LENGTHS.items():
        motion = whole.with_channels(whole.channels[:frames])
        carried = rhythmdb.train([motion]).compact()
        print(f"{frames:,} frames (table 4.1 estimate {thesis}:1); 20 primitives carried in {len(carried):,} bytes")
        for label, knobs in (
            ("carried, keys root, blended", {}),
            ("carried, keys root, not blended", {"blend": False}),
            ("carried, velocity root (thesis)", {"root": "velocity"}),
            (f"external {OTHER} db, keys root", {"db": other}),
        ):
            print(f"  {label:<34}{measure(motion, **knobs)}")
        print()


if __name__ == "__main__":
    main()
