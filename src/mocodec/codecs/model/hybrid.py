"""``hybrid``: gesture segmentation with transform coding of the segments (000 §8.5).

Every group (the root's channels one of them, in centimetres and degrees) is cut by gesture
segmentation (8.2.2). Each segment of every DOF goes through a DCT and keeps its first three
coefficients: the mean, quantised to 2^b0 levels spanning the channel's range, and the
amplitudes of the first two cosines, quantised in steps of the range over 2^b1 and 2^b2
(``level`` picks the bits of Appendix III, from (4, 3, 2) to (7, 7, 5)). No table, no
training. The decoder inverts the DCT and eases each segment in from the previous frame over
``blend`` seconds (at most half the segment), which hides the steps the coarse coefficients
leave at segment seams.

Per channel the header sends its lowest value (0.01 units) and its range (1/8 octave); then
the lags of every group, the level index of every segment mean (delta coded along the
channel) and the cosine amplitudes, each range coded. A frame waits until its segment's end
is detected (:meth:`delays`); the codec does not stream.
"""

from __future__ import annotations

import numpy as np
from scipy import fft

from mocodec.codecs.base import Knob, QualityKnob, continuous_frames
from mocodec.codecs.model import animate, modelcoding, segmentation
from mocodec.codecs.model.modelgroups import model_groups
from mocodec.codecs.model.segmented import BLEND_KNOB, GESTURE_KNOBS, SegmentedCodec
from mocodec.codecs.registry import register
from mocodec.codecs.shared.vqbook import channel_units
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton

BITS = ((4, 3, 2), (4, 4, 2), (5, 4, 3), (5, 5, 3), (6, 5, 4), (6, 6, 4), (7, 6, 5), (7, 7, 5))  # Appendix III
LOW_STEP = 0.01
RANGE_FLOOR = 0.01  # the smallest range (units) a channel is given


def _columns(groups) -> list[np.ndarray]:
    """The channel columns of every group, the root's first."""
    return ([groups.root] if groups.root.size else []) + [g.channels for g in groups.parts]


def _ranges(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(low codes, range codes, the ranges they give) per channel of ``x``, covering it."""
    low = np.floor(x.min(axis=0) / LOW_STEP).astype(np.int64)
    span = x.max(axis=0) - low * LOW_STEP
    code = np.ceil(8 * np.log2(np.maximum(span, RANGE_FLOOR) / RANGE_FLOOR) - 1e-9).astype(np.int64)
    return low, code, RANGE_FLOOR * 2.0 ** (code / 8)


def _steps(span: np.ndarray, bits: tuple[int, int, int]) -> np.ndarray:
    """(3, C) quantiser steps: the mean over 2^b0 levels of the range, the cosines range / 2^b."""
    return np.stack([span / (2 ** bits[0] - 1), span / 2 ** bits[1], span / 2 ** bits[2]])


def _segment_scale(n: int) -> np.ndarray:
    """Orthonormal DCT coefficient k of an n-frame segment over the value it stands for: the
    mean for k = 0, a cosine's amplitude for k > 0."""
    return np.array([np.sqrt(n)] + [np.sqrt(n / 2)] * 2)[: min(3, n)]


@register
class HybridCodec(SegmentedCodec):
    id = "hybrid"
    description = "hybrid coding: gesture segmentation, three DCT coefficients per segment and DOF, blending"
    knobs = (
        (Knob("level", int, 3, "coefficient bits of the three DCT terms: 0 = (4,3,2) ... 7 = (7,7,5)", low=0, high=7),)
        + GESTURE_KNOBS
        + (BLEND_KNOB,)
    )
    quality = QualityKnob("level", higher_is_better=True)

    def _segmentations(self, x, groups, fps):
        return [(segmentation.gesture_samples(x[:, cols], fps, self.gesture_params()), 0) for cols in _columns(groups)]

    def _encode(self, motion) -> bytes:
        sk = motion.skeleton
        x = self.prepared(motion)
        low, code, span = _ranges(x)
        steps = _steps(span, BITS[self.config["level"]])
        frames, means, cosines = [], [], []
        for cols in _columns(model_groups(sk)):
            at = segmentation.gesture_samples(x[:, cols], motion.fps, self.gesture_params()).frames
            frames.append(at)
            m, c = [], []
            for a, b in _bounds(at):
                coef = fft.dct(x[a:b, cols], norm="ortho", axis=0)[:3] / _segment_scale(b - a)[:, None]
                m.append(
                    np.clip(
                        np.round((coef[0] - low[cols] * LOW_STEP) / steps[0, cols]),
                        0,
                        2 ** BITS[self.config["level"]][0] - 1,
                    )
                )
                c.append(np.round(coef[1:] / steps[1 : 1 + len(coef) - 1, cols]).ravel())
            means.append(np.diff(np.array(m, dtype=np.int64), axis=0, prepend=0).T.ravel())
            cosines.append(np.concatenate(c).astype(np.int64))
        return join_parts(
            [
                encode_ints(low),
                encode_ints(np.diff(code, prepend=0)),
                modelcoding.encode_lags(frames),
                encode_ints(np.concatenate(means)),
                encode_ints(np.concatenate(cosines)),
            ]
        )

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        where = "hybrid body"
        parts = split_parts(body, 5, where)
        low, code = decode_ints(parts[0]), np.cumsum(decode_ints(parts[1]))
        width = skeleton.num_channels
        if low.size != width or code.size != width or code.min(initial=0) < 0 or code.max(initial=0) > 1024:
            raise CorruptStreamError(f"{where}: the channel ranges do not match the {width} channels")
        span = RANGE_FLOOR * 2.0 ** (code / 8)
        steps = _steps(span, BITS[self.config["level"]])
        columns = _columns(model_groups(skeleton))
        samples = modelcoding.decode_lags(parts[2], frames, len(columns), where)
        means, cosines = decode_ints(parts[3]), decode_ints(parts[4])
        bounds = [list(_bounds(at)) for at in samples]
        want = sum(len(b) * cols.size for b, cols in zip(bounds, columns))
        want_cos = sum(sum(min(3, e - s) - 1 for s, e in b) * cols.size for b, cols in zip(bounds, columns))
        if means.size != want or cosines.size != want_cos:
            raise CorruptStreamError(
                f"{where}: {means.size} means and {cosines.size} cosines for {want} and {want_cos} expected"
            )
        out = np.zeros((frames, width))
        blend = round(self.config["blend"] * fps)
        m_at = c_at = 0
        for cols, segs in zip(columns, bounds):
            level = np.cumsum(means[m_at : m_at + len(segs) * cols.size].reshape(cols.size, len(segs)), axis=1).T
            m_at += level.size
            for k, (a, b) in enumerate(segs):
                n = b - a
                kept = min(3, n)
                coef = np.zeros((n, cols.size))
                coef[0] = low[cols] * LOW_STEP + level[k] * steps[0, cols]
                amp = cosines[c_at : c_at + (kept - 1) * cols.size].reshape(kept - 1, cols.size)
                c_at += amp.size
                coef[1:kept] = amp * steps[1:kept, cols]
                seg = fft.idct(coef * np.pad(_segment_scale(n), (0, n - kept))[:, None], norm="ortho", axis=0)
                out[a:b, cols] = animate.blend_start(seg, out[a - 1, cols], min(blend, n // 2)) if a else seg
        return continuous_frames(self.id, skeleton, fps, out / channel_units(skeleton), None)


def _bounds(at: np.ndarray):
    """The frame ranges [a, b) of the segments between samples ``at``; the last takes the last frame."""
    for k, (a, b) in enumerate(zip(at[:-1], at[1:])):
        yield int(a), int(b) + (k == len(at) - 2)
    if len(at) == 1:
        yield 0, 1
