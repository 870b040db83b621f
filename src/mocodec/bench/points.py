"""The operating points a benchmark measures each codec at: a sweep of its quality knob, or
rate-controlled targets (compression ratio, bit rate, max joint error).

Sweeps cover the range where each codec is worth looking at on 30-120 fps human motion (and
where its coding time stays reasonable: VQ codebooks of 256 entries at most); error targets
are searched in the same range, so "unreachable" means "not within it"; ratio and bit-rate
targets over the knob's whole range. A codec missing from :data:`SWEEPS` (a plug-in) is swept
over its knob's own range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mocodec.codecs import Codec, codec_class
from mocodec.errors import CodecError

KINDS = ("knob", "error", "ratio", "bitrate")
DEFAULT_KINDS = ("knob", "error")
DEFAULT_ERRORS_CM = (0.1, 1.0)  # max joint error targets: the headline levels
DEFAULT_RATIOS = (10.0, 20.0, 40.0, 60.0, 80.0, 100.0)
DEFAULT_BITRATES = (2000.0, 8000.0, 32000.0)
SWEEP_POINTS = 5

# codec id -> (low, high) of its quality knob in a sweep
SWEEPS: dict[str, tuple[float, float]] = {
    "adpcm": (4, 256),
    "dct": (0.125, 8.0),
    "deadreckoning": (0.0125, 1.6),
    "dpcm": (4, 256),
    "gesture": (1.0, 20.0),
    "hybrid": (0, 7),
    "kinwave": (0.05, 5.0),
    "posture": (10.0, 80.0),
    "primitives": (0.0025, 0.04),
    "pwavelet": (0.01, 0.5),
    "quant": (8, 1024),
    "rhythmic": (5, 80),
    "spiht": (2000.0, 512000.0),
    "subband": (0.01, 0.32),
    "svq": (16, 256),
    "tvq": (16, 256),
    "sz3": (0.001, 1.0),
    "zfp": (0.001, 1.0),
    "fpzip": (12, 28),
}


@dataclass(frozen=True)
class Point:
    """One operating point: ``kind`` "knob" sets the quality knob to ``value``; the others are
    rate-control targets (``error`` is max joint error in cm)."""

    kind: str
    value: float

    @property
    def label(self) -> str:
        return f"{self.kind}={self.value:g}"


def sweep_range(cls: type[Codec]) -> tuple[float, float] | None:
    """(low, high) of the codec's quality knob in benchmarks: sweeps cover it and error targets
    are searched in it (None for a codec without a quality knob)."""
    if cls.quality is None:
        return None
    knob = next(k for k in cls.knobs if k.name == cls.quality.name)
    return SWEEPS.get(cls.id, (knob.low, knob.high))


def knob_sweep(cls: type[Codec], points: int = SWEEP_POINTS) -> list[float]:
    """``points`` settings of the codec's quality knob, from its worst to its best quality
    (log-spaced for log-scaled knobs; integers rounded and repeated ones dropped)."""
    q = cls.quality
    if q is None:
        return []
    knob = next(k for k in cls.knobs if k.name == q.name)
    low, high = SWEEPS.get(cls.id, (knob.low, knob.high))
    log = q.log_scale or (low > 0 and high / low >= 16)
    values = np.geomspace(low, high, points) if log else np.linspace(low, high, points)
    if knob.kind is int:
        values = np.unique(np.round(values).astype(int))
    else:
        values = np.array([float(f"{v:.4g}") for v in values])
    return [v.item() for v in (values if q.higher_is_better else values[::-1])]


def points_for(
    codec_id: str, kinds=DEFAULT_KINDS, errors=DEFAULT_ERRORS_CM, ratios=DEFAULT_RATIOS, bitrates=DEFAULT_BITRATES
) -> list[Point]:
    """The points a codec is measured at. A codec without a quality knob (lossless ones) is
    measured once, as it is."""
    for kind in kinds:
        if kind not in KINDS:
            raise CodecError(f"unknown kind of point {kind!r} (one of {', '.join(KINDS)})")
    for name, values in (("error", errors), ("ratio", ratios), ("bitrate", bitrates)):
        if any(not (math.isfinite(v) and v > 0) for v in values):
            raise CodecError(f"{name} targets must be positive numbers, got {list(values)}")
    cls = codec_class(codec_id)
    if cls.quality is None:
        return [Point("knob", math.nan)]
    out = [Point("knob", float(v)) for v in knob_sweep(cls)] if "knob" in kinds else []
    for kind, values in (("error", errors), ("ratio", ratios), ("bitrate", bitrates)):
        if kind in kinds:
            out += [Point(kind, float(v)) for v in values]
    return out
