"""``subband``: the time-frequency coders of 000 §7.8.2, the subband coder of fig. 7-17 and the
wavelet coder of fig. 7-18.

Blocks of ``block`` frames per channel (16 = 0.53 s at 30 Hz, the thesis's largest tolerable
delay) are split into bands by the 5/3 lifting wavelet (:mod:`mocodec.coding.transforms.subbands`):

* ``variant=bands``: as many splits as make the bands those of the visual MSE (fig. 6-1): at
  30 Hz 0-1.9, 1.9-3.75, 3.75-7.5 and 7.5-15 Hz;
* ``variant=wavelet``: the full decomposition, log2(N) levels, of which only the ``keep``
  largest coefficients of each block and channel are sent (weighted as below), the rest zero.

Each band, its coefficients of consecutive blocks in order, is a signal of its own, coded by
its own closed-loop first-order predictive coder (fig. 7-4; the coefficient per band and
channel from the first frames, (7-14), within [-1, 1]) with a uniform quantiser, its codes range coded with
their own adaptive models. The bit allocation favours the VPSNR: band b's step is
``step R / (a_b^e g_b)``, with R the channel's range, a_b the VMSE weight of the band (6-15),
g_b the weight of a coefficient error in the signal (the split's synthesis gain) and e the
``emphasis``. With e = 1 every band's error would cost the VMSE the same at high rates (slow
bands, where the eye forgives most, coded coarsest); but at the rates that matter most
high-band coefficients quantise to zero and that theory no longer holds: on the CMU clips at 30
Hz, e = 0.5 gives about 0.5 dB more VPSNR at the same rate than e = 1 and 0.6 dB more than
e = 0 (flat, the allocation for plain PSNR), so 0.5 is the default. The decoder smooths
the samples either side of block edges (``smooth``) as the dct coder does. Delay: one block
(plus the frame that waits for the next block's smoothing).
"""

from __future__ import annotations

import math

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.waveform.framewise import BlockwiseCodec
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.quantisation.predictive import ChannelParams, lag_one, run_uniform
from mocodec.coding.transforms import blocks, subbands
from mocodec.errors import CorruptStreamError
from mocodec.metrics.visual import BAND_EDGES_HZ, BAND_WEIGHTS

_COEFFICIENT_SCALE = 127.0  # predictor coefficients travel as int8 / 127


class _State:
    """Both ends' view of the split and of every band's predictive coder."""

    def __init__(self, codec: SubbandCodec, params: ChannelParams, coefficients: np.ndarray, fps: float):
        cfg = codec.config
        self.params, self.active = params, params.active
        self.n, self.levels = cfg["block"], codec.levels(fps)
        self.bounds = subbands.band_bounds(self.n, self.levels)
        gains = subbands.synthesis_gains(self.n, self.levels)
        weights = subbands.visual_weights(self.n, self.levels, fps, BAND_EDGES_HZ, BAND_WEIGHTS) ** cfg["emphasis"]
        self.significance = np.concatenate([np.full(b - a, w * g) for (a, b), w, g in zip(self.bounds, weights, gains)])
        rng = params.scale[self.active]
        self.steps = [cfg["step"] * rng / (w * g) for w, g in zip(weights, gains)]
        self.coefficients = coefficients  # (bands, K)
        self.prev = np.zeros((len(self.bounds), self.active.size))
        self.keep = cfg["keep"]
        self.smoother = blocks.EdgeSmoother(self.n) if cfg["smooth"] else None

    def split(self, x: np.ndarray) -> np.ndarray:
        """Coefficients ``(blocks, N, K)`` of the active channels about their centres, with only
        the ``keep`` most significant of each block and channel left."""
        coeffs = subbands.forward(blocks.split(x - self.params.centre[self.active], self.n), self.levels)
        if 0 < self.keep < self.n:
            weighted = np.abs(coeffs) * self.significance[None, :, None]
            floor = -np.partition(-weighted, self.keep - 1, axis=1)[:, self.keep - 1 : self.keep]
            coeffs = np.where(weighted >= floor, coeffs, 0.0)
        return coeffs

    def band_signal(self, coeffs: np.ndarray, b: int) -> np.ndarray:
        a, z = self.bounds[b]
        return np.ascontiguousarray(coeffs[:, a:z].reshape(coeffs.shape[0] * (z - a), coeffs.shape[2]))

    def run(self, b: int, x: np.ndarray, codes: np.ndarray, decode: bool) -> np.ndarray:
        return run_uniform(x, codes, decode, self.prev[b], self.coefficients[b], self.steps[b])

    def rebuild(self, coeffs: np.ndarray, frames: int) -> np.ndarray:
        blocks = subbands.inverse(coeffs, self.levels)  # (blocks, n, active): none active if all hold still
        x = blocks.reshape(blocks.shape[0] * blocks.shape[1], self.active.size)[:frames]
        out = np.empty((frames, self.params.centre.size))
        out[:] = self.params.centre
        out[:, self.active] = x + self.params.centre[self.active]
        return out


@register
class SubbandCodec(BlockwiseCodec):
    id = "subband"
    packet_number = 6
    description = "subband (VMSE bands) or wavelet (M largest) split of 16-frame blocks, a predictive coder per band"
    knobs = (
        Knob(
            "step",
            float,
            0.02,
            "quantiser step of a weight-1 band, as a fraction of the channel's range",
            low=1e-5,
            high=10.0,
        ),
        Knob(
            "variant",
            str,
            "bands",
            "bands: the VMSE's four bands (fig. 7-17); wavelet: full decomposition (fig. 7-18)",
            choices=("bands", "wavelet"),
        ),
        Knob(
            "keep", int, 0, "coefficients kept per block and channel, the most significant (0: all)", low=0, high=4096
        ),
        Knob(
            "emphasis",
            float,
            0.5,
            "band steps follow the VMSE weights a_b^emphasis (0: flat, for PSNR; 1: in full)",
            low=0.0,
            high=2.0,
        ),
        Knob("block", int, 16, "frames per block N (a power of two; the coding delay)", low=2, high=256),
        Knob("smooth", bool, True, "smooth the samples either side of each block edge on decoding"),
    )
    quality = QualityKnob("step", higher_is_better=False, log_scale=True)

    def levels(self, fps: float) -> int:
        n = self.config["block"]
        if self.config["variant"] == "wavelet":
            return int(math.log2(n))
        return subbands.visual_levels(n, fps, BAND_EDGES_HZ[0])

    # ----- side information --------------------------------------------------------------
    def _setup(self, values, skeleton, fps):
        spread = np.ptp(values, axis=0)
        params = ChannelParams(spread <= 0, values[0], spread, np.zeros(values.shape[1]))
        draft = _State(self, params, np.zeros((1, 0)), fps)
        coeffs = draft.split(values[:, params.active])
        coefficients = np.clip(
            [lag_one(draft.band_signal(coeffs, b), 0.0) for b in range(len(draft.bounds))], -1.0, 1.0
        )
        packed = np.round(coefficients * _COEFFICIENT_SCALE).astype(np.int8)
        state = _State(self, params, packed / _COEFFICIENT_SCALE, fps)
        return join_parts([params.pack(), packed.tobytes()]), state

    def _load(self, header, skeleton, fps):
        packed, coefficients = split_parts(header, 2, "subband header")
        params = ChannelParams.unpack(packed, skeleton.num_channels)
        bands = len(subbands.band_bounds(self.config["block"], self.levels(fps)))
        if len(coefficients) != bands * params.active.size:
            raise CorruptStreamError("subband header: the predictor coefficients do not match the channels")
        packed = np.frombuffer(coefficients, dtype=np.int8).reshape(bands, params.active.size)
        return _State(self, params, packed / _COEFFICIENT_SCALE, fps)

    # ----- coding ----------------------------------------------------------------------------
    def _code(self, state, frames, ahead):
        x = frames[:, state.active]
        if not len(x):
            return [np.zeros((0, x.shape[1]), dtype=np.int64)] * len(state.bounds), frames
        coeffs = state.split(x)
        arrays = []
        for b in range(len(state.bounds)):
            signal = state.band_signal(coeffs, b)
            codes = np.zeros(signal.shape, dtype=np.int64)
            state.run(b, signal, codes, False)
            arrays.append(codes)
        return arrays, frames

    def _uncode(self, state, n, read, last):
        k, m = state.active.size, -(-n // state.n)
        coeffs = np.zeros((m, state.n, k))
        for b, (lo, hi) in enumerate(state.bounds):
            codes = read(m * (hi - lo), k)
            coeffs[:, lo:hi] = state.run(b, np.zeros((0, k)), codes, True).reshape(m, hi - lo, k)
        frames = state.rebuild(coeffs, n)
        return state.smoother.push(frames, last) if state.smoother else frames
