"""Crowd allocation (001 §6.4, 6.5) and scene files."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec import scene
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.metrics import compare


def test_scores_and_split_follow_6_4_and_6_5():
    s = scene.bandwidth_scores(np.array([2.0, 4.0, 8.0]))
    assert s.tolist() == [1.0, 0.5, 0.25]
    assert scene.split_budget(700, s).tolist() == [400, 200, 100]
    weighted = scene.bandwidth_scores(np.array([2.0, 4.0]), weights=np.array([1.0, 2.0]))
    assert weighted.tolist() == [1.0, 1.0]
    per_segment = scene.bandwidth_scores(np.array([[1.0, 4.0], [2.0, 2.0], [np.nan, 1.0]]))
    assert per_segment[:, 0].tolist() == [1.0, 0.5, 0.0] and per_segment[:, 1].tolist() == [0.25, 0.5, 1.0]
    with pytest.raises(CodecError):
        scene.bandwidth_scores(np.array([1.0, 0.0]))


def test_a_scene_shares_one_budget(walk_amc):
    motions = [walk_amc, walk_amc, walk_amc[:200]]
    bps = 9000
    budgets = scene.allocate(motions, bps, [1.0, 2.0, 4.0])
    total = int(bps * 128 / walk_amc.fps)
    assert np.all(budgets.sum(axis=0) <= total) and np.all(budgets.sum(axis=0) >= total - 3)
    assert budgets[2, 2:].sum() == 0  # the short clip is gone after 200 frames
    data = scene.encode_scene(motions, bps, [1.0, 2.0, 4.0])
    decoded = scene.decode_scene(data)
    errors = [compare(m, d).joints.mean for m, d in zip(motions, decoded)]
    assert errors[0] < errors[1]
    sizes = scene.scene_sizes(data)
    assert sizes[0] > sizes[1]


def test_the_split_follows_the_camera(walk_amc):
    """Two characters swap places half way: their budgets swap with them."""
    d = np.array([[1.0, 1.0, 4.0, 4.0], [4.0, 4.0, 1.0, 1.0]])
    b = scene.allocate([walk_amc, walk_amc], 8000, d)
    assert b[0, 0] > b[1, 0] and b[0, 3] < b[1, 3]
    with pytest.raises(CodecError, match="distances"):
        scene.allocate([walk_amc, walk_amc], 8000, np.ones((2, 7)))


def test_damaged_scene_files_are_refused(walk_amc):
    data = scene.encode_scene([walk_amc[:100]], 5000, [1.0])
    with pytest.raises(CorruptStreamError, match="CRC"):
        scene.decode_scene(data[:20] + bytes([data[20] ^ 1]) + data[21:])
    with pytest.raises(CorruptStreamError, match="not a mocodec scene"):
        scene.decode_scene(b"MOC1" + data[4:])


def test_split_budget_splits_each_column_as_its_own_budget():
    from mocodec.scene import bandwidth_scores, split_budget

    rng = np.random.default_rng(3)
    scores = bandwidth_scores(rng.uniform(0.5, 30.0, (40, 7)))
    totals = rng.integers(1_000, 5_000_000, 7)
    together = split_budget(totals, scores)
    for k in range(7):
        assert np.array_equal(together[:, k], split_budget(int(totals[k]), scores[:, k]))
        assert together[:, k].sum() <= totals[k]
    assert np.array_equal(split_budget(100, np.zeros(3)), [0, 0, 0])


def test_viewer_shares_are_6_4_and_6_5_of_the_camera_distances():
    """The relay's shares for all viewers at once: avatars 1 m and 2 m from a camera share its
    3,000 bit/s 2:1 (a nearer one counting as 0.5 m), and every random case gives what the
    equations give of the distances one by one; the layers within a share count the layer
    rates up to it, at least one."""
    from mocodec.crowd import bandwidth_scores, layers_within, split_budget, viewer_shares

    where = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.1]])
    shares = viewer_shares(where, np.zeros((1, 3)), np.array([3500]), 0.5)
    assert shares[:, 0].tolist() == [1000, 500, 2000]
    rng = np.random.default_rng(4)
    for _ in range(50):
        avatars, cameras = rng.uniform(-20, 20, (30, 3)), rng.uniform(-20, 20, (4, 3))
        budgets = rng.integers(0, 10**7, 4)
        distances = np.maximum(np.linalg.norm(avatars[:, None] - cameras[None], axis=2), 0.1)
        expected = split_budget(budgets, bandwidth_scores(distances))
        assert np.array_equal(viewer_shares(avatars, cameras, budgets, 0.1), expected)
    rates = np.array([[100.0, 300.0, 900.0], [50.0, 60.0, 70.0]])
    assert layers_within(rates, np.array([[99.0, 300.0], [10.0, 1e6]])).tolist() == [[1, 2], [1, 3]]
