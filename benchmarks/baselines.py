"""Generic float compressors that benchmarks compare our codecs with."""

from __future__ import annotations

import numpy as np
from pysz import sz, szConfig, szErrorBoundMode

from mocodec import Motion


def sz3_per_channel(motion: Motion, bound: float) -> tuple[int, np.ndarray]:
    """SZ3 (pysz) on each channel of the continuous angles with one absolute bound (degrees;
    cm for translations): (compressed bytes, decoded channels)."""
    sk = motion.skeleton
    scale = np.where(sk.rotation_mask, 1.0, sk.units_per_metre / 100.0)
    data = motion.continuous().channels.astype(np.float32)
    size, out = 0, np.empty_like(motion.channels)
    for c in range(data.shape[1]):
        cfg = szConfig()
        cfg.errorBoundMode = szErrorBoundMode.ABS
        cfg.absErrorBound = float(bound * scale[c])
        comp, _ = sz.compress(np.ascontiguousarray(data[:, c]), cfg)
        size += len(comp)
        out[:, c] = sz.decompress(comp, np.float32, (len(data),))[0]
    return size, out
