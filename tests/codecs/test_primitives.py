"""The motion-primitive coder (001 ch. 5): quaternion segments, the primitive database, the codec."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import DATA
from mocodec import rotations
from mocodec.cli import main
from mocodec.codecs import get_codec
from mocodec.codecs.motionprimitives import primdb, primresidual, quatseg
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.metrics import compare
from mocodec.motion import Motion


@pytest.fixture(scope="module")
def martial_db(martial_amc, tmp_path_factory):
    """A database trained on the martial-arts clip only (never on the walk it codes)."""
    path = tmp_path_factory.mktemp("primitives") / "martial.mocdb"
    primdb.train([martial_amc], seed=3, names=["135_08.amc"]).save(path)
    return path


def _rotation_error(a: Motion, b: Motion) -> np.ndarray:
    """(frames, joints) angle (5.3) between the joint rotations of two motions."""
    lay = quatseg.layout(a.skeleton)
    return rotations.quat_distance(
        quatseg.joint_quaternions(lay, a.channels), quatseg.joint_quaternions(lay, b.channels)
    )


def test_partial_euler_angles_come_back():
    rng = np.random.default_rng(0)
    for order in ("X", "Y", "Z", "ZX", "ZY", "XY", "ZYX", "ZXY"):
        angles = rng.uniform(-80, 80, (50, len(order)))
        back = rotations.quat_to_partial_euler(rotations.euler_to_quat(angles, order), order)
        assert np.abs(back - angles).max() < 1e-9, order
    twist = rotations.quat_to_partial_euler(rotations.euler_to_quat(np.array([[170.0], [-175.0]]), "X"), "X")
    assert np.allclose(twist[:, 0], [170.0, -175.0])


def test_quaternions_are_hemisphere_continuous():
    q = rotations.euler_to_quat(np.stack([np.linspace(0, 720, 200), np.zeros(200), np.zeros(200)], 1), "ZYX")
    c = rotations.quat_continuous(q)
    assert np.all(np.sum(c[1:] * c[:-1], axis=-1) > 0)
    assert np.allclose(rotations.quat_distance(c, q), 0, atol=1e-6)


def test_joint_quaternions_give_the_same_poses(walk_amc, walk_bvh):
    for clip in (walk_amc, walk_bvh):
        lay = quatseg.layout(clip.skeleton)
        q = quatseg.joint_quaternions(lay, clip.channels)
        back = quatseg.quaternions_to_channels(lay, q, clip.channels[:, lay.translation], clip.skeleton.num_channels)
        assert np.abs(clip.positions() - clip.with_channels(back).positions()).max() < 1e-6
    lay = quatseg.layout(walk_amc.skeleton)
    assert lay.lower[0] and lay.lower[lay.names.index("ltibia")] and not lay.lower[lay.names.index("lhumerus")]


def test_segments_end_at_speed_extremes_within_bounds():
    fps, frames = 120.0, 600
    t = np.arange(frames) / fps
    angle = 5 * np.sin(2 * np.pi * 1.5 * t) + 60 * t  # speed 60 + 47 cos: extremes every 40 frames
    q = rotations.euler_to_quat(np.stack([angle, 0 * t, 0 * t], 1), "ZYX")[:, None]
    g = quatseg.speed_change(q, fps)
    for max_len in (64, 32):
        segs = quatseg.chop(g, np.zeros(1, dtype=np.int64), max_len, final=True)
        lengths = np.array([e - s for _, s, e in segs])
        assert segs[0][1] == 0 and segs[-1][2] == frames
        assert all(a[2] == b[1] for a, b in zip(segs, segs[1:]))
        assert lengths[:-1].min() >= quatseg.MIN_SEGMENT and lengths.max() <= max_len
        at_extremes = [e for _, s, e in segs[:-1] if e - s < max_len]
        # (5.1) and (5.2) are backward differences: the crossing shows a frame or two late
        assert at_extremes and all(0 <= e - 40 * round(e / 40) <= 2 for e in at_extremes)


def test_a_jump_gets_its_own_segment(walk_bvh):
    lay = quatseg.layout(walk_bvh.skeleton)  # frame 0 of the BVH is a T-pose
    q = quatseg.joint_quaternions(lay, walk_bvh.channels)
    segs = quatseg.chop(quatseg.speed_change(q, walk_bvh.fps), np.zeros(lay.count, dtype=np.int64), 32, True)
    first = [e for r, s, e in segs if s == 0 and r == lay.names.index("lShldr")]
    assert first == [1]


def test_normalising_keeps_ends_and_linear_motion():
    angle = np.linspace(0, 60, 40)
    q = rotations.euler_to_quat(np.stack([angle, 0 * angle, 0 * angle], 1), "ZYX")[:, None]
    segs = np.array([[0, 0, 23], [0, 23, 40]])
    normal = quatseg.normalise(q, segs)
    assert np.allclose(normal[0, 0], q[0, 0]) and np.allclose(normal[1, -1], q[39, 0])
    back = quatseg.denormalise(normal, segs[:, 2] - segs[:, 1])
    assert rotations.quat_distance(back, q[:, 0]).max() < 1e-9  # constant speed: slerp is exact


def test_clustering_finds_well_separated_primitives():
    rng = np.random.default_rng(1)
    centres = rotations.euler_to_quat(rng.uniform(-90, 90, (5, 3)), "ZYX")
    member = np.repeat(np.arange(5), 40)
    noise = rotations.euler_to_quat(rng.normal(0, 0.05, (200, 16, 3)), "ZYX")
    segs = rotations.quat_multiply(centres[member][:, None], noise)
    prims, error = primdb.cluster(segs, np.random.default_rng(0), threshold=0.05)
    assert len(prims) == 5 and error < 0.05
    assert np.all(quatseg.segment_distance(centres[:, None, None], prims[None]).min(axis=1) < 0.01)


def test_database_file_is_deterministic_and_checked(martial_amc, martial_db, tmp_path):
    again = primdb.train([martial_amc], seed=3, names=["135_08.amc"])
    data = martial_db.read_bytes()
    assert again.to_bytes() == data
    assert primdb.train([martial_amc], seed=4).to_bytes() != data
    db = primdb.PrimitiveDB.load(martial_db)
    assert 5 <= min(len(p) for p in db.primitives.values()) and max(len(p) for p in db.primitives.values()) <= 25
    assert db.fingerprint == again.fingerprint and db.trained_on == ["135_08.amc"]
    bad = tmp_path / "bad.mocdb"
    bad.write_bytes(data[:-10])
    with pytest.raises(CodecError, match="checksum"):
        primdb.PrimitiveDB.load(bad)
    bad.write_bytes(b"MOCVQ" + data[5:])
    with pytest.raises(CodecError, match="not a mocodec primitive database"):
        primdb.PrimitiveDB.load(bad)


def test_residuals_bring_segments_within_the_bound():
    rng = np.random.default_rng(2)
    ref = rotations.euler_to_quat(rng.uniform(-90, 90, (30, 1, 3)) + np.zeros((30, 16, 3)), "ZYX")
    wiggle = rotations.euler_to_quat(np.cumsum(rng.normal(0, 2, (30, 16, 3)), axis=1), "ZYX")
    target = rotations.quat_multiply(ref, wiggle)
    bound = np.full(30, 0.01)
    exps, q, recon = primresidual.fit(target, ref, bound, 10)
    assert np.all(quatseg.segment_distance(target, recon) <= bound)
    assert np.allclose(rotations.quat_multiply(ref, primresidual.differences(exps, q)), recon)
    assert (q != 0).sum(axis=1).mean() < primresidual.COEFFS  # thresholding kept fewer than all
    same = primresidual.fit(ref, ref, bound, 10)
    assert np.all(same[0] == primresidual.NO_RESIDUAL) and not same[1].any()


def test_codec_keeps_joints_within_their_thresholds(walk_amc, martial_db):
    codec = get_codec("primitives", db=str(martial_db), history=0)
    decoded = codec.decode(codec.encode(walk_amc), walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
    err = _rotation_error(walk_amc, decoded)
    lay = quatseg.layout(walk_amc.skeleton)
    bound = np.where(lay.lower, 0.01, 0.02)
    # the thesis checks t_j on the 16 normalised frames; resampling back to the segment's
    # frames adds the slerp's error between them (most on the toes, which snap at contact)
    assert np.mean(err <= bound) > 0.95 and np.mean(err <= 1.5 * bound) > 0.99 and (err / bound).max() < 10
    tr = lay.translation
    assert np.abs(decoded.channels[:, tr] - walk_amc.channels[:, tr]).max() < 0.05  # 0.3 cm


def test_threshold_trades_size_for_error(walk_amc, martial_db):
    sizes, errors = [], []
    for t in (0.0025, 0.01, 0.04):
        codec = get_codec("primitives", db=str(martial_db), t_lower=t)
        payload = codec.encode(walk_amc)
        sizes.append(len(payload))
        errors.append(
            compare(walk_amc, codec.decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)).joints.mean
        )
    assert sizes[0] > sizes[1] > sizes[2] and errors[0] < errors[1] < errors[2]


def test_history_candidates_help_a_repetitive_motion(walk_amc, martial_db):
    thesis = get_codec("primitives", db=str(martial_db), history=0).encode(walk_amc)
    ours = get_codec("primitives", db=str(martial_db)).encode(walk_amc)
    alone = get_codec("primitives").encode(walk_amc)
    assert len(ours) < len(thesis) and len(alone) < len(thesis) * 1.2


@pytest.mark.parametrize("smooth", [0, 3])
def test_streaming_decodes_like_the_whole_clip_within_the_delay(walk_bvh, smooth):
    codec = get_codec("primitives", max_segment=16, smooth=smooth)
    whole = codec.decode(codec.encode(walk_bvh), walk_bvh.skeleton, walk_bvh.num_frames, walk_bvh.fps).channels
    enc, dec = codec.encoder(walk_bvh.skeleton, walk_bvh.fps), codec.decoder(walk_bvh.skeleton, walk_bvh.fps)
    out, pushed = [], 0
    for k in range(0, walk_bvh.num_frames, 7):
        out += [dec.push(p) for p in enc.push(walk_bvh.channels[k : k + 7])]
        pushed = min(k + 7, walk_bvh.num_frames)
        assert pushed - sum(len(o) for o in out) <= codec.delay_frames() == 16 + smooth
    last = enc.flush()
    out += [dec.push(p) for p in last]
    assert np.abs(np.concatenate(out) - whole).max() < 1e-9
    with pytest.raises(CorruptStreamError, match="after the last one"):
        dec.push(last[-1])
    fresh = codec.decoder(walk_bvh.skeleton, walk_bvh.fps)
    second = get_codec("primitives", max_segment=16).encoder(walk_bvh.skeleton, walk_bvh.fps)
    packets = [p for k in range(0, 100, 20) for p in second.push(walk_bvh.channels[k : k + 20])]
    with pytest.raises(CorruptStreamError, match="start is missing"):
        fresh.push(packets[1])


def test_smoothing_joins_the_closest_frames_across_a_seam():
    angle = np.radians(np.concatenate((np.arange(20), np.arange(15, 35)))).astype(float)  # steps back at 20
    q = rotations.euler_to_quat(np.degrees(angle)[:, None], "Z")
    before = q.copy()
    quatseg.smooth_seams(q, np.array([20]), np.array([0]), np.array([40]), 4, fps=120.0)
    # the first closest pair is frame 16 and frame 21 (both 16 deg): frames 17..20 hold 16 deg
    assert np.allclose(rotations.quat_distance(q[17:21], before[16:17]), 0.0, atol=1e-7)
    assert np.array_equal(q[:17], before[:17]) and np.array_equal(q[21:], before[21:])
    smooth = rotations.euler_to_quat(np.arange(40.0)[:, None], "Z")
    kept = smooth.copy()
    quatseg.smooth_seams(smooth, np.array([20]), np.array([0]), np.array([40]), 4, fps=120.0)
    assert np.allclose(smooth, kept)  # adjacent frames are the closest pair: nothing to do
    step = rotations.euler_to_quat(np.where(np.arange(40) < 20, 0.0, 90.0)[:, None], "Z")
    held = step.copy()
    quatseg.smooth_seams(step, np.array([20]), np.array([0]), np.array([40]), 4, fps=120.0)
    assert np.array_equal(step, held)  # a jump is not smoothed


def test_smoothing_lowers_jerk_without_losing_accuracy(martial_amc):
    plain, smooth = (get_codec("primitives", smooth=m) for m in (0, 2))
    payload = plain.encode(martial_amc)
    assert smooth.encode(martial_amc) == payload  # a decoder-side filter
    a = compare(
        martial_amc, plain.decode(payload, martial_amc.skeleton, martial_amc.num_frames, martial_amc.fps)
    ).summary()
    b = compare(
        martial_amc, smooth.decode(payload, martial_amc.skeleton, martial_amc.num_frames, martial_amc.fps)
    ).summary()
    assert b["jerk_ratio"] < 0.95 * a["jerk_ratio"]
    assert b["mean_joint_error_cm"] < 1.05 * a["mean_joint_error_cm"]


def test_database_mismatches_are_clear_errors(walk_amc, walk_bvh, martial_db, martial_amc, tmp_path):
    with pytest.raises(CodecError, match="trained on another skeleton"):
        get_codec("primitives", db=str(martial_db)).encode(walk_bvh)
    payload = get_codec("primitives", db=str(martial_db)).encode(walk_amc)
    other = tmp_path / "other.mocdb"
    primdb.train([martial_amc], seed=9).save(other)
    with pytest.raises(CodecError, match="coded with primitive database"):
        get_codec("primitives", db=str(other)).decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
    with pytest.raises(CodecError, match="--db FILE"):
        get_codec("primitives").decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
    with pytest.raises(CodecError, match="30 Hz"):
        get_codec("primitives", db=str(martial_db)).encode(walk_amc.resample(30))


def test_primitives_on_the_command_line(tmp_path, capsys):
    db = tmp_path / "db.mocdb"
    assert main(["model", "train", "primitives", str(DATA / "135_08.amc"), "-o", str(db)]) == 0
    assert "primitives for 29 joints" in capsys.readouterr().out
    assert main(["model", "info", str(db)]) == 0
    assert "trained on 135_08.amc" in capsys.readouterr().out
    moc = tmp_path / "walk.moc"
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(moc), "--codec", "primitives", "--db", str(db)]) == 0
    moved = tmp_path / "moved.mocdb"
    db.rename(moved)
    assert main(["decode", str(moc), "-o", str(tmp_path / "w.amc")]) == 2
    err = capsys.readouterr().err  # the file's path for the database is never opened nor named
    assert "none is given (--db FILE)" in err and "db.mocdb" not in err
    assert main(["decode", str(moc), "-o", str(tmp_path / "w.amc"), "--db", str(moved)]) == 0
    assert (
        main(["eval", str(DATA / "07_03.amc"), "--codec", "primitives", "--db", str(moved), "--t-lower", "0.02"]) == 0
    )
    assert "joint error mean / max" in capsys.readouterr().out
    with pytest.raises(SystemExit) as missing:  # no -o FILE
        main(["model", "train", "primitives", str(DATA / "135_08.amc")])
    assert missing.value.code == 2
