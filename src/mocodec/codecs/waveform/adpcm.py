"""``adpcm``: adaptive predictive coding (000 §7.6).

The closed loop of fig. 7-4 with both parts adapted backwards, from the decoded signal only
(nothing but the codes is sent): an order-2 predictor whose coefficients come from the last
``window_s`` seconds of decoded samples by the autocorrelation method (7-16 to 7-18), updated
every eighth of a window, and the feedback adaptive quantiser (7-7) on the prediction error,
starting from the step a uniform quantiser would have over the largest frame-to-frame change
of the first frames. Codes range coded as an alphabet of N symbols with adaptive per-channel
models in the context of the previous code. As the thesis found, it beats ``dpcm`` at higher
rates and loses at 4-8 levels, where the coefficients are computed from a coarsely quantised
signal. Delay: none.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.waveform.framewise import FramewiseCodec
from mocodec.coding.quantisation.predictive import AdaptiveCoder, ChannelParams, difference_range
from mocodec.coding.quantisation.quantisers import even_levels, multipliers


@register
class AdpcmCodec(FramewiseCodec):
    id = "adpcm"
    packet_number = 3
    description = "adaptive predictive coding: backward-adaptive order-2 LPC, feedback-adaptive quantiser, range coded"
    knobs = (
        Knob("levels", int, 8, "adaptive quantiser levels N (the thesis: 4-256; rounded to even)", low=2, high=1 << 16),
        Knob("window_s", float, 1.0, "autocorrelation window in seconds (the thesis: 0.5-4)", low=0.05, high=60.0),
        Knob("order", int, 2, "predictor order", low=1, high=2),
    )
    quality = QualityKnob("levels", higher_is_better=True, log_scale=True)
    bounded_codes = True

    def _setup(self, values, skeleton, fps):
        constant = np.ptp(values, axis=0) <= 0
        params = ChannelParams(constant, values[0], difference_range(values, fps), np.zeros(values.shape[1]))
        return params.pack(), self._coder(params, fps)

    def _load(self, header, skeleton, fps):
        return self._coder(ChannelParams.unpack(header, skeleton.num_channels), fps)

    def _coder(self, params: ChannelParams, fps: float) -> AdaptiveCoder:
        n = even_levels(self.config["levels"])
        window = max(3, int(round(self.config["window_s"] * fps)))
        first = ChannelParams(params.constant, params.centre, 2.0 * params.scale / n, params.coefficient)
        return AdaptiveCoder(first, n, self.config["order"], window, max(1, window // 8), multipliers(n))
