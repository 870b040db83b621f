"""Hostile files, second round (docs/security.md): crafted glTF, FBX, .moc and JSON that once
cost time or memory out of proportion to their size, or ended in a traceback. Each input runs
in a child process with an address-space limit and a deadline far above what the reader needs
now and far below what it once took (:func:`bounded`): a reader that is quadratic again, or
allocates without bound, fails the test; no timing is asserted."""

from __future__ import annotations

import io
import json
import zlib

import numpy as np
import pytest

from fbx_chain import chain_fbx
from gltf_builder import chain_glb
from mocodec import limits, load, moc, sandbox, save
from mocodec.cli import main
from mocodec.codecs import get_codec
from mocodec.errors import CorruptStreamError, FormatError, MocodecError
from mocodec.formats import container, gltf, nodetree
from test_hostile import crafted_moc

LIMIT_BYTES = 1 << 30  # what any of these may take, at most


def _outcome(path: str) -> str:
    """What loading ``path`` gives: "ok", or the error's message."""
    try:
        load(path)
    except MocodecError as e:
        return str(e)
    return "ok"


def bounded(path, seconds: float = 60.0) -> str:
    """:func:`_outcome` in a child of at most LIMIT_BYTES that must finish within ``seconds``."""
    try:
        return sandbox.call_isolated(_outcome, str(path), what=str(path), memory_bytes=LIMIT_BYTES, timeout_s=seconds)
    except CorruptStreamError as e:  # the child ran out of time or memory
        pytest.fail(f"{path}: {e}")


# ----- 2: node chains: linear in time and memory, depth checked before the work ------------------
def test_a_deep_glb_chain_is_refused_at_once_and_a_long_one_loads(tmp_path):
    """A 0.5 MB .glb chain 8,000 deep took 39 s and 1.37 GB (16,000: over 60 s), quadratic in
    the cycle check and in parsing every node through pygltflib."""
    (tmp_path / "deep.glb").write_bytes(chain_glb(16_000).glb())
    assert f"past {limits.MAX_DEPTH}" in bounded(tmp_path / "deep.glb", 30)
    (tmp_path / "long.glb").write_bytes(chain_glb(3_000).glb())
    assert bounded(tmp_path / "long.glb", 60) == "ok"


def test_a_deep_fbx_chain_is_refused_before_sampling(tmp_path):
    """An FBX chain 8,000 deep took 17.5 s and 1.24 GB, then crashed its child (FBX is read in
    a child of its own, with its own limits: no :func:`bounded` around it)."""
    (tmp_path / "deep.fbx").write_text(chain_fbx(8_000))
    with pytest.raises(FormatError, match=f"past {limits.MAX_DEPTH}"):
        load(tmp_path / "deep.fbx")
    (tmp_path / "chain.fbx").write_text(chain_fbx(200))
    motion = load(tmp_path / "chain.fbx")
    assert len(motion.skeleton) == 200 and motion.num_frames > 1


def test_a_cycle_is_found_however_long():
    parents = np.arange(-1, 4999)
    parents[0] = 4999  # a ring of 5,000: no root
    assert nodetree.tree_problem(parents) == "node 0 is in a cycle of children"
    parents[0] = -1
    assert nodetree.tree_problem(parents) == f"node 4999 is 4999 deep, past {limits.MAX_DEPTH}"
    assert nodetree.tree_problem(parents[: limits.MAX_DEPTH]) is None


# ----- 3, 5: glTF memory bounded by the file, counts checked before the parse ------------------------
def test_channels_that_share_an_accessor_convert_it_once(tmp_path, monkeypatch):
    """A 5.3 MB file took 3.46 GB: every channel converted the shared accessor again."""
    g = chain_glb(40)
    times = g.array(np.linspace(0, 10, 3000), "SCALAR")
    values = g.array(np.tile([0, 0, 0, 1.0], (3000, 1)), "VEC4")
    animation = g.doc["animations"][0]
    animation["samplers"] = [{"input": times, "output": values}]
    animation["channels"] = [{"sampler": 0, "target": {"node": k, "path": "rotation"}} for k in range(40)] * 50
    (tmp_path / "shared.glb").write_bytes(g.glb())
    converted = []
    convert = gltf.Document.convert
    monkeypatch.setattr(gltf.Document, "convert", lambda doc, i, what: converted.append(i) or convert(doc, i, what))
    assert load(tmp_path / "shared.glb").num_frames > 1
    assert sorted(converted) == [times, values]


def test_an_accessor_without_data_cannot_declare_more_than_the_file_holds(tmp_path):
    """A 404-byte file once peaked at 824 MB, and a 2.2 KB one ended in a MemoryError."""
    g = chain_glb(2)
    for _ in range(8):
        g.doc["accessors"].append({"componentType": 5126, "count": 8_000_000, "type": "VEC4"})
    animation = g.doc["animations"][0]
    animation["samplers"] = [{"input": 0, "output": 2 + k} for k in range(8)]
    animation["channels"] = [{"sampler": k, "target": {"node": 0, "path": "rotation"}} for k in range(8)]
    (tmp_path / "zeros.glb").write_bytes(g.glb())
    assert "more than the file's size allows" in bounded(tmp_path / "zeros.glb", 30)


def test_a_glb_with_too_many_nodes_is_refused_before_the_parse(tmp_path):
    """100k nodes in 2 MB were refused after 32.6 s, once pygltflib had parsed them all."""
    g = chain_glb(2)
    g.doc["nodes"] += [{"name": "x"}] * 100_000
    (tmp_path / "many.glb").write_bytes(g.glb())
    assert "100002 nodes, more than a skeleton may have" in bounded(tmp_path / "many.glb", 20)


# ----- 7: FBX takes checked before sampling ------------------------------------------------------------
def test_a_long_fbx_take_is_refused_before_sampling(tmp_path):
    """A 1.7 KB ASCII file with a 50,000 s take ran 40 s and reached 2 GiB before its error."""
    (tmp_path / "long.fbx").write_text(chain_fbx(3, take_s=50_000))
    with pytest.raises(FormatError, match=f"past {limits.MAX_NODE_FRAMES} to evaluate; give a lower fps"):
        load(tmp_path / "long.fbx")


# ----- 8: .moc chunks: the count follows the file's size ----------------------------------------------------
def test_a_moc_index_cannot_claim_more_chunks_than_its_bytes_hold(walk_bvh):
    """20,000 chunks in 300 KB took 23 s to decode; a chunk is at least MIN_CHUNK_BYTES, so an
    index may not claim more than its file's chunk bytes can hold."""
    data = moc.pack(walk_bvh[:20], get_codec("raw"), chunk_frames=1)
    c = container.open_container(io.BytesIO(data), len(data), "x")
    index_at = c.index[-1].offset + c.index[-1].size
    raw = bytes([0x80, 0x80, 0x04])  # 65,536 chunks
    forged = data[:index_at] + raw + zlib.crc32(raw).to_bytes(4, "little")
    forged += container.FOOTER.pack(len(raw) + 4, container.FOOTER_MAGIC)
    with pytest.raises(CorruptStreamError, match="65536 chunks do not fit in"):
        moc.unpack(forged)


# ----- 9, 10: tracebacks and messages ----------------------------------------------------------------------
def test_deep_json_is_a_one_line_error(tmp_path, walk_bvh):
    g = chain_glb(2)
    g.doc["asset"]["extras"] = json.loads("[" * 900 + "]" * 900)
    text = json.dumps(g.doc)
    (tmp_path / "deep.gltf").write_text(text.replace('"extras": [', '"extras": ' + "[" * 8000, 1))
    with pytest.raises(FormatError, match="nested too deep|not JSON"):
        load(tmp_path / "deep.gltf")
    header = json.dumps({"codec": {"codec": "raw"}, "deep": "X"}).replace('"X"', "[" * 8000 + "]" * 8000)
    head = zlib.compress(header.encode())
    start = container.opening(container.VERSION, 0, len(head))
    data = start + head + zlib.crc32(head).to_bytes(4, "little") + b"\0" * 16
    with pytest.raises(CorruptStreamError, match="does not parse"):
        moc.unpack(data)


@pytest.mark.parametrize(
    "codec, why",
    [
        ({"codec": "raw", "knobs": [1, 2]}, "knobs must be an object"),
        ({"codec": "kinwave", "knobs": {"effort": 2**70}}, "knob effort: 1180591620717411303424 is outside"),
        ({"codec": ["raw"]}, "must be an object naming a codec"),
    ],
)
def test_info_and_decode_of_hostile_knobs_are_one_line_errors(tmp_path, walk_bvh, capsys, codec, why):
    (tmp_path / "k.moc").write_bytes(crafted_moc(walk_bvh.skeleton, codec, 10))
    for command in (["info", str(tmp_path / "k.moc")], ["decode", str(tmp_path / "k.moc"), "-o", "x.bvh"]):
        if command[0] == "info" and "effort" in why:  # a shape that is right: info shows it
            assert main(command) == 0
            continue
        assert main(command) == 2
        err = capsys.readouterr().err
        assert why in err and str(tmp_path / "k.moc") in err and "Traceback" not in err


@pytest.mark.parametrize("fps", [1e-300, 0.0, 1e5])
def test_a_frame_rate_out_of_range_is_refused_everywhere(walk_bvh, fps):
    with pytest.raises(CorruptStreamError, match="fps"):
        moc.unpack(crafted_moc(walk_bvh.skeleton, {"codec": "raw"}, 10, fps=fps))


@pytest.mark.parametrize(
    "edit, why",
    [
        (lambda d: d["nodes"][1].update(translation=[10**400, 0, 0]), "an integer of 401 digits"),
        (lambda d: d["nodes"][1]["extras"]["mocodec"].update(offset=[10**30, 0, 0]), "an integer of 31 digits"),
        (lambda d: d["nodes"][1].update(rotation=[1e400, 0, 0, 1]), "node 1 rotation: expected 4 finite numbers"),
    ],
)
def test_gltf_errors_name_the_file(tmp_path, walk_bvh, edit, why):
    """A huge integer once ended in an OverflowError traceback."""
    save(walk_bvh[:3], tmp_path / "walk.gltf")
    doc = json.loads((tmp_path / "walk.gltf").read_text())
    edit(doc)
    (tmp_path / "bad.gltf").write_text(json.dumps(doc).replace("Infinity", "1e400"))
    with pytest.raises(FormatError, match=why) as caught:
        load(tmp_path / "bad.gltf")
    assert str(caught.value).startswith(str(tmp_path / "bad.gltf"))


def test_a_forged_joint_layout_in_gltf_extras_is_ignored(tmp_path, walk_bvh):
    """A rotation order that is not one (in mocodec's extras) once ended in a ValueError
    traceback; the node's own transform is read instead."""
    save(walk_bvh[:3], tmp_path / "walk.gltf")
    doc = json.loads((tmp_path / "walk.gltf").read_text())
    doc["nodes"][1]["extras"]["mocodec"].update(axis_order="QQ", axis=[1, 2, 3])
    (tmp_path / "forged.gltf").write_text(json.dumps(doc))
    motion = load(tmp_path / "forged.gltf")
    np.testing.assert_allclose(motion.positions(), load(tmp_path / "walk.gltf").positions(), atol=1e-4)
