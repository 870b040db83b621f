"""``quant``: direct quantisation of every DOF (000 §7.2, 7.3), entropy coded.

Each channel is quantised on its own, frame by frame, with no prediction:

* ``uniform`` (7-4): N levels over the channel's range (``range=data``: the range of the
  first frames coded, sent as side information; ``range=limits``: the skeleton's joint limits
  where it has them), midpoint reconstruction (7-3);
* ``mulaw`` (7-5): the bipolar mu-law quantiser about the middle of that range;
* ``adaptive`` (7-7): the feedback adaptive quantiser about the middle of the range, starting
  from the uniform step; the step follows the codes, so nothing more is sent.

The codes are range coded as an alphabet of N symbols, with adaptive per-channel models in the
context of the previous code (the thesis's statistical coder, 7.4; ``intcoder.Model``). The
thesis's finding holds: below 64 levels the error is visible, and the ratio stays low; this is
the baseline the other coders of chapter 7 are measured against. Delay: none.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.waveform.framewise import FramewiseCodec
from mocodec.coding.quantisation.predictive import AdaptiveCoder, ChannelParams, TableCoder
from mocodec.coding.quantisation.quantisers import even_levels, multipliers, table

LAWS = ("uniform", "mulaw", "adaptive")


@register
class QuantCodec(FramewiseCodec):
    id = "quant"
    packet_number = 1
    description = "direct quantisation per DOF: uniform, mu-law or feedback-adaptive, range coded"
    knobs = (
        Knob(
            "levels",
            int,
            64,
            "quantiser levels N (the thesis: 8-256; mu-law and adaptive round to even)",
            low=2,
            high=1 << 16,
        ),
        Knob("law", str, "uniform", "quantiser", choices=LAWS),
        Knob("mu", float, 8.0, "mu of the mu-law quantiser", low=1e-3, high=1e6),
        Knob(
            "range",
            str,
            "data",
            "uniform range: the data's, or the joint limits where the skeleton has them",
            choices=("data", "limits"),
        ),
    )
    quality = QualityKnob("levels", higher_is_better=True, log_scale=True)
    bounded_codes = True

    def _setup(self, values, skeleton, fps):
        low, high = values.min(axis=0), values.max(axis=0)
        if self.config["range"] == "limits":
            limits = skeleton.limits
            finite = np.isfinite(limits).all(axis=1) & (limits[:, 1] > limits[:, 0])
            low, high = np.where(finite, limits[:, 0], low), np.where(finite, limits[:, 1], high)
        constant = high - low <= 0
        params = ChannelParams(
            constant, np.where(constant, values[0], (low + high) / 2), (high - low) / 2, np.zeros(len(low))
        )
        return params.pack(), self._coder(params)

    def _load(self, header, skeleton, fps):
        return self._coder(ChannelParams.unpack(header, skeleton.num_channels))

    def _coder(self, params: ChannelParams):
        law = self.config["law"]
        if law == "adaptive":
            n = even_levels(self.config["levels"])
            return AdaptiveCoder(
                ChannelParams(params.constant, params.centre, 2.0 * params.scale / n, np.zeros_like(params.scale)),
                n,
                0,
                3,
                1,
                multipliers(n),
            )
        return TableCoder(params, *table(law, self.config["levels"], self.config["mu"]))
