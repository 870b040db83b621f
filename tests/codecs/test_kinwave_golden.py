"""A whole .moc file pinned (container version 3, kinwave payload format 2: the rest pose, a
lead of 2 frames and fine turns in its more flags): a checked-in
file (a CMU walk re-expressed as another pipeline writes it: a MotionBuilder dummy root at
(0, -90, 0), a bind pose in frame 0, a proper Euler order on the legs) must decode to the
same channels, and encoding its input with the same settings must give the very same bytes.
The same file as container version 2 wrote it (an index and a footer after its one chunk) is
kept too, and must decode to the same channels.

Regenerate, after a deliberate format change only: ``PYTHONPATH=tests python tests/codecs/test_kinwave_golden.py``.
"""

from __future__ import annotations

import hashlib
import io

import numpy as np

from conftest import DATA  # noqa: E402
from mocodec import load, moc, reexpress
from mocodec.codecs import get_codec
from mocodec.codecs.kinwave.body import FINE_TURNS, LEAD_SHIFT, REST
from mocodec.formats import container
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors

GOLDEN = DATA / "kinwave_reexpressed.moc"
GOLDEN_V2 = DATA / "kinwave_reexpressed_v2.moc"  # (regenerating GOLDEN leaves it as it is)
KNOBS = {"max_error_cm": 0.5, "error_measure": "shell", "effort": 3}
DECODED_SHA256 = "25281ad3604ef833a7b0859384d818652808dba2227c0a1b084e754bd48520f8"


def _input():
    walk = load(DATA / "07_03.bvh")[:200]
    legs = {name: "XYX" for name in ("lThigh", "lShin", "rThigh", "rShin")}
    return reexpress.with_bind_frame(
        reexpress.with_dummy_root(reexpress.with_euler_orders(walk, legs), (0.0, -90.0, 0.0), position_channels=True)
    )


def _decoded_digest(data: bytes) -> str:
    return hashlib.sha256(np.ascontiguousarray(moc.unpack(data).channels).tobytes()).hexdigest()


def test_the_golden_file_decodes_to_the_same_channels_within_its_bound():
    data = GOLDEN.read_bytes()
    assert _decoded_digest(data) == DECODED_SHA256
    original, decoded = _input(), moc.unpack(data)
    assert decoded.skeleton.names == original.skeleton.names
    assert decoded.skeleton.channel_names == original.skeleton.channel_names
    sk, cm = original.skeleton, 100.0 / original.skeleton.units_per_metre
    p0, q0 = forward_kinematics(sk, original.channels)
    p1, q1 = forward_kinematics(decoded.skeleton, decoded.channels)
    assert shell_errors(sk, p0 * cm, q0, p1 * cm, q1).max <= KNOBS["max_error_cm"]
    assert data[4] == 3  # .moc version 3
    chunk = container.open_container(io.BytesIO(data), len(data), "golden").read_chunk(0)
    assert chunk[0] == 2 and chunk[6] == REST | 2 << LEAD_SHIFT | FINE_TURNS  # payload format 2


def test_the_version_2_golden_file_decodes_as_it_did():
    old = GOLDEN_V2.read_bytes()
    assert old[4] == 2 and old[-4:] == container.FOOTER_MAGIC
    assert _decoded_digest(old) == DECODED_SHA256
    files = (old, GOLDEN.read_bytes())
    chunks = [container.open_container(io.BytesIO(d), len(d), "golden").read_chunk(0) for d in files]
    # version 3: 3 bytes less of start, no chunk length (2 bytes), index (9) or footer (8), and
    # a header dictionary with the CMU skeletons' columns
    assert chunks[0] == chunks[1] and len(old) > len(GOLDEN.read_bytes()) + 22


def test_encoding_the_golden_input_gives_the_same_bytes():
    assert moc.pack(_input(), get_codec("kinwave", **KNOBS)) == GOLDEN.read_bytes()


if __name__ == "__main__":
    golden = moc.pack(_input(), get_codec("kinwave", **KNOBS))
    GOLDEN.write_bytes(golden)
    print(f"{GOLDEN}: {len(golden)} bytes, decoded sha256 {_decoded_digest(golden)}")
