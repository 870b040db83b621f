"""``lossless``: the exact float64 input back, as small as we can make it.

Mocap text files hold decimals with a few significant digits (CMU BVH and AMC: ``%g``, six
significant digits), so every value is an integer count of some power of ten. Per value we
find its number of decimals (the smallest d <= 22 with ``round(x 10^d) / 10^d == x``), and per
channel the finest scale D among them; every value becomes the integer v = x 10^D, which is a
multiple of its own granularity g = 10^(D - d). Each v is predicted from the previous ones
(none, the previous value or linear extrapolation, chosen per channel), the prediction is rounded to a
multiple of g, and only the residual in units of g is sent, with the decimals class of each
value. Both streams are range coded adaptively (:func:`mocodec.coding.entropy.rangecoder.encode_ints`).
So a value near 100 deg costs what its 3 decimals carry, not the 6 decimals of a value near 1.

Values that are not short decimals (or would overflow 2^53) are exceptions, sent as float64
with their frame; a channel of mostly exceptions is sent as float64 bit patterns (first
differences, byte planes regrouped, zstandard). Decoding returns every value bit for bit
(except that -0.0 comes back as 0.0).
"""

from __future__ import annotations

import struct

import numpy as np
import zstandard

from mocodec.codecs.base import Codec
from mocodec.codecs.registry import register
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CorruptStreamError
from mocodec.kernels import kernel
from mocodec.skeleton import Skeleton

MAX_DECIMALS = 22  # 10^22 is the largest exact power of ten in float64
FLOAT_CHANNEL = 0xFF
EXCEPTION_SHARE = 0.5  # more exceptions than this: float bits for the channel
ZSTD_LEVEL = 10
_U32 = struct.Struct("<I")
_LIMIT = 2.0**53


def decimals(x: np.ndarray) -> np.ndarray:
    """Per value the smallest d in 0..22 with round(x 10^d) / 10^d == x, or -1."""
    dec = np.full(x.shape, -1, dtype=np.int64)
    for d in range(MAX_DECIMALS, -1, -1):
        scale = 10.0**d
        v = np.round(x * scale)
        dec[(v / scale == x) & (np.abs(v) < _LIMIT)] = d
    return dec


def _granularity(exponent: np.ndarray) -> np.ndarray:
    """10^exponent as int64; exponents above 18 only occur for v = 0 and are capped."""
    return np.power(10, np.minimum(exponent, 18), dtype=np.int64)


@kernel
def _round_to(p, g):
    return ((p + g // 2) // g) * g


@kernel
def _predict(v, i, order):
    if i == 0 or order == 0:
        return 0
    if i == 1 or order == 1:
        return v[i - 1]
    return 2 * v[i - 1] - v[i - 2]


@kernel
def _residuals(v, gran, exception, order):
    r = np.zeros(v.size, dtype=np.int64)
    for i in range(v.size):
        if not exception[i]:
            r[i] = (v[i] - _round_to(_predict(v, i, order), gran[i])) // gran[i]
    return r


@kernel
def _rebuild(r, gran, exception, exception_v, order):
    v = np.empty(gran.size, dtype=np.int64)
    k = 0
    e = 0
    for i in range(gran.size):
        if exception[i]:
            v[i] = exception_v[e]
            e += 1
        else:
            v[i] = _round_to(_predict(v, i, order), gran[i]) + r[k] * gran[i]
            k += 1
    return v


def _encode_channel(x: np.ndarray) -> bytes | None:
    """One channel's bytes, or None if it should go as float bits."""
    dec = decimals(x)
    ok = dec >= 0
    if ok.mean() < 1 - EXCEPTION_SHARE:
        return None
    top = int(dec[ok].max())
    # v = x 10^top exactly: the short integer x 10^d times its granularity 10^(top - d)
    mantissa = np.where(ok, np.round(x * 10.0 ** np.maximum(dec, 0)), 0.0)
    exception = ~ok | ~(np.abs(x) * 10.0**top < _LIMIT)
    if exception.mean() > EXCEPTION_SHARE:
        return None
    gran = _granularity(np.where(exception, 0, top - dec))
    v = np.where(exception, 0, mantissa.astype(np.int64) * gran)
    candidates = [_residuals(v, gran, exception, order) for order in (0, 1, 2)]
    order = int(np.argmin([np.log2(1.0 + np.abs(c)).sum() for c in candidates]))
    r = candidates[order][~exception]
    classes = np.where(exception, top + 1, top - np.maximum(dec, 0))  # 0 = finest, top+1 = exception
    parts = [encode_ints(classes), encode_ints(r), x[exception].astype("<f8").tobytes()]
    header = struct.pack("<BBI", top, order, int(exception.sum()))
    return header + join_parts(parts)


def _decode_channel(data: bytes, frames: int) -> np.ndarray:
    top, order, n_exc = struct.unpack_from("<BBI", data)
    if top > MAX_DECIMALS or order not in (0, 1, 2) or n_exc > frames:
        raise CorruptStreamError(f"lossless channel header (scale {top}, order {order}, {n_exc} exceptions) is invalid")
    class_part, residual_part, exc = split_parts(data, 3, "lossless channel", start=6)
    classes, r = decode_ints(class_part), decode_ints(residual_part)
    if len(exc) != 8 * n_exc:
        raise CorruptStreamError(f"lossless channel: {len(exc)} bytes of exceptions for {n_exc} values")
    exc_values = np.frombuffer(exc, dtype="<f8")
    exception = classes == top + 1
    if (
        classes.size != frames
        or classes.min(initial=0) < 0
        or classes.max(initial=0) > top + 1
        or int(exception.sum()) != n_exc
        or r.size != frames - n_exc
    ):
        raise CorruptStreamError("lossless channel: class and residual streams do not match the frame count")
    gran = _granularity(np.where(exception, 0, classes))
    v = _rebuild(r, gran, exception, np.zeros(n_exc, dtype=np.int64), order)
    x = v / 10.0**top
    x[exception] = exc_values
    return x


def _float_bits(block: np.ndarray) -> bytes:
    bits = block.copy().view(np.int64)
    bits = np.concatenate((bits[:1], np.diff(bits, axis=0)))
    planes = np.ascontiguousarray(bits.view(np.uint8).reshape(len(block), block.shape[1], 8).transpose(2, 1, 0))
    return zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress(planes.tobytes())


def _from_float_bits(data: bytes, frames: int, count: int) -> np.ndarray:
    raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=8 * frames * count)
    if len(raw) != 8 * frames * count:
        raise CorruptStreamError("lossless body: float channels have the wrong size")
    planes = np.frombuffer(raw, dtype=np.uint8).reshape(8, count, frames).transpose(2, 1, 0)
    return np.cumsum(np.ascontiguousarray(planes).view(np.int64).reshape(frames, count), axis=0).view(np.float64)


@register
class LosslessCodec(Codec):
    id = "lossless"
    description = "exact float64: values as short decimals, predicted, range coded; other values as float bits"
    lossless = True

    def _encode(self, motion) -> bytes:
        ch = motion.channels
        modes, parts, floats = bytearray(), [], []
        for c in range(ch.shape[1]):
            data = _encode_channel(ch[:, c]) if len(ch) else None
            if data is None:
                modes.append(FLOAT_CHANNEL)
                floats.append(c)
            else:
                modes.append(0)
                parts.append(data)
        if floats and len(ch):
            parts.append(_float_bits(ch[:, floats]))
        return _U32.pack(ch.shape[1]) + bytes(modes) + join_parts(parts)

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        n = skeleton.num_channels
        (count,) = _U32.unpack_from(body)
        if count != n:
            raise CorruptStreamError(f"lossless body has {count} channels, the skeleton {n}")
        modes = body[4 : 4 + n]
        out = np.zeros((frames, n))
        if frames == 0:
            return out
        parts = iter(split_parts(body, None, "lossless body", start=4 + n))
        floats = [c for c, mode in enumerate(modes) if mode == FLOAT_CHANNEL]
        for c, mode in enumerate(modes):
            if mode == 0:
                out[:, c] = _decode_channel(next(parts), frames)
            elif mode != FLOAT_CHANNEL:
                raise CorruptStreamError(f"lossless body: channel {c} has an invalid mode {mode}")
        if floats:
            out[:, floats] = _from_float_bits(next(parts), frames, len(floats))
        return out
