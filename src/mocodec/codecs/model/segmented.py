"""What the model-based codecs of 000 ch. 8 (``posture``, ``gesture``, ``hybrid``) share as
codecs: the gesture segmentation knobs (Appendix III's nWin, beta, nMin, nMax, in seconds),
the variable coding delay they report, and for the two that code with tables
(:class:`TabledCodec`) the tables, the root and the body layout: the tables part, the
lags of the root and of every group, one stream of codes, the root's samples.

These coders wait for samples that lie an unknown time ahead (8.1: "as high as two
seconds"), so they do not stream; :meth:`SegmentedCodec.delays` gives, per frame of a clip,
how long a causal coder would have made it wait.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Codec, Knob
from mocodec.codecs.model import modelcoding, motiontables, segmentation
from mocodec.codecs.model.modelgroups import Groups, model_groups, posture_vectors
from mocodec.codecs.shared.vqbook import channel_units
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CorruptStreamError
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

_G = segmentation.GestureParams()
GESTURE_KNOBS = (
    Knob("beta", float, _G.beta, "gesture threshold scale beta", low=0.05, high=segmentation.BETA_LIMIT),
    Knob("window", float, round(_G.window, 4), "gesture threshold low-pass length, seconds", low=0.01, high=10),
    Knob("min_length", float, round(_G.min_length, 4), "shortest gesture segment, seconds", low=0.0, high=10),
    Knob("max_length", float, _G.max_length, "longest gesture segment, seconds", low=0.05, high=60),
)
MAX_LAG_KNOB = Knob(
    "max_lag", float, 2.0, "longest time between posture samples, seconds (0: none, as the thesis)", low=0.0, high=3600
)
ROOT_KNOBS = (
    Knob("root_d", float, 20.0, "posture distance between root samples (cm + degrees)", low=0.1, high=1e4),
    Knob("root_step", float, 1.0, "quantiser step of the root samples (cm, degrees)", low=0.001, high=100),
)
TABLE_KNOBS = (
    Knob(
        "tables",
        str,
        "",
        "a motion tables file (mocodec model train tables); empty: trained on the clip, carried",
        path=True,
    ),
    Knob(
        "spacing",
        float,
        motiontables.SPACING_CM,
        "posture table spacing in cm (tables trained on the clip)",
        low=0.01,
        high=1000,
    ),
)
BLEND_KNOB = Knob(
    "blend",
    float,
    round(10 / 30, 4),
    "seconds over which a segment eases in from the last (fig. 8-5)",
    low=0.0,
    high=10,
)


class SegmentedCodec(Codec):
    """Base of the ch. 8 codecs: work in degrees and centimetres, on continuous angles."""

    variable_delay = True

    def gesture_params(self) -> segmentation.GestureParams:
        c = self.config
        return segmentation.GestureParams(c["beta"], c["window"], c["min_length"], c["max_length"])

    def max_lag(self, fps: float) -> int:
        """The posture sample lag limit in frames (0: none)."""
        return round(self.config["max_lag"] * fps)

    @staticmethod
    def prepared(motion: Motion) -> np.ndarray:
        """The clip's channels, continuous, in degrees and centimetres."""
        return motion.continuous().channels * channel_units(motion.skeleton)

    def delays(self, motion: Motion) -> np.ndarray:
        """Per frame, the frames a causal coder waits before it can decode it (8.1)."""
        x = self.prepared(motion)
        return modelcoding.worst_delays(
            motion.num_frames, self._segmentations(x, model_groups(motion.skeleton), motion.fps)
        )

    def _segmentations(self, x, groups, fps) -> list[tuple[segmentation.Samples, int]]:
        """Every group's (samples, lookahead) for :meth:`delays`."""
        raise NotImplementedError


class TabledCodec(SegmentedCodec):
    """Base of ``posture`` and ``gesture``: knobs :data:`TABLE_KNOBS`, :data:`MAX_LAG_KNOB`
    and :data:`ROOT_KNOBS`."""

    def _prepare(self, motion: Motion, params: segmentation.GestureParams | None, discard: float):
        """(continuous channels in degrees and cm, groups, tables, the tables part, every
        group's posture vectors per frame) of ``motion``; tables trained on it hold gestures
        (made with ``params``, pruned at ``discard``) only if ``params`` is given."""
        cont = motion.continuous()
        groups = model_groups(motion.skeleton)
        tables, named = modelcoding.tables_for(
            cont, groups, self.config["tables"], self.config["spacing"], discard, params
        )
        return (
            cont.channels * channel_units(motion.skeleton),
            groups,
            tables,
            named,
            posture_vectors(motion.skeleton, cont.channels, groups),
        )

    def _payload(
        self, named: bytes, x: np.ndarray, groups: Groups, fps: float, frames: list[np.ndarray], codes: list[np.ndarray]
    ) -> bytes:
        """The body: tables part, lags (root first), codes, the root's samples."""
        root, samples = modelcoding.encode_root(
            x[:, groups.root], self.config["root_d"], self.config["root_step"], self.max_lag(fps)
        )
        return join_parts(
            [
                named,
                modelcoding.encode_lags([samples.frames] + frames),
                encode_ints(np.concatenate(codes) if codes else np.zeros(0, np.int64)),
                root,
            ]
        )

    def _read(self, body: bytes, skeleton: Skeleton, frames: int, where: str):
        """(groups, tables, every group's sample frames, its codes, the output with the root
        decoded) of a body from :meth:`_payload`."""
        groups = model_groups(skeleton)
        named, lags, code_bytes, root = split_parts(body, 4, where)
        tables = modelcoding.read_tables(named, self.config["tables"], skeleton, groups, where)
        samples = modelcoding.decode_lags(lags, frames, len(groups.parts) + 1, where)
        codes = decode_ints(code_bytes)
        sizes = [s.size for s in samples[1:]]
        if codes.size != sum(sizes):
            raise CorruptStreamError(f"{where}: {codes.size} codes for {sum(sizes)} samples")
        out = np.zeros((frames, skeleton.num_channels))
        out[:, groups.root] = modelcoding.decode_root(
            root, samples[0], frames, groups.root.size, self.config["root_step"], where
        )
        return groups, tables, samples[1:], np.split(codes, np.cumsum(sizes)[:-1]), out
