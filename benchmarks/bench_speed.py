"""kinwave's speed and bytes at each effort level, per source, on real clips (none tiled).

For each source (CMU BVH, CMU ASF/AMC, Bandai Namco, and the CMU BVH clips resampled to 24 fps
as a stand-in for game-engine exports) and each effort level: encode frames/s over all frames,
on the median clip and on the slowest clip (each clip's time the least of ENCODE_ROUNDS
encodings); decode frames/s over all frames (each clip's time the least of DECODE_ROUNDS
decodings); total bytes
against the highest level. Then kinwave-live's encode frames/s with 1 and 3 layers, and the first use's
compile time (a fresh process, the numba cache dropped).

    NUMBA_NUM_THREADS=1 python benchmarks/bench_speed.py [--clips N] [--bound CM] [--measure joint|shell]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

from common import shared_sources
from mocodec import load
from mocodec.codecs import codec_class, get_codec
from mocodec.codecs.kinwave import kinalloc

_EFFORT = next(k for k in codec_class("kinwave").knobs if k.name == "effort")
LEVELS = tuple(range(int(_EFFORT.low), int(_EFFORT.high) + 1))
#: Each clip's decode time is the least of this many decodings: one takes a fraction of a
#: millisecond, which another job on a shared machine can stretch several times.
DECODE_ROUNDS = 3
#: Each clip's encode time is the least of this many encodings (the same bytes each time):
#: one encoding of a short clip takes milliseconds, which another job can stretch as much.
ENCODE_ROUNDS = 2


def _sources(clips: int) -> dict:
    paths = shared_sources(clips)
    motions = {name: [load(p) for p in found] for name, found in paths.items()}
    motions["CMU BVH at 24 fps"] = [m[::5] for m in motions["CMU BVH"]]  # 120 fps / 5
    return motions


def _encode_all(codec, motions) -> tuple[int, list[float], list[bytes]]:
    bodies, seconds = [], []
    for m in motions:
        times, encoded = [], set()
        for _ in range(ENCODE_ROUNDS):
            t0 = time.perf_counter()
            encoded.add(codec.encode(m))
            times.append(time.perf_counter() - t0)
        if len(encoded) != 1:
            raise SystemExit(f"{codec.id}: two encodings of the same clip differ")
        bodies.append(encoded.pop())
        seconds.append(min(times))
    return sum(map(len, bodies)), seconds, bodies


def _row(name: str, level: int, motions, codec, top_bytes: int | None) -> tuple[int, str]:
    total, seconds, bodies = _encode_all(codec, motions)
    frames = [m.num_frames for m in motions]
    rates = [f / s for f, s in zip(frames, seconds)]
    decode_seconds = [float("inf")] * len(motions)
    for _ in range(DECODE_ROUNDS):
        for k, (m, body) in enumerate(zip(motions, bodies)):
            t0 = time.perf_counter()
            codec.decode(body, m.skeleton, m.num_frames, m.fps)
            decode_seconds[k] = min(decode_seconds[k], time.perf_counter() - t0)
    decode = sum(frames) / sum(decode_seconds)
    versus = f"{100.0 * (total / top_bytes - 1):+.1f}%" if top_bytes else "(highest)"
    return total, (
        f"| {name} | {level} | {sum(frames) / sum(seconds):,.0f} | {statistics.median(rates):,.0f} | "
        f"{min(rates):,.0f} | {decode:,.0f} | {total:,} | {versus} |"
    )


def _live(motions, layers: int) -> float:
    codec = get_codec("kinwave-live", layers=layers)
    frames, seconds = 0, 0.0
    for m in motions:
        t0 = time.perf_counter()
        encoder = codec.encoder(m.skeleton, m.fps)
        encoder.push(m.channels)
        encoder.flush()
        seconds += time.perf_counter() - t0
        frames += m.num_frames
    return frames / seconds


def _first_use() -> float:
    """Seconds a fresh process takes to encode a second of a clip, its kernels compiled anew
    (numba's cache in an empty folder)."""
    script = (
        "import time; t = time.perf_counter()\n"
        "from mocodec import load; from mocodec.codecs import get_codec; from common import DATA\n"
        "get_codec('kinwave').encode(load(DATA / '07_03.bvh')[:120])\n"
        "print(time.perf_counter() - t)"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=sys.path[0], env=env)
    return float(done.stdout.strip() or "nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=0, help="clips per source (0: all)")
    parser.add_argument("--bound", type=float, default=0.5, help="max error bound, cm (default 0.5)")
    parser.add_argument("--measure", default="joint", choices=("joint", "shell"))
    parser.add_argument("--live-clips", type=int, default=8, help="kinwave-live's clips per source (8; 0: none)")
    args = parser.parse_args()
    motions = _sources(args.clips)
    warm = get_codec("kinwave")
    warm.encode(motions["CMU BVH"][0][:64])  # compile (or load) the kernels before timing
    print(f"kinwave, max {args.measure} error {args.bound} cm, one core\n")
    print("| source | effort | encode f/s, all | median clip | slowest clip | decode f/s | bytes | vs highest |")
    print("|---|---|---|---|---|---|---|---|")
    for name, clips in motions.items():
        top = None
        for level in sorted(LEVELS, reverse=True):
            codec = get_codec("kinwave", max_error_cm=args.bound, error_measure=args.measure, effort=level)
            kinalloc.steps.cache_clear()  # each level pays the allocation of each skeleton, as a new process does
            total, line = _row(name, level, clips, codec, top)
            top = top or total
            print(line, flush=True)
    if args.live_clips:
        print("\n| source | kinwave-live, 1 layer, f/s | 3 layers, f/s |\n|---|---|---|")
    for name, clips in motions.items() if args.live_clips else ():
        some = clips[: args.live_clips]
        _live(some[:1], 3)  # (loads the kernels and this skeleton's tables before the clock)
        print(f"| {name} ({len(some)} clips) | {_live(some, 1):,.0f} | {_live(some, 3):,.0f} |", flush=True)
    print(f"\nfirst use (a fresh process, kernels compiled anew): {_first_use():.1f} s")


if __name__ == "__main__":
    main()
