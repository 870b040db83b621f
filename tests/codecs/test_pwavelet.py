"""pwavelet (001 §3.2): the allocation steps with known answers, round trips on real clips,
the ablations, and the rate/quality trade."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec import ratecontrol
from mocodec.codecs import get_codec
from mocodec.codecs.perceptual import pwavelet as pw
from mocodec.metrics import compare


def test_variation_and_importance_follow_3_1_and_3_2():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [2.0, 0.0]])
    bone = np.array([0.5, 1.0])
    a = pw.importance(x, bone, "perceptual")
    assert a.tolist() == [0.5 * (1 + 2 + 1) / 4, 0.0]
    assert pw.importance(x, bone, "bone").tolist() == [0.5, 1.0]
    assert pw.importance(x, bone, "uniform").tolist() == [1.0, 1.0]


def test_coefficient_counts_follow_step_6():
    a = np.array([1.0, 3.0, 0.0, 0.0])
    k = pw.coefficient_counts(a, alpha=0.25, frames=64, coefficients=64, minimum=2)
    assert k.tolist() == [16, 48, 2, 2]  # alpha A_i N W / sum A, at least C
    capped = pw.coefficient_counts(np.array([1.0, 9.0]), alpha=1.0, frames=10, coefficients=12, minimum=0)
    assert capped.tolist() == [8, 12]  # the excess of the capped one moves


def test_keep_largest_keeps_the_coarse_band_and_the_k_largest():
    c = np.array([[0.1, 0.2, 5.0, -7.0, 0.3, 1.0]])
    assert pw.keep_largest(c, np.array([2]), always=2).tolist() == [[0.1, 0.2, 5.0, -7.0, 0.0, 0.0]]


def test_root_channels_count_as_the_longest_bone(walk_amc):
    l = pw.channel_bone_lengths(walk_amc.skeleton)
    assert l.max() == 1.0 and np.all(l[walk_amc.skeleton.channel_joints == 0] == 1.0)


@pytest.mark.parametrize("allocation", ["perceptual", "bone", "uniform"])
def test_round_trip_error_shrinks_with_alpha(walk_amc, allocation):
    errors = []
    for alpha in (0.02, 0.1, 1.0):
        codec = get_codec("pwavelet", alpha=alpha, allocation=allocation, qp=14)
        decoded = codec.decode(codec.encode(walk_amc), walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
        errors.append(compare(walk_amc, decoded).joints.mean)
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.1


def test_slices_and_short_clips(walk_bvh):
    for frames, window in ((1, 256), (7, 4), (300, 64)):
        clip = walk_bvh[:frames]
        codec = get_codec("pwavelet", window=window, alpha=1.0, qp=16)
        decoded = codec.decode(codec.encode(clip), clip.skeleton, clip.num_frames, clip.fps)
        assert compare(clip, decoded).joints.max < 0.5
    assert get_codec("pwavelet", window=128).delay_frames() == 128


def test_twenty_five_to_one_on_a_short_walk(walk_amc):
    """3.5 s: the coarse bands and per-slice steps set a floor near 29:1 on a clip this short."""
    m = ratecontrol.tune(get_codec("pwavelet"), walk_amc, "ratio", 25)
    assert 25 <= m.ratio <= 25.5 and m.mean_error_cm < 3
