"""Encode and decode speed of every codec on one core, 10,000 frames x 62 channels at 120 fps
(CMU 135_08 tiled), and the first call's time in a fresh process, imports included: with the
numba cache in place, and compiling every kernel from scratch. The VQ coders use codebooks
trained beforehand on another clip (07_03), so LBG training is not timed; their first call
trains on the clip. primitives uses a database trained on 07_03 as well; rhythmic makes its
primitives from the clip, as by default. Run: `.venv/bin/python benchmarks/bench_codec_speed.py
[--codecs ID ...]`."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from common import DATA, best_of, tile  # noqa: E402
from mocodec import load  # noqa: E402
from mocodec.codecs import codec_ids, get_codec  # noqa: E402
from mocodec.codecs.motionprimitives import primdb
from mocodec.codecs.shared import vqbook

FRAMES = 10_000
SETTINGS = {"pwavelet": {"alpha": 0.02}, "spiht": {"bits_per_second": 4000}}
FIRST_CALL = """
import time, numpy as np
t0 = time.perf_counter()
from mocodec import load
from mocodec.codecs import get_codec
m = load({path!r})[:256]
c = get_codec({cid!r})
c.decode(c.encode(m), m.skeleton, m.num_frames, m.fps)
print(time.perf_counter() - t0)
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--codecs", nargs="*", help="only these codecs")
    args = ap.parse_args()
    clip = load(DATA / "135_08.amc")
    books = tempfile.mkdtemp()
    training = [load(DATA / "07_03.amc")]
    for cid, kind in (("svq", "spatial"), ("tvq", "temporal")):
        path = os.path.join(books, f"{cid}.mocvq")
        vqbook.train(kind, training, [32, 256]).save(path)
        SETTINGS[cid] = {"codebook": path}
    primdb.train(training).save(os.path.join(books, "primitives.mocdb"))
    SETTINGS["primitives"] = {"db": os.path.join(books, "primitives.mocdb")}
    motion = tile(clip, FRAMES)
    print(f"{FRAMES} frames x {motion.num_channels} channels; frames per second, best of 3")
    print(f"{'codec':<14}{'encode':>12}{'decode':>12}{'ratio':>8}{'first call: cached':>20}{'compiling':>11}")
    for cid in codec_ids():
        if cid.startswith("test") or (args.codecs and cid not in args.codecs):
            continue
        codec = get_codec(cid, **SETTINGS.get(cid, {}))
        payload = codec.encode(motion)
        enc = best_of(lambda: codec.encode(motion), 3)
        dec = best_of(lambda: codec.decode(payload, motion.skeleton, motion.num_frames, motion.fps), 3)
        script = FIRST_CALL.format(path=str(DATA / "135_08.amc"), cid=cid)
        cached = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True).stdout.strip()
        with tempfile.TemporaryDirectory() as empty:
            cold = subprocess.run(
                [sys.executable, "-c", script],
                capture_output=True,
                text=True,
                env={**os.environ, "NUMBA_CACHE_DIR": empty},
            ).stdout.strip()
        print(
            f"{cid:<14}{FRAMES / enc:>12,.0f}{FRAMES / dec:>12,.0f}{motion.raw_bits / 8 / len(payload):>8.1f}"
            f"{float(cached):>18.2f} s{float(cold):>9.2f} s"
        )


if __name__ == "__main__":
    main()
