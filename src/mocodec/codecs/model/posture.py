"""``posture``: posture-based compression (000 §8.4.3).

Every group (:mod:`mocodec.codecs.model.modelgroups`) is sampled where its distance (8-1) has grown
by ``d`` degrees since the last sample (posture segmentation, 8.2.1); each sample's posture
vector is replaced by the index of the nearest entry (L2) of the group's posture table. The
decoder looks the entries' joint angles up and joins them by Hermite cubics (8-5 to 8-8).
Lags and codes are range coded. The root is sent as quantised samples of its own
(``root_d``, ``root_step``: :mod:`mocodec.codecs.model.modelcoding`).

The tables come from ``tables`` (a file from ``mocodec model train tables``, which both ends load)
or, with ``tables`` empty, are trained on the clip (posture entries ``spacing`` cm apart) and
carried in the body. ``d`` is the quality knob: the thesis swept 80 to 10 (Appendix III)
and shows d = 20 on its dance at about 450 bit/s.

A frame waits for the sample after its segment's end (the slope (8-7) needs it): the coding
delay is variable and can be long (:meth:`delays`). The codec does not stream.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob, continuous_frames
from mocodec.codecs.model import animate, motiontables, segmentation
from mocodec.codecs.model.segmented import MAX_LAG_KNOB, ROOT_KNOBS, TABLE_KNOBS, TabledCodec
from mocodec.codecs.registry import register
from mocodec.codecs.shared.vqbook import channel_units
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton


@register
class PostureCodec(TabledCodec):
    id = "posture"
    description = "posture-based coding: posture segmentation, posture-table codes, Hermite interpolation"
    knobs = (
        (Knob("d", float, 20.0, "posture segmentation distance, degrees", low=0.1, high=1e4),)
        + TABLE_KNOBS
        + (MAX_LAG_KNOB,)
        + ROOT_KNOBS
    )
    quality = QualityKnob("d", higher_is_better=False, log_scale=True)

    def _segmentations(self, x, groups, fps):
        d, lag = self.config["d"], self.max_lag(fps)
        runs = [(segmentation.posture_samples(x[:, g.channels], d, lag), 1) for g in groups.parts]
        return runs + [(segmentation.posture_samples(x[:, groups.root], self.config["root_d"], lag), 1)]

    def _encode(self, motion) -> bytes:
        x, groups, tables, named, vectors = self._prepare(motion, None, motiontables.DISCARD_DEG)
        frames, codes = [], []
        for k, g in enumerate(groups.parts):
            samples = segmentation.posture_samples(x[:, g.channels], self.config["d"], self.max_lag(motion.fps))
            best, _ = motiontables.nearest(
                vectors[k][samples.frames], tables.posture_vectors(motion.skeleton, groups, k)
            )
            frames.append(samples.frames)
            codes.append(best)
        return self._payload(named, x, groups, motion.fps, frames, codes)

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        where = "posture body"
        groups, tables, samples, codes, out = self._read(body, skeleton, frames, where)
        for g, at, mine, table in zip(groups.parts, samples, codes, tables.postures):
            if mine.size and (mine.min() < 0 or mine.max() >= len(table)):
                raise CorruptStreamError(
                    f"{where}: a posture code of group {g.name} is outside its {len(table)}-entry table"
                )
            out[:, g.channels] = animate.hermite(at, animate.unwrap_degrees(table[mine]), frames)
        return continuous_frames(self.id, skeleton, fps, out / channel_units(skeleton), None)
