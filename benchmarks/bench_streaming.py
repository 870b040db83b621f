"""What a live stream costs: each real-time codec streamed through packets (30 Hz ticks,
keyframes every 0.5 s, 1 s, or never) beside the same codec coding the whole clip, on the
shared BVH and AMC clips: bit rate and mean / max joint error (cm). The stream's rate is what a
viewer receives: data packets with their 48-byte frames, not the one-off stream header (the
skeleton) nor the cut tables that only travel from sender to relay;
and how fast the relay cuts a spiht packet to a viewer's share. Run:
`.venv/bin/python benchmarks/bench_streaming.py [--clips N]`."""

from __future__ import annotations

import argparse
import time

import numpy as np

from common import DATA, SHARED
from mocodec import load
from mocodec.codecs import get_codec
from mocodec.metrics import compare
from mocodec.stream.live import receive_clip, stream_clip

CODECS = ("dpcm", "adpcm", "deadreckoning", "dct", "spiht", "primitives")
REFRESH = (0.5, 1.0, None)


def clips(n: int) -> list:
    if SHARED is None:
        return [load(DATA / "07_03.bvh"), load(DATA / "07_03.amc")]
    bvh = sorted((SHARED / "cmu" / "bvh").glob("*.bvh"))[:n]
    amc = sorted((SHARED / "cmu" / "asf_amc").glob("*.amc"))[:n]
    return [load(p) for p in bvh + amc]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=3, help="clips of each format (default 3)")
    args = ap.parse_args()
    motions = clips(args.clips)
    print(f"{len(motions)} clips; kbit/s and joint error (cm) are medians over the clips")
    print(
        f"{'codec':14s} {'whole clip':>22s} "
        + " ".join(f"{'keyframes ' + (f'{r:g} s' if r else 'never'):>24s}" for r in REFRESH)
    )
    for cid in CODECS:
        codec = get_codec(cid)
        cells = {}
        for key in ("batch",) + REFRESH:
            rates, means, maxes = [], [], []
            for m in motions:
                if key == "batch":
                    size = len(codec.encode(m))
                    decoded = codec.decode(codec.encode(m), m.skeleton, m.num_frames, m.fps)
                else:
                    packets = stream_clip(m, codec, keyframe_s=key or 1e9)
                    size = sum(len(p.without_cuts().to_bytes()) for p in packets[1:])  # what a viewer gets
                    decoded = receive_clip(packets)
                result = compare(m, decoded)
                rates.append(size * 8 / m.duration / 1000)
                means.append(result.joints.mean)
                maxes.append(result.joints.max)
            cells[key] = f"{np.median(rates):6.1f} kb/s {np.median(means):5.2f}/{np.median(maxes):5.2f} cm"
        print(f"{cid:14s} {cells['batch']:>22s} " + " ".join(f"{cells[r]:>24s}" for r in REFRESH))

    m = motions[0]
    hi = get_codec("spiht", bits_per_second=16000)
    enc = hi.encoder(m.skeleton, m.fps)
    packets = enc.push(m.channels) + enc.flush()
    cuts = [hi.packet_cuts(p, m.skeleton) for p in packets]
    reps = 20
    t0 = time.perf_counter()
    cutters = [hi.packet_cutter(p, m.skeleton, c, m.fps) for _ in range(reps) for p, c in zip(packets, cuts)]
    per_parse = (time.perf_counter() - t0) / len(cutters)
    t0 = time.perf_counter()
    for cutter in cutters:
        for rate in (2000, 3000, 4000, 6000):
            cutter(rate)
    per_cut = (time.perf_counter() - t0) / (4 * len(cutters))
    t0 = time.perf_counter()
    for p in packets:
        hi.packet_cuts(p, m.skeleton)
    per_table = (time.perf_counter() - t0) / len(packets)
    print(
        f"spiht packet of {hi.config['window']} frames x {m.skeleton.num_channels} channels at 16 kbit/s, at the "
        f"relay: parsed once in {per_parse * 1e6:.0f} us, then cut to 2-6 kbit/s in {per_cut * 1e6:.0f} us each; "
        f"the sender's cut table: {per_table * 1e6:.0f} us"
    )


if __name__ == "__main__":
    main()
