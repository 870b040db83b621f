"""The .moc container: round trips, random access, overhead, and damaged files."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mocodec import Motion, limits, moc
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


@pytest.fixture
def one_chunk_file(walk_amc):
    return moc.pack(walk_amc[:50], get_codec("lossless"))


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["small_file", "one_chunk_file"])
def test_every_truncation_is_caught(layout, request):
    data = request.getfixturevalue(layout)
    for cut in range(len(data)):
        with pytest.raises(CorruptStreamError):
            moc.unpack(data[:cut])


@pytest.mark.parametrize("layout", ["small_file", "one_chunk_file"])
def test_bit_flips_name_the_damaged_part(layout, request):
    whole = request.getfixturevalue(layout)
    rng = np.random.default_rng(2)
    for bit in rng.choice(len(whole) * 8, size=400, replace=False):
        data = bytearray(whole)
        data[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(CorruptStreamError) as err:
            moc.unpack(bytes(data), name="f.moc")
        assert str(err.value).startswith("f.moc: ")


def test_a_one_chunk_file_is_checked_like_an_indexed_one(one_chunk_file, walk_amc):
    """The one chunk of a version 3 file has no length or index to check: its CRC covers it,
    and its frames (the header's) must be a chunk's."""
    import io

    c = container.open_container(io.BytesIO(one_chunk_file), len(one_chunk_file), "f.moc")
    assert c.one_chunk and len(c.index) == 1 and c.index[0].count == 50
    assert c.index[0].offset + c.index[0].size == len(one_chunk_file)
    data = bytearray(one_chunk_file)
    data[c.index[0].offset + 3] ^= 0x10
    with pytest.raises(CorruptStreamError, match=f"f.moc: chunk 0 at byte {c.index[0].offset}: CRC mismatch"):
        moc.unpack(bytes(data), name="f.moc")
    header = {**c.header, "skeleton": c.skeleton}
    for frames in (0, limits.MAX_PAYLOAD_FRAMES + 1):
        forged = container.pack({**header, "frames": frames}, [container.Chunk(0, 50, c.read_chunk(0))])
        with pytest.raises(CorruptStreamError, match=f"a chunk of {frames} frames in the"):
            moc.unpack(forged)


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
        3: "7e7b300e8c8a6569671a7d6e066a2c253d23bc39b4789f42a000ea345aac00fd",
    }
    assert DICTIONARIES[3].startswith(DICTIONARIES[2]) and DICTIONARIES[2].startswith(DICTIONARIES[1])


def test_version_3s_dictionary_holds_the_columns_of_real_skeletons(walk_bvh, walk_amc):
    """What version 3's dictionary adds holds the parent and channel columns the compact
    skeleton writes for a cgspeed BVH, the same as a game export writes it (a turned root above
    the hips, bones in translation channels) and a CMU ASF skeleton: each such header costs
    over 30 bytes less than with version 2's dictionary."""
    from mocodec import reexpress
    from mocodec.formats.header_dict import DICTIONARIES
    from mocodec.formats.skeleton_bin import pack_skeleton
    from mocodec.skeleton import CHANNEL_NAMES

    added = DICTIONARIES[3][len(DICTIONARIES[2]) :]
    game = reexpress.with_dummy_root(reexpress.with_position_channels(walk_bvh[:6]), (0.0, -90.0, 0.0))
    for motion in (walk_bvh, walk_amc, game):
        joints = motion.skeleton.joints
        parents = bytes(i - j.parent if j.parent >= 0 else 0 for i, j in enumerate(joints))
        channels = b"".join(bytes([len(j.channels), *(CHANNEL_NAMES.index(c) for c in j.channels)]) for j in joints)
        assert parents in added and channels in added
        packed = pack_skeleton(motion.skeleton)
        sizes = []
        for version in (2, 3):
            deflate = zlib.compressobj(9, zdict=DICTIONARIES[version])
            sizes.append(len(deflate.compress(packed) + deflate.flush()))
        assert sizes[1] < sizes[0] - 30


def test_files_of_versions_1_and_2_read_as_they_did(walk_bvh):
    """The same chunks written as versions 1 and 2 (fixed-width start, index and footer; version
    1's header deflated with an older dictionary) read to the same motion as the version 3
    file, whose header the newer dictionaries make smaller (kinwave's settings; the CMU
    skeletons' parent and channel columns) and whose one chunk needs neither its length, an
    index nor a footer (21 bytes)."""
    import io

    data = moc.pack(walk_bvh[:40], get_codec("kinwave", max_error_cm=1.0, error_measure="shell"))
    assert data[4:6] == bytes([3, 0])
    c = container.open_container(io.BytesIO(data), len(data), "new.moc")
    header = {**c.header, "skeleton": c.skeleton}
    chunks = [container.Chunk(0, c.frames, c.read_chunk(0))]
    older = {v: container.pack(header, chunks, version=v) for v in (1, 2)}
    assert older[1][4:6] == bytes([1, 0]) and older[2][4:6] == bytes([2, 0])
    assert len(older[1]) > len(older[2]) + 10 and len(older[2]) > len(data) + 21 + 30
    new = moc.unpack(data)
    for old_data in older.values():
        old = moc.unpack(old_data)
        assert np.array_equal(old.channels, new.channels) and old.skeleton == new.skeleton
        assert container.open_container(io.BytesIO(old_data), len(old_data), "old.moc").read_chunk(0) == chunks[0].body
    with pytest.raises(ValueError, match="version 4 is not one"):
        container.pack(header, chunks, version=4)


def test_framing_costs_17_bytes_for_one_chunk(walk_bvh, long_walk):
    """Version 3: the start (magic, version, one-byte flags, the header's length: 8 bytes under
    128 header bytes, 9 under 16 KB), the header's CRC and the one chunk's CRC: 38 bytes in
    version 2, with the chunk's length, the index and the footer. A file of more chunks keeps
    them, with version 2's framing but for the start (6 bytes a chunk under 16 KB)."""
    import io

    clip = walk_bvh[:20]
    data = moc.pack(clip, get_codec("raw"), embed_skeleton=False)
    version, flags, head_at, head_len = container.read_opening(io.BytesIO(data), len(data), "f.moc")
    assert (version, flags, head_at) == (3, container.FLAG_ONE_CHUNK, 8) and head_len < 128
    c = container.open_container(io.BytesIO(data), len(data), "f.moc", clip.skeleton)
    assert len(data) - head_len - len(c.read_chunk(0)) == 16
    two = moc.pack(long_walk[:64], get_codec("kinwave"), chunk_frames=32, embed_skeleton=False)
    version, flags, head_at, head_len = container.read_opening(io.BytesIO(two), len(two), "f.moc")
    c = container.open_container(io.BytesIO(two), len(two), "f.moc", long_walk.skeleton)
    assert flags == 0 and len(c.index) == 2
    bodies = sum(len(c.read_chunk(k)) for k in range(2))
    index = 1 + 2 * 3 + 4  # a count, each chunk's frames and bytes, a CRC
    assert len(two) - head_len - bodies == head_at + 4 + 2 * 6 + index + 8


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
    assert data[4:6] == bytes([3, 0])  # .moc version 3
    for version in (0, 4):
        with pytest.raises(CorruptStreamError, match=f"version {version}; this mocodec reads versions 1, 2, 3"):
            moc.unpack(data[:4] + bytes([version, 0]) + data[6:])
    with pytest.raises(CorruptStreamError, match="flags 0x0007 at byte 6 set bits version 3 does not define"):
        moc.unpack(data[:6] + bytes([data[6] | 4]) + data[7:])
    old = moc.pack(walk_bvh[:8], get_codec("raw"), chunk_frames=4)
    version_2 = data[:4] + bytes([2, 0]) + old[6:]  # version 2 knows no flag 1 (one chunk)
    with pytest.raises(CorruptStreamError, match="set bits version 2 does not define"):
        moc.unpack(version_2[:6] + bytes([3, 0]) + version_2[8:])
