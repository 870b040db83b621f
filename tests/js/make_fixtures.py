"""Write the glTF fixture the JavaScript tests load (tests/formats/walk.glb) and what they expect
of it (tests/formats/walk.glb.json): run from the repository root after a change to the glTF writer;
tests/test_gltf_fbx.py checks both are what the writer makes now."""

from __future__ import annotations

import json
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent.parent
DATA, FORMATS = TESTS / "data", TESTS / "formats"
FRAMES = 30
#: The frame whose pose the JavaScript tests check.
POSE_FRAME = 17


def fixture() -> tuple[bytes, str]:
    """The .glb bytes and the expectations' JSON text."""
    from mocodec import load
    from mocodec.formats.gltf import to_gltf_bytes

    motion = load(DATA / "07_03.bvh")[:FRAMES]
    positions = motion.positions_m()[POSE_FRAME]
    expected = {
        "source": "tests/data/07_03.bvh, first 30 frames",
        "joints": len(motion.skeleton),
        "duration_s": (motion.num_frames - 1) / motion.fps,
        "fps": motion.fps,
        "pose_frame": POSE_FRAME,
        "positions_m": {name: [round(float(v), 9) for v in p] for name, p in zip(motion.skeleton.names, positions)},
    }
    return to_gltf_bytes(motion, binary=True), json.dumps(expected, indent=1) + "\n"


def main() -> int:
    glb, expected = fixture()
    (FORMATS / "walk.glb").write_bytes(glb)
    (FORMATS / "walk.glb.json").write_text(expected)
    print(f"wrote {FORMATS / 'walk.glb'} ({len(glb)} bytes) and walk.glb.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
