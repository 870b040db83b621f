"""The numcodecs codec: registered by entry point, chunks within the bound, a zarr array that
reads back on its own, hostile chunks and configs refused."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mocodec.errors import CorruptStreamError
from mocodec.motion import Motion

numcodecs = pytest.importorskip("numcodecs")
from mocodec.numcodecs import Kinwave  # noqa: E402 - after the skip


def _max_joint_error_cm(skeleton, fps, a, b) -> float:
    pa = Motion(skeleton, fps, np.asarray(a, float)).positions_m()
    pb = Motion(skeleton, fps, np.asarray(b, float)).positions_m()
    return float(np.linalg.norm(pa - pb, axis=2).max() * 100)


def _read_in_a_new_process(tmp_path, codec_expression: str) -> tuple[str, np.ndarray]:
    """``tmp_path/walk.zarr`` read by a new Python process: what ``codec_expression`` (of the
    opened array ``a``) gives there, and the array's values."""
    script = (
        "import sys, numpy as np, zarr; a = zarr.open_array(sys.argv[1]); "
        f"print({codec_expression}); np.save(sys.argv[2], a[:])"
    )
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "walk.zarr"), str(tmp_path / "back.npy")],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip(), np.load(tmp_path / "back.npy")


def test_numcodecs_finds_the_codec_by_its_id(walk_bvh):
    config = Kinwave.for_motion(walk_bvh, max_error_cm=1.0).get_config()
    codec = numcodecs.get_codec(dict(config))
    assert isinstance(codec, Kinwave) and codec.get_config() == config
    assert codec.skeleton.difference(walk_bvh.skeleton) is None


@pytest.mark.parametrize("dtype", ["<f4", "<f8"])
def test_a_chunk_decodes_within_the_bound(walk_bvh, dtype):
    codec = Kinwave.for_motion(walk_bvh, dtype=dtype, max_error_cm=1.0)
    chunk = walk_bvh.channels[:200].astype(dtype)
    encoded = codec.encode(chunk)
    decoded = codec.decode(encoded)
    assert decoded.dtype == np.dtype(dtype) and decoded.shape == chunk.shape and decoded.flags["C_CONTIGUOUS"]
    assert _max_joint_error_cm(walk_bvh.skeleton, walk_bvh.fps, chunk, decoded) <= 1.0
    assert len(encoded) < chunk.nbytes / 20
    out = np.empty_like(chunk)
    codec.decode(encoded, out=out)
    assert np.array_equal(out, decoded)
    assert codec.encode(chunk.ravel()) == encoded  # a flat chunk of whole frames is the same


def test_a_zarr_array_of_a_clip_reads_back_on_its_own(walk_bvh, tmp_path):
    zarr = pytest.importorskip("zarr")
    codec = Kinwave.for_motion(walk_bvh, max_error_cm=1.0)
    channels = walk_bvh.num_channels
    array = zarr.create_array(
        store=str(tmp_path / "walk.zarr"),
        shape=walk_bvh.channels.shape,
        chunks=(128, channels),
        dtype="f4",
        compressors=codec,
        zarr_format=2,
    )
    array[:] = walk_bvh.channels.astype("f4")
    stored = sum(p.stat().st_size for p in (tmp_path / "walk.zarr").iterdir() if p.name[0].isdigit())
    assert stored < walk_bvh.channels.astype("f4").nbytes / 20
    # a new process: the codec comes from the array's metadata through numcodecs' entry point
    found, back = _read_in_a_new_process(tmp_path, "type(a.metadata.compressor).__name__")
    assert found == "Kinwave"
    assert _max_joint_error_cm(walk_bvh.skeleton, walk_bvh.fps, walk_bvh.channels.astype("f4"), back) <= 1.0


def test_a_zarr_format_3_array_reads_back_on_its_own(walk_bvh, tmp_path):
    zarr = pytest.importorskip("zarr")
    from mocodec.zarr3 import Kinwave as Serializer

    array = zarr.create_array(
        store=str(tmp_path / "walk.zarr"),
        shape=walk_bvh.channels.shape,
        chunks=(128, walk_bvh.num_channels),
        dtype="f8",
        serializer=Serializer.for_motion(walk_bvh, max_error_cm=0.5),
        compressors=None,
    )
    array[:] = walk_bvh.channels
    found, back = _read_in_a_new_process(tmp_path, "type(a.metadata.codecs[0]).__module__")
    assert found == "mocodec.zarr3"  # found through zarr's entry point
    assert back.dtype == np.float64
    assert _max_joint_error_cm(walk_bvh.skeleton, walk_bvh.fps, walk_bvh.channels, back) <= 0.5


def test_damaged_chunks_and_configs_are_refused(walk_bvh):
    codec = Kinwave.for_motion(walk_bvh, max_error_cm=1.0)
    encoded = bytearray(codec.encode(walk_bvh.channels[:64]))
    encoded[len(encoded) // 2] ^= 0x10
    with pytest.raises(CorruptStreamError, match="CRC-32"):
        codec.decode(bytes(encoded))
    with pytest.raises(CorruptStreamError, match="too short"):
        codec.decode(b"\x01")
    config = codec.get_config()
    for key, value, message in (
        ("skeleton", "not base64!", "base64"),
        ("fps", float("inf"), "fps"),
        ("dtype", "<i4", "float"),
        ("knobs", {"max_error_cm": [1]}, "knobs"),
    ):
        with pytest.raises(CorruptStreamError, match=message):
            numcodecs.get_codec({**config, key: value})
    with pytest.raises(ValueError, match="every channel"):
        codec.encode(walk_bvh.channels[:10, :5])


def test_without_numcodecs_the_import_names_the_extra():
    script = (
        "import sys; sys.modules['numcodecs'] = None\n"
        "try:\n    import mocodec.numcodecs\nexcept Exception as e:\n    print(e)"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert "pip install 'mocodec[zarr]'" in done.stdout


@pytest.mark.parametrize(
    "key, value",
    [
        ("fps", [120]),
        ("fps", 10**400),
        ("fps", 1e-300),
        ("dtype", "zz"),
        ("dtype", "(2,)<f4"),
        ("dtype", ["<f4"]),
        ("knobs", "max_error_cm=1"),
        ("knobs", {"effort": 2**70}),
        ("chunk_frames", -1),
        ("chunk_frames", 1.5),
        ("frames", 64),
    ],
)
def test_a_config_of_a_wrong_type_is_a_mocodec_error(walk_bvh, key, value):
    config = Kinwave.for_motion(walk_bvh, max_error_cm=1.0).get_config()
    with pytest.raises(CorruptStreamError, match="mocodec.kinwave config"):
        numcodecs.get_codec({**config, key: value})


def test_a_chunk_decodes_to_its_arrays_chunk_shape_or_is_refused(walk_bvh):
    """A 341-byte chunk could say 254,000 frames and decode to 1.56 GB for a chunk of 128; now
    the frame count is checked against the chunk's before anything is decoded."""
    codec = Kinwave.for_motion(walk_bvh, max_error_cm=1.0, chunk_frames=128)
    assert Kinwave.from_config(codec.get_config()).chunk_frames == 128
    long = codec.encode(walk_bvh.channels[:256])
    with pytest.raises(CorruptStreamError, match="256 frames, but its array's chunks have 128"):
        codec.decode(long)
    with pytest.raises(CorruptStreamError, match="256 frames, but its array's chunks have 64"):
        codec.decode(long, out=np.zeros((64, walk_bvh.num_channels), dtype="f4"))
    plain = Kinwave.for_motion(walk_bvh, max_error_cm=1.0)
    with pytest.raises(CorruptStreamError, match="256 frames, but its array's chunks have 100"):
        plain.decode(long, frames=100)  # a zarr format 3 chunk's shape
    assert plain.decode(long, out=np.zeros((256, walk_bvh.num_channels), dtype="f4")).shape == (256, 132)
