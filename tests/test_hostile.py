"""Hostile files and streams (docs/security.md): each defect fuzzing found, with the input that
showed it. Every one must end in a clean mocodec error (or a safe result), never a crash,
a traceback, an unbounded allocation or a path opened on a file's say-so."""

from __future__ import annotations

import io
import json
import os
import re
import stat
import struct
import threading
import time
import warnings
import zlib

import numpy as np
import pytest

from conftest import DATA
from mocodec import limits, load, moc
from mocodec.cli import main
from mocodec.codecs import codec_from_untrusted, get_codec
from mocodec.codecs.perceptual.spihtlayout import PACKET
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.errors import CorruptStreamError, FormatError, MocodecError
from mocodec.formats import container
from mocodec.formats.asf import read_asf
from mocodec.formats.fileio import STALE_TEMP_S, atomic_write_bytes
from mocodec.formats.skeleton_bin import mirrors, pack_skeleton, unpack_skeleton
from mocodec.skeleton import Joint, Skeleton
from mocodec.stream.live import LiveDecoder, stream_clip
from mocodec.stream.packets import DATA as DATA_PACKET, Packet, StreamInfo


def crafted_moc(skeleton: Skeleton, codec: dict, frames: int, fps: float = 120.0, body: bytes = b"\0" * 8) -> bytes:
    """A .moc whose header says what a hostile writer wants (one chunk of ``frames``)."""
    header = {"codec": codec, "fps": fps, "frames": frames, "chunk_frames": max(frames, 1), "skeleton": skeleton}
    return container.pack(header, [container.Chunk(0, frames, body)])


def bomb(size: int) -> bytes:
    """A deflate stream of ``size`` zero bytes (a thousand to one)."""
    return zlib.compress(b"\0" * size, 9)


# ----- 1: a native decoder never sees unvalidated bytes in this process --------------------------
def test_damaged_fpzip_bodies_with_good_crcs_fail_cleanly(walk_bvh):
    pytest.importorskip("fpzip")
    codec = get_codec("fpzip")
    clip = walk_bvh[:64]
    body = codec.encode(clip)
    rng = np.random.default_rng(7)
    outcomes = set()
    for _ in range(12):
        damaged = bytearray(body)
        for at in rng.integers(0, len(body), 6):
            damaged[at] ^= int(rng.integers(1, 256))
        try:
            out = codec.decode(bytes(damaged), clip.skeleton, clip.num_frames, clip.fps)
            assert np.isfinite(out.channels).all()
            outcomes.add("decoded")
        except CorruptStreamError as e:
            outcomes.add("refused")
            assert "fpzip body" in str(e)
    assert "refused" in outcomes  # and this process is still here


# ----- 2, 3: stream headers ------------------------------------------------------------------------
def header_payload(doc: dict) -> bytes:
    return zlib.compress(json.dumps(doc).encode())


def good_header_doc(walk_bvh) -> dict:
    return json.loads(
        zlib.decompress(StreamInfo(walk_bvh.skeleton, 120.0, get_codec("dpcm").get_config()).to_payload())
    )


def test_a_packet_far_ahead_does_not_make_the_receiver_allocate(walk_bvh):
    packets = stream_clip(walk_bvh[:240], get_codec("dpcm"))
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
    for p in packets[1:4]:
        dec.push(p)
    p = packets[4]
    far = Packet(
        p.stream,
        p.sequence,
        p.timestamp_us,
        p.codec,
        2**32 - 200,
        p.frames,
        p.payload,
        DATA_PACKET,
        p.flags,
        p.position,
    )
    out = dec.push(far)  # np.repeat once asked for 4 TiB here
    assert len(out) <= dec.max_gap + p.frames


def test_a_stream_header_never_opens_a_file_it_names(walk_bvh, monkeypatch):
    from mocodec.codecs.motionprimitives.primdb import PrimitiveDB

    def refuse(path):
        raise AssertionError(f"opened {path}")

    monkeypatch.setattr(PrimitiveDB, "load", staticmethod(refuse))
    doc = good_header_doc(walk_bvh)
    doc["codec"] = {"codec": "primitives", "knobs": {"db": "/dev/zero"}}
    dec = LiveDecoder(StreamInfo.from_payload(header_payload(doc)))
    assert dec.codec.config["db"] == ""
    packets = stream_clip(walk_bvh[:120], get_codec("primitives"))
    for p in packets[1:]:
        dec.push(p)  # decodes (the stream needs no database), opens nothing


@pytest.mark.parametrize(
    "change, why",
    [
        (lambda d: d.update(codec={}), "codec config"),
        (lambda d: d.update(codec=[]), "codec config"),
        (lambda d: d.update(fps=float("nan")), "frame rate"),
        (lambda d: d.update(fps=1e8), "frame rate"),
        (lambda d: d.update(skeleton="x"), "skeleton"),
    ],
)
def test_malformed_stream_headers_are_refused(walk_bvh, change, why):
    doc = good_header_doc(walk_bvh)
    change(doc)
    with pytest.raises(CorruptStreamError, match=why):
        StreamInfo.from_payload(header_payload(doc))


@pytest.mark.parametrize("knobs", [[1, 2], "db=/dev/zero", {"levels": [1]}])
def test_knobs_that_are_not_an_object_of_scalars_are_refused(knobs):
    with pytest.raises(CorruptStreamError, match="knobs"):
        codec_from_untrusted({"codec": "dpcm", "knobs": knobs}, "stream header")


def test_a_deflate_bomb_header_is_refused_before_it_inflates():
    with pytest.raises(CorruptStreamError, match="inflates to over"):
        StreamInfo.from_payload(bomb(4 * limits.MAX_HEADER_TEXT))


# ----- 5: spiht packets whose cut table parses but whose parts do not --------------------------------
def test_a_spiht_packet_with_a_short_last_part_raises_a_mocodec_error(walk_bvh):
    codec = get_codec("spiht", bits_per_second=8000)
    packet = next(p for p in stream_clip(walk_bvh[:120], codec)[1:] if p.codec_payload)
    payload = packet.codec_payload
    parts = split_parts(payload, None, "spiht packet", start=PACKET.size)
    short = payload[: PACKET.size] + join_parts([*parts[:-1], b"\1\2"])
    with pytest.raises(CorruptStreamError, match="bit stream part"):
        codec.packet_cutter(short, walk_bvh.skeleton, np.zeros(0, np.int64), 120.0)(1000.0)


# ----- 6, 7, 8, 14: crafted .moc files ------------------------------------------------------------------
def test_a_moc_header_bomb_is_refused(walk_bvh):
    data = moc.pack(walk_bvh[:10], get_codec("raw"))
    _, flags, head_at, head_len = container.read_opening(io.BytesIO(data), len(data), "x")
    head = bomb(4 * limits.MAX_HEADER_TEXT)
    start = container.opening(container.VERSION, flags, len(head))
    forged = start + head + struct.pack("<I", zlib.crc32(head)) + data[head_at + head_len + 4 :]
    with pytest.raises(CorruptStreamError, match="inflates to over"):
        moc.unpack(forged)


@pytest.mark.parametrize("path", ["/dev/zero", "/dev/stdin", "/etc/passwd", "/no/such/file"])
def test_a_moc_never_opens_the_model_file_it_names(walk_amc, tmp_path, path):
    db = tmp_path / "db.mocdb"
    assert main(["model", "train", "primitives", str(DATA / "135_08.amc"), "-o", str(db)]) == 0
    coded = moc.pack(walk_amc[:200], get_codec("primitives", db=str(db)))
    c = container.open_container(io.BytesIO(coded), len(coded), "x")
    config = dict(c.header["codec"], knobs={**c.header["codec"]["knobs"], "db": path})
    forged = crafted_moc(c.skeleton, config, c.frames, c.fps, c.read_chunk(0))
    (tmp_path / "forged.moc").write_bytes(forged)
    with pytest.raises(MocodecError) as err:
        moc.decode(tmp_path / "forged.moc")
    assert "none is given (--db FILE)" in str(err.value) and path not in str(err.value)
    assert moc.decode(tmp_path / "forged.moc", local_files={"db": str(db)}).num_frames == 200


def test_crafted_index_and_knobs_raise_mocodec_errors(walk_bvh):
    sk = walk_bvh.skeleton
    with pytest.raises(CorruptStreamError, match="invalid"):
        moc.unpack(crafted_moc(sk, get_codec("raw").get_config(), 2**32))
    with pytest.raises(CorruptStreamError, match="knobs"):
        moc.unpack(crafted_moc(sk, {"codec": "raw", "knobs": [1]}, 10))
    with pytest.raises(CorruptStreamError):
        moc.unpack(crafted_moc(sk, {"codec": {}}, 10))


def test_declared_sizes_are_checked_before_anything_is_allocated(walk_bvh):
    sk = walk_bvh.skeleton
    claim = crafted_moc(sk, get_codec("kinwave").get_config(), 2**20)  # 2.6 KB claiming 2.3 GB once
    with pytest.raises(CorruptStreamError, match="--max-values"):
        moc.unpack(claim)
    with pytest.raises(CorruptStreamError, match="fps"):
        moc.unpack(crafted_moc(sk, get_codec("adpcm").get_config(), 10, fps=1e8))
    small = moc.pack(walk_bvh[:100], get_codec("raw"))
    with pytest.raises(CorruptStreamError, match="--max-values"):
        moc.unpack(small, max_values=99 * sk.num_channels)
    assert moc.unpack(small, max_values=100 * sk.num_channels).num_frames == 100


# ----- 15: decoded values are finite --------------------------------------------------------------------
def test_a_payload_that_decodes_to_nan_is_refused(walk_bvh):
    values = np.zeros((4, walk_bvh.skeleton.num_channels), "<f4")
    values[2, 5] = np.nan
    with pytest.raises(CorruptStreamError, match="frame 2"):
        get_codec("raw").decode(values.tobytes(), walk_bvh.skeleton, 4, 120.0)


def test_a_signalling_nan_gets_one_line_from_the_command_line(walk_bvh, tmp_path, capsys):
    """A float32 signalling NaN warns in numpy's cast to float64 before the finiteness check
    refuses it: the command line prints the refusal alone."""
    data = moc.pack(walk_bvh[:4], get_codec("raw"))
    _, _, head_at, head_len = container.read_opening(io.BytesIO(data), len(data), "x")
    body_at = head_at + head_len + 4
    body = b"\xff\xff\xbf\x7f" + data[body_at + 4 : -4]
    damaged = tmp_path / "snan.moc"
    damaged.write_bytes(data[:body_at] + body + struct.pack("<I", zlib.crc32(body)))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert main(["decode", str(damaged), "-o", str(tmp_path / "out.bvh")]) == 2
    assert not [w for w in seen if issubclass(w.category, RuntimeWarning)]
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "decodes to nan at frame 0" in err, err
    assert not (tmp_path / "out.bvh").exists()


# ----- 9, 12: writing files -------------------------------------------------------------------------------
def test_a_symlink_is_followed_and_modes_are_kept(tmp_path):
    target = tmp_path / "real.moc"
    target.write_bytes(b"old")
    os.chmod(target, 0o640)
    link = tmp_path / "link.moc"
    link.symlink_to(target)
    atomic_write_bytes(link, b"new")
    assert link.is_symlink() and target.read_bytes() == b"new"
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    old = os.umask(0o027)
    try:
        atomic_write_bytes(tmp_path / "fresh.moc", b"x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "fresh.moc").stat().st_mode) == 0o640


def test_a_fifo_is_written_through(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    atomic_write_bytes(fifo, b"through")
    reader.join(10)
    assert got == [b"through"] and stat.S_ISFIFO(fifo.stat().st_mode)


def test_a_link_to_a_descriptor_is_written_through(tmp_path):
    read_end, write_end = os.pipe()
    link = tmp_path / "out.moc"
    link.symlink_to(f"/proc/self/fd/{write_end}")
    try:
        atomic_write_bytes(link, b"to the pipe")
        os.close(write_end)
        assert os.read(read_end, 100) == b"to the pipe" and link.is_symlink()
    finally:
        os.close(read_end)


def test_a_live_packet_that_decodes_to_nan_is_concealed(walk_bvh):
    packets = stream_clip(walk_bvh[:60], get_codec("raw"))
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
    good = dec.push(packets[1])
    p = packets[2]
    values = np.frombuffer(p.payload, "<f4").copy()
    values[3] = np.inf
    out = dec.push(p.with_payload(values.tobytes()))
    assert np.isfinite(out).all() and dec.stats.dropped == 1 and len(good)


def test_stale_temporaries_are_removed_and_errors_name_the_target(tmp_path):
    stale, fresh = tmp_path / ".a.moc.abcd1234.tmp", tmp_path / ".b.moc.efgh5678.tmp"
    stale.write_bytes(b"")
    fresh.write_bytes(b"")
    old = time.time() - STALE_TEMP_S - 10
    os.utime(stale, (old, old))
    atomic_write_bytes(tmp_path / "c.moc", b"x")
    assert not stale.exists() and fresh.exists()
    with pytest.raises(FormatError, match=r"missing/out\.moc: cannot write: the directory"):
        atomic_write_bytes(tmp_path / "missing" / "out.moc", b"x")


# ----- 11, 13: parsers ----------------------------------------------------------------------------------------
ASF = (DATA / "07.asf").read_text()
AMC = (DATA / "07_03.amc").read_text()
BVH = (DATA / "07_03.bvh").read_text()


def chain_asf(bones: int) -> str:
    head = ASF.split(":bonedata")[0]
    blocks = "".join(
        f"  begin\n     id {i + 1}\n     name b{i}\n     direction 0 1 0\n     length 1\n"
        f"     axis 0 0 0 XYZ\n     dof rx ry rz\n  end\n"
        for i in range(bones)
    )
    links = "\n".join(["    root b0"] + [f"    b{i - 1} b{i}" for i in range(1, bones)])
    return f"{head}:bonedata\n{blocks}:hierarchy\n  begin\n{links}\n  end\n"


@pytest.mark.parametrize(
    "name, text, why",
    [
        ("ft.bvh", re.sub(r"Frame Time:\s*\S+", "Frame Time: 1e-320", BVH), "a frame rate outside"),
        ("slow.bvh", re.sub(r"Frame Time:\s*\S+", "Frame Time: 1e300", BVH), "a frame rate outside"),
        ("cycle.asf", chain_asf(3).replace("    b1 b2", "    b1 b2 root"), "root cannot be the child"),
        ("dof.asf", ASF.replace("dof rx ry rz", "dof rx rx rz", 1), "listed twice"),
        ("doft.asf", ASF.replace("dof rx ry rz", "dof tx tx", 1), "listed twice"),
        (
            "end.asf",
            ASF.replace(
                ":hierarchy",
                "  begin\n     id 99\n     name ltoes_end\n     direction 0 1 0\n"
                "     length 1\n     axis 0 0 0 XYZ\n  end\n:hierarchy",
            ).replace("lhumerus lradius", "lhumerus lradius ltoes_end"),
            "end site of leaf bone",
        ),
    ],
)
def test_malformed_skeletons_raise_format_errors(tmp_path, name, text, why):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(FormatError, match=why):
        load(path) if name.endswith(".bvh") else read_asf(path)


def test_a_thousand_bone_chain_loads(tmp_path):
    (tmp_path / "chain.asf").write_text(chain_asf(1000))
    sk = read_asf(tmp_path / "chain.asf")
    assert len(sk) == 1002 and sk.joints[-2].parent == 999


@pytest.mark.parametrize("frame", ["²", "9" * 4400, "٣"])
def test_odd_amc_frame_numbers_raise_format_errors(tmp_path, frame):
    (tmp_path / "x.amc").write_text(AMC.replace("\n1\n", f"\n{frame}\n", 1))
    with pytest.raises(FormatError, match=r"x\.amc:\d+: expected a frame number"):
        load(tmp_path / "x.amc", asf=DATA / "07.asf")


def test_many_end_sites_get_unique_names(tmp_path):
    ends = "".join("\tEnd Site\n\t{\n\t\tOFFSET 0 1 0\n\t}\n" for _ in range(50))
    (tmp_path / "e.bvh").write_text(
        "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 3 Xposition Yposition "
        f"Zposition\n{ends}}}\nMOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0\n"
    )
    names = load(tmp_path / "e.bvh").skeleton.names
    assert names[1:4] == ("Hips_end", "Hips_end2", "Hips_end3") and len(set(names)) == 51


def test_offset_mirrors_match_the_pairwise_search():
    rng = np.random.default_rng(3)
    base = [tuple(rng.integers(-2, 3, 3).astype(float)) for _ in range(40)]
    offsets = [tuple(-x if rng.random() < 0.3 else x for x in o) for o in base + base[::-1]] + [(0.0, -0.0, 0.0)]

    def pairwise(i):
        mine = struct.pack("<3d", *offsets[i])
        for k in range(i - 1, -1, -1):
            for signs in range(8):
                flipped = tuple(-x if signs >> a & 1 else x for a, x in enumerate(offsets[k]))
                if any(flipped) and struct.pack("<3d", *flipped) == mine:
                    return (i - k) << 3 | signs
        return 0

    assert mirrors(offsets) == [pairwise(i) for i in range(len(offsets))]
    sk = Skeleton([Joint(f"j{i}", i - 1, o) for i, o in enumerate(offsets)])
    assert unpack_skeleton(pack_skeleton(sk)).joints == sk.joints
