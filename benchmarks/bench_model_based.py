"""The model-based coders of 000 ch. 8 measured: VPSNR and mean joint error against bits per
second, beside the thesis's Appendix III figures, and their speed.

Tables are trained (``mocodec tables``, spacing 10 cm, discard 5 degrees) on every other shared
clip of a format and the codecs evaluated on the remaining clips, never on a training clip,
resampled to 30 Hz like the thesis. Per knob setting: the median over the evaluation clips of
bits per second (whole payload, tables not counted: both ends hold them), VPSNR and mean joint
position error, for all of them and for the dance clips (subjects 5, 60, 61, 94, 131), and the
coding delay (mean over clips of the mean, and the largest). The thesis's dance column of
Appendix III stands beside: posture d = 80 ... 10, gesture (its per-group parameter sets
0-5), hybrid bit allocations 0-7.

Speed: encode and decode frames per second with the tables loaded, on the longest evaluation
clip of each format at 120 Hz, best of 3.

Run: `.venv/bin/python benchmarks/bench_model_based.py` (about two minutes).
"""

from __future__ import annotations

import os
import tempfile
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from common import SHARED, best_of, options  # noqa: E402
from mocodec import load  # noqa: E402
from mocodec.codecs import get_codec  # noqa: E402
from mocodec.codecs.model import motiontables
from mocodec.metrics import compare  # noqa: E402

DANCERS = ("05", "60", "61", "94", "131")
POSTURE_D = (80.0, 40.0, 26.6667, 20.0, 16.0, 13.3333, 10.0)
GESTURE_E = (20.0, 10.0, 5.0, 2.0, 1.0)
THESIS_DANCE = {  # Appendix III, dance sequence: (bit/s, VPSNR dB) per parameter index
    "posture": [(67.7, 3.8), (101.2, 6.5), (317.2, 7.3), (440.5, 7.5), (566.8, 7.8), (666.5, 8.2), (762.8, 8.5)],
    "gesture": [(145.1, 4.1), (165.5, 5.5), (214.3, 7.8), (293.3, 11.5), (310.2, 12.4), (336.7, 13.3)],
    "hybrid": [
        (749.7, 10.8),
        (1034.0, 13.7),
        (1194.5, 15.0),
        (1313.0, 15.7),
        (1413.5, 16.2),
        (1497.2, 16.5),
        (1573.2, 16.7),
        (1640.3, 16.9),
    ],
}


def split(fmt: str, suffix: str) -> tuple[list, list]:
    paths = sorted((SHARED / "cmu" / fmt).glob(f"*.{suffix}"))
    return paths[0::2], paths[1::2]


def is_dance(path) -> bool:
    return path.stem.split("_")[0] in DANCERS


def sweep(codec_id: str, knob: str, values, clips, tables: str | None) -> list[str]:
    rows = []
    for v in values:
        extra = {"tables": tables} if tables else {}
        codec = get_codec(codec_id, **{knob: v}, **extra)
        stats = []
        for path, clip in clips:
            data = codec.encode(clip)
            s = compare(clip, codec.decode(data, clip.skeleton, clip.num_frames, clip.fps)).summary()
            delay = codec.delays(clip) / clip.fps
            stats.append(
                (
                    is_dance(path),
                    len(data) * 8 / clip.duration,
                    s["vpsnr_db"],
                    s["mean_joint_error_cm"],
                    delay.mean(),
                    delay.max(),
                )
            )
        a = np.array(stats)
        dance = a[a[:, 0] == 1]
        rows.append(
            f"  {knob}={v:<8g} all: {np.median(a[:, 1]):7.0f} bit/s {np.median(a[:, 2]):5.1f} dB "
            f"{np.median(a[:, 3]):5.1f} cm | dance: {np.median(dance[:, 1]):7.0f} bit/s "
            f"{np.median(dance[:, 2]):5.1f} dB {np.median(dance[:, 3]):5.1f} cm | delay "
            f"{a[:, 4].mean():4.2f} / {a[:, 5].max():4.2f} s"
        )
    return rows


def speed(codec_id: str, clip, tables: str | None) -> str:
    codec = get_codec(codec_id, **({"tables": tables} if tables else {}))
    data = codec.encode(clip)
    codec.decode(data, clip.skeleton, clip.num_frames, clip.fps)
    enc = best_of(lambda: codec.encode(clip), 3)
    dec = best_of(lambda: codec.decode(data, clip.skeleton, clip.num_frames, clip.fps), 3)
    n = clip.num_frames
    return f"  {codec_id:<8} encode {n / enc:8,.0f} f/s  decode {n / dec:8,.0f} f/s  ({n:,} frames at {clip.fps:g} Hz)"


def main() -> None:
    options(__doc__)
    folder = tempfile.mkdtemp()
    t_start = time.perf_counter()
    for fmt, suffix in (("bvh", "bvh"), ("asf_amc", "amc")):
        train, test = split(fmt, suffix)
        tables = os.path.join(folder, f"{fmt}.moctb")
        t0 = time.perf_counter()
        motiontables.train(
            [load(p) for p in train], spacing_cm=10.0, discard_deg=5.0, names=[p.name for p in train]
        ).save(tables)
        info = motiontables.Tables.load(tables)
        print(
            f"{fmt}: tables from {len(train)} clips in {time.perf_counter() - t0:.1f} s, "
            f"{os.path.getsize(tables):,} bytes; {info.describe()}"
        )
        full = [(p, load(p)) for p in test]
        clips = [(p, m.resample(30)) for p, m in full]
        print(f"evaluated on {len(clips)} clips at 30 Hz ({sum(is_dance(p) for p, _ in clips)} dance)")
        for codec_id, knob, values, with_tables in (
            ("posture", "d", POSTURE_D, True),
            ("gesture", "e", GESTURE_E, True),
            ("hybrid", "level", range(8), False),
        ):
            print(
                f"{codec_id} (thesis, dance: "
                + ", ".join(f"{r:g} bit/s {q:g} dB" for r, q in THESIS_DANCE[codec_id])
                + ")"
            )
            print("\n".join(sweep(codec_id, knob, values, clips, tables if with_tables else None)))
        longest = max(full, key=lambda pm: pm[1].num_frames)[1]
        print("speed, tables loaded:")
        for codec_id in ("posture", "gesture", "hybrid"):
            print(speed(codec_id, longest, tables if codec_id != "hybrid" else None))
        print()
    print(f"wall time {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    main()
