"""Compression ratio (vs 32-bit floats, whole .moc file) and speed of the `lossless` codec on
every clip of ../shared/data, beside zstandard (level 19) on the 32-bit floats, which is not
even lossless for these float64 values. Run: `.venv/bin/python benchmarks/bench_lossless.py`."""

from __future__ import annotations

import time

import numpy as np
import zstandard

from common import SHARED, options
from mocodec import load, moc
from mocodec.codecs import get_codec


def main() -> None:
    options(__doc__)
    if SHARED is None:
        print("bench_lossless: ../shared/data is not here; skipped")
        return
    codec = get_codec("lossless")
    rows = []
    for path in sorted((SHARED / "cmu").glob("*/*.bvh")) + sorted((SHARED / "cmu").glob("*/*.amc")):
        motion = load(path)
        raw = motion.raw_bits / 8
        t0 = time.perf_counter()
        data = moc.pack(motion, codec)
        t1 = time.perf_counter()
        assert np.array_equal(moc.unpack(data).channels, motion.channels)
        t2 = time.perf_counter()
        z = len(zstandard.ZstdCompressor(level=19).compress(motion.channels.astype("<f4").tobytes()))
        rows.append((path.parent.name, path.name, raw / len(data), raw / z, motion.num_frames, t1 - t0, t2 - t1))
    print(f"{'clip':<14}{'lossless':>9}{'zstd f32':>9}")
    for fmt in ("bvh", "asf_amc"):
        sel = [r for r in rows if r[0] == fmt]
        for r in sel:
            print(f"{r[1]:<14}{r[2]:>9.2f}{r[3]:>9.2f}")
        frames = sum(r[4] for r in sel)
        print(
            f"{fmt}: {len(sel)} clips, median ratio {np.median([r[2] for r in sel]):.2f} (zstd on float32 "
            f"{np.median([r[3] for r in sel]):.2f}); encode {frames / sum(r[5] for r in sel):,.0f} frames/s, "
            f"decode {frames / sum(r[6] for r in sel):,.0f} frames/s\n"
        )


if __name__ == "__main__":
    main()
