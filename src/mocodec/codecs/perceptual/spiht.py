"""``spiht``: 1-D SPIHT with perceptual bit allocation, 001 ch. 6.

Per segment of W frames (a power of two, 128 by default) and per channel:

1. Anchors. The channel's value at every segment start (and at the last frame) is sent at 0.1
   degree or 0.1 cm, delta coded; the segment's residual is taken from the straight line
   between its anchors. This is how the root (and every other channel) cannot drift: the
   figure is pinned to the anchors to 0.05 cm, whatever the budget, and a segment's residual
   starts and ends near zero, so the periodised wavelet sees no jump where a walk ends away
   from where it began.
2. The residual, zero-padded to W, goes through a periodised multi-level wavelet (CDF 9/7 by
   default, D4 available; ``levels`` deep, log2(W) - 1 by default: a coarsest band of two,
   better than four; W = 256 better still, at twice the delay: docs/codecs.md), is quantised to a
   fine quantum (1/256 degree or cm) and coded by 1-D SPIHT (:mod:`mocodec.coding.entropy.spiht`).
3. Bit allocation (6.1): B_c = F_c B_T / sum F_i, with B_T = bits_per_second x W / fps and F_c
   the importance of :mod:`mocodec.perception` (``perceptual``: body part, depth, energy, bone
   length; ``energy``; ``uniform``; and ours, ``impact``: amplitude times lever arm, on a log
   scale, which beats all three on joint errors). F_c is sent as a half-octave level (4 bits before entropy
   coding, as changes from the channel's previous segment) so the decoder derives the same
   budgets. A channel the anchor line already gives to within the anchors' precision gets
   F = 0: the encoder knows it, and the budget goes where it is used. Each channel's stream
   stops exactly at its budget, so the SPIHT part of a segment is exactly B_T bits (less only
   when a channel is coded to the quantum before its budget ends).
4. Beyond the thesis, ``closed_loop``: joints are coded parents first and each joint's angles
   are the target that restores its original global orientation on top of its parent's
   *decoded* one (the encoder decodes each stream at its budget, as kinwave does), so coding
   errors stop adding up from the hips to the hands: at 60:1 the median mean joint error falls
   by about a third. The budgets are those of the open-loop coder. The streams stay embedded,
   but a file cut to a lower rate decodes like an open-loop file at that rate (the targets
   compensated the parents' errors at the coded rate), not byte-identical to coding there.

Segments are coded independently, so their errors meet with a small step at every seam; the
decoder spreads the part of each step beyond what the motion itself shows over W/16 frames on
either side (:mod:`mocodec.coding.transforms.seams`). That cuts the jerk at seams about tenfold (131_04
at 15 kbit/s: 5.3 -> 0.46 cm/frame^3, the rest of a segment 0.095) and lowers the mean error a
little; finely coded motion is left as it is.

Streaming: ``encoder``/``decoder`` send one packet per segment, W + 1 + 11 frames behind (the
next segment's first frame is the end anchor; the seam estimate reads 11 frames on each
side), and decode exactly as the whole clip does.

Every channel stream is embedded: cutting each to a smaller budget (``truncate``) gives a
valid, coarser file without re-encoding. Angles are made continuous first
(:meth:`Motion.continuous`).
"""

from __future__ import annotations

import numpy as np

from mocodec import perception
from mocodec.codecs.base import (
    Codec,
    Knob,
    QualityKnob,
    StreamDecoder,
    StreamEncoder,
)
from mocodec.codecs.perceptual import spihtcut, spihtstream
from mocodec.codecs.perceptual.spihtlayout import (
    ANCHOR_QUANTUM,
    F_LEVELS,
    N0_BITS,
    QUANTUM,
    SEAM_LIMIT,
    U32,
    anchor_frames,
    channel_scale,
    importance_levels,
    level_weights,
)
from mocodec.codecs.registry import register
from mocodec.codecs.shared import closedloop
from mocodec.coding.entropy import spiht
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.coding.transforms import seams, wavelets
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.kinematics import forward_kinematics
from mocodec.skeleton import Skeleton


@register
class SpihtCodec(Codec):
    id = "spiht"
    packet_number = 7
    embedded = True
    description = "embedded wavelet coding: 1-D SPIHT per channel, perceptual bit allocation, truncatable streams"
    knobs = (
        Knob("bits_per_second", float, 8000.0, "SPIHT bits per second for the whole figure", low=1.0, high=1e8),
        Knob("window", int, 128, "frames per segment W (a power of two)", low=4, high=1 << 14),
        Knob("wavelet", str, "cdf97", "wavelet", choices=("cdf97", "d4")),
        Knob("levels", int, 0, "decomposition levels (0: log2(W) - 1)", low=0, high=14),
        Knob("allocation", str, "perceptual", "bit allocation across channels", choices=perception.ALLOCATIONS),
        Knob("leg_score", float, 1.0, "body-part score of the legs", low=0.0, high=1.0),
        Knob("upper_score", float, 0.5, "body-part score of arms, torso and head", low=0.0, high=1.0),
        Knob("smooth_seams", bool, True, "smooth the steps where segments meet (decoder side)"),
        Knob(
            "closed_loop",
            bool,
            False,
            "beyond the thesis: code each joint against its parent's decoded "
            "orientation, so errors do not add up along chains",
        ),
    )
    quality = QualityKnob("bits_per_second", higher_is_better=True, log_scale=True)

    def __init__(self, **knobs):
        super().__init__(**knobs)
        w = self.config["window"]
        if w & (w - 1):
            raise CodecError(f"codec spiht: window must be a power of two, got {w}")
        levels = self.config["levels"] or max(int(np.log2(w)) - 1, 0)
        if levels > int(np.log2(w)):
            raise CodecError(f"codec spiht: {levels} levels need a window of at least {1 << levels}")
        self.n_levels = levels

    @property
    def seam_frames(self) -> int:
        """Half width of the seam smoothing: W / 16 (8 frames for W = 128); 0 when it is off."""
        return max(self.config["window"] // 16, 1) if self.config["smooth_seams"] else 0

    def delay_frames(self) -> int:
        """A segment goes out when the first frame of the next one (its end anchor) is in, and
        its last frames once the next segment has smoothed the seam."""
        return self.config["window"] + 1 + (max(self.seam_frames, seams.CONTEXT) if self.seam_frames else 0)

    def segment_frames(self) -> int:
        return self.config["window"]

    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return spihtstream.SpihtStreamEncoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return spihtstream.SpihtStreamDecoder(self, skeleton, fps)

    def _scores(self) -> dict[str, float]:
        legs, upper = self.config["leg_score"], self.config["upper_score"]
        return {p: (legs if p.endswith("_leg") else upper) for p in perception.DEFAULT_SCORES}

    def segments(self, frames: int) -> list[tuple[int, int]]:
        w = self.config["window"]
        return [(a, min(a + w, frames)) for a in range(0, frames, w)]

    def lines(self, anchors: np.ndarray, frames: int) -> np.ndarray:
        """The anchor-to-anchor lines for every frame ``(frames, channels)``."""
        idx = anchor_frames(frames, self.config["window"])
        t = np.arange(frames)
        return np.stack([np.interp(t, idx, anchors[:, c]) for c in range(anchors.shape[1])], axis=1)

    def segment_budgets(self, frames: int, fps: float) -> np.ndarray:
        """B_T of every segment at the codec's bit rate."""
        return np.array(
            [int(np.floor(self.config["bits_per_second"] * (b - a) / fps)) for a, b in self.segments(frames)],
            dtype=np.int64,
        )

    def _encode(self, motion) -> bytes:
        return self.encode_body(motion, self.segment_budgets(motion.num_frames, motion.fps))

    def encode_with_budgets(self, motion, segment_bits: np.ndarray) -> bytes:
        """A body whose segments get the given SPIHT budgets B_T (crowd allocation, 6.5),
        instead of the codec's constant bit rate."""
        segment_bits = np.asarray(segment_bits, dtype=np.int64)
        if segment_bits.shape != (len(self.segments(motion.num_frames)),) or segment_bits.min(initial=0) < 0:
            raise CodecError(f"need {len(self.segments(motion.num_frames))} non-negative segment budgets")
        return self.encode_body(motion, segment_bits)

    def encode_body(self, motion, segment_bits: np.ndarray) -> bytes:
        sk, cfg = motion.skeleton, self.config
        ch = motion.continuous().channels
        frames = len(ch)
        if frames == 0:
            return b""
        scale = channel_scale(sk)
        anchor_q = ANCHOR_QUANTUM * scale
        a_int = np.round(ch[anchor_frames(frames, cfg["window"])] / anchor_q).astype(np.int64)
        residual = ch - self.lines(a_int * anchor_q, frames)
        levels_f, streams = [], []
        for (a, b), total in zip(self.segments(frames), segment_bits):
            lv, bits = self.code_segment(sk, ch[a:b], residual[a:b], int(total))
            levels_f.append(lv)
            streams += bits
        bits = np.concatenate(streams) if streams else np.zeros(0, dtype=np.uint8)
        levels = np.stack(levels_f)  # (segments, channels), sent per channel as changes
        parts = [
            encode_ints(np.diff(a_int, axis=0, prepend=0).T),
            encode_ints(np.diff(levels, axis=0, prepend=0).T),
            encode_ints(np.diff(segment_bits, prepend=0)),
            U32.pack(bits.size) + np.packbits(bits).tobytes(),
        ]
        return join_parts(parts)

    def code_segment(self, sk: Skeleton, values: np.ndarray, residual: np.ndarray, total: int):
        """(importance levels, bit arrays) of one segment: its values and their residual from
        the anchor line, ``(frames, channels)``, under a budget of ``total`` bits."""
        cfg = self.config
        scale = channel_scale(sk)
        f = perception.channel_importance(sk, values, cfg["allocation"], self._scores())
        # a channel the anchors already give to within their precision gets no budget
        f[np.abs(residual).max(axis=0, initial=0) <= 0.5 * ANCHOR_QUANTUM * scale + 1e-12] = 0.0
        lv = importance_levels(f)
        budgets = perception.allocate(level_weights(lv), total)
        streams: list[list[np.ndarray]] = [[] for _ in range(values.shape[1])]
        if cfg["closed_loop"]:
            self._code_closed_loop(sk, values, residual, budgets, streams)
        else:
            self._code_channels(np.arange(values.shape[1]), residual, budgets, scale, streams)
        return lv, [bits for channel in streams for bits in channel]

    def _code_channels(
        self, channels: np.ndarray, residual: np.ndarray, budgets: np.ndarray, scale: np.ndarray, streams: list
    ) -> np.ndarray | None:
        """Code the residual ``(frames, len(channels))`` of some channels into ``streams`` (one
        list per channel); with ``closed_loop``, returns the residual the decoder will make of
        them."""
        cfg = self.config
        w, approx = cfg["window"], cfg["window"] >> self.n_levels
        seg = np.zeros((w, channels.size))
        seg[: len(residual)] = residual
        coeffs = np.round(wavelets.forward(seg.T, cfg["wavelet"], self.n_levels) / (QUANTUM * scale[channels, None]))
        decoded = np.zeros_like(coeffs)
        for i, c in enumerate(channels):
            if budgets[c] <= N0_BITS:
                continue
            bits, n0 = spiht.encode(coeffs[i].astype(np.int64), approx, int(budgets[c]) - N0_BITS)
            head = np.array([(n0 + 1) >> k & 1 for k in range(N0_BITS - 1, -1, -1)], dtype=np.uint8)
            streams[c] += [head, bits]
            if cfg["closed_loop"]:
                decoded[i] = spiht.decode(bits, 0, int(budgets[c]) - N0_BITS, w, approx, n0)[0]
        if not cfg["closed_loop"]:
            return None
        return wavelets.inverse(decoded * (QUANTUM * scale[channels, None]), w, cfg["wavelet"], self.n_levels).T[
            : len(residual)
        ]

    def _code_closed_loop(
        self, sk: Skeleton, values: np.ndarray, residual: np.ndarray, budgets: np.ndarray, streams: list
    ) -> None:
        """Beyond the thesis (kinwave.md, "what mattered" 1): joints coded parents first, each
        joint's angles the closed-loop target that restores its original global orientation on
        top of its parent's decoded one (the stream decoded as the decoder will, before seam
        smoothing), so coding errors stop adding up along the chains; the joints of one tree
        depth are coded together (:func:`closedloop.code_down_tree`). Channels without a
        budget keep their anchor line."""
        scale = channel_scale(sk)
        line = values - residual
        active = budgets > N0_BITS

        def code(channels: np.ndarray, targets: np.ndarray) -> np.ndarray:
            return line[:, channels] + self._code_channels(
                channels, targets - line[:, channels], budgets, scale, streams
            )

        closedloop.code_down_tree(sk, np.where(active, values, line), active, forward_kinematics(sk, values)[1], code)

    def segment_streams(self, levels: np.ndarray, total: int, bits: np.ndarray, cursor: int, where: str):
        """Decode one segment's channel streams from ``bits[cursor:]``: yields (channel, start
        bit, bits used, coefficients, the bit plane it stopped in or -1)."""
        w, approx = self.config["window"], self.config["window"] >> self.n_levels
        budgets = perception.allocate(level_weights(levels), int(total))
        for c in range(levels.size):
            if budgets[c] <= N0_BITS:
                continue
            if cursor + N0_BITS > bits.size:
                raise CorruptStreamError(f"spiht body: bits end in {where}, channel {c}")
            n0 = int(np.dot(bits[cursor : cursor + N0_BITS], 1 << np.arange(N0_BITS - 1, -1, -1))) - 1
            coeffs, used, plane = spiht.decode(bits, cursor + N0_BITS, int(budgets[c]) - N0_BITS, w, approx, n0)
            yield c, cursor, N0_BITS + used, coeffs, plane
            cursor += N0_BITS + used

    def residual(self, coeffs: np.ndarray, skeleton: Skeleton, frames: int) -> np.ndarray:
        """The decoded residual of one segment ``(frames, channels)`` from its coefficients."""
        scale = channel_scale(skeleton)
        seg = wavelets.inverse(
            coeffs * (QUANTUM * scale[:, None]), self.config["window"], self.config["wavelet"], self.n_levels
        )
        return seg.T[:frames]

    def parse_body(self, body: bytes, skeleton: Skeleton, frames: int):
        """(parts, anchor deltas, importance levels, segment budgets, bits) of a body, checked
        against the frames."""
        n_ch = skeleton.num_channels
        parts = split_parts(body, 4, "spiht body")
        deltas = decode_ints(parts[0])
        level_changes = decode_ints(parts[1])
        n_seg = len(self.segments(frames))
        if (
            deltas.size != anchor_frames(frames, self.config["window"]).size * n_ch
            or level_changes.size != n_seg * n_ch
        ):
            raise CorruptStreamError("spiht body: anchor or allocation streams do not match the frames")
        levels_f = np.cumsum(level_changes.reshape(n_ch, n_seg).T, axis=0).ravel()
        if levels_f.size != n_seg * n_ch or levels_f.min(initial=0) < 0 or levels_f.max(initial=0) >= F_LEVELS:
            raise CorruptStreamError("spiht body: anchor or allocation streams do not match the frames")
        totals = np.cumsum(decode_ints(parts[2]))
        if totals.size != n_seg or totals.min(initial=0) < 0:
            raise CorruptStreamError("spiht body: segment budgets do not match the frames")
        (n_bits,) = U32.unpack_from(parts[3])
        bits = np.unpackbits(np.frombuffer(parts[3], dtype=np.uint8, offset=4))[:n_bits]
        if bits.size != n_bits or n_bits > totals.sum():
            raise CorruptStreamError(f"spiht body: {n_bits} bits announced, {bits.size} present")
        return parts, deltas, levels_f, totals, bits

    def walk_streams(self, levels_f, totals, bits, n_ch: int):
        """Decode every channel stream: yields (segment, channel, start bit, bits used, coeffs,
        stop plane)."""
        cursor = 0
        for k, total in enumerate(totals):
            for c, start, used, coeffs, plane in self.segment_streams(
                levels_f[k * n_ch : (k + 1) * n_ch], total, bits, cursor, f"segment {k}"
            ):
                yield k, c, start, used, coeffs, plane
                cursor = start + used
        if cursor != bits.size:
            raise CorruptStreamError(f"spiht body: {bits.size - cursor} bits left over after the last segment")

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        cfg = self.config
        n_ch = skeleton.num_channels
        if frames == 0:
            return np.zeros((0, n_ch))
        _, deltas, levels_f, totals, bits = self.parse_body(body, skeleton, frames)
        scale = channel_scale(skeleton)
        idx = anchor_frames(frames, cfg["window"])
        anchors = np.cumsum(deltas.reshape(n_ch, idx.size).T, axis=0) * (ANCHOR_QUANTUM * scale)
        out = self.lines(anchors, frames)
        segments = self.segments(frames)
        coeffs = np.zeros((len(segments), n_ch, cfg["window"]))
        uncertainty = np.stack(
            [self.uncertainty(levels_f[k * n_ch : (k + 1) * n_ch], skeleton) for k in range(len(segments))]
        )
        for k, c, _, _, values, plane in self.walk_streams(levels_f, totals, bits, n_ch):
            coeffs[k, c] = values
            uncertainty[k, c] = 2.0 ** (plane + 1) * QUANTUM * scale[c]
        for k, (a, b) in enumerate(segments):
            out[a:b] += self.residual(coeffs[k], skeleton, b - a)
        if not self.seam_frames:
            return out
        limits = SEAM_LIMIT * (uncertainty[:-1] + uncertainty[1:])
        return seams.smooth_seams(out, [a for a, _ in segments[1:]], self.seam_frames, limits)

    def uncertainty(self, levels: np.ndarray, skeleton: Skeleton) -> np.ndarray:
        """How far each channel's decoded residual may be off before its stream is read: half
        an anchor step for a channel with no budget by choice (level 0), unknown otherwise."""
        return np.where(levels == 0, 0.5 * ANCHOR_QUANTUM * channel_scale(skeleton), np.inf)

    def truncator(self, body: bytes, skeleton: Skeleton, frames: int, fps: float):
        return spihtcut.truncator(self, body, skeleton, frames, fps)

    def packet_cuts(self, packet: bytes, skeleton: Skeleton) -> np.ndarray:
        return spihtcut.packet_cuts(self, packet, skeleton)

    def packet_cutter(self, packet: bytes, skeleton: Skeleton, cuts: np.ndarray, fps: float):
        return spihtcut.packet_cutter(self, packet, skeleton, cuts, fps)

    def smaller(self, bits_per_second: float) -> SpihtCodec:
        if bits_per_second > self.config["bits_per_second"]:
            raise CodecError(
                f"cannot truncate to {bits_per_second:g} bit/s, above the coded {self.config['bits_per_second']:g}"
            )
        return self.at_rate(bits_per_second)

    def at_rate(self, bits_per_second: float) -> SpihtCodec:
        return SpihtCodec(**{**self.config, "bits_per_second": bits_per_second})
