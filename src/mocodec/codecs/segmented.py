"""What the model-based codecs of 000 ch. 8 (``posture``, ``gesture``, ``hybrid``) share as
codecs: the gesture segmentation knobs (Appendix III's nWin, beta, nMin, nMax, in seconds),
the root knobs, and the variable coding delay they report.

These coders wait for samples that lie an unknown time ahead (8.1: "as high as two
seconds"), so they do not stream; :meth:`SegmentedCodec.delays` gives, per frame of a clip,
how long a causal coder would have made it wait.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Codec, Knob
from mocodec.coding import modelcoding, segmentation
from mocodec.coding.modelgroups import model_groups
from mocodec.coding.vqbook import channel_units
from mocodec.motion import Motion

_G = segmentation.GestureParams()
GESTURE_KNOBS = (
    Knob("beta", float, _G.beta, "gesture threshold scale beta (8-4)", low=0.05, high=segmentation.BETA_LIMIT),
    Knob("window", float, round(_G.window, 4), "threshold low-pass length, seconds (8-4)", low=0.01, high=10),
    Knob("min_length", float, round(_G.min_length, 4), "shortest gesture segment, seconds", low=0.0, high=10),
    Knob("max_length", float, _G.max_length, "longest gesture segment, seconds", low=0.05, high=60),
)
MAX_LAG_KNOB = Knob("max_lag", float, 2.0, "longest time between posture samples, seconds (0: none, as the thesis)",
                   low=0.0, high=3600)
ROOT_KNOBS = (
    Knob("root_d", float, 20.0, "posture distance between root samples (cm + degrees, (8-1))", low=0.1, high=1e4),
    Knob("root_step", float, 1.0, "quantiser step of the root samples (cm, degrees)", low=0.001, high=100),
)
BLEND_KNOB = Knob("blend", float, round(10 / 30, 4), "seconds over which a segment eases in from the last (fig. 8-5)",
                  low=0.0, high=10)


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
        return modelcoding.worst_delays(motion.num_frames, self._segmentations(x, model_groups(motion.skeleton),
                                                                              motion.fps))

    def _segmentations(self, x, groups, fps) -> list[tuple[segmentation.Samples, int]]:
        """Every group's (samples, lookahead) for :meth:`delays`."""
        raise NotImplementedError
