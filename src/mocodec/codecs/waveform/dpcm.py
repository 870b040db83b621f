"""``dpcm``: first-order predictive coding in the closed loop of fig. 7-4 (000 §7.5).

Per channel the prediction is ``p(n) = c + a (y(n-1) - c)`` from the *decoded* previous
sample ``y(n-1)``, with ``c`` the channel's first value and ``a`` the least-squares
first-order coefficient about it ((7-14): R(1)/R(0)) of the first frames coded. The
difference (7-10) is quantised with N levels (uniform or mu-law) over a range chosen per
channel from the frame-to-frame changes of those frames (:func:`best_range`: the range with
the least squared error, overload included), and the codes are range coded with adaptive
per-channel models (7.4). Since the encoder predicts from what the decoder will have,
quantisation errors do not accumulate; a change larger than the range is followed over a few
frames (slope overload). Delay: none; every pushed frame goes out at once.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.waveform.framewise import FramewiseCodec
from mocodec.coding.quantisation.predictive import ChannelParams, TableCoder, best_range, difference_range, first_order
from mocodec.coding.quantisation.quantisers import table


@register
class DpcmCodec(FramewiseCodec):
    id = "dpcm"
    packet_number = 2
    description = "closed-loop first-order predictive coding (DPCM), quantised difference, range coded"
    knobs = (
        Knob(
            "levels",
            int,
            8,
            "difference quantiser levels N (the thesis: 4-256; mu-law rounds to even)",
            low=2,
            high=1 << 16,
        ),
        Knob("law", str, "uniform", "difference quantiser", choices=("uniform", "mulaw")),
        Knob("mu", float, 8.0, "mu of the mu-law quantiser", low=1e-3, high=1e6),
    )
    quality = QualityKnob("levels", higher_is_better=True, log_scale=True)

    def _setup(self, values, skeleton, fps):
        constant = np.ptp(values, axis=0) <= 0
        top, a = difference_range(values, fps), first_order(values)
        draft = ChannelParams(constant, values[0], top, a)
        params = ChannelParams(
            constant, values[0], best_range(values, top, draft.centre, draft.coefficient, *self._table()), a
        )
        return params.pack(), TableCoder(params, *self._table())

    def _load(self, header, skeleton, fps):
        return TableCoder(ChannelParams.unpack(header, skeleton.num_channels), *self._table())

    def _table(self) -> tuple[np.ndarray, np.ndarray]:
        return table(self.config["law"], self.config["levels"], self.config["mu"])
