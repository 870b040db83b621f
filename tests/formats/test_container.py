"""The .moc container: round trips, random access, overhead, and damaged files."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mocodec import Motion, moc
from mocodec.codecs import get_codec
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.formats import container


@pytest.fixture(scope="module")
def long_walk(walk_amc):
    """2490 frames: the walk six times over."""
    return Motion(walk_amc.skeleton, walk_amc.fps, np.tile(walk_amc.channels, (6, 1)))


@pytest.mark.parametrize("cid", ["raw", "lossless"])
def test_file_round_trip_and_frame_ranges(cid, long_walk, tmp_path):
    path = tmp_path / "walk.moc"
    size = moc.encode(long_walk, path, get_codec(cid), chunk_frames=500)
    assert path.stat().st_size == size and not list(tmp_path.glob("*.tmp"))
    whole = moc.decode(path)
    assert whole.skeleton.isclose(long_walk.skeleton, atol=0) and whole.fps == long_walk.fps
    expected = long_walk.channels if cid == "lossless" else long_walk.channels.astype(np.float32)
    assert np.array_equal(whole.channels, expected)
    for first, stop in ((0, 1), (499, 501), (1234, 2490), (2489, 2490), (700, 700)):
        part = moc.decode(path, frames=(first, stop))
        assert np.array_equal(part.channels, expected[first:stop])
    info = moc.info(path)
    assert info.chunks_for(499, 501) == [0, 1] and len(info.index) == 5
    with pytest.raises(CodecError, match="outside"):
        moc.decode(path, frames=(0, 9999))


def test_skeleton_survives_exactly(walk_amc, walk_bvh):
    for motion in (walk_amc, walk_bvh):
        back = container.skeleton_from_dict(container.skeleton_to_dict(motion.skeleton))
        assert back.isclose(motion.skeleton, atol=0) and back.body_parts == motion.skeleton.body_parts


def test_overhead_is_under_one_percent(long_walk):
    codec = get_codec("lossless")
    data = moc.pack(long_walk, codec)
    chunks = moc.unpack(data)  # decodes
    assert chunks.num_frames == long_walk.num_frames
    payload = sum(
        len(codec.encode(long_walk[a : a + moc.CHUNK_FRAMES])) for a in range(0, long_walk.num_frames, moc.CHUNK_FRAMES)
    )
    framing = len(data) - payload - len(_skeleton_bytes(long_walk))
    assert framing < 0.01 * payload


def _skeleton_bytes(motion) -> bytes:
    import json
    import zlib

    return zlib.compress(json.dumps(container.skeleton_to_dict(motion.skeleton), separators=(",", ":")).encode(), 9)


@pytest.fixture(scope="module")
def small_file(walk_amc):
    return moc.pack(walk_amc[:50], get_codec("lossless"), chunk_frames=20)


@pytest.mark.slow
def test_every_truncation_is_caught(small_file):
    for cut in range(len(small_file)):
        with pytest.raises(CorruptStreamError):
            moc.unpack(small_file[:cut])


def test_bit_flips_name_the_damaged_part(small_file):
    rng = np.random.default_rng(2)
    for bit in rng.choice(len(small_file) * 8, size=400, replace=False):
        data = bytearray(small_file)
        data[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(CorruptStreamError) as err:
            moc.unpack(bytes(data), name="f.moc")
        assert str(err.value).startswith("f.moc: ")


def test_damaged_chunk_is_reported_with_its_number_and_offset(small_file):
    c = container.open_container(__import__("io").BytesIO(small_file), len(small_file), "f.moc")
    e = c.index[1]
    data = bytearray(small_file)
    data[e.offset + 20] ^= 0xFF
    with pytest.raises(CorruptStreamError, match=f"chunk 1 at byte {e.offset}: CRC mismatch"):
        moc.unpack(bytes(data), name="f.moc")
    moc.unpack(bytes(data), frames=(0, 20), name="f.moc")  # chunk 0 alone still decodes


@settings(max_examples=50)
@given(st.binary(max_size=300))
def test_random_bytes_raise_only_our_error(data):
    try:
        moc.unpack(data)
    except CorruptStreamError:
        pass
    try:
        moc.unpack(b"MOC1" + data)
    except CorruptStreamError:
        pass


def test_not_a_moc_file(tmp_path, walk_amc):
    with pytest.raises(CorruptStreamError, match="not a .moc file"):
        moc.unpack(b"BVH nonsense" * 10)


def test_skeleton_by_reference(walk_amc, tmp_path):
    from mocodec.errors import SkeletonMismatchError

    full = moc.pack(walk_amc, get_codec("lossless"))
    ref = moc.pack(walk_amc, get_codec("lossless"), embed_skeleton=False)
    assert len(full) - len(ref) > 500
    assert np.array_equal(moc.unpack(ref, skeleton=walk_amc.skeleton).channels, walk_amc.channels)
    with pytest.raises(SkeletonMismatchError, match="without holding it"):
        moc.unpack(ref)
    other = container.skeleton_from_dict(container.skeleton_to_dict(walk_amc.skeleton))
    assert container.skeleton_id(other) == container.skeleton_id(walk_amc.skeleton)
    from conftest import DATA
    from mocodec import load

    with pytest.raises(SkeletonMismatchError, match="coded for skeleton"):
        moc.unpack(ref, skeleton=load(DATA / "135_08.amc").skeleton)


def test_the_header_dictionaries_never_change():
    """Each version's preset dictionary is part of the format: files written with it need
    these bytes. Version 2's is version 1's with kinwave's current settings after it."""
    import hashlib

    from mocodec.formats.header_dict import DICTIONARIES

    assert {v: hashlib.sha256(d).hexdigest() for v, d in DICTIONARIES.items()} == {
        1: "fa16a5c4da355da4b2481bff71f69fe0fc2fce99e1b69dbf02ea2352496ff950",
        2: "89467d50e04087e1cca088665075390e4794022d2138237d9b9b0cbebbe5c8c9",
    }
    assert DICTIONARIES[2].startswith(DICTIONARIES[1])


def test_a_version_1_file_reads_as_it_did(walk_bvh):
    """A file of version 1 (its header deflated with version 1's dictionary) reads to the same
    motion as the version 2 file of the same chunks, whose header the newer dictionary makes
    smaller for kinwave's settings."""
    import io
    import zlib

    from mocodec.formats.header_dict import DICTIONARIES

    data = moc.pack(walk_bvh[:40], get_codec("kinwave", max_error_cm=1.0, error_measure="shell"))
    assert data[4:6] == bytes([2, 0])
    start = container.START.unpack_from(data)
    head = data[container.START.size : container.START.size + start[3]]
    text = zlib.decompressobj(zdict=DICTIONARIES[2]).decompress(head)
    deflate = zlib.compressobj(9, zdict=DICTIONARIES[1])
    old_head = deflate.compress(text) + deflate.flush()
    version_1 = (
        container.START.pack(container.MAGIC, 1, start[2], len(old_head))
        + old_head
        + zlib.crc32(old_head).to_bytes(4, "little")
        + data[container.START.size + start[3] + 4 :]
    )
    assert len(version_1) > len(data) + 10
    old, new = moc.unpack(version_1), moc.unpack(data)
    assert np.array_equal(old.channels, new.channels) and old.skeleton == new.skeleton
    c = container.open_container(io.BytesIO(version_1), len(version_1), "old.moc")
    assert c.read_chunk(0) == container.open_container(io.BytesIO(data), len(data), "new.moc").read_chunk(0)


def test_framing_costs_38_bytes(walk_bvh):
    """Start and header CRC (16 bytes), one chunk's length and CRC (6 for a body under 16 KB),
    the index (8) and the footer (8): 30 bytes fewer than version 2's 68, which also kept each
    payload's 17-byte envelope."""
    clip = walk_bvh[:20]
    data = moc.pack(clip, get_codec("raw"), embed_skeleton=False)
    c = container.open_container(__import__("io").BytesIO(data), len(data), "f.moc", clip.skeleton)
    head_len = int.from_bytes(data[8:12], "little")
    assert len(data) - head_len - len(c.read_chunk(0)) == 38


def test_common_skeletons_cost_a_few_hundred_bytes(walk_bvh, walk_amc):
    """Joint names come from the header dictionary, mirrored bones refer to their other side,
    ASF bones are stored as length times direction: what embedding the skeleton costs."""
    cost = {}
    for motion in (walk_bvh, walk_amc):
        full = moc.pack(motion[:10], get_codec("raw"))
        cost[motion.num_channels] = len(full) - len(moc.pack(motion[:10], get_codec("raw"), embed_skeleton=False))
    assert cost[132] < 450 and cost[62] < 900


def test_lossy_files_round_the_skeleton_offsets(walk_bvh, walk_amc):
    """A lossy codec's file stores offsets to 0.001 cm (fewer bytes) and decodes on them; a
    lossless codec's, a file given ``exact_skeleton`` or one holding only the skeleton's id keep
    the skeleton bit for bit."""
    saved = {}
    for motion in (walk_bvh, walk_amc):
        clip = motion[:10]
        lossy = moc.unpack(data := moc.pack(clip, get_codec("kinwave")))
        cm = 100.0 / motion.skeleton.units_per_metre
        moved = np.abs(lossy.skeleton.offsets - motion.skeleton.offsets).max() * cm
        assert 0 < moved <= 0.0005
        saved[motion.num_channels] = len(moc.pack(clip, get_codec("kinwave"), exact_skeleton=True)) - len(data)
        for exact in (
            moc.unpack(moc.pack(clip, get_codec("raw"))),
            moc.unpack(moc.pack(clip, get_codec("kinwave"), exact_skeleton=True)),
            moc.unpack(moc.pack(clip, get_codec("kinwave"), embed_skeleton=False), skeleton=motion.skeleton),
        ):
            assert container.skeleton_id(exact.skeleton) == container.skeleton_id(motion.skeleton)
    assert saved[132] > 60 and saved[62] > 250


def test_other_versions_and_unknown_flags_are_refused(walk_bvh):
    data = moc.pack(walk_bvh[:8], get_codec("raw"))
    assert data[4:6] == bytes([2, 0])  # .moc version 2
    for version in (0, 3):
        with pytest.raises(CorruptStreamError, match=f"version {version}; this mocodec reads versions 1 and 2"):
            moc.unpack(data[:4] + bytes([version, 0]) + data[6:])
    with pytest.raises(CorruptStreamError, match="flags"):
        moc.unpack(data[:6] + bytes([data[6] | 2]) + data[7:])
