"""SZ3 as the earlier benchmarks count it: the bytes SZ3 itself produces per channel, without
the container and the 4-byte part lengths the ``sz3`` codec adds."""

from __future__ import annotations

import numpy as np

from mocodec import Motion
from mocodec.codecs import get_codec
from mocodec.coding.entropy.parts import split_parts


def sz3_per_channel(motion: Motion, bound: float) -> tuple[int, np.ndarray]:
    """SZ3 (pysz) on each channel of the continuous angles with one absolute bound (degrees;
    cm for translations): (compressed bytes, decoded channels)."""
    codec = get_codec("sz3", bound=bound)
    body = codec._encode(motion)
    size = sum(len(p) for p in split_parts(body, motion.skeleton.num_channels, "sz3"))
    return size, codec._decode(body, motion.skeleton, motion.num_frames, motion.fps)
