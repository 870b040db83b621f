"""The compact wire form of data packets (docs/formats.md): 4 bytes around the payload for an
ongoing stream of full packets (6 where packets vary in length), every field back at the
receiver, losses and late packets placed right."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec.codecs import get_codec
from mocodec.errors import CorruptStreamError, OutOfStepError
from mocodec.stream.live import stream_clip
from mocodec.stream.packets import HEADER, Reader, parse


@pytest.fixture(scope="module")
def packets(walk_bvh):
    return stream_clip(walk_bvh, get_codec("kinwave-live"))


def _same(a, b) -> bool:
    return (a.stream, a.sequence, a.first_frame, a.frames, a.flags, a.payload, a.codec) == (
        b.stream,
        b.sequence,
        b.first_frame,
        b.frames,
        b.flags,
        b.payload,
        b.codec,
    )


def test_an_ongoing_stream_spends_4_bytes_a_packet(packets):
    """kinwave-live's packets code 6 frames at 120 fps, which its header says once: a short
    packet is a tag with the sequence number's low 6 bits, the stream id and the CRC; the last
    packet of the clip (fewer frames) says its own count."""
    assert packets[0].kind == HEADER and packets[0].frames == 6
    data = [p for p in packets if p.kind != HEADER and not p.keyframe and not p.sends_position]
    assert data and all(len(p.to_bytes()) - len(p.payload) == (4 if p.frames == 6 else 6) for p in data)
    assert packets[-1].frames < 6
    framing = sum(len(p.to_bytes()) - len(p.payload) for p in packets[1:]) / len(packets[1:])
    assert framing < 5.0  # keyframes and moves carry more, on average under 5 bytes


def test_packets_of_varying_length_say_their_frame_count(walk_bvh):
    varying = stream_clip(walk_bvh[:240], get_codec("dpcm"))
    assert varying[0].kind == HEADER and varying[0].frames == 0
    data = [p for p in varying if p.kind != HEADER and not p.keyframe and not p.sends_position]
    assert data and all(len(p.to_bytes()) - len(p.payload) == 6 for p in data)
    reader = Reader()
    assert all(_same(reader.read(p.to_bytes()), p) for p in varying)


def test_the_usual_frame_count_of_a_stream_without_one_is_refused(packets):
    from dataclasses import replace

    reader = Reader()
    reader.read(replace(packets[0], frames=0).to_bytes())  # a header that gives no usual count
    short = next(p for p in packets[2:] if not (p.restart or p.sends_position))
    with pytest.raises(CorruptStreamError, match="usual frame count"):
        reader.read(short.to_bytes())


def test_every_field_comes_back(packets):
    reader = Reader()
    for p in packets:
        got = reader.read(p.to_bytes())
        assert _same(got, p)
        if p.kind != HEADER and p.sends_position:
            assert np.allclose(got.position, p.position, atol=0.005)


def test_lost_packets_are_counted_and_late_ones_placed_behind(packets):
    reader = Reader()
    reader.read(packets[0].to_bytes())
    reader.read(packets[1].to_bytes())
    after_loss = reader.read(packets[5].to_bytes())  # 2-4 lost
    assert _same(after_loss, packets[5])
    late = reader.read(packets[3].to_bytes())  # arrives after 5
    assert late.sequence == packets[3].sequence and late.first_frame == packets[3].first_frame
    assert _same(reader.read(packets[6].to_bytes()), packets[6])  # the late one did not move the cursor
    # a short packet's 6 bits place it up to 31 packets ahead (1.5 s at 120 fps), whatever the count
    far = next(k for k in range(7 + 31, 7, -1) if not (packets[k].restart or packets[k].sends_position))
    assert _same(reader.read(packets[far].to_bytes()), packets[far])


def test_a_joiner_waits_for_a_keyframe(packets):
    reader = Reader()
    reader.read(packets[0].to_bytes())
    key = next(k for k, p in enumerate(packets) if k > 2 and p.keyframe)
    with pytest.raises(OutOfStepError):
        reader.read(packets[key - 1].to_bytes())
    assert _same(reader.read(packets[key].to_bytes()), packets[key])
    assert _same(reader.read(packets[key + 1].to_bytes()), packets[key + 1])


def test_damage_and_strangers_are_refused(packets):
    raw = bytearray(packets[2].to_bytes())
    raw[len(raw) // 2] ^= 0x10
    reader = Reader()
    reader.read(packets[0].to_bytes())
    with pytest.raises(CorruptStreamError, match="CRC"):
        reader.read(bytes(raw))
    with pytest.raises(CorruptStreamError, match="before its stream header"):
        parse(packets[2].to_bytes())
    with pytest.raises(CorruptStreamError):
        reader.read(b"\x80\x00")


@pytest.mark.parametrize("compact", [True, False])
def test_a_packet_cut_from_its_bytes_is_the_packet_with_the_shorter_payload(packets, compact):
    """... and the layers cut off it read back from its check, which names no other count."""
    from dataclasses import replace

    from mocodec.stream.packets import truncated

    reader = Reader()
    reader.read(packets[0].to_bytes())
    for p in [q for q in packets if q.kind != HEADER][:20]:
        p = replace(p, compact=compact)
        data = p.to_bytes()
        reader.read(data)
        for size, dropped in ((0, 3), (1, 2), (len(p.payload) // 2, 1), (len(p.payload), 0)):
            cut = truncated(p, data, size, dropped)
            assert cut == replace(p, payload=p.payload[:size], dropped=dropped).to_bytes()
            back = parse(cut, "cut", reader.cursors.get)
            assert (back.dropped, back.payload, back.sequence) == (dropped, p.payload[:size], p.sequence)
    header = packets[0].to_bytes()  # a header is never cut: a check from another start is damage
    with pytest.raises(CorruptStreamError, match="CRC"):
        parse(replace(packets[0], dropped=1).to_bytes())
    assert parse(header).dropped == 0


def _three(streams: list[int]) -> list[int]:
    """Every stream's layer count: 3."""
    return [3] * len(streams)


def _same_as_one_by_one(read, prepared, alone, raw) -> None:
    """``read_batch``'s packets and layers are those read one by one (``alone``, from their
    bytes ``raw``): the layered ones stripped, as ``stripped`` gives them, their layer ends as
    ``layer_ends`` reads them, their variants as ``truncated`` cuts them."""
    from mocodec.stream.packets import layer_ends, stripped, truncated

    assert len(read) == len(alone)
    for k, (p, q) in enumerate(zip(read, alone)):
        if k in prepared:
            ends, variants = prepared[k]
            plain, whole = stripped(q, raw[k])
            assert (p, variants[-1]) == (plain, whole)
            assert ends == layer_ends(q, 3)
            assert variants[:-1] == tuple(truncated(plain, whole, ends[n - 1], 3 - n) for n in (1, 2))
        else:
            assert p == q


def _damaged(batch: bytes, start: int, rng, copies: int = 300):
    """``copies`` of ``batch`` with one byte from ``start`` on changed (the packet lengths before
    it stay, so each still splits)."""
    for _ in range(copies):
        damaged = bytearray(batch)
        damaged[int(rng.integers(start, len(batch)))] ^= int(rng.integers(1, 256))
        yield bytes(damaged)


def test_a_batch_read_together_is_its_packets_read_one_by_one(walk_bvh):
    """``read_batch`` (a relay's reading of a sender's batch in arrays and compiled calls)
    gives the packets ``parse`` gives one at a time, and the layered ones (for their stream's
    layer count) stripped of their cut tables with their layers, as ``stripped``, ``layer_ends``
    and ``truncated`` make them; where one packet would not parse, or is compact, it gives None
    (the caller reads them one by one and says what is wrong). Checked on a real batch and on
    300 copies of it with a byte changed (seeded), headers, tables and checks included."""
    from dataclasses import replace

    from mocodec.stream.packets import (
        CUTS,
        DATA,
        batch_offsets,
        layer_ends,
        pack_batch,
        read_batch,
        split_batch,
    )

    packets = stream_clip(walk_bvh[:300], get_codec("kinwave-live", layers=3))
    full = [replace(p, compact=False) for p in packets[:40]]
    batch = pack_batch([p.to_bytes() for p in full])

    def one_by_one(data: bytes):
        try:
            return [parse(r, "packet") for r in split_batch(data)]
        except CorruptStreamError:
            return None

    def check(data: bytes) -> bool:
        together, alone = read_batch(data, batch_offsets(data), _three), one_by_one(data)
        if together is None:
            return alone is None or any(r[0] >= 0x80 for r in split_batch(data))
        assert read_batch(data, batch_offsets(data)) == (alone, {})  # no layer counts: nothing peeled
        _same_as_one_by_one(*together, alone, split_batch(data))
        for k, q in enumerate(alone):
            if k not in together[1] and q.flags & CUTS and not q.dropped and q.kind == DATA and q.frames:
                with pytest.raises(CorruptStreamError):  # a table that does not read
                    layer_ends(q, 3)
        return True

    assert check(batch) and len(read_batch(batch, batch_offsets(batch), _three)[1]) > 30
    assert not read_batch(batch, batch_offsets(batch), lambda streams: [2] * len(streams))[1]  # another count
    rng = np.random.default_rng(7)
    assert all(map(check, _damaged(batch, len(batch) - sum(len(p.to_bytes()) for p in full), rng)))
    tables = 0  # a cut table changed under a good check: prepared as layer_ends reads it, or not
    for _ in range(300):
        k = int(rng.integers(1, len(full)))
        payload = bytearray(full[k].payload)
        at = int(rng.integers(0, min(len(payload), 2 + payload[0] + 2)))
        payload[at] = int(rng.integers(0, 256))
        changed = [p.to_bytes() for p in full[:k]] + [replace(full[k], payload=bytes(payload)).to_bytes()]
        data = pack_batch(changed)
        assert check(data)
        tables += k not in read_batch(data, batch_offsets(data), _three)[1]
    assert 30 < tables < 270  # both ways, often
    mixed = pack_batch([full[0].to_bytes(), replace(packets[1], compact=True).to_bytes()])
    assert read_batch(mixed, batch_offsets(mixed), _three) is None


def test_a_batch_of_compact_packets_read_together_is_its_packets_read_one_by_one(walk_bvh):
    """``read_batch`` of compact packets (given their streams' cursors, which it leaves as
    they are) gives the packets a receiver's cursors give reading them one at a time, placed
    by the cursors in order (two streams, two packets of each a batch at places), and the
    layered ones stripped of their cut tables with their layers, as ``stripped``,
    ``layer_ends`` and ``truncated`` make them; None where one would not parse (300 copies with
    a byte changed, seeded) or would need a cursor it has not got."""
    import copy
    from dataclasses import replace

    from mocodec.stream.packets import (
        CUTS,
        RESTART,
        batch_offsets,
        pack_batch,
        read_batch,
        split_batch,
    )

    clip = stream_clip(walk_bvh[:400], get_codec("kinwave-live", layers=3, refresh_s=0.1), keyframe_s=0.5)
    header, data = clip[0], clip[1:-1]
    twin = [replace(p, stream=7) for p in data]  # a second stream of the same packets
    reader = Reader()
    for p in (header, replace(header, stream=7), *data[:3], *twin[:5]):
        reader.read(p.to_bytes())
    sent = [p for pair in zip(data[3:23], twin[5:25]) for p in pair if p.sequence % 7]  # some lost on the way
    wire = [p.to_bytes() for p in sent]
    batch = pack_batch(wire)
    assert all(w[0] >= 0x80 for w in wire) and sum(1 for p in sent if p.flags & CUTS) > 20
    assert {p.restart for p in sent} == {True, False} and any(p.flags & RESTART and not p.keyframe for p in sent)

    def one_by_one(message: bytes):
        try:
            cursors = copy.deepcopy(reader)
            return [cursors.read(r, "packet") for r in split_batch(message)]
        except CorruptStreamError:
            return None

    def check(message: bytes) -> bool:
        before = copy.deepcopy(reader.cursors)
        together, alone = read_batch(message, batch_offsets(message), _three, reader.cursors.get), one_by_one(message)
        assert reader.cursors == before  # (read, not moved)
        if together is None:
            return alone is None or any(r[0] < 0x80 for r in split_batch(message))
        _same_as_one_by_one(*together, alone, split_batch(message))
        return True

    assert check(batch) and len(read_batch(batch, batch_offsets(batch), _three, reader.cursors.get)[1]) > 20
    assert read_batch(batch, batch_offsets(batch)) is None  # no cursors: one by one
    assert read_batch(batch, batch_offsets(batch), _three, {0: reader.cursors[0]}.get) is None  # stream 7's missing
    doubled = pack_batch(wire[:2] + [p.to_bytes() for p in (data[23], data[24], twin[25], data[23], data[26])])
    assert check(doubled)  # a stream's next packet follows on from the one before (a late one moves nothing)
    assert all(map(check, _damaged(batch, len(batch) - sum(map(len, wire)), np.random.default_rng(11))))


@pytest.mark.parametrize("compact", [True, False])
def test_a_packet_stripped_of_its_cut_table_is_the_packet_without_it(packets, compact):
    """What a relay forwards (``stripped``, made from the bytes as they came) is the packet
    without its cut table as its own ``to_bytes`` makes it, and reads back as that packet."""
    from dataclasses import replace

    from mocodec.stream.packets import CUTS, stripped, with_cut_table

    reader = Reader()
    reader.read(packets[0].to_bytes())
    for p in [q for q in packets if q.kind != HEADER][:20]:
        ends = [len(p.payload) // 3, len(p.payload) // 2]
        cut = replace(p, compact=compact, payload=with_cut_table(p.payload, ends), flags=p.flags | CUTS)
        data = cut.to_bytes()
        assert parse(data, "with cuts", reader.cursors.get).cuts  # a table to strip
        plain, forwarded = stripped(cut, data)
        assert plain == replace(p, compact=compact) and forwarded == plain.to_bytes()
        back = parse(forwarded, "forwarded", reader.cursors.get)
        assert (back.payload, back.flags, back.sequence) == (p.payload, p.flags, p.sequence)
        assert stripped(plain, forwarded) == (plain, forwarded)  # nothing to strip: the same bytes
        reader.read(data)


def test_a_parsed_full_packet_equals_the_packet_written(packets):
    from dataclasses import replace

    for p in [q for q in packets if q.kind != HEADER][:10]:
        full = replace(p, compact=False, timestamp_us=1_700_000_000_000_000, position=(1.5, 0.25, -2.0))
        assert parse(full.to_bytes()) == replace(full, usual_frames=0, sends_position=True)
