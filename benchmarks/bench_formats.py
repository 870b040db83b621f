"""glTF and FBX: conversion speed, file sizes and exactness on both sources.

    python benchmarks/bench_formats.py [--clips N]

For the first N clips (sorted; 0 = all) of CMU BVH, CMU ASF/AMC and Bandai Namco: the time to
write and read back a .glb (frames per second, median over the clips), its size against the
source file's and against a kinwave .moc at a max joint error of 1 cm, and the worst joint
error of BVH -> glTF -> BVH (cm). Then the FBX files of ../shared/data/fbx: read time, joints,
frames; and the same clips as zarr arrays (format 3, chunks of 1,024 frames, kinwave at a max
joint error of 1 cm through mocodec.zarr3): raw 32-bit size against the chunks' bytes, and the
worst joint error read back. Speeds are single-core figures on the machine it runs on.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from common import SHARED, shared_sources
from mocodec import load, moc, save
from mocodec.codecs import get_codec


def _clip_figures(path: Path, folder: Path) -> dict:
    motion = load(path)
    glb = folder / "m.glb"
    t0 = time.perf_counter()
    save(motion, glb)
    t1 = time.perf_counter()
    back = load(glb)
    t2 = time.perf_counter()
    save(back, folder / "m.bvh")
    again = load(folder / "m.bvh")
    error = np.abs(motion.positions_m() - again.positions_m()).max() * 100
    moc_bytes = len(moc.pack(motion, get_codec("kinwave", max_error_cm=1.0)))
    return {
        "write_fps": motion.num_frames / (t1 - t0),
        "read_fps": motion.num_frames / (t2 - t1),
        "glb_vs_source": glb.stat().st_size / path.stat().st_size,
        "moc_vs_glb": moc_bytes / glb.stat().st_size,
        "error_cm": error,
    }


def _zarr_figures(paths: list[Path], folder: Path) -> tuple[int, int, float]:
    """(raw float32 bytes, stored chunk bytes, worst joint error in cm) of ``paths`` as zarr arrays."""
    import zarr

    from mocodec.zarr3 import Kinwave

    raw = stored = 0
    worst = 0.0
    for k, path in enumerate(paths):
        motion = load(path)
        where = folder / f"{k}.zarr"
        array = zarr.create_array(
            str(where),
            shape=motion.channels.shape,
            chunks=(1024, motion.num_channels),
            dtype="f4",
            serializer=Kinwave.for_motion(motion, max_error_cm=1.0),
            compressors=None,
        )
        array[:] = motion.channels
        back = zarr.open_array(str(where))[:]
        error = np.linalg.norm(motion.positions_m() - motion.with_channels(back).positions_m(), axis=2).max() * 100
        worst = max(worst, float(error))
        raw += motion.channels.astype("f4").nbytes
        stored += sum(p.stat().st_size for p in (where / "c").rglob("*") if p.is_file())
    return raw, stored, worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clips", type=int, default=8, help="clips per source (0 = all)")
    args = parser.parse_args()
    sources = shared_sources(args.clips)
    print(
        "| source | clips | .glb write (frames/s) | .glb read (frames/s) | .glb / source file | 1 cm .moc / .glb "
        "| worst BVH -> glTF -> BVH error (cm) |"
    )
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, paths in sources.items():
            rows = [_clip_figures(p, Path(tmp)) for p in paths]
            med = {key: float(np.median([r[key] for r in rows])) for key in rows[0]}
            worst = max(r["error_cm"] for r in rows)
            print(
                f"| {name} | {len(rows)} | {med['write_fps']:,.0f} | {med['read_fps']:,.0f} | "
                f"{med['glb_vs_source']:.2f} | {med['moc_vs_glb']:.4f} | {worst:.1e} |"
            )
        print()
        print("| source | clips | raw float32 | zarr chunks (kinwave, 1 cm) | ratio | worst joint error (cm) |")
        print("|---|---|---|---|---|---|")
        for name, paths in sources.items():
            folder = Path(tmp) / "".join(c if c.isalnum() else "_" for c in name)
            folder.mkdir()
            raw, stored, worst = _zarr_figures(paths, folder)
            print(f"| {name} | {len(paths)} | {raw:,} | {stored:,} | {raw / stored:.1f} | {worst:.4f} |")
    print()
    print("| FBX file | joints | frames | fps | read (s) |")
    print("|---|---|---|---|---|")
    for path in sorted((SHARED / "fbx").glob("*.fbx")):
        t0 = time.perf_counter()
        motion = load(path)
        print(
            f"| {path.name} | {len(motion.skeleton)} | {motion.num_frames} | {motion.fps:g} | "
            f"{time.perf_counter() - t0:.2f} |"
        )


if __name__ == "__main__":
    main()
