"""``gesture``: gesture-based compression (000 §8.4.4).

Every group is cut where it comes to rest (gesture segmentation, 8.2.2, knobs ``beta``,
``window``, ``min_length``, ``max_length``); each segment, stretched to the table's length,
is replaced by the closest entry of the group's gesture table by the similarity (8-12, 8-13).
Where even the closest entry is further than ``e`` degrees, the segment falls back to posture
interpolation: the nearest posture-table entry for the segment's end, reached from the
previous frame by the raised cosine (8-9, 8-10), which suits gesture samples (the motion rests
there). A decoded gesture is stretched back to its segment and eased in from the previous
frame over ``blend`` seconds (fig. 8-5), at most half the segment. Lags and codes (a gesture
index g as g, a posture index p as -1 - p; the first frame's posture first) are range coded.
The root is sent as quantised samples of its own (``root_d``, ``root_step``).

The tables come from ``tables`` (``mocodec model train tables``) or are trained on the clip and
carried. ``e`` is the quality knob: the thesis shows e = 5 on its dance at about 220 bit/s.
A frame waits until its segment's end is detected (:meth:`delays`); the codec does not
stream.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob, continuous_frames
from mocodec.codecs.model import animate, motiontables, segmentation
from mocodec.codecs.model.segmented import BLEND_KNOB, GESTURE_KNOBS, MAX_LAG_KNOB, ROOT_KNOBS, TABLE_KNOBS, TabledCodec
from mocodec.codecs.registry import register
from mocodec.codecs.shared.vqbook import channel_units
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton


@register
class GestureCodec(TabledCodec):
    id = "gesture"
    description = "gesture-based coding: gesture segmentation, gesture-table codes with posture fallback, blending"
    knobs = (
        (
            Knob(
                "e",
                float,
                5.0,
                "largest similarity error (8-12) of a gesture, degrees; beyond it: posture",
                low=0.0,
                high=1e4,
            ),
        )
        + TABLE_KNOBS
        + (
            Knob(
                "discard",
                float,
                motiontables.DISCARD_DEG,
                "gesture table discard distance D in degrees (tables trained on the clip)",
                low=0.0,
                high=1e4,
            ),
        )
        + GESTURE_KNOBS
        + (BLEND_KNOB, MAX_LAG_KNOB)
        + ROOT_KNOBS
    )
    quality = QualityKnob("e", higher_is_better=False, log_scale=True)

    def _segmentations(self, x, groups, fps):
        runs = [(segmentation.gesture_samples(x[:, g.channels], fps, self.gesture_params()), 0) for g in groups.parts]
        root = segmentation.posture_samples(x[:, groups.root], self.config["root_d"], self.max_lag(fps))
        return runs + [(root, 1)]

    def _encode(self, motion) -> bytes:
        params = self.gesture_params()
        x, groups, tables, named, vectors = self._prepare(motion, params, self.config["discard"])
        frames, codes = [], []
        for k, g in enumerate(groups.parts):
            xg = x[:, g.channels]
            at = segmentation.gesture_samples(xg, motion.fps, params).frames
            postures, _ = motiontables.nearest(vectors[k][at], tables.posture_vectors(motion.skeleton, groups, k))
            moves = tables.gestures[k]
            segs = motiontables.gesture_segments(xg, at, tables.norm)
            segs = segs.reshape(len(at) - 1, segs.size // max(len(at) - 1, 1))  # (a 1-frame clip: none)
            if len(moves) and len(segs):
                best, error = motiontables.nearest(segs, moves.reshape(len(moves), -1), tables.weights(k))
            else:
                best, error = np.zeros(len(segs), np.int64), np.full(len(segs), np.inf)
            codes.append(
                np.concatenate([[-1 - postures[0]], np.where(error <= self.config["e"], best, -1 - postures[1:])])
            )
            frames.append(at)
        return self._payload(named, x, groups, motion.fps, frames, codes)

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        where = "gesture body"
        groups, tables, samples, codes, out = self._read(body, skeleton, frames, where)
        blend = round(self.config["blend"] * fps)
        for k, g in enumerate(groups.parts):
            out[:, g.channels] = self._animate(
                samples[k], codes[k], tables.postures[k], tables.gestures[k], blend, frames, f"{where}, group {g.name}"
            )
        return continuous_frames(self.id, skeleton, fps, out / channel_units(skeleton), None)

    @staticmethod
    def _animate(
        at: np.ndarray,
        codes: np.ndarray,
        postures: np.ndarray,
        gestures: np.ndarray,
        blend: int,
        frames: int,
        where: str,
    ) -> np.ndarray:
        """One group's frames from its sample frames and codes (8.3)."""
        posture = -1 - codes
        if (codes >= len(gestures)).any() or (posture >= len(postures)).any() or codes[0] >= 0:
            raise CorruptStreamError(f"{where}: a code is outside the tables")
        out = np.empty((frames, postures.shape[1]))
        out[0] = postures[posture[0]]
        for a, b, code in zip(at[:-1], at[1:], codes[1:]):
            if code >= 0:
                seq = animate.stretch(gestures[code], b - a + 1)[1:]
                seq = animate.turned_to(seq, out[a])
                out[a + 1 : b + 1] = animate.blend_start(seq, out[a], min(blend, (b - a) // 2))
            else:
                end = animate.turned_to(postures[-1 - code], out[a])
                out[a + 1 : b + 1] = animate.raised_cosine(np.array([0, b - a]), np.stack([out[a], end]), b - a + 1)[1:]
        return out
