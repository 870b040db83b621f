"""The codec registry and knobs, and the reference codecs (what every codec promises:
conformance.py)."""

from __future__ import annotations

import numpy as np
import pytest

import stepcodec  # noqa: F401  (registers test-step)
from mocodec.codecs import codec_class, codec_from_config, codec_ids, get_codec
from mocodec.errors import CodecError, CorruptStreamError


def test_registry_and_knobs():
    assert {"raw", "lossless"} <= set(codec_ids())
    with pytest.raises(CodecError, match="unknown codec 'nope'"):
        get_codec("nope")
    with pytest.raises(CodecError, match="unknown knob"):
        get_codec("raw", levels=3)
    codec = get_codec("test-step", step="0.5")
    assert codec.config == {"step": 0.5}
    with pytest.raises(CodecError, match="outside"):
        get_codec("test-step", step=1000)
    with pytest.raises(CodecError, match="expected float"):
        get_codec("test-step", step="fine")
    assert codec_from_config(codec.get_config()).config == codec.config
    with pytest.raises(CodecError):
        codec_class("raw").from_config({"codec": "lossless"})


@pytest.mark.parametrize("cid", ["raw", "lossless"])
def test_reference_codecs_round_trip(cid, walk_bvh, walk_amc):
    for motion in (walk_bvh, walk_amc, walk_amc[:1], walk_amc[:0]):
        codec = get_codec(cid)
        decoded = codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps)
        assert decoded.channels.shape == motion.channels.shape and decoded.fps == motion.fps
        if cid == "lossless":
            assert np.array_equal(decoded.channels, motion.channels)
        else:
            assert np.array_equal(decoded.channels, motion.channels.astype(np.float32).astype(np.float64))


def test_lossless_is_exact_on_awkward_values(walk_amc):
    rng = np.random.default_rng(0)
    ch = walk_amc.channels.copy()
    ch[:, 0] = rng.normal(size=len(ch))  # full-precision floats
    ch[::7, 1] = 1e-300  # exceptions inside a decimal channel
    ch[:, 2] = np.round(rng.normal(size=len(ch)) * 1e6)  # large integers
    ch[5, 3] = -0.0
    ch[:, 4] = 1e15 + np.arange(len(ch))
    motion = walk_amc.with_channels(ch)
    codec = get_codec("lossless")
    assert np.array_equal(
        codec.decode(codec.encode(motion), motion.skeleton, motion.num_frames, motion.fps).channels, ch
    )


def test_lossless_compresses_real_clips(walk_bvh, walk_amc):
    for motion in (walk_bvh, walk_amc):
        assert len(get_codec("lossless").encode(motion)) < 0.8 * len(get_codec("raw").encode(motion))


def test_raw_streams_frame_by_frame(walk_amc):
    codec = get_codec("raw")
    enc, dec = codec.encoder(walk_amc.skeleton, walk_amc.fps), codec.decoder(walk_amc.skeleton, walk_amc.fps)
    got = [dec.push(p) for k in range(0, 40, 7) for p in enc.push(walk_amc.channels[k : k + 7])]
    assert np.allclose(np.concatenate(got), walk_amc.channels[:42], atol=1e-4)
    with pytest.raises(CorruptStreamError):
        dec.push(b"\x00" * 5)
    with pytest.raises(CodecError, match="does not stream"):
        get_codec("lossless").encoder(walk_amc.skeleton, 120.0)
