"""Capture from the minimal sensor set (003 ch. 4): soft clipping, logs, and round trips from
poses through simulated sensors back to joint angles."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import DATA
from mocodec import human_model, load, rotations
from mocodec.capture.converter import Converter, convert
from mocodec.capture.sensors import SensorLog, read_log, to_thesis, write_log
from mocodec.capture.simulate import random_poses, simulate
from mocodec.capture.softclip import soft_clip, soft_clip_upper
from mocodec.cli import main
from mocodec.errors import FormatError, MocodecError
from mocodec.kinematics import forward_kinematics


def test_soft_clip_is_linear_then_parabolic_then_flat():
    x = np.linspace(0, 2, 2001)
    y = soft_clip_upper(x, 1.0, 0.2)
    np.testing.assert_array_equal(y[x <= 0.8], x[x <= 0.8])  # linear up to x1 = x_c - margin
    assert np.all(y[x >= 1.2] == 1.0)  # constant x_c beyond x2
    slope = np.gradient(y, x)
    assert slope[np.searchsorted(x, 0.8)] == pytest.approx(1.0, abs=0.01)
    assert slope[np.searchsorted(x, 1.2) - 1] == pytest.approx(0.0, abs=0.01)
    assert np.all(np.diff(y) >= -1e-12) and np.abs(np.diff(y)).max() < 0.002  # monotone, continuous
    both = soft_clip(np.array([-5.0, 0.0, 5.0]), -1.0, 1.0, 0.1)
    np.testing.assert_allclose(both, [-1.0, 0.0, 1.0])
    assert soft_clip(np.array([7.0]), -np.inf, np.inf, 0.1)[0] == 7.0


def errors_cm(truth, got, joint):
    sk = truth.skeleton
    a = forward_kinematics(sk, truth.channels)[0][:, sk.index(joint)]
    b = forward_kinematics(sk, got.channels)[0][:, sk.index(joint)]
    return np.linalg.norm(a - b, axis=1) * 100


@pytest.fixture(scope="module")
def poses():
    return random_poses(400, seed=3)


def test_noise_free_round_trip_puts_head_wrists_and_feet_back(poses):
    got = convert(simulate(poses, noise_deg=0, noise_cm=0, glove_noise=0, seed=1))
    for joint, mean, worst in (
        ("root", 1e-6, 1e-6),
        ("head_top", 0.2, 1.0),
        ("left_wrist", 0.05, 1.5),
        ("right_wrist", 0.05, 1.5),
        ("left_ankle", 0.1, 1.5),
        ("right_ankle", 0.1, 1.5),
    ):
        e = errors_cm(poses, got, joint)
        assert e.mean() < mean and e.max() < worst, (joint, e.mean(), e.max())
    sk = poses.skeleton
    # the forearms' orientation (what a wrist tracker measures) comes back
    qa = forward_kinematics(sk, poses.channels)[1][:, sk.index("left_elbow")]
    qb = forward_kinematics(sk, got.channels)[1][:, sk.index("left_elbow")]
    assert np.median(np.degrees(rotations.quat_distance(qa, qb))) < 0.5
    # fingers from the gloves, and what cannot be known stays at zero (hip twist, wrists)
    fingers = [sk.channel_index(f"left_{f}") for f in ("index2.Zrotation", "thumb2.Xrotation")]
    inside = (poses.channels[:, fingers] > sk.limits[fingers, 0] + 5) & (
        poses.channels[:, fingers] < sk.limits[fingers, 1] - 5
    )
    np.testing.assert_allclose(got.channels[:, fingers][inside], poses.channels[:, fingers][inside], atol=1e-6)
    assert inside.mean() > 0.5  # (within 5 degrees of a limit, soft clipping eases)
    for name in ("left_hip.Yrotation", "right_wrist.Zrotation", "left_index1.Xrotation"):
        assert np.all(got.channels[:, sk.channel_index(name)] == 0)


def test_noisy_trackers_give_errors_of_the_noise_size(poses):
    got = convert(simulate(poses, noise_deg=1.0, noise_cm=0.5, seed=2))
    for joint in ("head_top", "left_wrist", "right_wrist"):
        e = errors_cm(poses, got, joint)
        assert e.mean() < 1.5, (joint, e.mean())
    assert np.isfinite(got.channels).all()
    sk = got.skeleton
    rot = sk.rotation_mask
    assert np.all(got.channels[:, rot] >= sk.limits[rot, 0] - 1e-9)
    assert np.all(got.channels[:, rot] <= sk.limits[rot, 1] + 1e-9)


def test_wrist_correction_lands_the_wrist_on_its_tracker(poses):
    log = simulate(poses, noise_deg=2.0, noise_cm=0.0, seed=4)
    corrected = errors_cm(poses, Converter().convert(log), "left_wrist")
    plain = errors_cm(poses, Converter(wrist_correction=False).convert(log), "left_wrist")
    assert corrected.mean() < plain.mean()


def test_log_round_trip_and_the_thesis_frames(tmp_path, poses):
    log = simulate(poses[:20], seed=5)
    path = tmp_path / "log.npz"
    write_log(log, path)
    back = read_log(path)
    np.testing.assert_allclose(back.trackers["head"], log.trackers["head"])
    np.testing.assert_allclose(back.calibration["left_wrist"], log.calibration["left_wrist"])
    assert back.fps == pytest.approx(120.0)
    raw = np.load(path)["hips"][0]
    right_handed = log.trackers["hips"][0]
    np.testing.assert_allclose(raw[3, :3], right_handed[:3, 3] * [1, 1, -1])  # position in the bottom row, z mirrored
    np.testing.assert_allclose(to_thesis(right_handed), raw)


@pytest.mark.parametrize(
    "change, why",
    [
        (lambda d: d.pop("head"), "missing array 'head'"),
        (lambda d: d.__setitem__("left_glove", d["left_glove"][:, :4]), "'left_glove': expected shape"),
        (lambda d: d["time"].__setitem__(5, 0.0), "'time': frame 5"),
        (lambda d: d["right_wrist"].__setitem__((3, 0, 0), 2.0), "'right_wrist': frame 3: not a rigid"),
        (lambda d: d["right_glove"].__setitem__((7, 2), 1.5), "'right_glove': frame 7"),
        (lambda d: d["hips"].__setitem__((2, 1, 1), np.nan), "'hips': frame 2: a value is not finite"),
    ],
)
def test_malformed_logs_are_refused_with_array_and_frame(tmp_path, poses, change, why):
    log = simulate(poses[:10], seed=6)
    path = tmp_path / "log.npz"
    write_log(log, path)
    data = dict(np.load(path))
    change(data)
    np.savez(path, **data)
    with pytest.raises(FormatError, match=why) as e:
        read_log(path)
    assert "log.npz" in str(e.value)


def test_capture_commands_from_a_cmu_clip(tmp_path, capsys):
    log, out = tmp_path / "walk.npz", tmp_path / "walk.bvh"
    assert main(["capture", "--simulate", str(DATA / "07_03.amc"), "-o", str(log)]) == 0
    assert main(["capture", str(log), "-o", str(out)]) == 0
    got = load(out)
    assert got.num_frames == 415 and got.skeleton.height() == pytest.approx(human_model().height(), abs=0.01)
    # the retargeted walk moves: the root travels and the elbows bend
    assert np.ptp(got.channels[:, got.skeleton.channel_index("root.Zposition")]) > 0.5
    assert main(["capture", str(tmp_path / "missing.npz"), "-o", str(out)]) == 2
    assert "missing.npz" in capsys.readouterr().err


def test_simulation_refuses_a_skeleton_it_cannot_read():
    from mocodec.motion import Motion
    from mocodec.skeleton import Joint, Skeleton

    sk = Skeleton((Joint("a", -1, (0, 0, 0), ("Xrotation",), "X"),))
    with pytest.raises(MocodecError, match="cannot simulate"):
        simulate(Motion(sk, 30.0, np.zeros((5, 1))))


def test_an_empty_log_is_refused():
    empty = SensorLog(np.zeros(0), {}, {}, {})
    with pytest.raises(MocodecError, match="no frames"):
        convert(empty)
