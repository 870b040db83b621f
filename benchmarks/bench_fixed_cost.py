"""Where a short clip's bytes go: skeleton, header JSON, container framing and coded motion of a
kinwave .moc file at a mean joint error bound (docs/kinwave.md, "Short clips: the fixed cost").

    python benchmarks/bench_fixed_cost.py [--bound 0.5] [CLIP ...]

CLIPs are names in the shared data (default: 05_01.bvh, the median-length BVH clip, and
07_03.amc). The skeleton and the JSON are also deflated on their own, with the file's preset
dictionary, to show their shares of the header.
"""

from __future__ import annotations

import argparse
import io
import json
import zlib

from common import SHARED
from mocodec import load, moc
from mocodec.codecs import get_codec
from mocodec.formats import container
from mocodec.formats.header_dict import DICTIONARIES
from mocodec.formats.skeleton_bin import pack_skeleton


def deflated(data: bytes) -> int:
    z = zlib.compressobj(9, zdict=DICTIONARIES[container.VERSION])
    return len(z.compress(data) + z.flush())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("clips", nargs="*", default=["05_01.bvh", "07_03.amc"])
    ap.add_argument("--bound", type=float, default=0.5, help="mean joint error bound, cm")
    args = ap.parse_args()
    print("clip         frames   file  ratio | header (JSON alone, skeleton alone) | framing | coded motion")
    for name in args.clips:
        motion = load(SHARED / "cmu" / ("bvh" if name.endswith(".bvh") else "asf_amc") / name)
        codec = get_codec("kinwave", max_error_cm=args.bound, error_measure="mean")
        data = moc.pack(motion, codec)
        c = container.open_container(io.BytesIO(data), len(data), name)
        motion_bytes = sum(len(c.read_chunk(k)) for k in range(len(c.index)))
        header = container.read_opening(io.BytesIO(data), len(data), name)[3]
        meta = {
            "codec": codec.get_config(),
            "fps": float(motion.fps),
            "frames": motion.num_frames,
            "chunk_frames": moc.CHUNK_FRAMES,
        }
        text = json.dumps(meta, separators=(",", ":")).encode()
        skeleton = deflated(pack_skeleton(moc.stored_skeleton(motion, codec)))
        print(
            f"{name:12s} {motion.num_frames:6d} {len(data):6d} {motion.raw_bits / 8 / len(data):6.1f} | "
            f"{header:6d} ({deflated(text)}, {skeleton}) | {len(data) - header - motion_bytes:7d} | {motion_bytes:6d}"
        )


if __name__ == "__main__":
    main()
