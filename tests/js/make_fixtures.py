"""Write the fixtures the JavaScript tests load, and what they expect of them: the glTF file
tests/formats/walk.glb (and walk.glb.json), and live streams in tests/formats/live/ (each case's
stream as one batch message, the Python decoder's channels, the integers it read per packet and
layer, and joint positions). Run from the repository root after a change to the glTF writer or the
live format; tests/test_gltf_fbx.py and tests/test_js_fixtures.py check they are what the code
makes now."""

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


#: Live stream cases: (name, clip, frames, fps or None, codec knobs, keyframe seconds).
LIVE_CASES = (
    ("walk", "07_03.bvh", 240, None, {}, 1.0),
    ("walk-layers", "07_03.bvh", 240, None, {"layers": 3, "refresh_s": 0.5}, 1.0),
    ("asf-30fps-shell", "07_03.amc", 360, 30.0, {"layers": 2, "max_error_cm": 0.5, "error_measure": "shell"}, 2.0),
    ("run-refresh", "09_02.bvh", 240, None, {"refresh_s": 0.25}, 60.0),
)
POSE_FRAMES = (0, 61, -1)


def live_fixture(name, clip, frames, fps, knobs, keyframe_s) -> dict[str, bytes]:
    """The files of one live case: ``<name>.stream`` (header and data packets as one batch),
    ``<name>.json`` (per packet its frames and the integers' count per layer, and joint
    positions at a few frames), ``<name>.f64.gz`` (the decoded channels, float64) and
    ``<name>.ints.gz`` (every integer read, int32, packet by packet and layer by layer)."""
    import gzip

    import numpy as np

    from mocodec import load
    from mocodec.codecs import get_codec
    from mocodec.codecs.kinwave import live as kinwave_live
    from mocodec.stream.live import LiveDecoder, clip_encoder, tick_frames
    from mocodec.stream.packets import StreamInfo, pack_batch

    motion = load(DATA / clip)
    motion = (motion.resample(fps) if fps else motion)[:frames]
    codec = get_codec("kinwave-live", **knobs)
    enc = clip_encoder(motion, codec, 7, keyframe_s)
    step = tick_frames(motion.fps)
    packets = [enc.header(0)]
    for k in range(0, motion.num_frames, step):
        packets += enc.push(motion.channels[k : k + step], 0)
    packets += [p for p in enc.close(0) if p.frames or p.end]
    read: list[np.ndarray] = []
    original = kinwave_live._decode_ints

    def recording(st, data, coded, first, count, state, last_nonzero, ints, orders):
        result = original(st, data, coded, first, count, state, last_nonzero, ints, orders)
        read.append(ints.copy())
        return result

    kinwave_live._decode_ints = recording
    try:
        decoder = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
        decoded, described = [], []
        for p in packets[1:]:
            before = len(read)
            decoded.append(decoder.push(p))
            described.append({"frames": p.frames, "ints": [int(x.size) for x in read[before:]]})
    finally:
        kinwave_live._decode_ints = original
    channels = np.concatenate(decoded)
    positions = motion.with_channels(channels).positions()
    meta = {
        "clip": clip,
        "frames": int(channels.shape[0]),
        "channels": int(channels.shape[1]),
        "knobs": knobs,
        "packets": described,
        "positions": {str(f % len(channels)): positions[f].round(9).tolist() for f in POSE_FRAMES},
    }
    ints = np.concatenate([x.ravel() for x in read]).astype("<i4") if read else np.zeros(0, "<i4")
    return {
        f"{name}.stream": pack_batch([p.to_bytes() for p in packets]),
        f"{name}.json": (json.dumps(meta, indent=1) + "\n").encode(),
        f"{name}.f64.gz": gzip.compress(channels.astype("<f8").tobytes(), mtime=0),
        f"{name}.ints.gz": gzip.compress(ints.tobytes(), mtime=0),
    }


def live_fixtures() -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    for case in LIVE_CASES:
        out.update(live_fixture(*case))
    return out


def main() -> int:
    glb, expected = fixture()
    (FORMATS / "walk.glb").write_bytes(glb)
    (FORMATS / "walk.glb.json").write_text(expected)
    print(f"wrote {FORMATS / 'walk.glb'} ({len(glb)} bytes) and walk.glb.json")
    (FORMATS / "live").mkdir(exist_ok=True)
    for name, data in live_fixtures().items():
        (FORMATS / "live" / name).write_bytes(data)
        print(f"wrote {FORMATS / 'live' / name} ({len(data)} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
