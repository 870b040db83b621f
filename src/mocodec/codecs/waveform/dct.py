"""``dct``: block DCT coding with speed-adaptive quantiser tables (000 §7.8.1).

Blocks of ``block`` = 16 frames per channel, the orthonormal DCT-II, Appendix III's bit table
``table`` (0-4) scaled by ``scale``, the per-block speed class sent as side information
(``adaptive``), the DC predicted from the previous block, and the block-edge smoothing of the
decoder (``smooth``). Codes and classes are range coded with adaptive models. The channel's AC
range, DC range and largest block speed come from the first frames coded (the whole clip, or
the first push of a stream). See :mod:`mocodec.coding.transforms.blockdct`. Delay: one block (plus the
frame that waits for the next block's smoothing).
"""

from __future__ import annotations

import math

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.waveform.framewise import BlockwiseCodec
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.quantisation.predictive import ChannelParams
from mocodec.coding.transforms import blockdct, blocks as blockcut
from mocodec.errors import CorruptStreamError


class _State:
    def __init__(self, codec: DctCodec, params: ChannelParams, top_speed: np.ndarray):
        cfg = codec.config
        self.params, self.active = params, params.active
        self.n = cfg["block"]
        self.bits = blockdct.bits(cfg["table"], self.n)
        self.sent_ac = np.flatnonzero(self.bits[1:] > 0) + 1
        self.thresholds = blockdct.SPEED_THRESHOLDS[cfg["table"]]
        self.adaptive, self.smooth, self.scale = cfg["adaptive"], cfg["smooth"], cfg["scale"]
        self.ac_range = params.scale[self.active]
        self.dc_range = params.coefficient[self.active]
        self.top_speed = top_speed
        self.dc = params.centre[self.active] * math.sqrt(self.n)  # the decoded DC of the last block
        self.smoother = blockcut.EdgeSmoother(self.n)  # decoder side

    def multipliers(self, classes: np.ndarray) -> np.ndarray:
        return self.scale * blockdct.class_scale(classes)

    def ac_steps(self, mult: np.ndarray) -> np.ndarray:
        """``(blocks, sent AC, K)`` steps."""
        return 2.0 * self.ac_range[None, None, :] / (2.0 ** self.bits[self.sent_ac])[None, :, None] * mult[:, None, :]

    def dc_step(self, mult_row: np.ndarray) -> np.ndarray:
        return 2.0 * self.dc_range / 2.0 ** self.bits[0] * mult_row

    def rebuild(self, coeffs: np.ndarray, frames: int) -> np.ndarray:
        blocks = blockdct.inverse(coeffs)  # (blocks, n, active): none active if all hold still
        x = blocks.reshape(blocks.shape[0] * blocks.shape[1], self.active.size)[:frames]
        out = np.empty((frames, self.params.centre.size))
        out[:] = self.params.centre
        out[:, self.active] = x
        return out


@register
class DctCodec(BlockwiseCodec):
    id = "dct"
    packet_number = 5
    description = "block DCT (N=16) with fixed bit tables, speed-adaptive steps, block-edge smoothing"
    knobs = (
        Knob("table", int, 1, "bit table and speed thresholds (0 finest .. 4 coarsest)", low=0, high=4),
        Knob("scale", float, 1.0, "multiplies every quantiser step", low=1e-3, high=1e3),
        Knob("block", int, 16, "frames per block N (a power of two; the coding delay)", low=2, high=256),
        Knob("adaptive", bool, True, "speed-adaptive steps (the class of each block sent)"),
        Knob("smooth", bool, True, "smooth the samples either side of each block edge on decoding"),
    )
    quality = QualityKnob("scale", higher_is_better=False, log_scale=True)

    # ----- side information --------------------------------------------------------------
    def _setup(self, values, skeleton, fps):
        n = self.config["block"]
        constant = np.ptp(values, axis=0) <= 0
        blocks = blockcut.split(values, n)
        coeffs = blockdct.forward(blocks)
        ac = np.abs(coeffs[:, 1:]).max(axis=(0, 1)) if n > 1 else np.zeros(values.shape[1])
        dc = np.concatenate([values[:1] * math.sqrt(n), coeffs[:, 0]])
        params = ChannelParams(constant, values[0], ac, np.abs(np.diff(dc, axis=0)).max(axis=0))
        top = blockdct.block_speed(blocks).max(axis=0)[params.active].astype(np.float16)
        return join_parts([params.pack(), top.tobytes()]), _State(self, params, top.astype(np.float64))

    def _load(self, header, skeleton, fps):
        packed, top = split_parts(header, 2, "dct header")
        params = ChannelParams.unpack(packed, skeleton.num_channels)
        top = np.frombuffer(top, dtype="<f2").astype(np.float64)
        if top.size != params.active.size or not np.isfinite(top).all():
            raise CorruptStreamError("dct header: the block speeds do not match the channels")
        return _State(self, params, top)

    # ----- coding ----------------------------------------------------------------------------
    def _code(self, state, frames, ahead):
        x = frames[:, state.active]
        if not len(x):
            return [np.zeros((0, x.shape[1]), dtype=np.int64)] * 2, frames
        blocks = blockcut.split(x, state.n)
        coeffs = blockdct.forward(blocks)
        classes = (
            blockdct.speed_classes(blockdct.block_speed(blocks), state.top_speed, state.thresholds)
            if state.adaptive
            else np.zeros(blocks[:, 0].shape, dtype=np.int64)
        )
        mult = state.multipliers(classes)
        steps = state.ac_steps(mult)
        codes = np.zeros((len(blocks), 1 + state.sent_ac.size, x.shape[1]), dtype=np.int64)
        codes[:, 1:] = blockdct.mid_tread(coeffs[:, state.sent_ac], steps, state.ac_range)
        for b in range(len(blocks)):  # the DC in a closed loop, block after block
            step = state.dc_step(mult[b])
            codes[b, 0] = blockdct.mid_tread(coeffs[b, 0] - state.dc, step, state.dc_range)
            state.dc = state.dc + codes[b, 0] * step
        return [classes, codes.reshape(codes.shape[0] * codes.shape[1], x.shape[1])], frames

    def _uncode(self, state, n, read, last):
        k = state.active.size
        m = -(-n // state.n)
        classes = np.clip(read(m, k), 0, len(state.thresholds))
        codes = read(m * (1 + state.sent_ac.size), k).reshape(m, 1 + state.sent_ac.size, k)
        mult = state.multipliers(classes)
        coeffs = np.zeros((m, state.n, k))
        coeffs[:, state.sent_ac] = codes[:, 1:] * state.ac_steps(mult)
        for b in range(m):
            state.dc = state.dc + codes[b, 0] * state.dc_step(mult[b])
            coeffs[b, 0] = state.dc
        frames = state.rebuild(coeffs, n)
        return state.smoother.push(frames, last) if state.smooth else frames
