import numpy as np
import pytest

from mocodec import Joint, Motion, Skeleton
from mocodec.kinematics import forward_kinematics, global_matrices, positions_from_orientations


def two_joint_arm():
    return Skeleton(
        (
            Joint("root", -1, (0.0, 0.0, 0.0), ("Xposition", "Yposition", "Zposition", "Zrotation"), "Z"),
            Joint("elbow", 0, (2.0, 0.0, 0.0), ("Zrotation",), "Z"),
            Joint("hand", 1, (1.0, 0.0, 0.0)),
        )
    )


def test_two_joint_planar_arm_has_known_positions():
    sk = two_joint_arm()
    a, b = np.radians(30.0), np.radians(45.0)
    ch = np.array([[1.0, 2.0, 3.0, 30.0, 45.0], [0.0, 0.0, 0.0, 90.0, -90.0]])
    pos, _ = forward_kinematics(sk, ch)
    np.testing.assert_allclose(pos[0, 1], [1 + 2 * np.cos(a), 2 + 2 * np.sin(a), 3], atol=1e-12)
    np.testing.assert_allclose(pos[0, 2], pos[0, 1] + [np.cos(a + b), np.sin(a + b), 0], atol=1e-12)
    np.testing.assert_allclose(pos[1, 2], [1.0, 2.0, 0.0], atol=1e-12)


def test_bvh_channel_order_is_intrinsic():
    sk = Skeleton((Joint("root", -1, (0, 0, 0), ("Zrotation", "Xrotation"), "ZX"), Joint("tip", 0, (0, 1, 0))))
    pos, _ = forward_kinematics(sk, np.array([[90.0, 90.0]]))
    # Rz(90) Rx(90) (0,1,0): Rx takes y to z, Rz leaves z
    np.testing.assert_allclose(pos[0, 1], [0, 0, 1], atol=1e-12)


def test_asf_axis_rotates_in_the_bone_frame():
    # a bone whose frame is turned 90 deg about Z: its local X is world Y
    sk = Skeleton(
        (
            Joint("root", -1, (0, 0, 0)),
            Joint("b", 0, (0, 0, 0), ("Xrotation",), "X", axis=(90.0, 0.0, 0.0), axis_order="ZYX"),
            Joint("tip", 1, (0, 0, 1)),
        )
    )
    pos, _ = forward_kinematics(sk, np.array([[90.0]]))
    # rotation of 90 deg about world Y takes +Z to +X
    np.testing.assert_allclose(pos[0, 2], [1, 0, 0], atol=1e-12)


def test_bone_lengths_constant_and_matrices_orthonormal(walk_bvh, walk_amc):
    for m in (walk_bvh, walk_amc):
        pos = m.positions()
        sk = m.skeleton
        bones = np.linalg.norm(pos[:, 1:] - pos[:, sk.parents[1:]], axis=2)
        np.testing.assert_allclose(
            bones,
            np.broadcast_to(np.linalg.norm(sk.offsets[1:], axis=1), bones.shape),
            atol=1e-9 * sk.units_per_metre * 100,
        )
        rot = global_matrices(sk, m.channels[:20])
        np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)


def test_wrong_width_is_rejected():
    with pytest.raises(ValueError):
        forward_kinematics(two_joint_arm(), np.zeros((3, 4)))
    with pytest.raises(ValueError):
        Motion(two_joint_arm(), 30, np.zeros((3, 4)))


def test_positions_from_known_orientations_are_forward_kinematics_own(walk_bvh, walk_amc):
    """Given forward kinematics' own orientations, the positions are its positions to the bit
    (the same translations and formula), on a BVH and an ASF skeleton; and the planar arm's
    known answer."""
    for motion in (
        walk_bvh[:50],
        walk_amc[:50],
        Motion(two_joint_arm(), 30.0, np.array([[1.0, 2.0, 3.0, 30.0, 45.0]])),
    ):
        pos, quat = forward_kinematics(motion.skeleton, motion.channels)
        placed, same = positions_from_orientations(
            motion.skeleton, motion.channels.T, np.ascontiguousarray(quat.transpose(1, 0, 2))
        )
        assert np.array_equal(placed, pos) and np.array_equal(same, quat)
