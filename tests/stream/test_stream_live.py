"""Live streams: the packet format, keyframes, loss concealment, tokens."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec.codecs import get_codec
from mocodec.errors import CorruptStreamError
from mocodec.stream import tokens
from mocodec.stream.live import LiveDecoder, keyframe_frames, receive_clip, stream_clip
from mocodec.stream.packets import (
    DATA,
    SEQUENCE_OFFSET,
    TIMESTAMP_OFFSET,
    Packet,
    StreamInfo,
    batch_offsets,
    header_packet,
    pack_batch,
    parse,
    read_u32,
    read_u64,
    split_batch,
)


# ----- packets -----------------------------------------------------------------------------------
def test_packet_round_trip_and_damage():
    p = Packet(7, 42, 1_700_000_000_123_456, "spiht", 128, 64, b"payload bytes", DATA, 1, (1.5, 0.0, -2.25))
    data = p.to_bytes()
    assert parse(data) == p and len(data) == len(p.payload) + 48
    for k in (0, 3, 12, len(data) - 10, len(data) - 1):  # magic, kind, sequence, payload, CRC
        bad = bytearray(data)
        bad[k] ^= 0x40
        with pytest.raises(CorruptStreamError):
            parse(bytes(bad))
    with pytest.raises(CorruptStreamError, match="shorter"):
        parse(data[:20])
    with pytest.raises(CorruptStreamError, match="announced"):
        parse(data[:-1])


def test_batch_split_and_bulk_fields():
    packets = [Packet(s, 10 + s, 1000 * s, "dpcm", 0, 4, bytes(s)) for s in range(5)]
    batch = pack_batch([p.to_bytes() for p in packets])
    assert [parse(r) for r in split_batch(batch)] == packets
    offsets = batch_offsets(batch)[:-1]
    assert read_u32(batch, offsets, SEQUENCE_OFFSET).tolist() == [10, 11, 12, 13, 14]
    assert read_u64(batch, offsets, TIMESTAMP_OFFSET).tolist() == [0, 1000, 2000, 3000, 4000]
    with pytest.raises(CorruptStreamError, match="add up"):
        split_batch(batch[:-3])
    with pytest.raises(CorruptStreamError, match="magic"):
        split_batch(b"XX" + batch[2:])


def test_a_batch_spends_a_byte_on_each_short_packets_length_and_refuses_what_it_cannot_hold():
    packets = [bytes(n) for n in (0, 1, 127, 128, 16383, 16384)]
    batch = pack_batch(packets)
    assert len(batch) == 2 + 1 + (1 + 1 + 1 + 2 + 2 + 3) + sum(map(len, packets))
    assert [bytes(r) for r in split_batch(batch)] == packets
    assert pack_batch([]) == b"Mb\0" and split_batch(b"Mb\0") == []
    with pytest.raises(CorruptStreamError, match="format 1"):
        split_batch(b"MB" + (1).to_bytes(4, "little") + (3).to_bytes(4, "little") + b"abc")
    with pytest.raises(CorruptStreamError, match="announced"):  # refused before anything is allocated
        split_batch(b"Mb\xff\xff\xff\xff\x0f" + bytes(8))
    with pytest.raises(CorruptStreamError, match="inside a number"):
        split_batch(b"Mb\x02\x80\x80")
    with pytest.raises(CorruptStreamError, match="longer than 4 bytes"):
        split_batch(b"Mb\x01\x80\x80\x80\x80\x01" + bytes(3))


def test_stream_header_carries_skeleton_and_codec(walk_bvh):
    info = StreamInfo(walk_bvh.skeleton, walk_bvh.fps, get_codec("dpcm").get_config(), "walker")
    back = StreamInfo.from_payload(info.to_payload())
    assert back.skeleton.isclose(walk_bvh.skeleton) and back.fps == 120.0 and back.codec == info.codec
    with pytest.raises(CorruptStreamError, match="stream header"):
        StreamInfo.from_payload(b"not zlib")


def test_a_skeleton_without_channels_is_not_streamed(walk_bvh):
    """A rig whose joints never move has nothing to stream: the sender says so, and a header
    that claims one (hostile, or from another tool) is refused as damaged, not divided by."""
    from dataclasses import replace

    from mocodec import Skeleton
    from mocodec.errors import CodecError
    from mocodec.stream.live import LiveEncoder
    from mocodec.stream.relay import BAD_MESSAGE, Closing, RelayCore

    sk = walk_bvh.skeleton
    still = Skeleton(
        tuple(replace(j, channels=(), rotation_order="", limits=()) for j in sk.joints), sk.units_per_metre
    )
    with pytest.raises(CodecError, match="nothing to stream"):
        LiveEncoder(get_codec("dpcm"), still, 30.0, 0)
    header = header_packet(0, StreamInfo(still, 30.0, get_codec("dpcm").get_config()))
    with pytest.raises(CorruptStreamError, match="nothing to stream"):
        StreamInfo.from_payload(header.payload)
    core = RelayCore()
    with pytest.raises(Closing) as closed:
        core.ingest(core.room("lobby"), pack_batch([header.to_bytes()]), owner=1)
    assert closed.value.code == BAD_MESSAGE


# ----- live streams ------------------------------------------------------------------------------
def test_a_lost_packet_is_concealed_and_the_receiver_resyncs_at_the_next_keyframe(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("dpcm"), keyframe_s=0.5)
    clean = receive_clip(packets).channels
    keys = [k for k, p in enumerate(packets) if p.keyframe]
    lost = keys[1] + 2  # inside the second refresh period
    got = receive_clip(packets[:lost] + packets[lost + 1 :]).channels
    assert got.shape == clean.shape
    first_lost = packets[lost].first_frame
    resync = packets[keys[2]].first_frame
    np.testing.assert_array_equal(got[:first_lost], clean[:first_lost])
    held = got[first_lost:resync]
    assert np.all(held == got[first_lost - 1])  # held, not garbage
    np.testing.assert_array_equal(got[resync:], clean[resync:])  # exact again after the keyframe
    assert resync - first_lost <= keyframe_frames(get_codec("dpcm"), 120, 0.5)


def test_a_receiver_that_holds_decodes_a_late_packet_in_step(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("kinwave-live"), keyframe_s=60.0)
    clean = receive_clip(packets).channels
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload), hold_s=0.1)  # 12 frames, two packets
    late = 10
    out = [dec.push(p) for p in packets[1:late]]
    assert dec.push(packets[late + 1]).shape[0] == 0 and dec.wanted() == [packets[late].sequence]
    out.append(dec.push(packets[late]))  # resent: both come out, decoded in order
    assert dec.wanted() == [] and out[-1].shape[0] == packets[late].frames + packets[late + 1].frames
    out += [dec.push(p) for p in packets[late + 2 :]]
    np.testing.assert_array_equal(np.vstack(out), clean)
    assert (dec.stats.lost, dec.stats.repaired, dec.stats.concealed_frames) == (0, 1, 0)


def test_a_receiver_that_holds_goes_on_to_the_next_gap_as_each_is_filled(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("kinwave-live"), keyframe_s=60.0)
    clean = receive_clip(packets).channels
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload), hold_s=0.25)  # 30 frames, five packets
    out = [dec.push(p) for p in packets[1:10]]
    assert [len(dec.push(p)) for p in (packets[11], packets[13])] == [0, 0]
    assert dec.wanted() == [packets[10].sequence, packets[12].sequence]
    out.append(dec.push(packets[10]))  # the first gap filled: out up to the second
    assert len(out[-1]) == packets[10].frames + packets[11].frames and dec.wanted() == [packets[12].sequence]
    out.append(dec.push(packets[12]))
    out += [dec.push(p) for p in packets[14:]]
    np.testing.assert_array_equal(np.vstack(out), clean)
    assert (dec.stats.lost, dec.stats.repaired) == (0, 2)


def test_a_resent_restart_point_fills_its_gap_like_any_packet(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("kinwave-live", refresh_s=0.25), keyframe_s=60.0)
    clean = receive_clip(packets).channels
    late = next(k for k, p in enumerate(packets) if p.restart and not p.keyframe)
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload), hold_s=0.1)
    order = packets[1:late] + [packets[late + 1], packets[late]] + packets[late + 2 :]
    np.testing.assert_array_equal(np.vstack([dec.push(p) for p in order]), clean)
    assert (dec.stats.lost, dec.stats.repaired) == (0, 1)


def test_a_receiver_that_holds_gives_a_gap_up_after_hold_s(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("kinwave-live"), keyframe_s=0.5)
    late = 10
    lossy = packets[:late] + packets[late + 1 :]
    plain = receive_clip(lossy).channels
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload), hold_s=0.1)
    out = [dec.push(p) for p in lossy[1:]]
    held = [len(x) for x in out[late - 1 : late + 1]]  # 12 frames held, the next packet is past them
    assert held == [0, sum(p.frames for p in packets[late : late + 3])]
    np.testing.assert_array_equal(np.vstack(out), plain)  # then as without holding: concealed, resynced
    assert dec.stats.lost == 1 and dec.push(packets[late]).shape[0] == 0  # too late now


def test_a_receiver_that_holds_takes_reordered_and_hostile_sequences(walk_bvh):
    from mocodec.stream.live import MAX_HELD

    packets = stream_clip(walk_bvh, get_codec("kinwave-live"), keyframe_s=0.5)
    clean = receive_clip(packets).channels
    order = list(range(1, len(packets)))
    rng = np.random.default_rng(5)
    for k in range(0, len(order) - 1, 2):  # swap neighbours: a gap, filled by the next packet
        if rng.random() < 0.5:
            order[k], order[k + 1] = order[k + 1], order[k]
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload), hold_s=0.1)
    np.testing.assert_array_equal(np.vstack([dec.push(packets[k]) for k in order]), clean)
    assert dec.stats.repaired > 0 and dec.stats.lost == 0
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload), hold_s=10.0)
    for p in packets[1:12]:
        dec.push(p)
    p = packets[12]
    for k in range(3 * MAX_HELD):  # sequence numbers from a hostile sender, far and near
        near = (p.sequence + int(rng.integers(-5, 70))) & 0xFFFFFFFF
        seq = near if k % 2 else int(rng.integers(0, 1 << 32))
        hostile = Packet(p.stream, seq, 0, p.codec, p.first_frame + 6 * k, p.frames, p.payload)
        out = dec.push(hostile)
        assert len(dec.held) <= MAX_HELD and len(dec.wanted()) <= 2 * 64 and np.isfinite(out).all()


def test_a_watcher_asks_for_a_missing_packet_again_after_doubling_waits(walk_bvh):
    from mocodec.stream.client import REPAIR_AGAIN_S, Watcher

    packets = stream_clip(walk_bvh, get_codec("kinwave-live"), keyframe_s=60.0)
    watcher = Watcher(hold_s=1.0)
    watcher.take(pack_batch([p.to_bytes() for p in packets[:10] + packets[11:12]]))
    want = [[0, packets[10].sequence]]
    times = [k / 100 + 1e-6 * k for k in range(40)]  # a clock a little ahead of the 10 ms grid
    asked = [t for t in times if watcher.repairs(now_s=t) == want]
    assert np.allclose(asked, [0.0, REPAIR_AGAIN_S, 3 * REPAIR_AGAIN_S, 7 * REPAIR_AGAIN_S], atol=1e-3)
    watcher.take(pack_batch([packets[10].to_bytes()]))
    assert watcher.repairs(now_s=1.0) == [] and not watcher.asked


def test_late_joiner_starts_at_a_keyframe(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("spiht"), keyframe_s=2.0)  # two segments per refresh
    clean = receive_clip(packets).channels
    k = next(k for k, p in enumerate(packets) if p.keyframe and p.first_frame > 0)
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
    out = np.vstack([dec.push(p) for p in packets[k - 1 :]])  # one packet before the keyframe: dropped
    start = packets[k].first_frame
    assert dec.stats.dropped == 1
    assert len(out) == walk_bvh.num_frames - start
    # the joiner's first segment is not smoothed against the one it never saw; the rest is exact
    tail = packets[k].frames
    np.testing.assert_array_equal(out[tail:], clean[start + tail :])


def test_damaged_payload_never_crashes_the_receiver(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("adpcm"))
    victim = packets[5]
    garbage = Packet(
        victim.stream,
        victim.sequence,
        victim.timestamp_us,
        victim.codec,
        victim.first_frame,
        victim.frames,
        bytes(len(victim.payload)),
        DATA,
        victim.flags,
        victim.position,
    )
    got = receive_clip(packets[:5] + [garbage] + packets[6:])
    assert got.num_frames == walk_bvh.num_frames and np.isfinite(got.channels).all()


def test_extrapolation_continues_the_motion(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("dpcm"), keyframe_s=2.0)
    clean = receive_clip(packets).channels
    errors = {"hold": [], "extrapolate": []}
    for lost in range(5, len(packets) - 3, 3):
        if not packets[lost].keyframe:
            span = slice(packets[lost].first_frame, packets[lost].first_frame + 8)
            for mode, found in errors.items():
                got = receive_clip(packets[:lost] + packets[lost + 1 :], mode).channels
                found.append(np.abs(got[span] - clean[span]).mean())
    assert np.mean(errors["extrapolate"]) < 0.9 * np.mean(errors["hold"])


def test_spiht_packets_cut_to_a_rate_are_the_packets_coded_at_that_rate(walk_bvh):
    hi, lo = get_codec("spiht", bits_per_second=8000), get_codec("spiht", bits_per_second=2500)

    def packets(codec):
        enc = codec.encoder(walk_bvh.skeleton, walk_bvh.fps)
        return enc.push(walk_bvh.channels) + enc.flush()

    for a, b in zip(packets(hi), packets(lo), strict=True):
        cut = hi.packet_cutter(a, walk_bvh.skeleton, hi.packet_cuts(a, walk_bvh.skeleton), walk_bvh.fps)(2500)
        assert cut == b and len(cut) < len(a)
    with pytest.raises(CorruptStreamError, match="cut table"):
        p = packets(hi)[0]
        hi.packet_cutter(p, walk_bvh.skeleton, np.array([1, 2, 3]), walk_bvh.fps)(2500)


# ----- tokens ------------------------------------------------------------------------------------
def test_tokens():
    t = tokens.issue("secret", "lobby", "subscribe", ttl_s=60, now=1000.0)
    assert tokens.verify("secret", t, "lobby", "subscribe", now=1030.0)["room"] == "lobby"
    cases = [
        ("other", t, "lobby", "subscribe", 1030.0, "signature"),
        ("secret", t, "lobby", "subscribe", 1061.0, "expired"),
        ("secret", t, "hall", "subscribe", 1030.0, "room"),
        ("secret", t, "lobby", "publish", 1030.0, "allows"),
        ("secret", "garbage", "lobby", "subscribe", 1030.0, "malformed"),
        ("secret", t[:-2] + "AA", "lobby", "subscribe", 1030.0, "signature"),
    ]
    for secret, token, room, role, now, why in cases:
        with pytest.raises(tokens.TokenError, match=why):
            tokens.verify(secret, token, room, role, now=now)
    both = tokens.issue("secret", "lobby", "both", now=1000.0)
    assert tokens.verify("secret", both, "lobby", "publish", now=1001.0)
    with pytest.raises(tokens.TokenError):
        tokens.issue("", "lobby")


def test_a_refreshing_stream_is_back_without_keyframes_after_a_loss_or_a_late_join(walk_bvh):
    """kinwave-live with refresh_s: no keyframe after the first, yet a receiver that lost a
    packet, or joined late, decodes exactly again once every layer has restarted."""
    codec = get_codec("kinwave-live", layers=2, refresh_s=0.25)
    packets = stream_clip(walk_bvh, codec, keyframe_s=60.0)
    assert sum(p.keyframe for p in packets) == 1
    clean = receive_clip(packets).channels
    period = int(0.25 * walk_bvh.fps)
    lost = 20
    frame = packets[lost].first_frame
    got = receive_clip(packets[:lost] + packets[lost + 1 :]).channels
    assert len(got) == len(clean)
    assert not np.array_equal(got[frame : frame + 4], clean[frame : frame + 4])  # concealed
    back = frame + 2 * period  # both layers restart within a period, after the lost packet
    np.testing.assert_array_equal(got[back:], clean[back:])
    late = receive_clip(packets[:1] + packets[lost:])  # the header, then mid-stream
    start = len(clean) - late.num_frames
    assert packets[lost].first_frame <= start <= back
    np.testing.assert_array_equal(late.channels[back - start :], clean[back:])


def test_a_refreshing_stream_is_back_after_a_damaged_packet(walk_bvh):
    codec = get_codec("kinwave-live", refresh_s=0.25)
    packets = stream_clip(walk_bvh, codec, keyframe_s=60.0)
    clean = receive_clip(packets).channels
    victim = 20
    damaged = packets[victim].with_payload(bytes(255 - b for b in packets[victim].payload))
    got = receive_clip(packets[:victim] + [damaged] + packets[victim + 1 :]).channels
    assert len(got) == len(clean) and np.isfinite(got).all()
    back = packets[victim].first_frame + int(0.25 * walk_bvh.fps) + 6  # the next restart, and its packet
    np.testing.assert_array_equal(got[back:], clean[back:])


def test_restart_points_are_flagged_and_a_late_joiner_reads_from_one(walk_bvh):
    from mocodec.stream.packets import RESTART, Reader

    codec = get_codec("kinwave-live", layers=2, refresh_s=0.25)
    packets = stream_clip(walk_bvh, codec, keyframe_s=60.0)
    data = [p for p in packets if p.kind == DATA and p.frames]
    flagged = [bool(p.flags & RESTART) for p in data]
    assert flagged == [not p.keyframe and codec.layer_starts(p.codec_payload)[0] for p in data]
    assert sum(flagged) >= 10 and all(p.compact for p in data)
    k = flagged.index(True, 5)
    reader = Reader()
    reader.read(packets[0].to_bytes())  # the stream header, then the stream from a restart point
    again = [reader.read(p.to_bytes()) for p in data[k:]]
    assert [(p.sequence, p.first_frame, p.flags) for p in again] == [
        (p.sequence, p.first_frame, p.flags) for p in data[k:]
    ]
    late = receive_clip(packets[:1] + data[k:])
    clean = receive_clip(packets).channels
    np.testing.assert_array_equal(late.channels[-60:], clean[-60:])


@pytest.mark.parametrize("layers", [1, 3])
def test_a_packet_cut_by_more_layers_than_its_stream_has_is_concealed(walk_bvh, layers):
    """A relay's cut is said by the packet's check (Packet.dropped); the receiver decodes the
    layers left and conceals a packet that claims a cut its stream cannot have had."""
    from dataclasses import replace

    clip = walk_bvh[:240]
    packets = [p.without_cuts() for p in stream_clip(clip, get_codec("kinwave-live", layers=layers))]
    whole = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
    for p in packets[1:6]:
        whole.push(p)
    cut = replace(packets[6], dropped=1)
    frames = whole.push(cut)
    assert len(frames) == packets[6].frames and np.isfinite(frames).all()
    assert whole.stats.dropped == (1 if layers == 1 else 0)


def test_a_batchs_length_varints_are_varints():
    from mocodec.formats import varint
    from mocodec.stream.packets import length_varint

    for n in [*range(300), 0x3FFF, 0x4000, 0x4001, 65_535, 1 << 20, 1 << 28]:
        assert length_varint(n) == varint.pack(n)
