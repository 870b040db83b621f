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

The tables come from ``tables`` (``mocodec tables train``) or are trained on the clip and
carried. ``e`` is the quality knob: the thesis shows e = 5 on its dance at about 220 bit/s.
A frame waits until its segment's end is detected (:meth:`delays`); the codec does not
stream.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob, continuous_frames
from mocodec.codecs.registry import register
from mocodec.codecs.segmented import BLEND_KNOB, GESTURE_KNOBS, MAX_LAG_KNOB, ROOT_KNOBS, SegmentedCodec
from mocodec.coding import animate, modelcoding, motiontables, segmentation
from mocodec.coding.modelgroups import model_groups, posture_vectors
from mocodec.coding.parts import join_parts, split_parts
from mocodec.coding.rangecoder import decode_ints, encode_ints
from mocodec.coding.vqbook import channel_units
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton


@register
class GestureCodec(SegmentedCodec):
    id = "gesture"
    description = "000 8.4.4: gesture segmentation, gesture-table codes with posture fallback, blending"
    knobs = (
        Knob("e", float, 5.0, "largest similarity error (8-12) of a gesture, degrees; beyond it: posture",
             low=0.0, high=1e4),
        Knob("tables", str, "", "a motion tables file (mocodec tables train); empty: trained on the clip, carried"),
        Knob("spacing", float, motiontables.SPACING_CM, "posture table spacing in cm (tables trained on the clip)",
             low=0.01, high=1000),
        Knob("discard", float, motiontables.DISCARD_DEG, "gesture table discard distance D in degrees (tables "
             "trained on the clip)", low=0.0, high=1e4),
    ) + GESTURE_KNOBS + (BLEND_KNOB, MAX_LAG_KNOB) + ROOT_KNOBS
    quality = QualityKnob("e", higher_is_better=False, log_scale=True)

    def _segmentations(self, x, groups, fps):
        runs = [(segmentation.gesture_samples(x[:, g.channels], fps, self.gesture_params()), 0) for g in groups.parts]
        root = segmentation.posture_samples(x[:, groups.root], self.config["root_d"], self.max_lag(fps))
        return runs + [(root, 1)]

    def _encode(self, motion) -> bytes:
        sk, groups = motion.skeleton, model_groups(motion.skeleton)
        cont = motion.continuous()
        x = cont.channels * channel_units(sk)
        params = self.gesture_params()
        tables, named = modelcoding.tables_for(cont, groups, self.config["tables"], self.config["spacing"],
                                               self.config["discard"], params)
        vectors = posture_vectors(sk, cont.channels, groups)
        frames, codes = [], []
        for k, g in enumerate(groups.parts):
            xg = x[:, g.channels]
            at = segmentation.gesture_samples(xg, motion.fps, params).frames
            entries = tables.posture_vectors(sk, groups, k)
            postures, _ = motiontables.nearest(vectors[k][at], entries)
            moves = tables.gestures[k]
            segs = motiontables.gesture_segments(xg, at, tables.norm).reshape(len(at) - 1, -1)
            if len(moves) and len(segs):
                best, error = motiontables.nearest(segs, moves.reshape(len(moves), -1), tables.weights(k))
            else:
                best, error = np.zeros(len(segs), np.int64), np.full(len(segs), np.inf)
            codes.append(np.concatenate([[-1 - postures[0]], np.where(error <= self.config["e"], best,
                                                                      -1 - postures[1:])]))
            frames.append(at)
        root, samples = modelcoding.encode_root(x[:, groups.root], self.config["root_d"], self.config["root_step"],
                                                self.max_lag(motion.fps))
        return join_parts([named, modelcoding.encode_lags([samples.frames] + frames),
                           encode_ints(np.concatenate(codes) if codes else np.zeros(0, np.int64)), root])

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        where = "gesture payload"
        groups = model_groups(skeleton)
        named, lags, code_bytes, root = split_parts(body, 4, where)
        tables = modelcoding.read_tables(named, self.config["tables"], skeleton, groups, where)
        samples = modelcoding.decode_lags(lags, frames, len(groups.parts) + 1, where)
        codes = decode_ints(code_bytes)
        if codes.size != sum(s.size for s in samples[1:]):
            raise CorruptStreamError(f"{where}: {codes.size} codes for {sum(s.size for s in samples[1:])} samples")
        out = np.zeros((frames, skeleton.num_channels))
        out[:, groups.root] = modelcoding.decode_root(root, samples[0], frames, groups.root.size,
                                                      self.config["root_step"], where)
        blend = round(self.config["blend"] * fps)
        start = 0
        for k, g in enumerate(groups.parts):
            at = samples[k + 1]
            mine = codes[start:start + at.size]
            start += at.size
            out[:, g.channels] = self._animate(at, mine, tables.postures[k], tables.gestures[k], blend, frames,
                                               f"{where}, group {g.name}")
        return continuous_frames(self.id, skeleton, fps, out / channel_units(skeleton), None)

    @staticmethod
    def _animate(at: np.ndarray, codes: np.ndarray, postures: np.ndarray, gestures: np.ndarray, blend: int,
                 frames: int, where: str) -> np.ndarray:
        """One group's frames from its sample frames and codes (8.3)."""
        posture = -1 - codes
        if (codes >= len(gestures)).any() or (posture >= len(postures)).any() or codes[0] >= 0:
            raise CorruptStreamError(f"{where}: a code is outside the tables")
        out = np.empty((frames, postures.shape[1]))
        out[0] = postures[posture[0]]
        for a, b, code in zip(at[:-1], at[1:], codes[1:]):
            if code >= 0:
                seq = animate.stretch(gestures[code], b - a + 1)[1:]
                seq = seq + 360.0 * np.round((out[a] - seq[0]) / 360.0)
                out[a + 1:b + 1] = animate.blend_start(seq, out[a], min(blend, (b - a) // 2))
            else:
                end = postures[-1 - code]
                end = end + 360.0 * np.round((out[a] - end) / 360.0)
                out[a + 1:b + 1] = animate.raised_cosine(np.array([0, b - a]), np.stack([out[a], end]), b - a + 1)[1:]
        return out
