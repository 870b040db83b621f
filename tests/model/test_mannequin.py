"""The procedural mannequin (:mod:`mocodec.mannequin`) on every kind of skeleton: a closed,
skinned surface around the bones, weights that sum to one and blend at the joints, and a body
that moves with its bones."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec import Motion, mannequin
from mocodec.human import human_model
from mocodec.kinematics import forward_kinematics
from mocodec.reexpress import with_dummy_root, with_position_channels


def _skeletons(walk_bvh, walk_amc) -> dict[str, Motion]:
    bandai_like = with_dummy_root(with_position_channels(walk_bvh[:60]), position_channels=True)
    human = human_model()
    return {
        "CMU ASF/AMC": walk_amc[:60],
        "cgspeed BVH (fingers)": walk_bvh[:60],
        "dummy root, 6-channel joints": bandai_like,
        "built-in human model": Motion(human, 30.0, np.zeros((2, human.num_channels))),
    }


@pytest.fixture(scope="module")
def skeletons(walk_bvh, walk_amc):
    return _skeletons(walk_bvh, walk_amc)


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point from the segment of its row's ``a`` to ``b``."""
    ab = b - a
    t = np.clip(((points - a) * ab).sum(axis=1) / np.maximum((ab * ab).sum(axis=1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


@pytest.mark.parametrize(
    "kind", ["CMU ASF/AMC", "cgspeed BVH (fingers)", "dummy root, 6-channel joints", "built-in human model"]
)
def test_a_mannequin_is_a_closed_skinned_surface_around_the_bones(skeletons, kind):
    motion = skeletons[kind]
    sk = motion.skeleton
    bind = mannequin.bind_positions(sk, motion.channels[0])
    body = mannequin.build(sk, bind)
    metre = sk.units_per_metre
    assert np.allclose(body.weights.sum(axis=1), 1.0) and (body.weights >= 0).all()
    corners = body.positions[body.triangles]
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1) / 2
    assert areas.min() > 1e-8 * metre**2  # no degenerate triangle
    edges = np.sort(np.concatenate([body.triangles[:, [0, 1]], body.triangles[:, [1, 2]], body.triangles[:, [2, 0]]]))
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert (uses == 2).all()  # every edge joins two triangles: each capsule is closed
    parents = sk.parents[body.owners]
    away = _segment_distance(body.positions, bind[parents], bind[body.owners]) / metre
    assert away.max() <= max(mannequin.RADII_M.values()) + 1e-9  # within a capsule's radius of its bone
    assert (np.count_nonzero(body.weights > 0.05, axis=1) >= 2).mean() > 0.2  # joints blend two influences
    assert np.isin(np.arange(1, len(sk)), body.owners).sum() >= len(sk) // 2


def test_the_body_moves_with_its_bones(walk_amc):
    """Skinned at a frame of the walk, a vertex that follows one joint keeps its distance from
    its bone, and a blended one stays near both."""
    motion = walk_amc[:120]
    sk = motion.skeleton
    bind = mannequin.bind_positions(sk, motion.channels[0])
    body = mannequin.build(sk, bind)
    positions, quats = forward_kinematics(sk, motion.channels[90:91])
    posed = mannequin.skinned(body, bind, positions[0], quats[0])
    parents = sk.parents[body.owners]
    rest = _segment_distance(body.positions, bind[parents], bind[body.owners])
    now = _segment_distance(posed, positions[0][parents], positions[0][body.owners])
    rigid = body.weights.max(axis=1) > 0.999
    assert np.allclose(now[rigid], rest[rigid], atol=1e-9 * sk.units_per_metre)
    assert (now / sk.units_per_metre).max() < 0.15  # the blended ones stay near their bone too


def test_levels_of_detail_and_the_size_of_a_57_joint_body(walk_bvh):
    sk = walk_bvh.skeleton
    assert len(sk) >= 57
    triangles = [len(mannequin.build(sk, level=k).triangles) for k in range(len(mannequin.LEVELS))]
    assert triangles[0] < 20_000 and triangles == sorted(triangles, reverse=True) and triangles[-1] < 2_000
    with pytest.raises(ValueError, match="level"):
        mannequin.build(sk, level=len(mannequin.LEVELS))


def test_the_hips_are_the_top_of_the_body(walk_bvh):
    """A dummy root above the hips, at the origin while the capture starts metres away, adds no
    bone to the body: the same capsules as without it."""
    clip = walk_bvh[:10]
    own = mannequin.build(clip.skeleton, mannequin.bind_positions(clip.skeleton, clip.channels[0]))
    dummy = with_dummy_root(clip, (0.0, -90.0, 0.0))
    under = mannequin.build(dummy.skeleton, mannequin.bind_positions(dummy.skeleton, dummy.channels[0]))
    assert len(under.positions) == len(own.positions) and len(under.triangles) == len(own.triangles)
