"""What every codec promises, checked the same way for each: one test per codec and promise,
so one codec's failure hides no other's. Every registered codec (``codec_ids()``) round-trips,
refuses what it cannot code, equals its own config, and decodes damaged bodies to our error
only; every codec with a packet number (``packet_codecs()``) streams through live packets,
says what each packet decodes to, and equals its whole-clip coding when pushed at once."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import stepcodec  # noqa: F401  (registers test-step)
from mocodec import moc
from mocodec.codecs import codec_class, codec_from_config, codec_ids, get_codec, packet_codecs
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.stream.live import LiveEncoder, keyframe_frames, receive_clip, stream_clip
from mocodec.stream.packets import HEADER

CODECS = codec_ids()
STREAMING = packet_codecs()
#: Codecs whose stream codes each segment as a clip of its own (kinwave's segments decode
#: alone), rather than as its whole-clip coding does.
SEGMENT_WISE = {"kinwave"}
#: Codecs whose live stream may code far worse than the whole clip: quant's default range is
#: that of the first frames each codec stream sees (000 7-4), so a keyframe in a calm second
#: clips the motion after it (``range=limits`` takes the skeleton's joint limits instead).
RANGE_FROM_FIRST_FRAMES = {"quant"}


def wrapped_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs((a - b + 180.0) % 360.0 - 180.0).max())


@pytest.fixture(scope="module")
def clip(walk_amc):
    return walk_amc[:60]


@pytest.fixture(scope="module")
def bodies(clip):
    return {cid: get_codec(cid).encode(clip) for cid in CODECS}


# ----- every codec ----------------------------------------------------------------------------
@pytest.mark.parametrize("cid", CODECS)
def test_round_trip(cid, clip, bodies):
    codec = get_codec(cid)
    got = codec.decode(bodies[cid], clip.skeleton, clip.num_frames, clip.fps)
    assert got.channels.shape == clip.channels.shape and np.isfinite(got.channels).all()
    if codec.lossless:
        np.testing.assert_allclose(got.channels, clip.channels, atol=1e-3)


@pytest.mark.parametrize("cid", CODECS)
def test_a_rig_without_channels_round_trips(cid, clip):
    """Some exporters write a rig whose joints never move: no channels, a few frames (Blender
    2.79's, in ../shared/data/fbx). Every codec codes it, as an empty body, through a file."""
    from dataclasses import replace

    from mocodec import Motion, Skeleton

    sk = clip.skeleton
    joints = tuple(replace(j, channels=(), rotation_order="", limits=()) for j in sk.joints)
    still = Skeleton(joints, sk.units_per_metre, sk.name)
    motion = Motion(still, clip.fps, np.zeros((2, 0)))
    back = moc.unpack(moc.pack(motion, get_codec(cid)))
    assert back.num_frames == 2 and back.channels.shape == (2, 0)
    assert get_codec(cid).encode(motion) == b""


def without_translations(clip, turns: bool):
    """``clip`` on a rig without translation channels, as glTF rigs often are: its root joint
    keeping its rotations (``turns``, the shared RiggedFigure) or no channel at all (Fox,
    SimpleSkin)."""
    from dataclasses import replace

    from mocodec import Motion, Skeleton

    sk = clip.skeleton
    turning = [c for c in sk.joints[0].channels if c.endswith("rotation")] if turns else []
    root = replace(sk.joints[0], channels=tuple(turning), rotation_order="".join(c[0] for c in turning), limits=())
    later = np.arange(sk.num_channels) >= sk.channel_offsets[1]
    keep = later | (sk.rotation_mask if turns else False)
    return Motion(Skeleton((root, *sk.joints[1:]), sk.units_per_metre, sk.name), clip.fps, clip.channels[:, keep])


@pytest.mark.parametrize("cid", CODECS)
@pytest.mark.parametrize("turns", [True, False])
def test_a_rig_without_translations_round_trips(cid, clip, turns):
    """Every codec codes a clip on a rig without translations and decodes what it wrote."""
    motion = without_translations(clip, turns)
    back = moc.unpack(moc.pack(motion, get_codec(cid)))
    assert back.channels.shape == motion.channels.shape and np.isfinite(back.channels).all()


@pytest.mark.parametrize("cid", CODECS)
def test_a_file_decodes_where_rounded_offsets_move_a_joint_to_another_body_part(cid):
    """A MotionBuilder rig (the shared sausage): bones 3.8 cm along X with 1.4e-7 cm sideways.
    A lossy file rounds offsets to 0.001 cm, and the rounded rig's joints fall into other body
    parts; whatever a codec derives from the skeleton (spatial groups) must be what its
    decoder derives from the file's skeleton."""
    from mocodec import Motion, Skeleton
    from mocodec.skeleton import Joint

    turns = ("Zrotation", "Yrotation", "Xrotation")
    joints = (
        Joint("Skeleton", -1, (0.0, 0.0, 0.0), turns, "ZYX"),
        Joint("Bottom", 0, (0.0, 0.0, 0.0), turns, "ZYX"),
        Joint(
            "Middle",
            1,
            (3.8000001907348633, 1.434460147178641e-07, 0.0),
            ("Xposition", "Yposition", "Zposition", *turns),
            "ZYX",
        ),
        Joint(
            "Top",
            2,
            (3.7999999523162837, 2.868920030843652e-07, 0.0),
            ("Xposition", "Yposition", "Zposition", *turns),
            "ZYX",
        ),
    )
    sk = Skeleton(joints, 100.0, "sausage")
    t = np.arange(60)[:, None] / 30.0
    channels = 20.0 * np.sin(t * np.arange(1, sk.num_channels + 1) * 0.7)
    channels[:, ~sk.rotation_mask] = 0.05 * np.cos(3.0 * t)
    motion = Motion(sk, 30.0, channels)
    assert moc.stored_skeleton(motion, get_codec("dpcm")).body_parts != sk.body_parts
    back = moc.unpack(moc.pack(motion, get_codec(cid)))
    assert back.channels.shape == motion.channels.shape and np.isfinite(back.channels).all()


@pytest.mark.parametrize("cid", CODECS)
def test_a_clip_that_holds_still_round_trips(cid, clip):
    """Every channel constant (a rig posed, not animated: the shared Maya characters), through
    a file: nothing moves, and the pose comes back."""
    still = clip.with_channels(np.repeat(clip.channels[:1], clip.num_frames, axis=0))
    back = moc.unpack(moc.pack(still, get_codec(cid)))
    assert back.channels.shape == still.channels.shape and np.isfinite(back.channels).all()


@pytest.mark.parametrize("cid", CODECS)
def test_clips_of_no_one_and_two_frames_round_trip(cid, clip):
    """A rig without a take (no frames), a single pose and two frames, through a file: the
    gesture codec's one-frame clip, whose gesture segments were none, failed to reshape them."""
    for frames in (0, 1, 2):
        back = moc.unpack(moc.pack(clip[:frames], get_codec(cid)))
        assert back.channels.shape == (frames, clip.num_channels) and np.isfinite(back.channels).all()


@pytest.mark.parametrize("cid", CODECS)
def test_config_round_trips_and_decides_equality(cid):
    codec = get_codec(cid)
    config = json.loads(json.dumps(codec.get_config()))
    again = codec_from_config(config)
    assert again == codec and hash(again) == hash(codec) and again is not codec
    assert codec != get_codec("raw" if cid != "raw" else "lossless")
    changeable = [k for k in codec.knobs if k.kind in (int, float) and k.low is not None and not k.path]
    if changeable:
        knob = changeable[0]
        other = knob.low if codec.config[knob.name] != knob.low else knob.high
        assert codec.with_knob(knob.name, other) != codec


@pytest.mark.parametrize("cid", CODECS)
def test_capabilities_are_declared_once(cid):
    cls = codec_class(cid)
    codec = cls()
    assert cls.streaming == (cls.packet_number is not None)
    assert isinstance(codec.delay_frames(), int) and codec.delay_frames() >= 0
    assert codec.layers >= 1 and codec.segment_frames() >= 1
    if not cls.embedded:
        with pytest.raises(CodecError, match="not embedded"):
            codec.packet_cuts(b"", None)
    try:
        faster = codec.at_rate(1234.0)
    except CodecError as e:
        assert "no bit rate knob" in str(e)
    else:
        assert faster != codec and faster.get_config()["codec"] == cid and 1234.0 in faster.config.values()


@pytest.mark.parametrize("cid", CODECS)
def test_encoding_refuses_nan(cid, walk_amc):
    bad = walk_amc.channels.copy()
    bad[10, 5] = np.inf
    with pytest.raises(CodecError, match="frame 10"):
        get_codec(cid).encode(walk_amc.with_channels(bad))


@pytest.mark.parametrize("cid", CODECS)
@settings(max_examples=20)
@given(data=st.binary(max_size=400))
def test_random_bytes_raise_only_our_error(cid, clip, data):
    try:
        get_codec(cid).decode(data, clip.skeleton, clip.num_frames, clip.fps)
    except CorruptStreamError:
        pass


@pytest.mark.parametrize("cid", CODECS)
def test_every_truncation_and_bit_flip_of_a_file_is_caught(cid, clip):
    """Bodies carry no check of their own: the container's framing (CRCs over the header, each
    chunk and the index) catches damage before any codec parses a byte."""
    rng = np.random.default_rng(1)
    data = moc.pack(clip, get_codec(cid))
    for cut in range(0, len(data), max(1, len(data) // 100)):
        with pytest.raises(CorruptStreamError):
            moc.unpack(data[:cut])
    for bit in rng.choice(len(data) * 8, size=min(200, len(data) * 8), replace=False):
        flipped = bytearray(data)
        flipped[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(CorruptStreamError):
            moc.unpack(bytes(flipped))


@pytest.mark.parametrize("cid", CODECS)
def test_a_body_for_another_skeleton_is_refused(cid, bodies, walk_bvh):
    with pytest.raises(CorruptStreamError):
        get_codec(cid).decode(bodies[cid], walk_bvh.skeleton, walk_bvh.num_frames, walk_bvh.fps)


@pytest.mark.parametrize("cid", sorted(set(CODECS) - set(STREAMING)))
def test_a_codec_without_a_packet_number_is_refused_by_live_streams(cid, clip):
    with pytest.raises(CodecError, match="no packet number"):
        LiveEncoder(get_codec(cid), clip.skeleton, clip.fps, 0)


# ----- every streaming codec ------------------------------------------------------------------
def coded_stream(codec, clip, step: int):
    """(the Coded packets of one codec stream of ``clip`` pushed ``step`` frames at a time,
    what its decoder gives for each)."""
    enc, dec = codec.encoder(clip.skeleton, clip.fps), codec.decoder(clip.skeleton, clip.fps)
    coded = [c for k in range(0, clip.num_frames, step) for c in enc.code(clip.channels[k : k + step])]
    coded += enc.finish()
    return coded, [dec.push(c.payload) for c in coded], dec


LAYERED = [cid for cid in STREAMING if "layers" in {k.name for k in codec_class(cid).knobs}]


@pytest.mark.parametrize(
    "cid, knobs",
    [(cid, {}) for cid in STREAMING] + [(cid, {"layers": 3}) for cid in LAYERED],
    ids=[*STREAMING, *(f"{cid}-layered" for cid in LAYERED)],
)
def test_each_packet_says_what_it_decodes_to(cid, knobs, walk_amc):
    """A stream encoder's Coded packets carry the frames their decoder gives out (what a live
    packet tells a receiver) and the cut table a relay cuts by, with no decoding by the sender."""
    codec, clip = get_codec(cid, **knobs), walk_amc[:200]
    coded, decoded, dec = coded_stream(codec, clip, 7)
    assert [c.frames for c in coded] == [len(d) for d in decoded]
    assert sum(c.frames for c in coded) == clip.num_frames
    if codec.embedded:
        assert all(list(c.cuts) == codec.packet_cuts(c.payload, clip.skeleton).tolist() for c in coded)
    if codec.layers > 1:
        ends = []
        dec = codec.decoder(clip.skeleton, clip.fps)
        for c in coded:
            dec.push(c.payload)
            ends.append(dec.layer_ends[:-1])
        assert [list(c.cuts) for c in coded] == ends
    if not codec.embedded and codec.layers == 1:
        assert all(c.cuts == () for c in coded)


@pytest.mark.parametrize("cid", STREAMING)
def test_a_stream_pushed_at_once_equals_the_whole_clip(cid, walk_amc):
    codec, clip = get_codec(cid), walk_amc[:300]
    _, decoded, _ = coded_stream(codec, clip, clip.num_frames)
    streamed = np.concatenate(decoded)
    if cid in SEGMENT_WISE:
        w = codec.segment_frames()
        pieces = [clip[k : k + w] for k in range(0, clip.num_frames, w)]
        whole = np.concatenate(
            [codec.decode(codec.encode(p), p.skeleton, p.num_frames, p.fps).channels for p in pieces]
        )
    else:
        whole = codec.decode(codec.encode(clip), clip.skeleton, clip.num_frames, clip.fps).channels
    np.testing.assert_allclose(streamed, whole, rtol=0, atol=1e-9)


@pytest.mark.parametrize("cid", STREAMING)
def test_every_streaming_codec_goes_through_live_packets(walk_bvh, cid):
    codec = get_codec(cid)
    packets = stream_clip(walk_bvh, codec)
    assert packets[0].kind == HEADER and packets[-1].end
    assert sum(p.keyframe for p in packets) >= walk_bvh.num_frames // keyframe_frames(codec, 120, 1.0)
    frames = [(p.first_frame, p.frames) for p in packets[1:]]
    assert all(a + n == b for (a, n), (b, _) in zip(frames, frames[1:]))  # ranges tile the clip
    got = receive_clip(packets)
    assert got.num_frames == walk_bvh.num_frames
    batch = codec.decode(codec.encode(walk_bvh), walk_bvh.skeleton, walk_bvh.num_frames, walk_bvh.fps)
    if cid in RANGE_FROM_FIRST_FRAMES:
        return
    # a keyframe every second costs some quality against one uninterrupted stream, within a small factor
    assert wrapped_error(got.channels, walk_bvh.channels) < 3 * wrapped_error(batch.channels, walk_bvh.channels) + 1


@pytest.mark.parametrize("cid", STREAMING)
@pytest.mark.parametrize("rig", ["walk", "bone"])
def test_a_rig_without_translations_streams_every_frame(cid, walk_amc, rig):
    """Every frame of such a rig comes through live packets at 30 frames/s: a walk, and one
    bone swinging under a root of no channels (the shared SimpleSkin, whose frames a decoder
    that failed on each packet concealed into silence)."""
    from mocodec import Motion, Skeleton
    from mocodec.skeleton import Joint
    from mocodec.stream.live import LiveDecoder
    from mocodec.stream.packets import StreamInfo

    if rig == "walk":
        motion = without_translations(walk_amc.resample(30.0), turns=False)
    else:
        turns = ("Zrotation", "Yrotation", "Xrotation")
        bone = Skeleton((Joint("root", -1, (0.0, 0.0, 0.0)), Joint("bone", 0, (0.0, 1.0, 0.0), turns, "ZYX")), 1.0)
        swing = np.zeros((166, 3))
        swing[:, 0] = 90.0 * np.sin(np.arange(166) / 166 * 2 * np.pi)
        motion = Motion(bone, 30.0, swing)
    packets = stream_clip(motion, get_codec(cid))
    decoder = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
    got = np.vstack([decoder.push(p) for p in packets[1:]])
    assert len(got) == motion.num_frames and np.isfinite(got).all()
    assert decoder.stats.dropped == 0 and decoder.stats.concealed_frames == 0


@pytest.mark.parametrize("cid", STREAMING)
def test_random_payloads_are_concealed(walk_bvh, cid):
    packets = stream_clip(walk_bvh[:200], get_codec(cid))
    rng = np.random.default_rng(7)

    def noise(p):
        return p.with_payload(rng.integers(0, 256, len(p.payload), dtype=np.uint8).tobytes())

    shown = next(k for k, p in enumerate(packets) if p.frames)  # from here there is a frame to hold
    later = [p if k <= shown or p.keyframe or k % 3 else noise(p) for k, p in enumerate(packets)]
    got = receive_clip(later)
    assert got.num_frames == 200 and np.isfinite(got.channels).all()  # concealed, in time
    every_third = [packets[0]] + [noise(p) if k % 3 == 1 else p for k, p in enumerate(packets[1:])]
    got = receive_clip(every_third)  # no frames before the first good key
    assert got.num_frames <= 200 and np.isfinite(got.channels).all()
