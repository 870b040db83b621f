"""Generic rate control: the knob setting of any codec for a target compression ratio, bit
rate, PSNR, or joint position error (mean or max, cm).

The codec's quality knob (:class:`~mocodec.codecs.QualityKnob`) is searched by bisection
(in log space for log-scaled knobs), each candidate encoded into the real container and
decoded again, so every figure is measured, never estimated. Error targets return the
smallest file whose decoded output meets the bound, and the bound is verified on the very
bytes returned. Ratio and bit-rate targets stop within ``tolerance`` (2%) of the target when
the knob can get there, and otherwise report the closest setting.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass

import numpy as np

from mocodec import moc
from mocodec.codecs import Codec
from mocodec.errors import CodecError
from mocodec.formats import container
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.waveform import dof_errors
from mocodec.motion import Motion

TARGETS = ("ratio", "bitrate", "psnr", "mean_error_cm", "max_error_cm")
MAX_STEPS = 40
KNOB_RESOLUTION = 1e-3  # relative: finer knob steps change a file by less than this


@dataclass(frozen=True)
class Measurement:
    codec: Codec
    data: bytes  # the .moc bytes
    ratio: float  # vs 32-bit floats
    bitrate: float  # bits per second
    psnr: float
    mean_error_cm: float
    max_error_cm: float


def coded_size(data: bytes, whole_file: bool = True) -> int:
    """Bytes of a .moc file, or only of its chunk bodies (the coded motion without the
    skeleton and header, the convention of the theses' ratios)."""
    if whole_file:
        return len(data)
    c = container.open_container(io.BytesIO(data), len(data), "<bytes>")
    return sum(len(c.read_chunk(k)) for k in range(len(c.index)))


def measure(
    codec: Codec, motion: Motion, positions_cm: np.ndarray | None = None, whole_file: bool = True
) -> Measurement:
    """Encode into a container, decode it back and measure everything rate control needs;
    sizes count the whole file, or with ``whole_file=False`` the coded motion only."""
    data = moc.pack(motion, codec)
    size = coded_size(data, whole_file)
    decoded = moc.unpack(data)
    sk = motion.skeleton
    if positions_cm is None:
        positions_cm = forward_kinematics(sk, motion.channels)[0] * (100.0 / sk.units_per_metre)
    decoded_cm = forward_kinematics(decoded.skeleton, decoded.channels)[0] * (100.0 / sk.units_per_metre)
    err = np.linalg.norm(decoded_cm - positions_cm, axis=2)  # on the file's skeleton (offsets rounded)
    aligned = decoded.aligned_to(motion).channels  # equivalent Euler triples are not errors
    psnr = dof_errors(motion.channels, aligned, sk.rotation_mask).body_psnr
    return Measurement(
        codec,
        data,
        motion.raw_bits / 8 / size,
        size * 8 / max(motion.duration, 1e-12),
        psnr,
        float(err.mean()) if err.size else 0.0,
        float(err.max()) if err.size else 0.0,
    )


def _meets(m: Measurement, target: str, value: float) -> bool:
    return {
        "ratio": m.ratio >= value,
        "bitrate": m.bitrate <= value,
        "psnr": m.psnr >= value,
        "mean_error_cm": m.mean_error_cm <= value,
        "max_error_cm": m.max_error_cm <= value,
    }[target]


def _achieved(m: Measurement, target: str) -> float:
    return getattr(m, target)


def guaranteed(codec: Codec, target: str, value: float) -> Codec | None:
    """``codec`` set to meet an error target by itself (:meth:`Codec.bound_knobs`: its encoder
    verifies the bound on the bytes it returns), with no search and nothing measured; None when
    the target needs rate control."""
    knobs = codec.bound_knobs(target, value)
    return None if knobs is None else type(codec)(**{**codec.config, **knobs})


def configure(codec: Codec, motion: Motion, target: str, value: float) -> Codec:
    """``codec`` set for a target: by its own knob where it guarantees it (:func:`guaranteed`),
    else by :func:`tune`."""
    return guaranteed(codec, target, value) or tune(codec, motion, target, value).codec


def tune(
    codec: Codec,
    motion: Motion,
    target: str,
    value: float,
    tolerance: float = 0.02,
    whole_file: bool = True,
    knob_range: tuple[float, float] | None = None,
    resolution: float = KNOB_RESOLUTION,
) -> Measurement:
    """The measured setting of ``codec``'s quality knob for the target (see the module doc).
    Ratio and bit-rate targets count the whole file unless ``whole_file`` is False. The knob is
    searched over its whole range, or over ``knob_range``, down to steps of ``resolution``
    (relative)."""
    if target not in TARGETS:
        raise CodecError(f"unknown target {target!r} (one of {', '.join(TARGETS)})")
    if not (math.isfinite(value) and value > 0):
        raise CodecError(f"target {target} needs a positive number, got {value}")
    positions = forward_kinematics(motion.skeleton, motion.channels)[0] * (100.0 / motion.skeleton.units_per_metre)
    bound = guaranteed(codec, target, value)
    if bound is not None:
        m = measure(bound, motion, positions, whole_file)
        if _meets(m, target, value):
            return m
    if hasattr(codec, "target_knobs"):
        direct = _direct(codec, motion, target, value, tolerance, whole_file, positions)
        if direct is not None:
            return direct
    q = codec.quality
    if q is None:
        m = measure(codec, motion, positions, whole_file)
        if _meets(m, target, value):
            return m
        raise CodecError(
            f"codec {codec.id} has no quality knob and gives {target} {_achieved(m, target):.4g}, not {value:g}"
        )
    knob = next(k for k in codec.knobs if k.name == q.name)
    lo, hi = map(float, knob_range or (knob.low, knob.high))
    integer = knob.kind is int

    def at(x: float) -> Measurement:
        return measure(codec.with_knob(q.name, int(round(x)) if integer else x), motion, positions, whole_file)

    def mid(a: float, b: float) -> float:
        m = math.sqrt(a * b) if q.log_scale and a > 0 and b > 0 else (a + b) / 2
        return math.floor(m) if integer and m not in (a, b) else m

    # orient so that "good" (more quality, bigger file) is at `best`
    best_x, worst_x = (hi, lo) if q.higher_is_better else (lo, hi)
    best, worst = at(best_x), at(worst_x)
    size_target = target in ("ratio", "bitrate")
    if size_target:
        if _meets(best, target, value):
            return best  # even full quality is small enough
        if not _meets(worst, target, value):
            raise CodecError(
                f"codec {codec.id} cannot reach {target} {value:g}: at its smallest it gives "
                f"{_achieved(worst, target):.4g}"
            )
    else:
        if _meets(worst, target, value):
            return worst  # even the lowest quality is good enough
        if not _meets(best, target, value):
            raise CodecError(
                f"codec {codec.id} cannot reach {target} {value:g}: at its best it gives {_achieved(best, target):.4g}"
            )
    # invariant: `good` meets the target, `bad` does not; error targets want the smallest good
    # file, size targets the largest good file, i.e. both move `good` towards `bad`.
    good_x, good, bad_x = (worst_x, worst, best_x) if size_target else (best_x, best, worst_x)
    for _ in range(MAX_STEPS):
        if size_target and abs(_achieved(good, target) - value) <= tolerance * value:
            break
        x = mid(good_x, bad_x)
        if x in (good_x, bad_x) or abs(x - good_x) <= resolution * max(abs(good_x), 1e-12):
            break
        m = at(x)
        if _meets(m, target, value):
            good_x, good = x, m
        else:
            bad_x = x
    return good


DIRECT_PASSES = 5


def _direct(
    codec: Codec, motion: Motion, target: str, value: float, tolerance: float, whole_file: bool, positions: np.ndarray
) -> Measurement | None:
    """For a codec that meets a size target itself (``target_knobs``: kinwave's bit-rate knob),
    a few corrected encodings instead of a bisection; None if it does not get there (the caller
    bisects). Error targets a codec guarantees go through :func:`guaranteed`."""
    overhead = 0.0
    best = None
    for _ in range(DIRECT_PASSES):
        knobs = codec.target_knobs(target, value, motion, overhead)
        if knobs is None:
            return None
        m = measure(type(codec)(**{**codec.config, **knobs}), motion, positions, whole_file)
        if _meets(m, target, value):
            if abs(_achieved(m, target) - value) <= tolerance * value:
                return m
            if best is None or m.ratio < best.ratio:
                best = m
        # the file came out (size - wanted) bytes off: take that much more (or less) off the
        # bodies, aiming at the middle of the tolerance
        wanted = motion.raw_bits / 8 / value if target == "ratio" else value * motion.duration / 8
        overhead += coded_size(m.data, whole_file) - wanted * (1 - tolerance / 2)
    return best
