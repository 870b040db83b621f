"""The rhythmic framework (001 ch. 4): whole-body segments, the database, blending, the codec."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import DATA, SHARED
from mocodec import ratecontrol, rotations
from mocodec.cli import main
from mocodec.codecs import get_codec
from mocodec.codecs.motionprimitives import blend, quatseg, rhythmdb
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.metrics import compare


@pytest.fixture(scope="module")
def martial_db(martial_amc, tmp_path_factory):
    path = tmp_path_factory.mktemp("rhythm") / "martial.mocrd"
    rhythmdb.train([martial_amc], names=["135_08.amc"]).save(path)
    return path


def test_body_segments_cover_the_clip_within_bounds(walk_amc):
    q = quatseg.joint_quaternions(quatseg.layout(walk_amc.skeleton), walk_amc.channels)
    cuts = rhythmdb.body_cuts(q, walk_amc.fps, 40)
    assert cuts[0, 0] == 0 and cuts[-1, 1] == walk_amc.num_frames and np.array_equal(cuts[1:, 0], cuts[:-1, 1])
    lengths = cuts[:-1, 1] - cuts[:-1, 0]
    assert lengths.min() >= quatseg.MIN_SEGMENT and lengths.max() <= 40


def test_medoids_find_separated_groups():
    points = np.concatenate([np.full(10, c) + np.linspace(0, 0.1, 10) for c in (0.0, 5.0, 9.0)])
    dist = np.abs(points[:, None] - points[None, :])
    chosen = rhythmdb.medoids(dist, 3, np.random.default_rng(1))
    assert sorted(np.round(points[chosen])) == [0.0, 5.0, 9.0]
    assert sorted(chosen % 10) == [4, 4, 4] or all(3 <= c % 10 <= 6 for c in chosen)  # central members


def test_database_file_and_compact_form(martial_amc, martial_db, tmp_path):
    db = rhythmdb.RhythmDB.load(martial_db)
    again = rhythmdb.train([martial_amc], names=["135_08.amc"])
    assert again.to_bytes() == martial_db.read_bytes() and db.count == 18  # every segment of the short clip
    lay = quatseg.layout(martial_amc.skeleton)
    compact = db.as_compact(lay, martial_amc.fps)
    assert np.abs(compact.rotations - db.rotations).max() < rhythmdb.QUAT_STEP * 4
    assert np.abs(compact.root - db.root).max() < rhythmdb.ROOT_STEP * 4
    assert len(db.compact()) < len(db.to_bytes()) / 3
    with pytest.raises(CodecError, match="trained at 120 Hz, the motion is 30 Hz"):
        db.check(lay, 3, 30.0, "db")
    damaged = tmp_path / "bad.mocrd"
    damaged.write_bytes(martial_db.read_bytes()[:-9])
    with pytest.raises(CodecError, match="checksum|not a mocodec"):
        rhythmdb.RhythmDB.load(damaged)


def test_play_lays_primitives_end_to_end():
    turn = rotations.euler_to_quat(np.linspace(0, 90, 16)[:, None], "Z")
    normal = np.stack([np.stack([turn, turn[::-1]], axis=1)])  # one segment, two joints
    q = blend.play(np.concatenate([normal, normal]), np.array([20, 31]))
    assert q.shape == (51, 2, 4)
    angles = np.degrees(rotations.quat_distance(q[:, 0], turn[0]))
    assert np.allclose(angles[[0, 19, 20, 50]], [0, 90, 0, 90]) and np.allclose(angles[:20], np.linspace(0, 90, 20))
    assert np.allclose(np.degrees(rotations.quat_distance(q[:, 1], turn[0]))[[0, 19]], [90, 0])


def test_blending_joins_the_closest_frames_and_keeps_the_rest(walk_amc):
    lay = quatseg.layout(walk_amc.skeleton)
    q = quatseg.joint_quaternions(lay, walk_amc.channels[:80])
    q = np.concatenate([q[:40], q[10:50]])  # a jump back in time at frame 40
    lengths = np.array([40, 40])
    seams = blend.transitions(walk_amc.skeleton, lay, q, lengths)
    ((cut, i, j),) = seams
    assert cut == 40 and 30 <= i < 40 <= j < 50
    out = blend.blend_rotations(q, seams)
    assert np.array_equal(out[: i + 1], q[: i + 1]) and np.array_equal(out[j:], q[j:])
    before = np.abs(np.diff(q[i : j + 1], axis=0)).max()
    assert np.abs(np.diff(out[i : j + 1], axis=0)).max() < before


def test_roots_follow_keys_or_velocity():
    path = np.zeros((30, 3))
    path[:, 0] = np.concatenate([np.arange(15.0), np.arange(15.0)])  # two segments walking in x
    path[:, 1] = 10.0
    lengths = np.array([15, 15])
    keys = np.array([[0.0, 10.0, 0.0], [20.0, 10.0, 0.0], [50.0, 12.0, 0.0]])
    root = blend.keyed_root(path, lengths, keys)
    assert np.allclose(root[[0, 15, 29]], keys)
    up = np.array([False, True, False])
    moved = blend.velocity_root(path, lengths, up, np.array([5.0, 0.0, 0.0]), np.zeros((0, 3), np.int64))
    assert np.allclose(moved[:, 0], 5.0 + np.arange(30.0)) and np.allclose(moved[:, 1], 10.0)


def test_codec_trades_primitives_for_size_and_error(walk_amc):
    results = {}
    for count in (3, 8, 1000):
        codec = get_codec("rhythmic", primitives=count)
        payload = codec.encode(walk_amc)
        decoded = codec.decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
        assert decoded.num_frames == walk_amc.num_frames
        results[count] = (len(payload), compare(walk_amc, decoded).summary()["mean_joint_error_cm"])
    assert results[3][0] < results[8][0] < results[1000][0]
    assert results[1000][1] < 1.0 < results[3][1]  # every segment its own primitive: resampling only
    assert results[8][1] < results[3][1]


def test_rate_control_turns_the_primitive_count(walk_amc):
    m = ratecontrol.tune(get_codec("rhythmic"), walk_amc, "mean_error_cm", 2.0)
    assert m.mean_error_cm <= 2.0
    fewer = ratecontrol.measure(m.codec.with_knob("primitives", m.codec.config["primitives"] // 2), walk_amc)
    assert fewer.mean_error_cm > 2.0 and len(fewer.data) < len(m.data)


def test_blending_smooths_the_seams(walk_amc):
    payload = get_codec("rhythmic", primitives=6).encode(walk_amc)
    plain = compare(
        walk_amc,
        get_codec("rhythmic", primitives=6, blend=False).decode(
            payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps
        ),
    )
    smooth = compare(
        walk_amc,
        get_codec("rhythmic", primitives=6).decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps),
    )
    plain, smooth = plain.summary(), smooth.summary()
    assert smooth["jerk_ratio"] < 0.9 * plain["jerk_ratio"]
    assert smooth["mean_joint_error_cm"] < 1.1 * plain["mean_joint_error_cm"]


def test_external_database_and_its_errors(walk_amc, walk_bvh, martial_db, martial_amc, tmp_path):
    codec = get_codec("rhythmic", db=str(martial_db))
    payload = codec.encode(walk_amc)
    assert len(payload) < len(get_codec("rhythmic").encode(walk_amc)) / 5
    assert codec.decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps).num_frames == walk_amc.num_frames
    with pytest.raises(CodecError, match="--db FILE"):
        get_codec("rhythmic").decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
    other = tmp_path / "other.mocrd"
    rhythmdb.train([martial_amc], seed=5).save(other)
    with pytest.raises(CodecError, match="coded with rhythm database"):
        get_codec("rhythmic", db=str(other)).decode(payload, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
    with pytest.raises(CodecError, match="another skeleton"):
        codec.encode(walk_bvh)
    carried = get_codec("rhythmic").encode(walk_amc)
    with pytest.raises(CodecError, match="drop --db"):
        codec.decode(carried, walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
    with pytest.raises(CorruptStreamError):
        get_codec("rhythmic").decode(carried[:-40], walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)


def test_rhythm_on_the_command_line(tmp_path, capsys):
    db = tmp_path / "dance.mocrd"
    assert main(["model", "train", "rhythm", str(DATA / "135_08.amc"), "-o", str(db), "--count", "12"]) == 0
    assert "12 whole-body primitives" in capsys.readouterr().out
    assert main(["model", "info", str(db)]) == 0
    assert "trained on 135_08.amc" in capsys.readouterr().out
    assert main(["eval", str(DATA / "07_03.amc"), "--codec", "rhythmic", "--db", str(db)]) == 0
    assert "joint error mean / max" in capsys.readouterr().out
    with pytest.raises(SystemExit) as missing:  # no -o FILE
        main(["model", "train", "rhythm", str(DATA / "135_08.amc")])
    assert missing.value.code == 2
    assert main(["model", "train", "rhythm", str(DATA / "135_08.amc"), "-o", str(db), "--count", "0"]) == 2


@pytest.mark.shared_data
@pytest.mark.skipif(SHARED is None or not (SHARED / "cmu/bvh/06_02.bvh").exists(), reason="needs shared clip 06_02")
def test_segments_at_zero_distance_from_each_other_still_give_one_primitive_each():
    """06_02 has whole-body segments identical to each other: two clusters settled on one
    medoid and a primitive had no segment left to average its length over (NaN)."""
    from mocodec import load

    motion = load(SHARED / "cmu/bvh/06_02.bvh")
    codec = get_codec("rhythmic", primitives=80)
    decoded = codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)
    assert compare(motion, decoded).joints.max < 5.0
    dist = np.zeros((4, 4))
    chosen = rhythmdb.medoids(dist, 4, np.random.default_rng(0))
    assert len(set(chosen.tolist())) == len(chosen)
