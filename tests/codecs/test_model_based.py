"""The model-based coders of 000 ch. 8: segmentation, segment animation, tables and the
posture, gesture and hybrid codecs."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import DATA
from mocodec import ratecontrol
from mocodec.cli import main
from mocodec.codecs import get_codec
from mocodec.codecs.model import animate, modelgroups, motiontables, segmentation
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.metrics import compare


@pytest.fixture(scope="module")
def walk30(walk_amc):
    return walk_amc.resample(30)


@pytest.fixture(scope="module")
def martial_tables(martial_amc, tmp_path_factory):
    """Tables trained on another subject and motion than the walk they code."""
    path = tmp_path_factory.mktemp("tables") / "martial.moctb"
    motiontables.train([martial_amc], spacing_cm=3.0, discard_deg=2.0, names=["135_08.amc"]).save(path)
    return path


def _rests_and_moves(fps: float, rest: float, move: float, count: int) -> tuple[np.ndarray, list[range]]:
    """A 2-DOF signal resting and moving by raised-cosine steps in turn; (x, the rests)."""
    r, m = round(rest * fps), round(move * fps)
    ramp = 1 - animate.cosine_weight(np.linspace(0, 1, m))
    level, rests = [np.zeros(r)], [range(0, r)]
    for k in range(count):
        level += [k + ramp, np.full(r, k + 1.0)]
        rests.append(range(r + (k + 1) * (m + r) - r, r + (k + 1) * (m + r)))
    level = 40 * np.concatenate(level)
    return np.stack([level, 0.5 * level], axis=1), rests


# ----- segmentation (8.2) ------------------------------------------------------------------
def test_posture_samples_every_d_of_the_distance():
    x = np.stack([np.arange(100.0), np.zeros(100)], axis=1)  # 1 degree per frame
    s = segmentation.posture_samples(x, 10.0)
    assert list(s.frames) == list(range(0, 100, 10)) + [99] and np.array_equal(s.known, s.frames)
    still = segmentation.posture_samples(np.zeros((100, 2)), 10.0, max_lag=30)
    assert list(still.frames) == [0, 30, 60, 90, 99]
    assert list(segmentation.posture_samples(np.zeros((100, 2)), 10.0).frames) == [0, 99]


def test_gesture_samples_fall_where_the_motion_rests():
    fps = 30.0
    x, rests = _rests_and_moves(fps, 0.6, 0.8, 6)
    s = segmentation.gesture_samples(x, fps)
    speed = np.abs(np.gradient(x[:, 0]))
    inner = s.frames[1:-1]
    assert (speed[inner] < 0.2 * speed.max()).all()  # samples where the motion rests
    for rest in rests[1:-1]:  # every rest between moves has one
        assert any(rest.start - 3 <= f < rest.stop for f in inner), rest
    assert (s.known >= s.frames).all()
    assert np.diff(s.frames).min() >= round(segmentation.GestureParams().min_length * fps)


def test_gesture_segments_never_exceed_the_longest():
    fps = 30.0
    x = np.stack([np.arange(300.0) * 2, np.zeros(300)], axis=1)  # steady motion: no rest at all
    params = segmentation.GestureParams(max_length=1.0)
    s = segmentation.gesture_samples(x, fps, params)
    assert np.diff(s.frames).max() <= 30 and s.frames[0] == 0 and s.frames[-1] == 299


def test_frame_delays_wait_for_the_next_sample():
    s = segmentation.Samples(np.array([0, 10, 30]), np.array([0, 10, 30]))
    d = segmentation.frame_delays(s, 31, 1)
    assert d[0] == 10 and d[1] == 29 and d[10] == 20 and d[11] == 19 and d[30] == 0
    assert segmentation.frame_delays(s, 31, 0)[1] == 9


# ----- segment animation (8.3) -------------------------------------------------------------
def test_hermite_keeps_lines_and_samples_and_is_smooth_at_unequal_lags():
    times = np.array([0, 4, 14, 20])
    line = np.stack([2.0 * times + 1, -times], axis=1)
    assert np.allclose(animate.hermite(times, line, 21), np.stack([2.0 * np.arange(21) + 1, -np.arange(21)], axis=1))
    values = np.array([[0.0], [5.0], [-3.0], [2.0]])
    y = animate.hermite(times, values, 21)[:, 0]
    assert np.allclose(y[times], values[:, 0])
    fine = animate.hermite(times * 100, values, 2001)[:, 0]
    for t in (400, 1400):  # one-sided derivatives agree
        assert abs((fine[t] - fine[t - 1]) - (fine[t + 1] - fine[t])) < 1e-3


def test_hermite_slope_is_the_thesis_estimate_at_equal_lags():
    times = np.array([0, 1000, 2000])
    values = np.array([[0.0], [10.0], [40.0]])
    y = animate.hermite(times, values, 2001)[:, 0]
    delta = 0.5 * (10.0 - 0.0) + 0.5 * (40.0 - 10.0)  # (8-7) with s = 1/2 (8-8)
    assert abs((y[1001] - y[999]) / 2 * 1000 - delta) < 0.01


def test_raised_cosine_rests_at_the_samples_and_blending_is_continuous():
    times = np.array([0, 10, 20])
    values = np.array([[0.0], [1.0], [0.0]])
    y = animate.raised_cosine(times, values, 21)[:, 0]
    assert np.allclose(y[times], values[:, 0]) and abs(y[1] - y[0]) < 0.03 and abs(y[10] - y[9]) < 0.03
    seg = np.full((12, 1), 5.0)
    eased = animate.blend_start(seg, np.array([1.0]), 6)[:, 0]
    assert 1.0 < eased[0] < 1.5 and np.all(np.diff(eased) >= 0) and eased[6:].tolist() == [5.0] * 6
    assert np.array_equal(animate.stretch(np.arange(5.0)[:, None], 9)[:, 0], np.arange(0, 4.5, 0.5))


# ----- tables (8.4.1, 8.4.2) ---------------------------------------------------------------
def test_posture_table_entries_are_spaced_and_tables_are_deterministic(martial_amc, martial_tables):
    tables = motiontables.Tables.load(martial_tables)
    again = motiontables.train([martial_amc], spacing_cm=3.0, discard_deg=2.0, names=["135_08.amc"])
    assert again.to_bytes() == martial_tables.read_bytes()
    sk = martial_amc.skeleton
    groups = modelgroups.model_groups(sk)
    for k, g in enumerate(groups.parts):
        v = tables.posture_vectors(sk, groups, k)
        d = np.linalg.norm(v[:, None] - v[None], axis=2) + np.eye(len(v)) * 1e9
        assert d.min() >= 0.03 - 2e-3, g.name  # angle steps move entries a little
        assert len(tables.gestures[k]) >= 1 and tables.gestures[k].shape[1] == motiontables.NORM
    assert all(len(p) >= 1 for p in tables.postures) and sum(len(p) for p in tables.postures) > len(groups.parts)


def test_similarity_weights_follow_8_13():
    w = motiontables.similarity_weights(6, 0.5, 1)
    raw = w / w[0]
    assert np.allclose(raw, [1, 0.75, 2 / 3, 2 / 3, 0.75, 1]) and np.isclose(w.sum(), 1.0)


def test_tables_file_errors(martial_tables, walk_bvh, tmp_path):
    data = martial_tables.read_bytes()
    bad = tmp_path / "bad.moctb"
    bad.write_bytes(data[:-10])
    with pytest.raises(CodecError, match="checksum"):
        motiontables.Tables.load(bad)
    with pytest.raises(CodecError, match="another channel layout"):
        get_codec("posture", tables=str(martial_tables)).encode(walk_bvh[:50])


# ----- codecs (8.4.3, 8.4.4, 8.5) ----------------------------------------------------------
@pytest.mark.parametrize("cid", ["posture", "gesture", "hybrid"])
def test_codec_round_trips_and_is_deterministic(cid, walk30, walk_bvh):
    for clip in (walk30, walk_bvh.resample(30)):
        codec = get_codec(cid)
        data = codec.encode(clip)
        assert data == get_codec(cid).encode(clip)
        out = codec.decode(data, clip.skeleton, clip.num_frames, clip.fps)
        assert out.channels.shape == clip.channels.shape and np.isfinite(out.channels).all()
        s = compare(clip, out).summary()
        assert s["mean_joint_error_cm"] < 15 and s["vpsnr_db"] > 5, (cid, s)


def test_trained_tables_beat_nothing_and_reach_low_rates(walk30, martial_tables):
    for cid in ("posture", "gesture"):
        external = get_codec(cid, tables=str(martial_tables))
        data = external.encode(walk30)
        bits_per_second = len(data) * 8 / (walk30.num_frames / walk30.fps)
        assert bits_per_second < 2000, (cid, bits_per_second)  # the thesis: hundreds of bit/s
        carried = get_codec(cid).encode(walk30)
        assert len(carried) > 3 * len(data)  # the carried tables cost their size
        out = external.decode(data, walk30.skeleton, walk30.num_frames, walk30.fps)
        held = walk30.with_channels(np.repeat(walk30.channels[:1], walk30.num_frames, axis=0))
        assert (
            compare(walk30, out).summary()["mean_joint_error_cm"]
            < 0.5 * compare(walk30, held).summary()["mean_joint_error_cm"]
        )
        with pytest.raises(CodecError, match="none is given"):
            get_codec(cid).decode(data, walk30.skeleton, walk30.num_frames, walk30.fps)


def test_quality_knobs_trade_rate_for_error(walk30, martial_tables):
    coarse, fine = get_codec("posture", d=60.0), get_codec("posture", d=8.0)
    assert len(fine.encode(walk30)) > len(coarse.encode(walk30))
    low, high = get_codec("hybrid", level=0), get_codec("hybrid", level=7)
    e = [
        compare(walk30, c.decode(c.encode(walk30), walk30.skeleton, walk30.num_frames, walk30.fps)).summary()[
            "mean_joint_error_cm"
        ]
        for c in (low, high)
    ]
    assert e[1] < 0.7 * e[0] and len(high.encode(walk30)) > len(low.encode(walk30))
    rate = ratecontrol.measure(get_codec("hybrid", level=4), walk30).bitrate
    assert ratecontrol.tune(get_codec("hybrid"), walk30, "bitrate", rate).codec.config["level"] == 4


def test_gesture_falls_back_to_postures_when_no_gesture_fits(walk30, martial_tables):
    every = get_codec("gesture", tables=str(martial_tables), e=1e4).encode(walk30)
    none = get_codec("gesture", tables=str(martial_tables), e=0.0).encode(walk30)
    assert every != none
    for data in (every, none):
        out = get_codec("gesture", tables=str(martial_tables)).decode(
            data, walk30.skeleton, walk30.num_frames, walk30.fps
        )
        assert np.isfinite(out.channels).all()


def test_delays_are_reported_and_bounded(walk30):
    posture = get_codec("posture", max_lag=1.0).delays(walk30)
    assert posture.shape == (walk30.num_frames,) and posture.max() <= 2 * 30
    gesture = get_codec("gesture", max_length=1.0).delays(walk30)
    assert 0 < gesture.mean() and gesture.max() <= 30 + segmentation.fit_window(30) + 30


def test_payload_damage_is_caught(walk30, martial_tables):
    data = get_codec("posture", tables=str(martial_tables)).encode(walk30)
    body = bytearray(data)
    body[30] ^= 0xFF
    with pytest.raises(CorruptStreamError):
        get_codec("posture", tables=str(martial_tables)).decode(
            bytes(body), walk30.skeleton, walk30.num_frames, walk30.fps
        )


def test_cli_trains_tables_and_codes_with_them(tmp_path, capsys):
    tables = tmp_path / "t.moctb"
    assert main(["model", "train", "tables", str(DATA / "135_08.amc"), "-o", str(tables)]) == 0
    assert main(["model", "info", str(tables)]) == 0
    assert "fingerprint" in capsys.readouterr().out
    moc = tmp_path / "w.moc"
    assert main(["encode", str(DATA / "07_03.amc"), "--codec", "gesture", "--tables", str(tables), "-o", str(moc)]) == 0
    moved = tmp_path / "moved.moctb"
    tables.rename(moved)
    assert main(["decode", str(moc), "-o", str(tmp_path / "w.amc"), "--tables", str(moved)]) == 0
    with pytest.raises(SystemExit) as missing:  # no -o FILE
        main(["model", "train", "tables", str(DATA / "135_08.amc")])
    assert missing.value.code == 2
    capsys.readouterr()
    assert main(["eval", str(DATA / "07_03.amc"), "--codec", "hybrid"]) == 0
    assert "coding delay mean / max" in capsys.readouterr().out
