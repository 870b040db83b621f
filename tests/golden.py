"""Golden fixtures, numcodecs-style: for every codec, a config, the encoded bytes of a short
CMU test clip and its decoded output, in ``tests/fixtures/<codec>/``. ``test_golden.py``
checks that the stored bytes decode to the stored output bit for bit and that encoding the
input again gives the same bytes: the formats are pinned.

The bytes are the codec's body (:meth:`Codec.encode`), what the container and the stream
packets frame.

Regenerate, after a deliberate format change only: ``python tests/golden.py [CODEC ...]``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

FIXTURES = Path(__file__).parent / "fixtures"
DATA = Path(__file__).parent / "data"

# codec id -> its knobs; the model-based codecs' models are trained on another subject and
# motion (the martial-arts clip) and stored beside the fixture
CONFIGS: dict[str, dict] = {
    "adpcm": {},
    "dct": {},
    "deadreckoning": {},
    "dpcm": {},
    "fpzip": {},
    "gesture": {},
    "hybrid": {},
    "kinwave": {"max_error_cm": 0.5, "error_measure": "shell", "effort": 3},
    "kinwave-live": {"max_error_cm": 1.0},
    "lossless": {},
    "posture": {},
    "primitives": {},
    "pwavelet": {},
    "quant": {},
    "raw": {},
    "rhythmic": {},
    "spiht": {"bits_per_second": 8000},
    "subband": {},
    "svq": {"size": 64},
    "sz3": {},
    "tvq": {"size": 64},
    "zfp": {},
    "zstd": {},
}
# further configurations pinned beside a codec's fixture: name -> knobs (files NAME.bin and
# NAME_decoded.npy), checked by the codec's own tests
VARIANTS: dict[str, dict[str, dict]] = {
    "kinwave": {"effort1": {"effort": 1}, "effort2": {"effort": 2}},
    "kinwave-live": {"layers3": {"layers": 3}},
}
MODEL_KNOB = {
    "gesture": "tables",
    "posture": "tables",
    "svq": "codebook",
    "tvq": "codebook",
    "primitives": "db",
    "rhythmic": "db",
}
# the baselines' libraries come with the [bench] extra
LIBRARY = {"fpzip": "fpzip", "sz3": "pysz", "zfp": "zfpy"}


def clip():
    """The fixtures' input: one second of a CMU walk (ASF/AMC, 120 fps, 62 channels)."""
    from mocodec import load

    return load(DATA / "07_03.amc")[:120]


def model_path(codec_id: str) -> Path:
    return FIXTURES / codec_id / "model.bin"


def train_model(codec_id: str, path: Path) -> None:
    """A small model for ``codec_id`` trained (seeded) on the martial-arts clip."""
    from mocodec import load
    from mocodec.codecs.model import motiontables
    from mocodec.codecs.motionprimitives import primdb, rhythmdb
    from mocodec.codecs.shared import vqbook

    martial = load(DATA / "135_08.amc")
    if codec_id in ("gesture", "posture"):
        model = motiontables.train([martial], spacing_cm=6.0, discard_deg=2.0, names=["135_08.amc"])
    elif codec_id in ("svq", "tvq"):
        model = vqbook.train(
            "spatial" if codec_id == "svq" else "temporal", [martial], [16, 32, 64], names=["135_08.amc"]
        )
    elif codec_id == "primitives":
        model = primdb.train([martial], max_clusters=16, names=["135_08.amc"])
    else:
        model = rhythmdb.train([martial], count=8, names=["135_08.amc"])
    model.save(path)


def codec(codec_id: str):
    """The fixture's configured codec (with its stored model)."""
    from mocodec.codecs import get_codec

    knobs = dict(CONFIGS[codec_id])
    if codec_id in MODEL_KNOB:
        knobs[MODEL_KNOB[codec_id]] = str(model_path(codec_id))
    return get_codec(codec_id, **knobs)


def write(codec_id: str) -> None:
    folder = FIXTURES / codec_id
    folder.mkdir(parents=True, exist_ok=True)
    if codec_id in MODEL_KNOB:
        train_model(codec_id, model_path(codec_id))
    c, motion = codec(codec_id), clip()
    body = c.encode(motion)
    decoded = c.decode(body, motion.skeleton, motion.num_frames, motion.fps, trusted=True).channels
    revision = {"revision": c.revision} if c.revision > 1 else {}
    (folder / "config.json").write_text(
        json.dumps(
            {"codec": codec_id, "knobs": CONFIGS[codec_id], **revision, "input": "07_03.amc frames 0-119"}, indent=1
        )
        + "\n"
    )
    (folder / "encoded.bin").write_bytes(body)
    np.save(folder / "decoded.npy", decoded)
    print(f"{codec_id}: {len(body):,} bytes")
    for name, knobs in VARIANTS.get(codec_id, {}).items():
        variant = type(c)(**{**CONFIGS[codec_id], **knobs})
        body = variant.encode(motion)
        decoded = variant.decode(body, motion.skeleton, motion.num_frames, motion.fps, trusted=True).channels
        (folder / f"{name}.bin").write_bytes(body)
        np.save(folder / f"{name}_decoded.npy", decoded)
        print(f"{codec_id} {name}: {len(body):,} bytes")


if __name__ == "__main__":
    from mocodec.codecs import codec_ids

    for cid in sys.argv[1:] or codec_ids():
        write(cid)
