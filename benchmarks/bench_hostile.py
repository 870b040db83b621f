"""What hostile inputs cost (docs/security.md): the crafted files and headers that once took
seconds or gigabytes, each timed with the peak memory it adds (tracemalloc), and a native-decoder
body decoded in its child process against in this one.

    python benchmarks/bench_hostile.py
"""

from __future__ import annotations

import time
import tracemalloc
import zlib

import numpy as np

from common import DATA, best_of, options
from mocodec import limits, load, moc
from mocodec.codecs import get_codec
from mocodec.errors import MocodecError
from mocodec.formats import container
from mocodec.formats.skeleton_bin import pack_skeleton
from mocodec.skeleton import Joint, Skeleton
from mocodec.stream.packets import StreamInfo


def outcome_of(fn) -> str:
    try:
        fn()
        return "ok"
    except MocodecError as e:
        return f"refused: {str(e)[:70]}"


def measured(what: str, fn) -> None:
    """Timed on its own, then run again under tracemalloc for the peak (which slows it)."""
    t0 = time.perf_counter()
    outcome = outcome_of(fn)
    seconds = time.perf_counter() - t0
    tracemalloc.start()
    outcome_of(fn)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(f"{what:<44} {seconds * 1000:9.1f} ms  {peak / 2**20:8.1f} MiB  {outcome}")


def main() -> None:
    options(__doc__)
    import tempfile
    from pathlib import Path

    folder = Path(tempfile.mkdtemp())
    ends = "".join("\tEnd Site\n\t{\n\t\tOFFSET 0 1 0\n\t}\n" for _ in range(16_000))
    (folder / "ends.bvh").write_text(
        "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 3 Xposition Yposition "
        f"Zposition\n{ends}}}\nMOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0\n"
    )
    rng = np.random.default_rng(1)
    big = Skeleton([Joint(f"j{i}", i - 1 if i else -1, tuple(rng.normal(size=3))) for i in range(4001)])
    walk = load(DATA / "07_03.bvh")

    print(f"{'input':<44} {'time':>12}  {'peak':>12}  outcome")
    measured("BVH, 16,000 End Sites under one joint", lambda: load(folder / "ends.bvh"))
    measured("compact skeleton of 4,001 joints (pack)", lambda: pack_skeleton(big))
    measured("compact skeleton of 2,001 joints (pack)", lambda: pack_skeleton(Skeleton(big.joints[:2001])))
    bomb = zlib.compress(b" " * (900 << 20), 9)
    measured(f"stream header bomb ({len(bomb) / 1e6:.2f} MB -> 900 MB)", lambda: StreamInfo.from_payload(bomb))
    head = container.opening(container.VERSION, 0, len(bomb)) + bomb + zlib.crc32(bomb).to_bytes(4, "little")
    measured(".moc header bomb (same)", lambda: moc.unpack(head + bytes(40)))
    claim = container.pack(
        {
            "codec": get_codec("kinwave").get_config(),
            "fps": 120.0,
            "frames": 1 << 20,
            "chunk_frames": 1 << 20,
            "skeleton": walk.skeleton,
        },
        [container.Chunk(0, 1 << 20, bytes(8))],
    )
    measured(f".moc of {len(claim):,} bytes claiming 2**20 frames", lambda: moc.unpack(claim))
    try:
        fpzip = moc.pack(walk, get_codec("fpzip"))
    except MocodecError:
        print("fpzip not installed (pip install 'mocodec[bench]'): no native-decoder timing")
        return
    inside = best_of(lambda: moc.unpack(fpzip, codec=get_codec("fpzip")), 5)
    child = best_of(lambda: moc.unpack(fpzip), 5)
    print(
        f"fpzip decode of {walk.num_frames} frames: {inside * 1000:.1f} ms in this process (trusted), "
        f"{child * 1000:.1f} ms in a child (untrusted), limit {limits.MAX_DECODED_VALUES:,} values"
    )


if __name__ == "__main__":
    main()
