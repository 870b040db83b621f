"""Does Blender's BVH importer see the motion mocodec read? A real client's check of ``convert``.

Each file is read by mocodec and written as BVH; Blender (``bpy``, in its own Python 3.11 venv:
``pip install 'bpy==4.2.*'``) imports that BVH, and the distances between every two joints, at
every frame, are compared with mocodec's (distances do not depend on Blender's axis convention).

    python benchmarks/blender_bvh_check.py --blender-python /path/to/bpy-venv/bin/python FILE...
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path


def _blender_side(bvh: str, out: str) -> None:
    """In Blender: import ``bvh``, write every bone head's world position at every frame."""
    import bpy  # noqa: PLC0415 - only in Blender's Python

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=bvh, update_scene_fps=True, update_scene_duration=True)
    ob = bpy.context.object
    scene = bpy.context.scene
    names = [b.name for b in ob.pose.bones]
    frames = []
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        frames.append([list(ob.matrix_world @ ob.pose.bones[n].head) for n in names])
    Path(out).write_text(json.dumps({"names": names, "frames": frames}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*")
    parser.add_argument("--blender-python", help="the Python of a venv with bpy")
    parser.add_argument("--blender-side", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.blender_side:
        _blender_side(*args.blender_side)
        return
    import numpy as np

    from mocodec import load, save

    for path in args.files:
        with tempfile.TemporaryDirectory() as folder:
            bvh, dump = Path(folder) / "m.bvh", Path(folder) / "m.json"
            motion = load(path)
            save(motion, bvh)
            written = load(bvh)  # its unit, as the file states or a reader guesses
            done = subprocess.run(
                [args.blender_python, __file__, "--blender-side", str(bvh), str(dump)], capture_output=True, text=True
            )
            if done.returncode or not dump.exists():
                print(f"{path}: Blender failed: {done.stderr.strip().splitlines()[-1:]}")
                continue
            got = json.loads(dump.read_text())
            sk = motion.skeleton
            scale = written.skeleton.units_per_metre / sk.units_per_metre  # BVH units = Blender units
            names = ["_".join(n.split()) for n in sk.names]
            keep = [k for k, n in enumerate(names) if n in got["names"]]
            blender = np.array(got["frames"])[:, [got["names"].index(names[k]) for k in keep]]
            ours = motion.positions()[:, keep] * scale
            frames = min(len(blender), len(ours))

            def distances(p):
                return np.linalg.norm(p[:, :, None] - p[:, None, :], axis=-1)

            error = np.abs(distances(blender[:frames]) - distances(ours[:frames])).max()
            error_cm = error / written.skeleton.units_per_metre * 100
            print(
                f"{Path(path).name}: {len(keep)} of {len(sk)} joints, {frames} of {motion.num_frames} frames, "
                f"largest joint-distance difference {error_cm:.1e} cm"
            )


if __name__ == "__main__":
    sys.exit(main())
