"""Quality at fixed compression ratios: spiht (each allocation mode of the thesis, and ours,
``impact``, also with closed-loop coding at W = 128, 256 and 512), pwavelet, SZ3 on the whole clip
at once (``sz3-2d``), and SZ3 (pysz, one channel at a time, absolute error bound) in the same
run, on the shared CMU clips.

For each clip and ratio (vs 32-bit floats, whole file: container and skeleton included; SZ3
gets the same compressed skeleton added) the codec's knob is set by rate control and the
decoded motion measured: mean and max joint error (cm), max shell error (cm), PSNR, VPSNR.
Prints one row per (codec, ratio) with medians over clips, and writes every measurement to
bench-out/perceptual-SET[-motion-only].csv.

Run: `.venv/bin/python benchmarks/bench_perceptual.py [--set amc|bvh|all] [--ratios 20 40 60 80]`.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
import zlib

import numpy as np
from pysz import sz, szConfig, szErrorBoundMode

from baselines import sz3_per_channel
from common import ROOT, SHARED
from mocodec import Motion, load, moc, ratecontrol
from mocodec.codecs import get_codec
from mocodec.formats import container
from mocodec.metrics import compare

CODECS = {
    "spiht-perceptual": ("spiht", {"allocation": "perceptual"}),
    "spiht-energy": ("spiht", {"allocation": "energy"}),
    "spiht-uniform": ("spiht", {"allocation": "uniform"}),
    "spiht-impact": ("spiht", {"allocation": "impact"}),
    "spiht-impact-closed": ("spiht", {"allocation": "impact", "closed_loop": True}),
    "spiht-impact-closed-256": ("spiht", {"allocation": "impact", "closed_loop": True, "window": 256}),
    "spiht-impact-closed-512": ("spiht", {"allocation": "impact", "closed_loop": True, "window": 512}),
    "pwavelet": ("pwavelet", {}),
}


def sz3_2d_at_ratio(motion: Motion, ratio: float, with_skeleton: bool = True) -> tuple[Motion, int] | None:
    """SZ3 on the whole clip at once ((channels, frames), time contiguous), translations in
    cm, one absolute bound (degrees / cm), bisected to the ratio: one header per clip instead
    of one per channel."""
    sk = motion.skeleton
    skeleton_bytes = len(zlib.compress(json.dumps(container.skeleton_to_dict(sk)).encode(), 9)) if with_skeleton else 0
    to_common = np.where(sk.rotation_mask, 1.0, 100.0 / sk.units_per_metre)
    data = np.ascontiguousarray((motion.continuous().channels * to_common).T.astype(np.float32))  # time fastest
    target = motion.raw_bits / 8 / ratio
    lo, hi, best = 1e-4, 1e3, None
    for _ in range(40):
        mid = np.sqrt(lo * hi)
        cfg = szConfig()
        cfg.errorBoundMode = szErrorBoundMode.ABS
        cfg.absErrorBound = float(mid)
        comp, _ = sz.compress(data, cfg)
        size = len(comp) + skeleton_bytes
        if size <= target:
            hi, best = mid, (size, sz.decompress(comp, np.float32, data.shape)[0].T / to_common)
            if size >= 0.98 * target:
                break
        else:
            lo = mid
    if best is None:
        return None
    return motion.with_channels(best[1].astype(np.float64)), best[0]


def sz3_at_ratio(motion: Motion, ratio: float, with_skeleton: bool = True) -> tuple[Motion, int] | None:
    """SZ3 per channel with one absolute bound (degrees; cm for translations), bisected to
    the ratio; the compressed skeleton counts towards the size like in a .moc file."""
    sk = motion.skeleton
    skeleton_bytes = len(zlib.compress(json.dumps(container.skeleton_to_dict(sk)).encode(), 9)) if with_skeleton else 0
    target = motion.raw_bits / 8 / ratio

    def run(bound: float):
        size, out = sz3_per_channel(motion, bound)
        return size + skeleton_bytes, out

    lo, hi = 1e-4, 1e3
    best = None
    for _ in range(40):
        mid = np.sqrt(lo * hi)
        size, out = run(mid)
        if size <= target:
            hi, best = mid, (size, out)
            if size >= 0.98 * target:
                break
        else:
            lo = mid
    if best is None:
        return None  # about 100 bytes per channel of SZ3 headers: short clips cannot get there
    return motion.with_channels(best[1]), best[0]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", choices=("amc", "bvh", "all"), default="amc")
    ap.add_argument("--ratios", type=float, nargs="+", default=[20, 40, 60, 80])
    ap.add_argument("--limit", type=int, default=0, help="at most this many clips")
    ap.add_argument(
        "--motion-only",
        action="store_true",
        help="count only the coded motion (no skeleton, no container), as the theses do",
    )
    args = ap.parse_args()
    if SHARED is None:
        print("../shared/data is not here; skipped")
        return
    globs = {"amc": ["asf_amc/*.amc"], "bvh": ["bvh/*.bvh"], "all": ["asf_amc/*.amc", "bvh/*.bvh"]}[args.set]
    clips = [p for g in globs for p in sorted((SHARED / "cmu").glob(g))]
    if args.limit:
        clips = clips[: args.limit]
    out_dir = ROOT / "bench-out"
    out_dir.mkdir(exist_ok=True)
    rows = []
    t0 = time.perf_counter()
    for path in clips:
        motion = load(path)
        for ratio in args.ratios:
            for name, (cid, knobs) in CODECS.items():
                try:
                    m = ratecontrol.tune(
                        get_codec(cid, **knobs), motion, "ratio", ratio, whole_file=not args.motion_only
                    )
                except Exception as e:  # noqa: BLE001 - a codec that cannot reach the ratio is reported
                    rows.append({"clip": path.name, "codec": name, "ratio_target": ratio, "note": str(e)})
                    continue
                decoded, size = moc.unpack(m.data), ratecontrol.coded_size(m.data, not args.motion_only)
                rows.append(_row(path.name, name, ratio, motion, decoded, size))
            for name, run in (("sz3", sz3_at_ratio), ("sz3-2d", sz3_2d_at_ratio)):
                result = run(motion, ratio, with_skeleton=not args.motion_only)
                if result is None:
                    rows.append({"clip": path.name, "codec": name, "ratio_target": ratio, "note": "unreachable"})
                else:
                    rows.append(_row(path.name, name, ratio, motion, *result))
        print(f"{path.name} done ({time.perf_counter() - t0:.0f} s)", flush=True)
    csv_path = out_dir / f"perceptual-{args.set}{'-motion-only' if args.motion_only else ''}.csv"
    with open(csv_path, "w", newline="") as f:
        keys = sorted({k for r in rows for k in r})
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    counted = "coded motion only" if args.motion_only else "whole .moc file, skeleton included"
    print(f"\n{len(clips)} clips ({args.set}); ratios count the {counted}; medians over clips")
    print(f"{'codec':<18}{'target':>7}{'ratio':>7}{'mean cm':>9}{'max cm':>8}{'shell max':>10}{'PSNR':>7}{'VPSNR':>7}")
    for ratio in args.ratios:
        for name in [*CODECS, "sz3", "sz3-2d"]:
            sel = [r for r in rows if r["codec"] == name and r["ratio_target"] == ratio and "mean_cm" in r]
            if not sel:
                print(f"{name:<18}{ratio:>7.0f}   (no clip reached the ratio)")
                continue
            med = {
                k: float(np.median([r[k] for r in sel]))
                for k in ("ratio", "mean_cm", "max_cm", "shell_cm", "psnr", "vpsnr")
            }
            missing = sum(1 for r in rows if r["codec"] == name and r["ratio_target"] == ratio) - len(sel)
            print(
                f"{name:<18}{ratio:>7.0f}{med['ratio']:>7.1f}{med['mean_cm']:>9.3f}{med['max_cm']:>8.2f}"
                f"{med['shell_cm']:>10.2f}{med['psnr']:>7.1f}{med['vpsnr']:>7.1f}"
                + (f"   ({missing} clips could not reach it)" if missing else "")
            )
    print(f"\nwrote {csv_path}")


def _row(clip, codec, target, motion, decoded, size):
    s = compare(motion, decoded).summary()
    return {
        "clip": clip,
        "codec": codec,
        "ratio_target": target,
        "ratio": motion.raw_bits / 8 / size,
        "mean_cm": s["mean_joint_error_cm"],
        "max_cm": s["max_joint_error_cm"],
        "shell_cm": s["max_shell_error_cm"],
        "psnr": s["psnr_db"],
        "vpsnr": s["vpsnr_db"],
    }


if __name__ == "__main__":
    main()
