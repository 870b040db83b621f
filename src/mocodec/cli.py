"""The ``mocodec`` command line: ``info``, ``convert`` and ``demo``.

User errors (bad files, impossible conversions) print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np

from mocodec import __version__
from mocodec.errors import MocodecError
from mocodec.formats import load, save
from mocodec.motion import Motion


def _human_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"  # pragma: no cover


def describe(motion: Motion, path: str) -> str:
    """The ``info`` summary of a motion."""
    sk = motion.skeleton
    parts: dict[str, int] = {}
    for i, part in enumerate(sk.body_parts):
        parts[part] = parts.get(part, 0) + len(sk.joints[i].channels)
    pos = motion.positions_m()
    height = float(np.ptp(sk.rest_positions[:, 1])) / sk.units_per_metre
    lines = [
        f"file        {path}",
        f"skeleton    {len(sk)} joints ({int(sk.end_sites.sum())} end sites), {sk.num_channels} channels "
        f"({int(sk.rotation_mask.sum())} rotation, {int((~sk.rotation_mask).sum())} translation)",
        f"units       {sk.units_per_metre:.6g} per metre; rest-pose height {height:.2f} m",
        f"frames      {motion.num_frames} at {motion.fps:g} fps = {motion.duration:.2f} s",
        f"raw size    {_human_bytes(motion.raw_bits / 8)} at 32-bit floats, "
        f"{motion.raw_bitrate / 1000:.1f} kbit/s",
        f"root path   {np.linalg.norm(np.diff(pos[:, 0, [0, 2]], axis=0), axis=1).sum():.2f} m horizontal",
        "body parts  " + ", ".join(f"{p} {n}" for p, n in parts.items() if n),
    ]
    return "\n".join(lines)


def cmd_info(args) -> int:
    for path in args.files:
        motion = load(path, asf=args.asf, fps=args.fps)
        print(describe(motion, path))
        if args.joints:
            sk = motion.skeleton
            print(f"{'joint':<22}{'parent':<18}{'part':<12}{'depth':>5}{'bone m':>9}  channels")
            for i, j in enumerate(sk.joints):
                parent = sk.names[j.parent] if j.parent >= 0 else "-"
                print(f"{j.name:<22}{parent:<18}{sk.body_parts[i]:<12}{sk.chain_depths[i]:>5}"
                      f"{sk.bone_lengths[i] / sk.units_per_metre:>9.3f}  {' '.join(j.channels)}")
        if len(args.files) > 1:
            print()
    return 0


def cmd_convert(args) -> int:
    motion = load(args.input, asf=args.asf, fps=args.fps)
    written = save(motion, args.output, asf=args.out_asf)
    print(f"wrote {', '.join(str(p) for p in written)} ({motion.num_frames} frames)")
    return 0


def cmd_demo(args) -> int:
    """Load the bundled sample, run forward kinematics, round-trip it through BVH and AMC."""
    import tempfile

    sample = resources.files("mocodec") / "data" / "sample_walk_02_02.bvh"
    with resources.as_file(sample) as path:
        t0 = time.perf_counter()
        motion = load(path)
        t_load = time.perf_counter() - t0
        print(describe(motion, f"(bundled) {Path(path).name}"))
    t0 = time.perf_counter()
    pos = motion.positions_m()
    t_fk = time.perf_counter() - t0
    print(f"\nparse       {t_load * 1e3:.1f} ms; forward kinematics {t_fk * 1e3:.1f} ms "
          f"({motion.num_frames * len(motion.skeleton) / max(t_fk, 1e-9) / 1e6:.1f} M joint-frames/s)")
    with tempfile.TemporaryDirectory() as tmp:
        for ext in (".bvh", ".amc"):
            out = Path(tmp) / f"roundtrip{ext}"
            save(motion, out)
            back = load(out)
            names = [n for n in motion.skeleton.names if n in back.skeleton.names]
            a = pos[:, [motion.skeleton.index(n) for n in names]]
            b = back.positions_m()[:, [back.skeleton.index(n) for n in names]]
            size = sum(p.stat().st_size for p in Path(tmp).glob(f"roundtrip.*") if p.suffix in (ext, ".asf"))
            print(f"round trip  {ext[1:].upper():<4} {_human_bytes(size):>9}  max joint error "
                  f"{np.abs(a - b).max() * 1000:.4f} mm over {len(names)} joints")
    print("\nCodecs arrive with the codec framework; `mocodec --help` lists what is here now.")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mocodec", description="Coding of human motion capture (BVH, ASF/AMC).")
    parser.add_argument("--version", action="version", version=f"mocodec {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def common(p):
        p.add_argument("--asf", help="ASF skeleton of an .amc input (default: <subject>.asf beside it)")
        p.add_argument("--fps", type=float, help="frame rate of an .amc input (default 120, the CMU rate)")

    p = sub.add_parser("info", help="summarise motion files", description="Skeleton, frames, rate, duration, "
                       "channels, raw size and bit rate at 32-bit floats.")
    p.add_argument("files", nargs="+", metavar="FILE", help=".bvh or .amc file")
    p.add_argument("--joints", action="store_true", help="also list every joint")
    common(p)
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="convert between BVH and ASF/AMC",
                       description="Convert a motion file; the pose of every frame is kept exactly. "
                                   "Writing .amc also writes its .asf (same stem unless --out-asf).")
    p.add_argument("input", metavar="IN", help=".bvh or .amc file")
    p.add_argument("output", metavar="OUT", help=".bvh or .amc file to write")
    p.add_argument("--out-asf", help="where to write the ASF when OUT is .amc")
    common(p)
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("demo", help="run the main job on the bundled sample clip",
                       description="Load the bundled CMU walk, run forward kinematics and round-trip it "
                                   "through BVH and ASF/AMC, reporting sizes, errors and speed.")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except MocodecError as e:
        print(f"mocodec: error: {e}", file=sys.stderr)
        return 2
    except (OSError, ValueError) as e:
        print(f"mocodec: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
