"""Rate-distortion of the waveform coders of 000 ch. 7 over the thesis's parameter grids
(Appendix III), on the shared clips resampled to 30 Hz (the thesis's rate), beside the
thesis's own figures for the same setting.

The clips differ: the thesis coded its own four sequences (conversation, wave, dance,
gestures) on an 80-DOF model of which about 52 DOFs move; ours are CMU clips (AMC: 62
channels, BVH: 132). Rates are therefore compared per DOF-sample as well as per second. The
thesis's column is its conversation sequence (whole body). PSNR is the whole-body average of
000 ch. 6 (docs/measures.md). Medians over the clips. The VQ coders' codebooks are trained on
every other clip and measured on the rest (the thesis does not say it held clips out).

    python benchmarks/bench_waveform.py [--set amc|bvh] [--limit N] [--codecs ID ...]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from common import SHARED
from mocodec import load
from mocodec.codecs import get_codec
from mocodec.codecs.shared import vqbook
from mocodec.metrics import compare

THESIS_DOFS = 52
# (codec, knobs, thesis conversation bit/s, thesis PSNR dB) per Appendix III row
GRID = [
    *[
        ("quant", {"levels": n}, r, p)
        for n, r, p in (
            (8, 4454.8, 9.9),
            (16, 6135.6, 16.7),
            (32, 7812.9, 23.0),
            (64, 9476.0, 29.1),
            (128, 11062.1, 35.2),
            (256, 12526.4, 41.3),
        )
    ],
    *[
        ("dpcm", {"levels": n}, r, p)
        for n, r, p in (
            (4, 2356.5, 13.4),
            (8, 3548.7, 24.1),
            (16, 5285.1, 31.1),
            (32, 7090.6, 38.1),
            (64, 8897.8, 44.7),
            (128, 10594.6, 51.0),
            (256, 12141.0, 57.3),
        )
    ],
    *[
        ("adpcm", {"levels": n}, r, p)
        for n, r, p in (
            (4, 2939.8, 10.7),
            (8, 3325.4, 23.2),
            (16, 4048.2, 31.4),
            (32, 5267.9, 38.7),
            (64, 6784.6, 44.1),
            (128, None, None),
            (256, None, None),
        )
    ],
    *[
        ("deadreckoning", {"threshold": t}, r, p)
        for t, r, p in (
            (1.6, 2567.3, 4.4),
            (0.8, 4049.3, 9.2),
            (0.4, 5967.0, 13.5),
            (0.2, 8344.5, 18.3),
            (0.1, 10884.5, 22.4),
            (0.05, 13048.7, 28.0),
            (0.025, 14996.4, 33.1),
            (0.0125, 16140.5, 35.5),
        )
    ],
    *[
        ("dct", {"table": i}, r, p)
        for i, r, p in ((0, 1669.5, 20.0), (1, 2507.8, 24.8), (2, 3295.5, 28.3), (3, 4019.4, 30.5), (4, 4784.7, 31.1))
    ],
    # 7.8.2 prints no table: the thesis found the time-frequency coders "roughly the same as the DCT"
    *[("subband", {"step": s}, None, None) for s in (0.32, 0.16, 0.08, 0.04, 0.02)],
    *[("subband", {"step": s, "emphasis": e}, None, None) for e in (0.0, 1.0) for s in (0.16, 0.08, 0.04)],
    *[("subband", {"variant": "wavelet", "keep": m, "step": 0.04}, None, None) for m in (2, 4, 8)],
    # VQ codebooks are trained on every other clip and evaluated on the others (held out)
    *[
        ("svq", {"size": n, "predictive": p}, r, q)
        for p in (False, True)
        for n, r, q in (
            (16, 747.3, -0.8),
            (32, 959.6, 0.5),
            (64, 1519.1, 1.7),
            (128, 2145.1, 3.2),
            (256, 2569.6, 4.6),
            (512, 2910.3, 6.1),
        )
    ],
    *[
        ("tvq", {"size": n, "predictive": p}, r, q)
        for p in (False, True)
        for n, r, q in (
            (16, 988.4, 7.5),
            (32, 1254.7, 10.0),
            (64, 1586.8, 12.7),
            (128, 1972.5, 15.3),
            (256, 2412.3, 18.4),
            (512, 2906.4, 22.0),
        )
    ],
]
VQ_KIND = {"svq": "spatial", "tvq": "temporal"}


def trained_codebooks(clips, folder: Path) -> dict[tuple[str, bool], str]:
    """Codebook files for svq and tvq, both modes, trained on ``clips``."""
    out = {}
    for cid, kind in VQ_KIND.items():
        for predictive in (False, True):
            path = folder / f"{cid}_{int(predictive)}.mocvq"
            vqbook.train(kind, clips, [16, 32, 64, 128, 256, 512], predictive=predictive).save(path)
            out[cid, predictive] = str(path)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", choices=("amc", "bvh"), default="amc")
    ap.add_argument("--limit", type=int, default=0, help="only the first N clips")
    ap.add_argument("--codecs", nargs="*", help="only these codecs")
    args = ap.parse_args()
    folder = SHARED / "cmu" / ("asf_amc" if args.set == "amc" else "bvh")
    paths = sorted(folder.glob("*.amc" if args.set == "amc" else "*.bvh"))
    paths = paths[: args.limit] if args.limit else paths
    clips = [load(p).resample(30.0) for p in paths]
    held_out = clips[1::2]
    books = trained_codebooks(clips[0::2], Path(tempfile.mkdtemp()))
    print(
        f"{len(clips)} {args.set.upper()} clips at 30 Hz, {clips[0].num_channels} channels; "
        f"thesis: conversation sequence, about {THESIS_DOFS} DOFs (the clips differ)"
    )
    print(
        "| codec | setting | delay ms | bit/s | bits/DOF-sample | PSNR dB | VPSNR dB | mean joint cm | "
        "thesis bit/s | thesis bits/DOF-sample | thesis PSNR dB |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for cid, knobs, t_rate, t_psnr in GRID:
        if args.codecs and cid not in args.codecs:
            continue
        vq = cid in VQ_KIND
        codec = get_codec(cid, **knobs, **({"codebook": books[cid, knobs["predictive"]]} if vq else {}))
        rows = []
        for clip in held_out if vq else clips:
            payload = codec.encode(clip)
            s = compare(clip, codec.decode(payload, clip.skeleton, clip.num_frames, clip.fps)).summary()
            bps = len(payload) * 8 / clip.duration
            rows.append(
                (bps, bps / clip.fps / clip.num_channels, s["psnr_db"], s["vpsnr_db"], s["mean_joint_error_cm"])
            )
        med = np.median(np.array(rows), axis=0)
        setting = ", ".join(f"{k}={v}" for k, v in knobs.items())
        thesis = f"{t_rate:.0f} | {t_rate / 30 / THESIS_DOFS:.2f} | {t_psnr:.1f}" if t_rate else "not printed | | "
        print(
            f"| {cid} | {setting} | {1000 * codec.delay_frames / 30:.0f} | {med[0]:.0f} | {med[1]:.2f} | "
            f"{med[2]:.1f} | {med[3]:.1f} | {med[4]:.2f} | {thesis} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
