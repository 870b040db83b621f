"""Every codec's format pinned by its golden fixture (tests/golden.py): the stored bytes decode
to the stored output (to the last bits that the platform's sin, cos and arctan2 leave open:
numpy picks their SIMD loops by the CPU's instruction set, and one AVX-512 machine decoded the
primitives fixture 1 ulp away in 90 of 7,440 values), and encoding the stored input again gives
the same bytes."""

from __future__ import annotations

import json

import numpy as np
import pytest

import golden
from mocodec.codecs import codec_class, codec_ids


@pytest.fixture(scope="module")
def clip():
    return golden.clip()


def _skip_without_library(codec_id: str) -> None:
    if codec_id in golden.LIBRARY:
        pytest.importorskip(golden.LIBRARY[codec_id])


def test_every_codec_has_a_fixture():
    built_in = [c for c in codec_ids() if codec_class(c).__module__.startswith("mocodec.")]
    assert sorted(golden.CONFIGS) == built_in
    assert sorted(p.name for p in golden.FIXTURES.iterdir() if p.is_dir()) == built_in


@pytest.mark.parametrize("codec_id", sorted(golden.CONFIGS))
def test_fixture_decodes_to_its_output(codec_id, clip):
    _skip_without_library(codec_id)
    folder = golden.FIXTURES / codec_id
    config = json.loads((folder / "config.json").read_text())
    assert config["knobs"] == golden.CONFIGS[codec_id]
    codec = golden.codec(codec_id)
    assert config.get("revision", 1) == codec.revision  # a new revision comes with new fixtures
    stored = (folder / "encoded.bin").read_bytes()
    decoded = codec.decode(stored, clip.skeleton, clip.num_frames, clip.fps).channels
    expected = np.load(folder / "decoded.npy")
    assert decoded.dtype == expected.dtype
    np.testing.assert_allclose(decoded, expected, rtol=1e-14, atol=1e-12)


@pytest.mark.parametrize("codec_id", sorted(golden.CONFIGS))
def test_fixture_input_encodes_to_the_same_bytes(codec_id, clip):
    _skip_without_library(codec_id)
    stored = (golden.FIXTURES / codec_id / "encoded.bin").read_bytes()
    assert golden.codec(codec_id).encode(clip) == stored
