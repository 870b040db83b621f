"""kinwave-live: the low-delay live mode of kinwave (docs/streaming.md)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from mocodec.codecs import get_codec
from mocodec.codecs.kinwave import live
from mocodec.codecs.kinwave.live.predict import Layer, update_misses
from mocodec.errors import CorruptStreamError, OutOfStepError
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


@pytest.mark.parametrize("bound", [1.0, 16.0])
def test_the_bound_holds_when_an_avatar_moves_after_standing_still(walk_bvh, bound):
    still = np.repeat(walk_bvh.channels[:1], 800, axis=0)  # 6.7 s: the scale drifts far coarser
    motion = walk_bvh.with_channels(np.vstack((still, walk_bvh.channels)))
    codec = get_codec("kinwave-live", max_error_cm=bound)
    decoded = codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)
    assert _frame_errors(motion, decoded.channels).max() <= bound + 1e-9


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


@pytest.mark.parametrize("layers", [1, 3])
def test_damaged_packets_raise_only_our_error(walk_bvh, layers):
    codec = get_codec("kinwave-live", layers=layers)
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


# ----- layers ------------------------------------------------------------------------------------
def _layered_packets(motion, layers=3, bound=1.0, **knobs):
    """The codec and its packets of ``motion``, each as the relay may send it: cut to 1, 2, ...
    layers (the last whole), at the ends a decoder of the whole stream finds."""
    codec = get_codec("kinwave-live", max_error_cm=bound, layers=layers, **knobs)
    enc = codec.encoder(motion.skeleton, motion.fps)
    return codec, _variants(codec, motion, enc.push(motion.channels) + enc.flush())


def _variants(codec, motion, packets):
    dec, out = codec.decoder(motion.skeleton, motion.fps), []
    for p in packets:
        dec.push(p)
        out.append([p[:end] for end in dec.layer_ends])
    return out


def _decoded(codec, motion, variants, keeps):
    dec = codec.decoder(motion.skeleton, motion.fps)
    return np.concatenate([dec.push(v[k - 1], k) for v, k in zip(variants, keeps)])


@pytest.mark.parametrize("clip,fps", [("walk_bvh", None), ("walk_amc", None), ("walk_amc", 30.0)])
def test_each_layer_holds_its_bound_on_every_frame_with_the_layers_below(clip, fps, request):
    motion = request.getfixturevalue(clip)
    motion = motion.resample(fps) if fps else motion
    codec, packets = _layered_packets(motion)
    assert codec.layer_bounds == [4.0, 2.0, 1.0]
    for keep, bound in zip((1, 2, 3), codec.layer_bounds):
        errors = _frame_errors(motion, _decoded(codec, motion, packets, [keep] * len(packets)))
        assert errors.max() <= bound + 1e-9
        assert np.median(errors) > 0.3 * bound
    sizes = [sum(len(v[k - 1]) for v in packets) for k in (1, 2, 3)]
    assert sizes[0] < sizes[1] < sizes[2]


def test_a_single_layer_stream_is_the_stream_without_layers(walk_bvh):
    plain, layered = get_codec("kinwave-live"), get_codec("kinwave-live", layers=1)
    assert plain.encode(walk_bvh) == layered.encode(walk_bvh)
    assert plain.layer_bounds == [1.0]


def test_a_dropped_layer_stays_out_until_the_stream_restarts(walk_amc):
    codec, packets = _layered_packets(walk_amc[:240])
    n = len(packets)
    keeps = [3] * 10 + [2] * 5 + [3] * (n - 15)  # the top layer comes back: it has lost its history
    got = _decoded(codec, walk_amc, packets, keeps)
    expected = _decoded(codec, walk_amc, packets, [3] * 10 + [2] * (n - 10))
    assert np.array_equal(got, expected)
    assert not np.array_equal(got, _decoded(codec, walk_amc, packets, [3] * n))
    assert _frame_errors(walk_amc[:240], got).max() <= 2.0 + 1e-9


def test_a_packet_cut_at_a_layer_end_decodes_that_layer_and_those_below_as_the_whole_packet(walk_bvh, walk_amc):
    """The layers are one arithmetic-coded stream, base first: a relay cuts it where the
    decoder of the whole stream says each layer ends (the sender's cut table). Each end is the
    shortest such prefix: one byte less decodes something else."""
    for motion in (walk_bvh[:480], walk_amc[:480].resample(30.0)):
        codec, variants = _layered_packets(motion, layers=3, refresh_s=0.5)
        ends = np.array([[len(x) for x in v] for v in variants])
        assert (np.diff(ends, axis=1) >= 0).all() and ends[:, 0].mean() < 0.5 * ends[:, 2].mean()
        for keep in (1, 2, 3):
            whole, cut = codec.decoder(motion.skeleton, motion.fps), codec.decoder(motion.skeleton, motion.fps)
            for v in variants:
                if len(v[keep - 1]):
                    assert not _decodes_alike(copy.deepcopy(whole), v[keep - 1][:-1], v[-1], keep)
                assert np.array_equal(cut.push(v[keep - 1], keep), whole.push(v[-1], keep))


def _decodes_alike(dec, short, whole, keep):
    try:
        got = copy.deepcopy(dec).push(short, keep)
    except CorruptStreamError:
        return False
    return np.array_equal(got, dec.push(whole, keep))


def test_the_layered_format_is_pinned():
    """Like the golden fixtures (tests/golden.py): a layered stream's bytes and decoding."""
    import golden

    clip, folder = golden.clip(), golden.FIXTURES / "kinwave-live"
    for name, knobs in golden.VARIANTS["kinwave-live"].items():
        codec = get_codec("kinwave-live", **golden.CONFIGS["kinwave-live"], **knobs)
        stored = (folder / f"{name}.bin").read_bytes()
        assert codec.encode(clip) == stored
        decoded = codec.decode(stored, clip.skeleton, clip.num_frames, clip.fps).channels
        assert np.array_equal(decoded, np.load(folder / f"{name}_decoded.npy"))


# ----- refresh inside the codec stream -----------------------------------------------------------
def test_layers_restart_on_their_own_spread_over_the_refresh_period(walk_bvh):
    codec, packets = _layered_packets(walk_bvh, layers=3)
    refreshing = get_codec("kinwave-live", layers=3, refresh_s=0.5)
    enc = refreshing.encoder(walk_bvh.skeleton, walk_bvh.fps)
    again = enc.push(walk_bvh.channels) + enc.flush()
    starts = np.array([refreshing.layer_starts(p) for p in again])
    period, phases = refreshing.restart_frames(walk_bvh.fps)
    assert (period, phases) == (60, [0, 20, 40])
    size = live.packet_frames(walk_bvh.fps)
    for k, phase in enumerate(phases):  # each layer in the packets that hold its restart frames
        expected = [a > 0 and (phase - a) % period < size for a in range(0, walk_bvh.num_frames, size)]
        assert starts[:, k].tolist() == expected
    assert starts.sum(axis=1).max() == 1  # never two layers at once: no bursts
    assert not np.array(codec.layer_starts(packets[3][-1])).any()  # without refresh_s: no flags
    variants = _variants(refreshing, walk_bvh, again)
    for keep, bound in zip((1, 2, 3), refreshing.layer_bounds):
        errors = _frame_errors(walk_bvh, _decoded(refreshing, walk_bvh, variants, [keep] * len(again)))
        assert errors.max() <= bound + 1e-9


def test_after_a_loss_each_layer_is_back_at_its_next_restart(walk_bvh):
    codec = get_codec("kinwave-live", layers=3, refresh_s=0.5)
    enc = codec.encoder(walk_bvh.skeleton, walk_bvh.fps)
    packets = enc.push(walk_bvh.channels) + enc.flush()
    clean = codec.decoder(walk_bvh.skeleton, walk_bvh.fps)
    expected = [clean.push(p) for p in packets]
    starts = [codec.layer_starts(p) for p in packets]
    dec = codec.decoder(walk_bvh.skeleton, walk_bvh.fps)
    for p in packets[:12]:
        dec.push(p)
    assert dec.lost() and not dec.in_step  # packet 12 is lost
    base_back = next(i for i in range(13, len(packets)) if starts[i][0])
    for i in range(13, base_back):
        with pytest.raises(OutOfStepError):
            dec.push(packets[i])
    top_back = next(i for i in range(base_back, len(packets)) if starts[i][2])
    layers_seen = []
    for i in range(base_back, len(packets)):
        out = dec.push(packets[i])
        layers_seen.append(dec.layers_in_step)
        if i >= top_back:
            assert np.array_equal(out, expected[i])
    assert layers_seen[0] == 1 and layers_seen[-1] == 3 and layers_seen == sorted(layers_seen)
    assert (top_back - base_back) * live.packet_frames(walk_bvh.fps) <= 60  # within one period


def test_a_stream_that_follows_another_starts_at_its_scale_and_decodes_alone(walk_bvh):
    codec = get_codec("kinwave-live", layers=2)
    first = codec.encoder(walk_bvh.skeleton, walk_bvh.fps)
    first.push(walk_bvh.channels[:240])
    assert any(first.offsets)  # the scale has moved from the allocation's
    second = codec.encoder(walk_bvh.skeleton, walk_bvh.fps)
    second.follow(first)
    assert second.offsets == first.offsets
    part = walk_bvh[240:]
    packets = second.push(part.channels) + second.flush()
    dec = codec.decoder(walk_bvh.skeleton, walk_bvh.fps)  # knows nothing of the first stream
    assert _frame_errors(part, np.concatenate([dec.push(p) for p in packets])).max() <= 1.0 + 1e-9


def test_the_stream_header_carries_the_base_codes_the_decoder_derives(walk_bvh):
    from mocodec.codecs.kinwave.live import base_codes
    from mocodec.stream.live import LiveEncoder
    from mocodec.stream.packets import StreamInfo

    codec = get_codec("kinwave-live", layers=3, max_error_cm=1.0)
    info = StreamInfo.from_payload(LiveEncoder(codec, walk_bvh.skeleton, walk_bvh.fps, 0).header(0).payload)
    tables = info.extra["decoder"]["base_codes"]
    assert tables == [base_codes(walk_bvh.skeleton, b, "joint").tolist() for b in (4.0, 2.0, 1.0)]


def test_each_channel_takes_the_predictor_that_missed_its_decoded_frames_less(walk_amc):
    # a ramp: the straight line misses nothing, the last value misses the slope each frame,
    # and each miss counts half as much one frame later
    ramp = np.array([[0.0, 5.0], [2.0, 5.0], [4.0, 5.0], [6.0, 5.0]])
    misses = np.zeros((2, 2))
    update_misses(misses, ramp[:2].copy(), 2, 1, 1, ramp[2:].copy())
    assert misses[:, 0].tolist() == [2.0 * 0.5 + 2.0, 0.0]
    assert misses[:, 1].tolist() == [0.0, 0.0]  # a constant channel: both exact
    layer = Layer(walk_amc.skeleton, get_codec("kinwave-live").layer_codes(walk_amc.skeleton)[0])
    layer.misses[:, :2] = misses
    orders = layer.orders()
    assert orders[:2].tolist() == [2, 1]  # a tie goes to the last value
    assert (orders[2:] == 1).all()  # nothing decoded yet


def test_a_steady_turn_costs_about_what_standing_still_does(walk_amc):
    # every channel still but one angle turning 1 degree a frame: the decoded frames make both
    # ends switch that channel to the straight line, after which its integers are zero
    still = np.repeat(walk_amc.channels[:1], 240, axis=0)
    turning = still.copy()
    turning[:, 3] += np.arange(240) * 1.0
    codec = get_codec("kinwave-live")
    sizes = []
    for channels in (still, turning):
        motion = walk_amc.with_channels(channels)
        body = codec.encode(motion)
        decoded = codec.decode(body, motion.skeleton, motion.num_frames, motion.fps)
        assert _frame_errors(motion, decoded.channels).max() <= 1.0 + 1e-9
        sizes.append(len(body))
    assert sizes[1] < sizes[0] + 30


def test_data_of_another_format_revision_is_refused():
    from mocodec.codecs import codec_from_untrusted

    config = get_codec("kinwave-live").get_config()
    assert config["revision"] == 3
    for revision in (None, 2, 4):
        older = {k: v for k, v in config.items() if k != "revision"}
        if revision is not None:
            older["revision"] = revision
        with pytest.raises(CorruptStreamError, match="format revision"):
            codec_from_untrusted(older, "stream header")
    assert "revision" not in get_codec("kinwave").get_config()  # revision 1 is not written


def test_translations_that_stand_still_are_not_made_to_carry_their_parents_errors(walk_bvh):
    # six channels on every joint, the translations repeating the bone (a MotionBuilder export):
    # they are coded as they are, not re-aimed at each joint's position every frame
    from mocodec.reexpress import with_position_channels

    plain = walk_bvh[:600]
    six = with_position_channels(plain)
    codec = get_codec("kinwave-live")
    body = codec.encode(six)
    decoded = codec.decode(body, six.skeleton, six.num_frames, six.fps)
    assert _frame_errors(six, decoded.channels).max() <= 1.0 + 1e-9
    assert len(body) < 1.4 * len(codec.encode(plain))  # 2.6x when they were re-aimed


def test_keyframes_predicted_from_the_reference_pose_cost_less_and_decode_the_same(walk_bvh):
    # a live stream primed with the clip carries its first frame in the header; each codec
    # stream (a keyframe every 0.25 s) predicts its first frame from it, not from the rest pose
    # (in proper Euler orders, whose angles are far from zero: 4% fewer bytes in all)
    from mocodec.reexpress import with_euler_orders
    from mocodec.stream.live import LiveDecoder, LiveEncoder, clip_encoder
    from mocodec.stream.packets import StreamInfo

    clip = with_euler_orders(walk_bvh[120:840], "ZXZ")
    codec = get_codec("kinwave-live", layers=2)
    sizes = []
    unprimed = LiveEncoder(codec, clip.skeleton, clip.fps, 0, 0.25)
    for encoder, primed in ((unprimed, False), (clip_encoder(clip, codec, 0, 0.25), True)):
        packets = [encoder.header(0)] + encoder.push(clip.channels, 0) + encoder.close(0)
        info = StreamInfo.from_payload(packets[0].payload)
        assert ("reference" in info.extra["decoder"]) == primed
        receiver = LiveDecoder(info)
        frames = np.concatenate([receiver.push(p) for p in packets[1:]])
        assert _frame_errors(clip, frames).max() <= 1.0 + 1e-9
        sizes.append(sum(len(p.payload) for p in packets[1:]))
    assert sizes[1] < 0.98 * sizes[0]


@pytest.mark.parametrize("reference", [[0.0] * 3, "pose", [True] * 132, [1e12] * 132, [float("nan")] * 132])
def test_a_hostile_reference_pose_is_refused(walk_bvh, reference):
    codec = get_codec("kinwave-live")
    assert walk_bvh.skeleton.num_channels == 132
    with pytest.raises(CorruptStreamError, match="reference"):
        codec.for_stream(walk_bvh.skeleton, {"reference": reference})
    assert codec.for_stream(walk_bvh.skeleton, {}) is codec and codec.for_stream(walk_bvh.skeleton, []) is codec


def test_a_primed_stream_takes_its_levers_from_the_motions_bones(walk_bvh):
    # bones kept in position channels over zero offsets: a primed stream's allocation sees the
    # bones of its first frame, and costs about what the plain skeleton's stream does
    from mocodec.reexpress import with_position_channels
    from mocodec.stream.live import LiveDecoder, stream_clip
    from mocodec.stream.packets import StreamInfo

    codec = get_codec("kinwave-live")
    plain = walk_bvh[:600]
    sizes = []
    for motion in (plain, with_position_channels(plain)):
        packets = stream_clip(motion, codec)
        receiver = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
        frames = np.concatenate([receiver.push(p) for p in packets[1:]])
        assert _frame_errors(motion, frames).max() <= 1.0 + 1e-9
        sizes.append(sum(len(p.payload) for p in packets[1:]))
    assert sizes[1] < 1.1 * sizes[0]  # 1.16x with the offsets' (zero) levers


@pytest.mark.parametrize("codes", ["x", [[0] * 44], [[0] * 44, [0] * 43], [[256] * 44] * 2, [[True] * 44] * 2])
def test_hostile_base_codes_are_refused(walk_bvh, codes):
    codec = get_codec("kinwave-live", layers=2)
    assert len(codec.layer_codes(walk_bvh.skeleton)[0]) == 44
    with pytest.raises(CorruptStreamError, match="base_codes"):
        codec.for_stream(walk_bvh.skeleton, {"base_codes": codes})


def test_a_packet_layer_down_the_tree_in_one_call_is_the_python_loop(walk_bvh):
    """predict_tree codes a packet layer's depths as closedloop.code_down_tree does with
    predict_columns as its coder, to the same integers and floats (a dummy root's translated
    child makes the loop restore positions too)."""
    from mocodec import reexpress
    from mocodec.codecs.kinwave.live.predict import predict_columns, predict_tree
    from mocodec.codecs.shared import closedloop

    clip = reexpress.with_dummy_root(walk_bvh[:7], (0.0, -90.0, 0.0), position_channels=True)
    frames, channels = clip.channels.shape
    positions, quats = forward_kinematics(clip.skeleton, clip.channels)
    rng = np.random.default_rng(7)
    history, steps = rng.normal(size=(2, channels)), rng.uniform(0.05, 0.5, channels)
    order, trust = rng.integers(1, 3, channels), rng.random(channels) < 0.5
    lo, hi = np.full((frames, channels), -1e9), np.full((frames, channels), 1e9)
    active = np.ones(channels, dtype=bool)
    runs = []
    for compiled in (True, False):
        out = [np.zeros((frames, channels), dtype=np.int64)] + [np.zeros((frames, channels)) for _ in range(3)]
        coding = (history, 2, 1, 1, steps, order, trust, lo, hi, *out)
        if compiled:
            predict_tree(closedloop.tree_loop(clip.skeleton, clip.channels, active, quats, True, positions), *coding)
        else:
            closedloop.code_down_tree(
                clip.skeleton,
                clip.channels,
                active,
                quats,
                lambda coded, targets: predict_columns(coded, np.ascontiguousarray(targets), *coding),
                True,
                positions,
            )
        runs.append(out)
    for compiled, looped in zip(*runs):
        assert np.array_equal(compiled, looped)
    assert runs[0][0].any()
