"""The relay's core without a network: ingest, repairs, layers, slow viewers, catch-up,
retention and settings, called through its public API (:mod:`mocodec.stream.relay.core`)."""

from __future__ import annotations

import copy
from dataclasses import replace

import pytest

from mocodec.codecs import get_codec
from mocodec.stream.live import stream_clip
from mocodec.stream.packets import Reader, pack_batch, split_batch
from mocodec.stream.relay import BAD_MESSAGE, Bucket, Closing, Limits, RelayCore, Room, Viewer
from mocodec.stream.relay.core import apply_settings
from mocodec.stream.relay.cutting import layers_for
from mocodec.stream.relay.retention import REPAIR_PACKETS, Caps, RoomHistory
from mocodec.stream.relay.rooms import Forward, StreamState


def ingested(core: RelayCore, packets, room: Room | None = None) -> Room:
    room = room or core.room("lobby")
    for p in packets:
        core.ingest(room, pack_batch([p.to_bytes()]), owner=1)
    return room


@pytest.mark.parametrize("compact_from", [0, 5, None])
def test_a_message_of_full_packets_reads_as_one_with_compact_ones(walk_bvh, compact_from):
    """A sender's message is read alike whether its packets are full, compact, or both (a
    compact packet follows on from the full one before it in the same message), and each
    layered packet's variants (read with its batch, or one by one) are the packet with its
    lowest 1, 2 and 3 layers, as a receiver reads them."""
    packets = stream_clip(walk_bvh[:40], get_codec("kinwave-live", layers=3), keyframe_s=60.0)[:-1]
    head, data = packets[0], packets[1:]
    wire = [replace(p, compact=compact_from is not None and k >= compact_from).to_bytes() for k, p in enumerate(data)]
    core = RelayCore()
    room = core.room("lobby")
    core.ingest(room, pack_batch([head.to_bytes()]), owner=1)
    core.ingest(room, pack_batch(wire), owner=1)
    kept, _ = room.streams[0].history.since(0, float("inf"))
    assert [(f.packet.sequence, f.packet.first_frame, f.packet.payload) for f in kept] == [
        (p.sequence, p.first_frame, p.codec_payload) for p in data
    ]
    assert room.streams[0].next_sequence == data[-1].sequence + 1
    reader = Reader()
    reader.read(head.to_bytes())
    for f in kept:
        assert len(f.layer_variants) == 3 and f.layer_variants[-1] == f.data
        for keep, variant in enumerate(f.layer_variants, 1):
            cut = copy.deepcopy(reader).read(variant)
            assert (cut.payload, cut.dropped) == (f.packet.payload[: f.layer_ends[keep - 1]], 3 - keep)
        reader.read(f.data)


@pytest.mark.parametrize(("before", "after"), [(3, 2), (2, 3), (3, 3), (3, 0)])
def test_a_header_that_changes_a_streams_layers_reads_its_packets_for_the_new_count(walk_bvh, before, after):
    """A message with a new header for a stream (other layers, or a codec without them: 0) and
    then packets of the old layer count: the batch was read for the old count, the packets are
    read again for the new one, and taken or refused as they are one message at a time."""

    def clip(layers):
        codec = get_codec("kinwave-live", layers=layers) if layers else get_codec("dpcm")
        return [replace(p, compact=False) for p in stream_clip(walk_bvh[:40], codec, keyframe_s=60.0)[:-1]]

    old, new = clip(before), clip(after)

    def outcome(messages):
        core = RelayCore()
        room = core.room("lobby")
        try:
            for m in messages:
                core.ingest(room, m, owner=1)
        except Closing as c:
            return c.reason
        kept, _ = room.streams[0].history.since(0, float("inf"))
        return [(f.data, f.layer_ends, f.layer_variants) for f in kept]

    first, switch, stale = pack_batch([old[0].to_bytes()]), new[0].to_bytes(), [p.to_bytes() for p in old[1:4]]
    together = outcome([first, pack_batch([switch, *stale])])
    assert together == outcome([first, pack_batch([switch]), *(pack_batch([p]) for p in stale)])
    if before == after:
        assert together == outcome([pack_batch([switch, *stale])])
    elif after:
        assert "cut table" in together


def test_repair_requests_are_checked_and_limited(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("kinwave-live", refresh_s=0.5), keyframe_s=60.0)[:-1]
    core, viewer = RelayCore(), Viewer()
    room = ingested(core, packets)
    history = room.streams[0].history
    kept = [p.sequence for p in packets[-REPAIR_PACKETS:]]  # the last REPAIR_PACKETS, restarts or not
    assert len(packets) > REPAIR_PACKETS and history.find(kept[0] - 1) is None
    assert [history.find(s).packet.sequence for s in kept] == kept
    bucket = Bucket(rate=1.0, burst_s=3.0)  # three packets
    core.resend(room, viewer, [[0, kept[1]], [0, kept[0] - 1], [7, kept[1]], [0, kept[2]], [0, kept[3]]], bucket)
    core.resend(room, viewer, [[0, kept[4]]], bucket)  # the bucket is empty: ignored
    assert [f.packet.sequence for f in viewer.resends] == kept[1:4] and not viewer.pending  # misses cost nothing
    assert core.counters["repairs"] == 3 and core.counters["repairs_missed"] == 3
    sizes = [len(history.find(s).data) for s in kept[5:8]]
    viewer.repair_volume = Bucket(rate=sum(sizes[:2]), burst_s=1.0)  # the bytes of two packets
    core.resend(room, viewer, [[0, s] for s in kept[5:8]], Bucket(100.0, 1.0))
    assert [f.packet.sequence for f in viewer.resends[3:]] == kept[5:7]
    for bad in ([[0, -1]], [[0]], [[0, 1.5]], [["0", 1]], [[0, 1]] * 257, {"0": 1}):
        with pytest.raises(Closing, match="repair"):
            core.resend(room, viewer, bad, Bucket(100.0, 1.0))


def test_a_viewer_gains_a_layer_only_where_it_restarts(walk_bvh):
    codec = get_codec("kinwave-live", layers=3, refresh_s=0.5)
    state = StreamState(None, None, None, codec, Room().history.stream())
    viewer = Viewer()

    def kept(fits, starts, keyframe=False):
        packet = stream_clip(walk_bvh[:12], codec)[1 if keyframe else 2]
        f = Forward(packet, b"", layer_ends=[1, 2, 3], layer_starts=starts)
        return layers_for(viewer, f, state, fits)

    assert kept(1, [False] * 3, keyframe=True) == 1  # the share fits the base only
    assert kept(3, [False] * 3) == 1  # room for more, but layer 1 has no history
    assert kept(3, [False, False, True]) == 1  # layer 2 cannot come without layer 1
    assert kept(3, [False, True, False]) == 2
    assert kept(3, [False, False, True]) == 3
    assert kept(2, [False] * 3) == 2  # dropping a layer needs no restart
    assert kept(1, [False] * 3) == 1


def test_a_late_joiner_of_a_refreshing_stream_starts_at_its_last_restart(walk_bvh):
    codec = get_codec("kinwave-live", refresh_s=0.25)
    packets = stream_clip(walk_bvh, codec, keyframe_s=60.0)[:-1]  # not ended
    room = ingested(RelayCore(), packets)
    history = room.streams[0].history
    gop, _ = history.since(history.restart, float("inf"))
    last = max(i for i, p in enumerate(packets) if p.restart)
    assert gop[0].packet.restart and not gop[0].packet.keyframe
    assert [f.packet.sequence for f in gop] == [p.sequence for p in packets[last:]]


def test_a_slow_viewer_misses_ticks_keeps_headers_and_is_dropped():
    now = [100.0]
    aborted = []
    core = RelayCore(Limits(slow_viewer_s=0.05), clock=lambda: now[0])
    viewer = Viewer(abort=lambda: aborted.append(True), capacity=1)
    viewer.outbox.append((b"a batch still on its way",))
    header = type("F", (), {"packet": type("P", (), {"kind": 0})()})()
    data = type("F", (), {"packet": type("P", (), {"kind": 1})()})()
    core.offer(viewer, (b"next",), [header, data])
    assert viewer.missed == 1 and viewer.pending == [header] and len(viewer.outbox) == 1  # memory stays one batch
    now[0] += 0.1
    core.offer(viewer, (b"next",), [data])
    assert aborted and viewer.dropped and core.counters["dropped_slow"] == 1
    core.offer(viewer, (b"next",), [data])
    assert len(aborted) == 1  # dropped once


def ticked(core: RelayCore, room, viewer: Viewer, packets, per_tick: int = 1, extra_ticks: int = 400):
    """Ingest ``packets`` ``per_tick`` a tick and dispatch each tick; then ticks without packets
    until ``viewer`` has caught up: per tick, the bytes it got and the tick's fresh bytes."""
    got = []
    for k in range(0, len(packets) + per_tick * extra_ticks, per_tick):
        chunk = packets[k : k + per_tick]
        if chunk:
            core.ingest(room, pack_batch([p.to_bytes() for p in chunk]), owner=1)
        elif not viewer.behind:
            break
        core.dispatch(room)
        batches = viewer.outbox.popleft() if viewer.outbox else ()
        got.append((batches, sum(len(p.to_bytes()) for p in chunk)))
    return got


def test_a_late_viewer_catches_up_paced_and_decodes_exactly(walk_bvh):
    """A viewer joining a stream half way catches up from its keyframe at the catch-up pace
    beyond the live packets (it once got everything kept in one message), and gets every
    packet once, in order: it decodes what a viewer from the start decodes."""
    packets = stream_clip(walk_bvh, get_codec("dpcm"), keyframe_s=60.0)
    pace, tick_hz = 40_000.0, 60.0
    core = RelayCore(Limits(catchup_bytes_per_s=pace), tick_hz=tick_hz)
    half = len(packets) // 2
    room = ingested(core, packets[:half])
    core.dispatch(room)
    viewer = Viewer()
    core.join(room, viewer)
    ticks = ticked(core, room, viewer, packets[half:])
    largest = max(len(p.to_bytes()) for p in packets)
    received = []
    header = len(packets[0].to_bytes())  # in the first tick's batch
    for k, (batches, live) in enumerate(ticks):
        sent = sum(len(b) for b in batches) - (header if k == 0 else 0)
        assert sent <= live + pace / tick_hz + largest + 64  # the pace, and the packet that crosses it
        received += [bytes(r) for b in batches for r in split_batch(b)]
    kept = sum(len(p.to_bytes()) for p in packets[1:half])
    assert len([t for t in ticks if t[0]]) > kept / (pace / tick_hz) / 2  # paced over many ticks
    assert received == [p.to_bytes() for p in packets]
    assert not viewer.behind and not viewer.notes


def test_a_sender_that_leaves_ends_its_streams_once(walk_bvh):
    packets = stream_clip(walk_bvh[:120], get_codec("dpcm"))[:-1]  # no END
    core = RelayCore()
    room = ingested(core, packets)
    batch = core.sender_left(room, owner=1)
    assert batch is not None and room.streams[0].ended
    core.dispatch(room)
    assert not room.streams and core.sender_left(room, owner=1) is None


def test_what_the_relay_keeps_is_capped_per_stream_and_per_room():
    class F:
        def __init__(self, size: int, sequence: int):
            self.data, self.packet = b"x" * size, type("P", (), {"sequence": sequence})()

    room = RoomHistory(Caps(stream_bytes=1000, room_bytes=2500, stream_packets=100))
    a, b, c = room.stream(), room.stream(), room.stream()
    for k in range(50):  # a restart point at the start only
        a.add(F(100, k), restart=k == 0)
    assert a.bytes == 1000 and a.partial and a.first == 40 and room.bytes == 1000
    for k in range(10):
        b.add(F(300, k), restart=True)
    assert b.bytes == 900 and room.bytes == 1900  # the last packets for repairs, within its cap
    for k in range(20):
        c.add(F(150, k), restart=k % 5 == 0)
    assert room.bytes <= 2500 and c.bytes <= 1000 and all(h.bytes >= 0 for h in (a, b, c))
    assert a.bytes < 1000  # the room's cap took the oldest first: a's
    got, after = c.since(c.restart, 200)
    assert len(got) == 2 and after == c.first + (c.restart - c.first) + 2  # past the budget by one packet
    c.close()
    assert room.bytes == a.bytes + b.bytes and room.packets == len(a.kept) + len(b.kept)
    for k in range(10_000):  # stale entries are compacted: the queue stays in proportion
        a.add(F(10, 100 + k), restart=False)
    assert len(room.arrivals) <= 2 * room.packets + 65


@pytest.mark.parametrize("text", ["[" * 8000, '{"budget": 1e999}', '{"budget": ' + "9" * 5000 + "}"])
def test_a_viewer_message_nested_deep_or_too_large_closes_with_4400(text):
    """``'[' * 8000`` once raised RecursionError out of the handler (close code 1006)."""
    with pytest.raises(Closing) as caught:
        apply_settings(Viewer(), text)
    assert caught.value.code == BAD_MESSAGE


def test_an_idle_room_goes_at_the_next_tick(walk_bvh):
    core = RelayCore()
    room = core.room("lobby")
    viewer = Viewer()
    core.join(room, viewer)
    core.tick()
    assert "lobby" in core.rooms
    core.leave(room, viewer)
    core.tick()
    assert "lobby" not in core.rooms and core.status()["rooms"] == 0


def test_the_crowd_layout_is_kept_a_few_ticks_and_remade_when_a_camera_moves(walk_bvh):
    """Viewers' shares are worked out every LAYOUT_TICKS ticks, not every tick; a camera, a
    budget or a stream that changes makes them anew at once, and a near avatar gets more of a
    budget than a far one."""
    from mocodec.stream.relay.cutting import LAYOUT_TICKS, layout_of

    codec = get_codec("kinwave-live", layers=3, refresh_s=0.5)
    core = RelayCore()
    room = core.room("lobby")
    for stream, x in ((0, 1.0), (1, 9.0)):
        for p in stream_clip(walk_bvh[:60], codec, stream=stream)[:3]:
            core.ingest(room, pack_batch([replace(p, position=(x, 0.0, 0.0)).to_bytes()]), owner=1)
    viewer = Viewer(budget=8000.0, camera=(0.0, 0.0, 0.0))
    first = layout_of(room, [viewer], 0.1)
    near, far = first.shares[first.row[0], 0], first.shares[first.row[1], 0]
    assert near > 4 * far and near + far <= 8000
    kept = [layout_of(room, [viewer], 0.1) for _ in range(LAYOUT_TICKS)]
    assert all(k is first for k in kept) and layout_of(room, [viewer], 0.1) is not first  # its age is up
    again = layout_of(room, [viewer], 0.1)
    viewer.camera = (10.0, 0.0, 0.0)
    moved = layout_of(room, [viewer], 0.1)
    assert moved is not again and moved.shares[moved.row[1], 0] > moved.shares[moved.row[0], 0]
