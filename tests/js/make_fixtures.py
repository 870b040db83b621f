"""Write the fixtures the JavaScript tests load, and what they expect of them: the glTF files
tests/formats/walk.glb and walk_mannequin.glb (and their .json), live streams in tests/data/live/ (each case's
stream as one batch message, the Python decoder's channels, the integers it read per packet and
layer, and joint positions), .moc files in tests/data/moc/ (the same per chunk) and the
JavaScript copy of the .moc header dictionary (js/src/header-dict.js). Run from the repository
root after a change to the glTF writer, the live format or kinwave's; tests/formats/test_gltf_fbx.py and
tests/viewer/test_js_fixtures.py check they are what the code makes now."""

from __future__ import annotations

import json
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent.parent
DATA, FORMATS = TESTS / "data", TESTS / "formats"
JS = TESTS.parent / "js" / "src"
FRAMES = 30
#: The frame whose pose the JavaScript tests check.
POSE_FRAME = 17


def fixture() -> tuple[bytes, str]:
    """The .glb bytes and the expectations' JSON text."""
    from mocodec import load
    from mocodec.formats.gltfwrite import to_gltf_bytes

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


#: Live stream cases: (name, clip, frames, fps or None, codec knobs, keyframe seconds), and for a
#: layered stream as a relay forwards it to a viewer whose layers change, from which data packet
#: on it keeps how many layers.
LIVE_CASES = (
    ("walk", "07_03.bvh", 240, None, {}, 1.0),
    ("walk-layers", "07_03.bvh", 240, None, {"layers": 3, "refresh_s": 0.5}, 1.0),
    (
        "walk-layers-cut",
        "07_03.bvh",
        240,
        None,
        {"layers": 3, "refresh_s": 0.5},
        60.0,
        ((0, 3), (8, 1), (20, 2), (30, 3)),
    ),
    ("asf-30fps-shell", "07_03.amc", 360, 30.0, {"layers": 2, "max_error_cm": 0.5, "error_measure": "shell"}, 2.0),
    ("run-refresh", "09_02.bvh", 240, None, {"refresh_s": 0.25}, 60.0),
)
POSE_FRAMES = (0, 61, -1)


def live_fixture(name, clip, frames, fps, knobs, keyframe_s, keeps=()) -> dict[str, bytes]:
    """The files of one live case: ``<name>.stream`` (header and data packets as one batch),
    ``<name>.json`` (per packet its frames and the integers' count per layer, and joint
    positions at a few frames), ``<name>.f64.gz`` (the decoded channels, float64) and
    ``<name>.ints.gz`` (every integer read, int32, packet by packet and layer by layer)."""
    import gzip

    import numpy as np

    from mocodec import load
    from mocodec.codecs import get_codec
    from mocodec.codecs.kinwave.live import decoder as live_decoder
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
    if keeps:
        packets = packets[:1] + [relayed(p, keep_at(keeps, k), codec) for k, p in enumerate(packets[1:])]
    read: list[np.ndarray] = []
    original = live_decoder.decode_ints

    def recording(st, data, coded, first, count, state, last_nonzero, ints):
        result = original(st, data, coded, first, count, state, last_nonzero, ints)
        read.append(ints.copy())
        return result

    live_decoder.decode_ints = recording
    try:
        decoder = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
        decoded, described = [], []
        for p in packets[1:]:
            before = len(read)
            decoded.append(decoder.push(p))
            described.append({"frames": p.frames, "ints": [int(x.size) for x in read[before:]]})
    finally:
        live_decoder.decode_ints = original
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


def keep_at(keeps, k: int) -> int:
    return [keep for first, keep in keeps if first <= k][-1]


def relayed(p, keep: int, codec):
    """Packet ``p`` of a layered stream as a relay forwards it with its ``keep`` lowest layers."""
    from dataclasses import replace

    from mocodec.stream.packets import layer_ends

    plain = p.without_cuts()
    if not p.frames:
        return plain
    ends = layer_ends(p, codec.config["layers"])
    return replace(plain, payload=plain.payload[: ends[keep - 1]], dropped=len(ends) - keep)


def live_fixtures() -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    for case in LIVE_CASES:
        out.update(live_fixture(*case))
    return out


#: .moc cases: (name, clip, frames, fps or None, re-expression, kinwave knobs, chunk frames). Between
#: them they use every part of the format: chunks, segment step offsets, coding forms (vectors,
#: coding orders, WORLD forms under a turned dummy root), world-axis translations, constant
#: 6-channel joints, keyframes, an isolated frame, the three wavelets, a rate target, ASF axes and
#: a leading rest pose (payload format 2) of either kind, a layout's lead (a clip cut off the
#: frames its wavelet grid falls on), fine constants (bones in position channels) and constants
#: about 0 (MotionBuilder's offsets repeated in the position channels).
MOC_CASES = (
    ("bvh-joint", "07_03.bvh", 600, None, None, {}, 256),
    ("asf-30fps-shell", "135_08.amc", 300, 30.0, None, {"max_error_cm": 1.0, "error_measure": "shell"}, 1024),
    ("dummy-root", "09_02.bvh", 300, None, "dummy", {"max_error_cm": 1.0}, 1024),
    ("dummy-root-bind", "07_03.bvh", 200, None, "dummy-bind", {"max_error_cm": 1.0}, 1024),
    ("zxz-d4", "07_03.bvh", 300, None, "zxz", {"wavelet": "d4", "window": 64}, 1024),
    ("haar-bitrate", "07_03.amc", 300, None, None, {"wavelet": "haar", "bits_per_second": 6000.0, "levels": 3}, 1024),
    ("glitch", "09_02.bvh", 300, None, "glitch", {}, 1024),
    ("rest-pose", "07_03.bvh", 300, None, "rest", {"max_error_cm": 1.0, "error_measure": "shell"}, 256),
    ("rest-at-zero", "135_08.amc", 200, None, "rest-at-zero", {}, 1024),
    ("turned-root-bind", "07_03.bvh", 200, None, "turned-bind", {"max_error_cm": 1.0}, 1024),
    ("lead", "07_03.bvh", 400, None, "cut", {"max_error_cm": 0.2, "window": 128}, 256),
    ("bones-in-channels", "07_03.amc", 200, None, "bones-in-channels", {"max_error_cm": 1.0, "effort": 3}, 1024),
    ("offsets-in-channels", "07_03.amc", 200, None, "offsets-in-channels", {"max_error_cm": 1.0}, 1024),
)


def _reexpressed(motion, how):
    import numpy as np

    from mocodec import reexpress

    if how == "dummy":
        return reexpress.with_position_channels(reexpress.with_dummy_root(motion, (30.0, 20.0, 10.0)))
    if how == "dummy-bind":
        return reexpress.with_bind_frame(reexpress.with_dummy_root(motion, (0.0, -90.0, 0.0), position_channels=True))
    if how == "turned-bind":  # a game export: the bind pose under a rotation-only root turned to the engine's axes
        return reexpress.with_dummy_root(reexpress.with_bind_frame(motion), (0.0, -90.0, 0.0))
    if how == "rest":
        return reexpress.with_bind_frame(motion)
    if how == "rest-at-zero":
        return motion.with_channels(np.vstack((np.zeros((1, motion.skeleton.num_channels)), motion.channels)))
    if how == "cut":
        return motion[1:]
    if how == "bones-in-channels":
        return reexpress.with_position_channels(motion)
    if how == "offsets-in-channels":
        return reexpress.with_position_channels(motion, keep_offsets=True)
    if how == "zxz":
        return reexpress.with_euler_orders(motion, "ZXZ")
    if how == "glitch":
        channels = motion.channels.copy()
        channels[len(channels) // 2, motion.skeleton.rotation_mask] += 25.0
        return motion.with_channels(channels)
    return motion


def moc_fixture(name, clip, frames, fps, how, knobs, chunk_frames) -> dict[str, bytes]:
    """The files of one .moc case: ``<name>.moc``, ``<name>.json`` (frames, channels, the error
    bound, per chunk its body's flags and integers' count, joint positions decoded and original
    at a few frames; per chunk its more flags, 0 in format 1), ``<name>.f64.gz`` (the
    decoded channels, float64) and ``<name>.ints.gz`` (per chunk the integers the coefficient
    decoder read: side integers as sent, constant flags, knots, coefficients; int32)."""
    import gzip
    import io

    import numpy as np

    from mocodec import load, moc
    from mocodec.codecs import get_codec
    from mocodec.coding.entropy import coefcoder
    from mocodec.formats import container

    motion = load(DATA / clip)
    motion = _reexpressed((motion.resample(fps) if fps else motion)[:frames], how)
    data = moc.pack(motion, get_codec("kinwave", **knobs), chunk_frames=chunk_frames)
    read: list[np.ndarray] = []
    original = coefcoder.decode

    def recording(*args, **kwargs):
        coded = original(*args, **kwargs)
        parts = [*coded.terms, coded.const, coded.knots.ravel(), coded.coeffs.ravel()]
        read.append(np.concatenate([np.asarray(p, dtype=np.int64) for p in parts]))
        return coded

    coefcoder.decode = recording
    try:
        decoded = moc.unpack(data)
    finally:
        coefcoder.decode = original
    info = container.open_container(io.BytesIO(data), len(data), name)
    ints = np.concatenate(read)
    assert np.abs(ints).max(initial=0) < 2**31
    positions, original = decoded.positions(), motion.positions()
    frames_shown = [f % decoded.num_frames for f in POSE_FRAMES]
    meta = {
        "clip": clip,
        "frames": decoded.num_frames,
        "channels": decoded.skeleton.num_channels,
        "knobs": knobs,
        # a max joint error bound, which the JavaScript test checks (shell errors it does not compute)
        "bound_cm": None
        if knobs.get("bits_per_second") or knobs.get("error_measure", "joint") != "joint"
        else knobs.get("max_error_cm", 0.5),
        "chunks": [
            {
                "format": int(body[0]),
                "flags": int(body[1]),
                "more": int(body[6]) if body[0] > 1 else 0,
                "ints": int(x.size),
            }
            for body, x in ((info.read_chunk(k), x) for k, x in enumerate(read))
        ],
        "positions": {str(f): positions[f].round(9).tolist() for f in frames_shown},
        "original_positions": {str(f): original[f].round(9).tolist() for f in frames_shown},
    }
    return {
        f"{name}.moc": data,
        f"{name}.json": (json.dumps(meta, indent=1) + "\n").encode(),
        f"{name}.f64.gz": gzip.compress(decoded.channels.astype("<f8").tobytes(), mtime=0),
        f"{name}.ints.gz": gzip.compress(ints.astype("<i4").tobytes(), mtime=0),
    }


def moc_fixtures() -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    for case in MOC_CASES:
        out.update(moc_fixture(*case))
    return out


def still_rig_fixture() -> dict[str, bytes]:
    """``still-rig.moc`` and ``.json``: a rig whose joints never move (no channels, as Blender
    2.79 exports one), kinwave's empty body; the JavaScript decoder opens it as Python's does."""
    from dataclasses import replace

    import numpy as np

    from mocodec import Motion, Skeleton, load, moc
    from mocodec.codecs import get_codec

    sk = load(DATA / "07_03.bvh").skeleton
    still = Skeleton(
        tuple(replace(j, channels=(), rotation_order="", limits=()) for j in sk.joints), sk.units_per_metre
    )
    data = moc.pack(Motion(still, 30.0, np.zeros((FRAMES, 0))), get_codec("kinwave"))
    meta = {"frames": FRAMES, "joints": len(still), "fps": 30.0}
    return {"still-rig.moc": data, "still-rig.json": (json.dumps(meta, indent=1) + "\n").encode()}


def steps_table() -> bytes:
    """Python's quantiser steps of every kinwave step code and segment offset factors, which the
    JavaScript decoder makes from eight constants (js/src/steps.js)."""
    from mocodec.codecs.kinwave.body import code_step

    table = {
        "code_steps": [code_step(c) for c in range(256)],
        "offset_factors": {str(o): 2.0 ** (o / 8.0) for o in range(-128, 129)},
    }
    return (json.dumps(table) + "\n").encode()


def header_dictionary_module() -> str:
    """js/src/header-dict.js: each .moc version's header dictionary (each one the one before
    it with more after it), as base64."""
    import base64

    from mocodec.formats.header_dict import DICTIONARIES

    newest = DICTIONARIES[max(DICTIONARIES)]
    assert all(newest.startswith(d) for d in DICTIONARIES.values())
    text = base64.b64encode(newest).decode()
    lines = "\n".join(f"  '{text[k : k + 100]}'," for k in range(0, len(text), 100))
    lengths = ", ".join(f"{v}: {len(d)}" for v, d in DICTIONARIES.items())
    return (
        "// The preset dictionaries .moc headers are deflated with, by container version\n"
        "// (formats/header_dict.py), generated by tests/js/make_fixtures.py;\n"
        "// tests/viewer/test_js_fixtures.py checks they are Python's, byte for byte.\n"
        f"const BASE64 = [\n{lines}\n].join('');\n"
        "const NEWEST = Uint8Array.from(atob(BASE64), (c) => c.charCodeAt(0));\n\n"
        f"const LENGTHS = {{ {lengths} }};\n"
        "export const HEADER_DICTIONARIES = Object.fromEntries(\n"
        "  Object.entries(LENGTHS).map(([version, length]) => [version, NEWEST.subarray(0, length)]),\n"
        ");\n"
    )


#: Vertices whose skinned positions the JavaScript test checks (every SAMPLE_STEP-th).
SAMPLE_STEP = 97


def mannequin_fixture() -> tuple[bytes, str]:
    """The .glb with the mannequin and the expectations' JSON text: its counts, and where
    linear-blend skinning (:func:`mocodec.mannequin.skinned`) puts some vertices at POSE_FRAME."""
    import numpy as np

    from mocodec import load, mannequin
    from mocodec.formats.gltfwrite import to_gltf_bytes
    from mocodec.kinematics import forward_kinematics

    motion = load(DATA / "07_03.bvh")[:FRAMES]
    sk = motion.skeleton
    bind = mannequin.bind_positions(sk, motion.channels[0])
    body = mannequin.build(sk, bind)
    positions, quats = forward_kinematics(sk, motion.channels[POSE_FRAME : POSE_FRAME + 1])
    posed = mannequin.skinned(body, bind, positions[0], quats[0]) / sk.units_per_metre
    picked = np.arange(0, len(body.positions), SAMPLE_STEP)
    expected = {
        "source": "tests/data/07_03.bvh, first 30 frames, --mesh mannequin",
        "joints": len(sk),
        "vertices": len(body.positions),
        "triangles": len(body.triangles),
        "fps": motion.fps,
        "pose_frame": POSE_FRAME,
        "posed_m": {str(int(v)): [round(float(x), 7) for x in posed[v]] for v in picked},
    }
    return to_gltf_bytes(motion, binary=True, mesh="mannequin"), json.dumps(expected, indent=1) + "\n"


def main() -> int:
    for name, (glb, expected) in (("walk", fixture()), ("walk_mannequin", mannequin_fixture())):
        (FORMATS / f"{name}.glb").write_bytes(glb)
        (FORMATS / f"{name}.glb.json").write_text(expected)
        print(f"wrote {FORMATS / (name + '.glb')} ({len(glb)} bytes) and {name}.glb.json")
    moc_files = {**moc_fixtures(), **still_rig_fixture(), "steps.json": steps_table()}
    for folder, files in (("live", live_fixtures()), ("moc", moc_files)):
        (DATA / folder).mkdir(exist_ok=True)
        for name, data in files.items():
            (DATA / folder / name).write_bytes(data)
            print(f"wrote {DATA / folder / name} ({len(data)} bytes)")
    (JS / "header-dict.js").write_text(header_dictionary_module())
    print(f"wrote {JS / 'header-dict.js'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
