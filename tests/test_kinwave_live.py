"""kinwave-live: the low-delay live mode of kinwave (docs/streaming.md)."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec.codecs import get_codec
from mocodec.codecs.kinwave import live
from mocodec.errors import CorruptStreamError
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors


def _frame_errors(motion, channels, measure="joint"):
    """Per frame, the max joint (or shell) error in cm of ``channels`` against ``motion``."""
    sk, cm = motion.skeleton, 100.0 / motion.skeleton.units_per_metre
    p0, q0 = forward_kinematics(sk, motion.channels)
    p1, q1 = forward_kinematics(sk, channels)
    if measure == "shell":
        return shell_errors(sk, p0 * cm, q0, p1 * cm, q1).per_frame.max(axis=1)
    return (np.linalg.norm(p1 - p0, axis=2) * cm).max(axis=1)


@pytest.mark.parametrize("fps,frames", [(120.0, 6), (100.0, 5), (60.0, 3), (30.0, 1), (24.0, 1), (10.0, 1)])
def test_packets_hold_their_first_frame_back_at_most_50_ms(fps, frames):
    assert live.packet_frames(fps) == frames and (frames - 1) / fps <= live.DELAY_S + 1e-9


@pytest.mark.parametrize("clip", ["walk_bvh", "walk_amc"])
@pytest.mark.parametrize("bound,measure", [(1.0, "joint"), (0.3, "joint"), (1.0, "shell")])
def test_the_bound_holds_on_every_decoded_frame(clip, bound, measure, request):
    motion = request.getfixturevalue(clip)
    codec = get_codec("kinwave-live", max_error_cm=bound, error_measure=measure)
    decoded = codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)
    errors = _frame_errors(motion, decoded.channels, measure)
    assert errors.max() <= bound + 1e-9
    assert np.median(errors) > 0.3 * bound  # the budget is used, not wasted


def test_a_stream_pushed_in_any_pieces_gives_the_same_packets_and_frames(walk_bvh):
    codec = get_codec("kinwave-live")
    whole = codec.encoder(walk_bvh.skeleton, walk_bvh.fps)
    packets = whole.push(walk_bvh.channels) + whole.flush()
    pieces, enc = [], codec.encoder(walk_bvh.skeleton, walk_bvh.fps)
    for a in range(0, walk_bvh.num_frames, 7):
        pieces += enc.push(walk_bvh.channels[a : a + 7])
    pieces += enc.flush()
    assert pieces == packets
    dec = codec.decoder(walk_bvh.skeleton, walk_bvh.fps)
    frames = [dec.push(p) for p in packets]
    assert all(len(f) <= live.packet_frames(walk_bvh.fps) for f in frames)  # 50 ms at most behind
    out = np.concatenate(frames)
    assert np.array_equal(
        out, codec.decode(codec.encode(walk_bvh), walk_bvh.skeleton, walk_bvh.num_frames, walk_bvh.fps).channels
    )


def test_coding_is_deterministic_and_sparse_strides_are_used_at_120_fps(walk_bvh, walk_amc):
    codec = get_codec("kinwave-live")
    assert codec.encode(walk_bvh) == codec.encode(walk_bvh)
    # at 120 fps most packets code fewer than all their frames: far fewer bytes than one per frame
    fine = codec.encode(walk_amc)
    thirty = codec.encode(walk_amc.resample(30.0))
    assert len(fine) < 2.0 * len(thirty)


def test_a_constant_clip_costs_almost_nothing(walk_amc):
    still = walk_amc.with_channels(np.repeat(walk_amc.channels[:1], 240, axis=0))
    codec = get_codec("kinwave-live")
    body = codec.encode(still)
    decoded = codec.decode(body, still.skeleton, still.num_frames, still.fps)
    assert _frame_errors(still, decoded.channels).max() <= 1.0
    assert len(body) < 40 + 250  # the first frame, then about a byte per packet


def test_damaged_packets_raise_only_our_error(walk_bvh):
    codec = get_codec("kinwave-live")
    enc = codec.encoder(walk_bvh.skeleton, walk_bvh.fps)
    packets = enc.push(walk_bvh.channels[:120]) + enc.flush()
    rng = np.random.default_rng(3)
    for _ in range(60):
        dec = codec.decoder(walk_bvh.skeleton, walk_bvh.fps)
        for k, p in enumerate(packets):
            if k == 3:
                p = bytes(rng.integers(0, 256, rng.integers(0, 40), dtype=np.uint8))
            try:
                out = dec.push(p)
                assert np.isfinite(out).all()
            except CorruptStreamError:
                break
