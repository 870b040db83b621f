import numpy as np
import pytest

from mocodec import Joint, Motion, Skeleton, rotations as r


def spinner():
    return Skeleton(
        (
            Joint("root", -1, (0, 0, 0), ("Xposition", "Zrotation", "Xrotation", "Yrotation"), "ZXY"),
            Joint("knee", 0, (0, -1, 0), ("Xrotation",), "X"),
            Joint("foot", 1, (0, -1, 0)),
        )
    )


def test_slicing_selection_and_sizes(walk_bvh):
    part = walk_bvh[100:200]
    assert part.num_frames == 100 and part.fps == walk_bvh.fps
    np.testing.assert_array_equal(part.channels, walk_bvh.channels[100:200])
    assert walk_bvh[::2].fps == walk_bvh.fps / 2
    cols = walk_bvh.select_channels(["hip.Xposition", "lShin"])
    assert cols.shape == (walk_bvh.num_frames, 4)
    np.testing.assert_array_equal(cols[:, 0], walk_bvh.channels[:, 0])
    assert walk_bvh.raw_bits == 32 * walk_bvh.num_frames * 132
    assert walk_bvh.raw_bitrate == 32 * 132 * 120
    with pytest.raises(KeyError):
        walk_bvh.select_channels("nojoint.Xrotation")


def test_isclose_compares_angles_modulo_360():
    sk = spinner()
    a = Motion(sk, 30, np.array([[0.0, 179.9, 0, 0, 10]]))
    b = Motion(sk, 30, np.array([[0.0, -180.1, 0, 0, 10]]))
    assert a.isclose(b, atol_degrees=1e-6)
    assert not a.isclose(Motion(sk, 30, np.array([[0.0, 179.8, 0, 0, 10]])), atol_degrees=0.01)
    assert "fps" in a.difference(Motion(sk, 60, a.channels))


def test_resample_linear_channels_and_constant_speed_slerp():
    sk = spinner()
    n = 31
    ch = np.zeros((n, 5))
    ch[:, 0] = np.linspace(0, 3, n)  # translation ramp
    ch[:, 1] = np.linspace(-170, 170, n)  # 3-axis joint turning about Z through 0
    ch[:, 4] = np.linspace(0, 90, n)  # knee
    m = Motion(sk, 30.0, ch)
    up = m.resample(120.0)
    assert up.num_frames == 121 and up.fps == 120.0
    np.testing.assert_allclose(up.channels[:, 0], np.linspace(0, 3, 121), atol=1e-12)
    np.testing.assert_allclose(up.channels[:, 4], np.linspace(0, 90, 121), atol=1e-12)
    np.testing.assert_allclose(up.channels[:, 1], np.linspace(-170, 170, 121), atol=1e-9)
    down = m.resample(10.0)
    np.testing.assert_allclose(down.channels, m.channels[::3], atol=1e-9)


def test_resample_slerps_a_general_rotation():
    sk = spinner()
    q0 = r.euler_to_quat(np.array([10.0, 20.0, 30.0]), "ZXY")
    q1 = r.euler_to_quat(np.array([60.0, -30.0, 100.0]), "ZXY")
    ch = np.zeros((2, 5))
    ch[0, 1:4], ch[1, 1:4] = [10, 20, 30], [60, -30, 100]
    mid = Motion(sk, 1.0, ch).resample(2.0).channels[1, 1:4]
    np.testing.assert_allclose(r.quat_distance(r.euler_to_quat(mid, "ZXY"), r.quat_slerp(q0, q1, 0.5)), 0, atol=1e-7)


def test_resample_keeps_euler_curves_continuous(walk_bvh):
    up = walk_bvh.resample(240.0)
    rot = walk_bvh.skeleton.rotation_mask
    jumps = np.abs(np.diff(up.channels[:, rot], axis=0)).max()
    assert jumps < np.abs(np.diff(walk_bvh.channels[:, rot], axis=0)).max() + 1e-6
    np.testing.assert_allclose(up.positions()[::2][:50], walk_bvh.positions()[:50], atol=1e-6)


def test_root_positions_are_joint_0s_forward_kinematics(walk_bvh, walk_amc):
    for motion in (walk_bvh, walk_amc):
        assert np.allclose(motion.root_positions(), motion.positions()[:, 0], atol=1e-9)


def test_skeletons_read_alike_are_equal_and_share_their_plans(walk_bvh):
    """A file read twice gives two skeletons that are equal and hash alike, so per-skeleton
    plans (cached on the skeleton) are made once; another offset, unit or name makes another
    skeleton, and the metadata does not count."""
    from dataclasses import replace

    from conftest import DATA
    from mocodec import load
    from mocodec.kinematics import channel_plan

    again = load(DATA / "07_03.bvh").skeleton
    sk = walk_bvh.skeleton
    assert again is not sk and again == sk and hash(again) == hash(sk)
    assert channel_plan(again) is channel_plan(sk)
    moved = list(sk.joints)
    moved[3] = replace(moved[3], offset=(moved[3].offset[0] + 1.0, *moved[3].offset[1:]))
    for other in (Skeleton(tuple(moved), sk.units_per_metre), Skeleton(sk.joints, 2 * sk.units_per_metre)):
        assert other != sk
    assert Skeleton(sk.joints, sk.units_per_metre, sk.name, {"note": 1}) == sk
    assert sk != "skeleton"
