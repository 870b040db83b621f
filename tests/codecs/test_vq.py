"""Vector quantisation (000 §7.9): LBG with diameter splitting, the codebook file, and the
svq and tvq coders with codebooks trained on other clips."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec import cli
from mocodec.codecs import get_codec
from mocodec.codecs.shared import vqbook
from mocodec.coding.quantisation import vq
from mocodec.errors import CodecError
from mocodec.metrics import compare


def test_lbg_finds_separated_clusters_and_keeps_every_size():
    rng = np.random.default_rng(3)
    centres = rng.normal(size=(8, 3)) * 10
    data = np.repeat(centres, 100, axis=0) + rng.normal(size=(800, 3)) * 0.1
    books = vq.lbg(data, [2, 8])
    assert sorted(books) == [2, 8] and books[2].shape == (2, 3)
    assert np.abs(books[8][:, None] - centres[None]).sum(axis=2).min(axis=0).max() < 0.1
    assert all(np.array_equal(a, b) for a, b in zip(vq.lbg(data, [2, 8]).values(), books.values()))
    # most used entries first
    use = np.bincount(vq.nearest(data, books[2]), minlength=2)
    assert use[0] >= use[1]
    assert len(vq.lbg(np.ones((10, 2)), [4])[4]) == 1  # one distinct point: one entry


def test_lbg_distortion_falls_with_size():
    data = np.random.default_rng(5).normal(size=(5000, 6))
    books = vq.lbg(data, [16, 64, 256])
    errors = [((data - b[vq.nearest(data, b)]) ** 2).sum(axis=1).mean() for b in books.values()]
    assert errors[0] > errors[1] > errors[2]


def test_temporal_closed_loop_rebuilds_code_vectors_exactly():
    # a signal made of code vectors (each relative to the sample before it) decodes exactly,
    # and the closed loop keeps later vectors exact however the earlier ones were rounded
    book = np.array([[0.0] * 6, [1, 2, 3, 4, 5, 6], [-1, -1, -2, -2, -3, -3.0]])
    choice = np.array([[1, 0], [2, 1], [0, 2], [1, 1]])
    x = np.zeros((4, 6, 2))
    prev = np.array([5.0, -5.0])
    start = prev.copy()
    for b in range(4):
        x[b] = prev + book[choice[b]].T
        prev = x[b, -1]
    codes = np.zeros((4, 2), dtype=np.int64)
    out = vq.run_temporal(x, codes, False, True, start.copy(), book)
    assert np.array_equal(codes, choice) and np.allclose(out, x)


def test_codebook_file_round_trip_and_damage(tmp_path, martial_amc):
    book = vqbook.train("temporal", [martial_amc.resample(30.0)], [16, 32], names=["135_08.amc"])
    path = tmp_path / "t.mocvq"
    book.save(path)
    again = vqbook.Codebook.load(path)
    assert again.fingerprint == book.fingerprint and again.trained_on == ["135_08.amc"]
    assert all(np.allclose(a, b, atol=1e-5) for a, b in zip(again.book(32), book.book(32)))
    data = path.read_bytes()
    (tmp_path / "cut.mocvq").write_bytes(data[:-9])
    with pytest.raises(CodecError, match="cut.mocvq: checksum mismatch"):
        vqbook.Codebook.load(tmp_path / "cut.mocvq")
    (tmp_path / "not.mocvq").write_bytes(b"hello world, not a codebook")
    with pytest.raises(CodecError, match="not a mocodec VQ codebook"):
        vqbook.Codebook.load(tmp_path / "not.mocvq")
    with pytest.raises(CodecError, match="sizes \\[16, 32\\], not 64"):
        again.book(64)


@pytest.mark.parametrize("cid", ("svq", "tvq"))
def test_trained_codebooks_code_held_out_clips(cid, walk_amc, codebooks):
    clip = walk_amc.resample(30.0)  # the codebooks were trained on another subject's clip
    results = {}
    for predictive in (False, True):
        for size in (16, 256):
            codec = get_codec(cid, size=size, predictive=predictive, codebook=codebooks[cid, predictive])
            payload = codec.encode(clip)
            results[predictive, size] = (
                len(payload),
                compare(clip, codec.decode(payload, clip.skeleton, clip.num_frames, clip.fps)).summary()["psnr_db"],
            )
    for predictive in (False, True):
        assert results[predictive, 16][0] < results[predictive, 256][0]
        assert results[predictive, 16][1] < results[predictive, 256][1]
    assert results[True, 256][1] > results[False, 256][1] + 3  # the closed loop's gain
    inband = get_codec(cid, size=256).encode(clip)
    assert len(inband) > results[True, 256][0]  # a shared codebook costs nothing


def test_payload_names_its_codebook(walk_amc, codebooks):
    clip = walk_amc.resample(30.0)
    payload = get_codec("tvq", codebook=codebooks["tvq", True]).encode(clip)
    with pytest.raises(CodecError, match="give the file with --codebook"):
        get_codec("tvq").decode(payload, clip.skeleton, clip.num_frames, clip.fps)
    with pytest.raises(CodecError, match="was trained with predictive=True"):
        get_codec("tvq", predictive=False, codebook=codebooks["tvq", True]).encode(clip)
    with pytest.raises(CodecError, match="is a temporal codebook"):
        get_codec("svq", codebook=codebooks["tvq", True]).encode(clip)


def test_spatial_codebook_needs_its_channel_layout(walk_bvh, codebooks):
    with pytest.raises(CodecError, match="do not match this skeleton's channels"):
        get_codec("svq", codebook=codebooks["svq", True]).encode(walk_bvh[:60])


def test_hand_groups_on_a_skeleton_with_fingers(walk_bvh):
    groups = dict(vqbook.spatial_groups(walk_bvh.skeleton))
    assert len(groups["left_hand"]) == 30 and len(groups["root_position"]) == 3
    clip = walk_bvh.resample(30.0)
    codec = get_codec("svq", size=16)
    decoded = codec.decode(codec.encode(clip), clip.skeleton, clip.num_frames, clip.fps)
    assert compare(clip, decoded).summary()["psnr_db"] > 15


def test_cli_trains_encodes_and_decodes_with_a_codebook(tmp_path, capsys):
    from tests.conftest import DATA

    book = tmp_path / "t.mocvq"
    assert (
        cli.main(
            [
                "model",
                "train",
                "codebook",
                "--vectors",
                "temporal",
                "--max-size",
                "64",
                str(DATA / "135_08.amc"),
                "-o",
                str(book),
            ]
        )
        == 0
    )
    assert cli.main(["model", "info", str(book)]) == 0
    assert "sizes [16, 32, 64]" in capsys.readouterr().out
    moc = tmp_path / "w.moc"
    assert (
        cli.main(
            [
                "encode",
                str(DATA / "07_03.amc"),
                "-o",
                str(moc),
                "--codec",
                "tvq",
                "--size",
                "64",
                "--codebook",
                str(book),
            ]
        )
        == 0
    )
    moved = tmp_path / "elsewhere.mocvq"
    book.rename(moved)
    out = tmp_path / "w.bvh"
    assert cli.main(["decode", str(moc), "-o", str(out)]) == 2  # the file has moved
    assert "codebook" in capsys.readouterr().err
    assert cli.main(["decode", str(moc), "-o", str(out), "--codebook", str(moved)]) == 0
    assert out.exists()
    assert cli.main(["model", "train", "codebook", str(DATA / "07_03.amc"), "-o", str(book), "--max-size", "100"]) == 2
