"""``posture``: posture-based compression (000 §8.4.3).

Every group (:mod:`mocodec.coding.modelgroups`) is sampled where its distance (8-1) has grown
by ``d`` degrees since the last sample (posture segmentation, 8.2.1); each sample's posture
vector is replaced by the index of the nearest entry (L2) of the group's posture table. The
decoder looks the entries' joint angles up and joins them by Hermite cubics (8-5 to 8-8).
Lags and codes are range coded. The root is sent as quantised samples of its own
(``root_d``, ``root_step``: :mod:`mocodec.coding.modelcoding`).

The tables come from ``tables`` (a file from ``mocodec tables train``, which both ends load)
or, with ``tables`` empty, are trained on the clip (posture entries ``spacing`` cm apart) and
carried in the payload. ``d`` is the quality knob: the thesis swept 80 to 10 (Appendix III)
and shows d = 20 on its dance at about 450 bit/s.

A frame waits for the sample after its segment's end (the slope (8-7) needs it): the coding
delay is variable and can be long (:meth:`delays`). The codec does not stream.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob, continuous_frames
from mocodec.codecs.registry import register
from mocodec.codecs.segmented import MAX_LAG_KNOB, ROOT_KNOBS, SegmentedCodec
from mocodec.coding import animate, modelcoding, motiontables, segmentation
from mocodec.coding.modelgroups import model_groups, posture_vectors
from mocodec.coding.parts import join_parts, split_parts
from mocodec.coding.rangecoder import decode_ints, encode_ints
from mocodec.coding.vqbook import channel_units
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton


@register
class PostureCodec(SegmentedCodec):
    id = "posture"
    description = "000 8.4.3: posture segmentation, posture-table codes, Hermite interpolation"
    knobs = (
        Knob("d", float, 20.0, "posture segmentation distance (8-1), degrees", low=0.1, high=1e4),
        Knob("tables", str, "", "a motion tables file (mocodec tables train); empty: trained on the clip, carried"),
        Knob("spacing", float, motiontables.SPACING_CM, "posture table spacing in cm (tables trained on the clip)",
             low=0.01, high=1000),
        MAX_LAG_KNOB,
    ) + ROOT_KNOBS
    quality = QualityKnob("d", higher_is_better=False, log_scale=True)

    def _segmentations(self, x, groups, fps):
        d, lag = self.config["d"], self.max_lag(fps)
        runs = [(segmentation.posture_samples(x[:, g.channels], d, lag), 1) for g in groups.parts]
        return runs + [(segmentation.posture_samples(x[:, groups.root], self.config["root_d"], lag), 1)]

    def _encode(self, motion) -> bytes:
        sk, groups = motion.skeleton, model_groups(motion.skeleton)
        cont = motion.continuous()
        x = cont.channels * channel_units(sk)
        tables, named = modelcoding.tables_for(cont, groups, self.config["tables"], self.config["spacing"],
                                               motiontables.DISCARD_DEG, None)
        vectors = posture_vectors(sk, cont.channels, groups)
        frames, codes = [], []
        for k, g in enumerate(groups.parts):
            samples = segmentation.posture_samples(x[:, g.channels], self.config["d"], self.max_lag(motion.fps))
            best, _ = motiontables.nearest(vectors[k][samples.frames], tables.posture_vectors(sk, groups, k))
            frames.append(samples.frames)
            codes.append(best)
        root, samples = modelcoding.encode_root(x[:, groups.root], self.config["root_d"], self.config["root_step"],
                                                self.max_lag(motion.fps))
        return join_parts([named, modelcoding.encode_lags([samples.frames] + frames),
                           encode_ints(np.concatenate(codes) if codes else np.zeros(0, np.int64)), root])

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        where = "posture payload"
        groups = model_groups(skeleton)
        named, lags, code_bytes, root = split_parts(body, 4, where)
        tables = modelcoding.read_tables(named, self.config["tables"], skeleton, groups, where)
        samples = modelcoding.decode_lags(lags, frames, len(groups.parts) + 1, where)
        codes = decode_ints(code_bytes)
        if codes.size != sum(s.size for s in samples[1:]):
            raise CorruptStreamError(f"{where}: {codes.size} posture codes for {sum(s.size for s in samples[1:])} "
                                     f"samples")
        units = channel_units(skeleton)
        out = np.zeros((frames, skeleton.num_channels))
        out[:, groups.root] = modelcoding.decode_root(root, samples[0], frames, groups.root.size,
                                                      self.config["root_step"], where)
        start = 0
        for k, g in enumerate(groups.parts):
            mine = codes[start:start + samples[k + 1].size]
            start += mine.size
            table = tables.postures[k]
            if mine.size and (mine.min() < 0 or mine.max() >= len(table)):
                raise CorruptStreamError(f"{where}: a posture code of group {g.name} is outside its "
                                         f"{len(table)}-entry table")
            out[:, g.channels] = animate.hermite(samples[k + 1], animate.unwrap_degrees(table[mine]), frames)
        return continuous_frames(self.id, skeleton, fps, out / units, None)
