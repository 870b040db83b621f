"""Every clip of ../shared/data: loads, round-trips, keeps bone lengths; both formats agree."""

import numpy as np
import pytest

from conftest import SHARED
from mocodec import load, save

pytestmark = [pytest.mark.shared_data, pytest.mark.skipif(SHARED is None, reason="../shared/data is absent")]

CLIPS = sorted((SHARED / "cmu").glob("*/*.bvh")) + sorted((SHARED / "cmu").glob("*/*.amc")) if SHARED else []


@pytest.mark.parametrize("path", CLIPS, ids=lambda p: p.name)
def test_clip_loads_round_trips_and_keeps_bone_lengths(path, tmp_path):
    motion = load(path)
    assert motion.num_frames > 100 and motion.fps == 120.0
    pos = motion.positions()
    sk = motion.skeleton
    bones = np.linalg.norm(pos[:, 1:] - pos[:, sk.parents[1:]], axis=2)
    rest = np.linalg.norm(sk.offsets[1:], axis=1)
    assert np.abs(bones - rest).max() < 1e-9 * sk.units_per_metre * 100
    out = tmp_path / f"rt{path.suffix}"
    save(motion, out)
    back = load(out)
    assert back.skeleton.isclose(sk, atol=1e-5)
    assert back.isclose(motion, atol_degrees=1e-6, atol_units=1e-6), back.difference(motion)


# ASF bone (pivot) -> BVH joint at the same anatomical point
_SEGMENTS = [
    (("lfemur", "ltibia"), ("lThigh", "lShin")),
    (("ltibia", "lfoot"), ("lShin", "lFoot")),
    (("lhumerus", "lradius"), ("lShldr", "lForeArm")),
    (("lradius", "lwrist"), ("lForeArm", "lHand")),
    (("rfemur", "rtibia"), ("rThigh", "rShin")),
    (("rtibia", "rfoot"), ("rShin", "rFoot")),
    (("rhumerus", "rradius"), ("rShldr", "rForeArm")),
    (("rradius", "rwrist"), ("rForeArm", "rHand")),
]


def _segment_directions(motion, pairs):
    pos = motion.positions()
    sk = motion.skeleton
    d = np.stack([pos[:, sk.index(b)] - pos[:, sk.index(a)] for a, b in pairs], axis=1)
    return d / np.linalg.norm(d, axis=2, keepdims=True)


DUAL = (
    sorted(
        p.stem
        for p in (SHARED / "cmu" / "asf_amc").glob("*.amc")
        if (SHARED / "cmu" / "bvh" / f"{p.stem}.bvh").exists()
    )
    if SHARED
    else []
)


@pytest.mark.parametrize("clip", DUAL)
def test_both_formats_give_the_same_pose_sequence(clip):
    """The BVH is a retargeting of the AMC onto another skeleton with one T-pose frame in front,
    so positions differ but limb directions (thigh, shin, upper arm, forearm) must agree frame
    by frame; a half-second misalignment must agree much worse."""
    amc = load(SHARED / "cmu" / "asf_amc" / f"{clip}.amc")
    bvh = load(SHARED / "cmu" / "bvh" / f"{clip}.bvh")
    assert bvh.num_frames == amc.num_frames + 1
    a = _segment_directions(amc, [s[0] for s in _SEGMENTS])
    b = _segment_directions(bvh, [s[1] for s in _SEGMENTS])[1:]
    angle = np.degrees(np.arccos(np.clip(np.sum(a * b, axis=2), -1, 1)))
    shifted = np.degrees(np.arccos(np.clip(np.sum(a[60:] * b[:-60], axis=2), -1, 1)))
    assert np.median(angle) < 8.0 and angle.mean() < 12.0
    assert angle.mean() < 0.6 * shifted.mean()


@pytest.mark.parametrize("path", CLIPS, ids=lambda p: p.name)
def test_clip_measures_and_analysis(path):
    """compare() of a float32 copy and analyze() run on every clip and give strict JSON."""
    import json

    from mocodec.analysis import analyze
    from mocodec.metrics import compare

    motion = load(path)
    copy = motion.with_channels(motion.channels.astype(np.float32))
    result = compare(motion, copy)
    summary = result.summary()
    assert summary["max_joint_error_cm"] < 1e-3 and summary["psnr_db"] > 90
    assert summary["velocity_outliers"] == 0
    json.dumps(result.as_dict(per_joint=True), allow_nan=False)
    numbers = analyze(motion)
    json.dumps(numbers, allow_nan=False)
    assert numbers["groups"] and all(0 < g["power_99_hz"] <= 60 for g in numbers["groups"].values())


@pytest.mark.parametrize("path", CLIPS, ids=lambda p: p.name)
def test_reference_codecs_round_trip_through_the_container(path):
    from mocodec import moc
    from mocodec.codecs import get_codec

    motion = load(path)
    lossless = moc.unpack(moc.pack(motion, get_codec("lossless")))
    assert np.array_equal(lossless.channels, motion.channels)
    raw = moc.unpack(moc.pack(motion, get_codec("raw")), frames=(1, motion.num_frames))
    assert np.array_equal(raw.channels, motion.channels[1:].astype(np.float32))


@pytest.mark.skipif(SHARED is None or not (SHARED / "cmu" / "bvh" / "02_03.bvh").exists(), reason="clip absent")
def test_seam_smoothing_leaves_finely_coded_motion_alone():
    """02_03 turns near gimbal lock right at a seam: the smoothing must not mistake that for a
    coding step when the coding is fine."""
    from mocodec.codecs import get_codec
    from mocodec.metrics import compare

    motion = load(SHARED / "cmu" / "bvh" / "02_03.bvh")
    codec = get_codec("spiht", bits_per_second=1e8)
    assert (
        compare(motion, codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)).joints.max
        < 0.05
    )


@pytest.mark.parametrize("path", CLIPS, ids=lambda p: p.name)
def test_kinwave_holds_its_bound_on_every_clip(path):
    from mocodec.codecs import get_codec
    from mocodec.kinematics import forward_kinematics

    motion = load(path)
    codec = get_codec("kinwave", max_error_cm=0.5)
    decoded = codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)
    cm = 100.0 / motion.skeleton.units_per_metre
    err = (
        np.linalg.norm(
            forward_kinematics(motion.skeleton, decoded.channels)[0]
            - forward_kinematics(motion.skeleton, motion.channels)[0],
            axis=2,
        )
        * cm
    )
    assert err.max() <= 0.5
