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
from mocodec.bench.published import APPENDIX_III, APPENDIX_III_DOFS, APPENDIX_III_FPS
from mocodec.codecs import get_codec
from mocodec.codecs.shared import vqbook
from mocodec.metrics import compare


def thesis_rows(codec: str, knob: str, unprinted: tuple = ()) -> list[tuple]:
    """(codec, knobs, thesis conversation bit/s, thesis PSNR dB) per Appendix III row, then the
    settings the thesis leaves empty."""
    rows = [(codec, {knob: v}, r, p) for v, r, p in APPENDIX_III[codec]]
    return rows + [(codec, {knob: v}, None, None) for v in unprinted]


def vq_rows(codec: str) -> list[tuple]:
    return [(codec, {"size": n, "predictive": p}, r, q) for p in (False, True) for n, r, q in APPENDIX_III[codec]]


GRID = [
    *thesis_rows("quant", "levels"),
    *thesis_rows("dpcm", "levels"),
    *thesis_rows("adpcm", "levels", (128, 256)),
    *thesis_rows("deadreckoning", "threshold"),
    *thesis_rows("dct", "table"),
    # 7.8.2 prints no table: the thesis found the time-frequency coders "roughly the same as the DCT"
    *[("subband", {"step": s}, None, None) for s in (0.32, 0.16, 0.08, 0.04, 0.02)],
    *[("subband", {"step": s, "emphasis": e}, None, None) for e in (0.0, 1.0) for s in (0.16, 0.08, 0.04)],
    *[("subband", {"variant": "wavelet", "keep": m, "step": 0.04}, None, None) for m in (2, 4, 8)],
    # VQ codebooks are trained on every other clip and evaluated on the others (held out)
    *vq_rows("svq"),
    *vq_rows("tvq"),
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
        f"thesis: conversation sequence, about {APPENDIX_III_DOFS} DOFs (the clips differ)"
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
        per_dof = t_rate / APPENDIX_III_FPS / APPENDIX_III_DOFS if t_rate else 0.0
        thesis = f"{t_rate:.0f} | {per_dof:.2f} | {t_psnr:.1f}" if t_rate else "not printed | | "
        print(
            f"| {cid} | {setting} | {1000 * codec.delay_frames() / 30:.0f} | {med[0]:.0f} | {med[1]:.2f} | "
            f"{med[2]:.1f} | {med[3]:.1f} | {med[4]:.2f} | {thesis} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
