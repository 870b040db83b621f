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

import struct

import numpy as np

from mocodec import perception
from mocodec.codecs.base import (
    Codec,
    Coded,
    HeldFrames,
    Knob,
    QualityKnob,
    StreamDecoder,
    StreamEncoder,
    continuous_frames,
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

QUANTUM = 1.0 / 256  # degrees, or cm for translations: the finest SPIHT plane
ANCHOR_QUANTUM = 0.1  # degrees, or cm: the root is pinned to within 0.05 cm
N0_BITS = 6  # each channel stream starts with its top plane + 1 (0: all zero)
SEAM_LIMIT = 2.0  # a seam step is removed up to twice the two sides' coding uncertainty
F_LEVELS = 16  # importance sent as half-octave levels 1..15 below the segment's top; 0 = none
_U32 = struct.Struct("<I")


def channel_scale(skeleton: Skeleton) -> np.ndarray:
    """Per channel, skeleton units (or degrees) per cm (or degree)."""
    return np.where(skeleton.rotation_mask, 1.0, skeleton.units_per_metre / 100.0)


def importance_levels(f: np.ndarray) -> np.ndarray:
    """F as levels: 15 for the largest, one less per half octave below it, 1 at least; 0 for 0."""
    top = f.max() if f.size else 0.0
    if top <= 0:
        return np.zeros(f.size, dtype=np.int64)
    with np.errstate(divide="ignore"):
        level = F_LEVELS - 1 + np.round(2 * np.log2(f / top))
    return np.where(f > 0, np.clip(level, 1, F_LEVELS - 1), 0).astype(np.int64)


def level_weights(levels: np.ndarray) -> np.ndarray:
    return np.where(levels > 0, 2.0 ** ((levels - (F_LEVELS - 1)) / 2.0), 0.0)


def anchor_frames(frames: int, window: int) -> np.ndarray:
    starts = np.arange(0, frames, window)
    return starts if frames - 1 in starts else np.append(starts, frames - 1)


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
        return _StreamEncoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return _StreamDecoder(self, skeleton, fps)

    def _scores(self) -> dict[str, float]:
        legs, upper = self.config["leg_score"], self.config["upper_score"]
        return {p: (legs if p.endswith("_leg") else upper) for p in perception.DEFAULT_SCORES}

    def _segments(self, frames: int) -> list[tuple[int, int]]:
        w = self.config["window"]
        return [(a, min(a + w, frames)) for a in range(0, frames, w)]

    def _lines(self, anchors: np.ndarray, frames: int) -> np.ndarray:
        """The anchor-to-anchor lines for every frame ``(frames, channels)``."""
        idx = anchor_frames(frames, self.config["window"])
        t = np.arange(frames)
        return np.stack([np.interp(t, idx, anchors[:, c]) for c in range(anchors.shape[1])], axis=1)

    def segment_budgets(self, frames: int, fps: float) -> np.ndarray:
        """B_T of every segment at the codec's bit rate."""
        return np.array(
            [int(np.floor(self.config["bits_per_second"] * (b - a) / fps)) for a, b in self._segments(frames)],
            dtype=np.int64,
        )

    def _encode(self, motion) -> bytes:
        return self.encode_body(motion, self.segment_budgets(motion.num_frames, motion.fps))

    def encode_with_budgets(self, motion, segment_bits: np.ndarray) -> bytes:
        """A payload whose segments get the given SPIHT budgets B_T (crowd allocation, 6.5),
        instead of the codec's constant bit rate."""
        segment_bits = np.asarray(segment_bits, dtype=np.int64)
        if segment_bits.shape != (len(self._segments(motion.num_frames)),) or segment_bits.min(initial=0) < 0:
            raise CodecError(f"need {len(self._segments(motion.num_frames))} non-negative segment budgets")
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
        residual = ch - self._lines(a_int * anchor_q, frames)
        levels_f, streams = [], []
        for (a, b), total in zip(self._segments(frames), segment_bits):
            lv, bits = self._code_segment(sk, ch[a:b], residual[a:b], int(total))
            levels_f.append(lv)
            streams += bits
        bits = np.concatenate(streams) if streams else np.zeros(0, dtype=np.uint8)
        levels = np.stack(levels_f)  # (segments, channels), sent per channel as changes
        parts = [
            encode_ints(np.diff(a_int, axis=0, prepend=0).T),
            encode_ints(np.diff(levels, axis=0, prepend=0).T),
            encode_ints(np.diff(segment_bits, prepend=0)),
            _U32.pack(bits.size) + np.packbits(bits).tobytes(),
        ]
        return join_parts(parts)

    def _code_segment(self, sk: Skeleton, values: np.ndarray, residual: np.ndarray, total: int):
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

    def _segment_streams(self, levels: np.ndarray, total: int, bits: np.ndarray, cursor: int, where: str):
        """Decode one segment's channel streams from ``bits[cursor:]``: yields (channel, start
        bit, bits used, coefficients, the bit plane it stopped in or -1)."""
        w, approx = self.config["window"], self.config["window"] >> self.n_levels
        budgets = perception.allocate(level_weights(levels), int(total))
        for c in range(levels.size):
            if budgets[c] <= N0_BITS:
                continue
            if cursor + N0_BITS > bits.size:
                raise CorruptStreamError(f"spiht payload: bits end in {where}, channel {c}")
            n0 = int(np.dot(bits[cursor : cursor + N0_BITS], 1 << np.arange(N0_BITS - 1, -1, -1))) - 1
            coeffs, used, plane = spiht.decode(bits, cursor + N0_BITS, int(budgets[c]) - N0_BITS, w, approx, n0)
            yield c, cursor, N0_BITS + used, coeffs, plane
            cursor += N0_BITS + used

    def _residual(self, coeffs: np.ndarray, skeleton: Skeleton, frames: int) -> np.ndarray:
        """The decoded residual of one segment ``(frames, channels)`` from its coefficients."""
        scale = channel_scale(skeleton)
        seg = wavelets.inverse(
            coeffs * (QUANTUM * scale[:, None]), self.config["window"], self.config["wavelet"], self.n_levels
        )
        return seg.T[:frames]

    def _parse(self, body: bytes, skeleton: Skeleton, frames: int):
        """(parts, anchor deltas, importance levels, segment budgets, bits) of a body, checked
        against the frames."""
        n_ch = skeleton.num_channels
        parts = split_parts(body, 4, "spiht payload")
        deltas = decode_ints(parts[0])
        level_changes = decode_ints(parts[1])
        n_seg = len(self._segments(frames))
        if (
            deltas.size != anchor_frames(frames, self.config["window"]).size * n_ch
            or level_changes.size != n_seg * n_ch
        ):
            raise CorruptStreamError("spiht payload: anchor or allocation streams do not match the frames")
        levels_f = np.cumsum(level_changes.reshape(n_ch, n_seg).T, axis=0).ravel()
        if levels_f.size != n_seg * n_ch or levels_f.min(initial=0) < 0 or levels_f.max(initial=0) >= F_LEVELS:
            raise CorruptStreamError("spiht payload: anchor or allocation streams do not match the frames")
        totals = np.cumsum(decode_ints(parts[2]))
        if totals.size != n_seg or totals.min(initial=0) < 0:
            raise CorruptStreamError("spiht payload: segment budgets do not match the frames")
        (n_bits,) = _U32.unpack_from(parts[3])
        bits = np.unpackbits(np.frombuffer(parts[3], dtype=np.uint8, offset=4))[:n_bits]
        if bits.size != n_bits or n_bits > totals.sum():
            raise CorruptStreamError(f"spiht payload: {n_bits} bits announced, {bits.size} present")
        return parts, deltas, levels_f, totals, bits

    def _walk(self, levels_f, totals, bits, n_ch: int):
        """Decode every channel stream: yields (segment, channel, start bit, bits used, coeffs,
        stop plane)."""
        cursor = 0
        for k, total in enumerate(totals):
            for c, start, used, coeffs, plane in self._segment_streams(
                levels_f[k * n_ch : (k + 1) * n_ch], total, bits, cursor, f"segment {k}"
            ):
                yield k, c, start, used, coeffs, plane
                cursor = start + used
        if cursor != bits.size:
            raise CorruptStreamError(f"spiht payload: {bits.size - cursor} bits left over after the last segment")

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        cfg = self.config
        n_ch = skeleton.num_channels
        if frames == 0:
            return np.zeros((0, n_ch))
        _, deltas, levels_f, totals, bits = self._parse(body, skeleton, frames)
        scale = channel_scale(skeleton)
        idx = anchor_frames(frames, cfg["window"])
        anchors = np.cumsum(deltas.reshape(n_ch, idx.size).T, axis=0) * (ANCHOR_QUANTUM * scale)
        out = self._lines(anchors, frames)
        segments = self._segments(frames)
        coeffs = np.zeros((len(segments), n_ch, cfg["window"]))
        uncertainty = np.stack(
            [self._uncertainty(levels_f[k * n_ch : (k + 1) * n_ch], skeleton) for k in range(len(segments))]
        )
        for k, c, _, _, values, plane in self._walk(levels_f, totals, bits, n_ch):
            coeffs[k, c] = values
            uncertainty[k, c] = 2.0 ** (plane + 1) * QUANTUM * scale[c]
        for k, (a, b) in enumerate(segments):
            out[a:b] += self._residual(coeffs[k], skeleton, b - a)
        if not self.seam_frames:
            return out
        limits = SEAM_LIMIT * (uncertainty[:-1] + uncertainty[1:])
        return seams.smooth_seams(out, [a for a, _ in segments[1:]], self.seam_frames, limits)

    def _uncertainty(self, levels: np.ndarray, skeleton: Skeleton) -> np.ndarray:
        """How far each channel's decoded residual may be off before its stream is read: half
        an anchor step for a channel with no budget by choice (level 0), unknown otherwise."""
        return np.where(levels == 0, 0.5 * ANCHOR_QUANTUM * channel_scale(skeleton), np.inf)

    def truncator(self, body: bytes, skeleton: Skeleton, frames: int, fps: float):
        """A function bits_per_second -> (the codec of that rate, the body cut to it, without
        re-encoding: every segment budget shrinks by bits_per_second / the codec's rate, and
        every channel stream keeps the prefix its new budget allows). The streams are
        decoded once to find where each ends, so a rate search cuts many times cheaply."""
        if frames == 0:
            return lambda bps: (self._smaller(bps), body)
        parts, _, levels_f, totals, bits = self._parse(body, skeleton, frames)
        n_ch = skeleton.num_channels
        streams = [(k, c, start, used) for k, c, start, used, _, _ in self._walk(levels_f, totals, bits, n_ch)]
        rate_coded = np.array_equal(totals, self.segment_budgets(frames, fps))

        def cut(bits_per_second: float) -> tuple[SpihtCodec, bytes]:
            smaller = self._smaller(bits_per_second)
            if rate_coded:
                new_totals = smaller.segment_budgets(frames, fps)  # as if encoded at the new rate
            else:  # explicit (crowd) budgets scale
                new_totals = np.floor(totals * (bits_per_second / self.config["bits_per_second"])).astype(np.int64)
            budgets = [
                perception.allocate(level_weights(levels_f[k * n_ch : (k + 1) * n_ch]), int(t))
                for k, t in enumerate(new_totals)
            ]
            keep = [
                bits[start : start + min(used, int(budgets[k][c]))]
                for k, c, start, used in streams
                if budgets[k][c] > N0_BITS
            ]
            new_bits = np.concatenate(keep) if keep else np.zeros(0, dtype=np.uint8)
            new_parts = [
                parts[0],
                parts[1],
                encode_ints(np.diff(new_totals, prepend=0)),
                _U32.pack(new_bits.size) + np.packbits(new_bits).tobytes(),
            ]
            return smaller, join_parts(new_parts)

        return cut

    def packet_cuts(self, packet: bytes, skeleton: Skeleton) -> np.ndarray:
        """The bits each channel stream of a stream packet uses, in stream order: what
        :meth:`packet_cutter` needs to cut the packet without decoding it (a sender works it
        out once, a relay then cuts for every viewer)."""
        _, _, levels, total, bits = self._packet_fields(packet, skeleton)
        return np.array(
            [used for _, _, used, _, _ in self._segment_streams(levels, total, bits, 0, "the packet")], dtype=np.int64
        )

    def packet_cutter(self, packet: bytes, skeleton: Skeleton, cuts: np.ndarray, fps: float):
        """A function bits_per_second -> the packet cut to that rate (if below its own): every
        channel keeps the prefix of its embedded stream its new share allows, so it decodes to a
        coarser segment with no re-encoding, the same bytes as coding at that rate;
        the packet is parsed once, so cutting it for many viewers costs a few array operations
        each."""
        head, parts, levels, total, bits = self._packet_fields(packet, skeleton)
        frames = _PACKET.unpack_from(head)[1]
        weights = level_weights(levels)
        present = np.flatnonzero(perception.allocate(weights, total) > N0_BITS)
        if cuts.size != present.size or cuts.min(initial=0) < 0 or cuts.sum() != bits.size:
            raise CorruptStreamError("spiht packet: the cut table does not match the packet's streams")
        starts = np.cumsum(cuts) - cuts

        def cut(bits_per_second: float) -> bytes:
            total_bits = max(int(np.floor(bits_per_second * frames / fps)), 0)
            if total_bits >= total:
                return packet
            new = perception.allocate(weights, total_bits)[present]
            keep = np.where(new > N0_BITS, np.minimum(cuts, new), 0)
            # the kept prefixes, gathered in one indexing: work in proportion to what is kept
            kept = bits[np.arange(keep.sum()) + np.repeat(starts - (np.cumsum(keep) - keep), keep)]
            return head + join_parts(
                [*parts[:-2], _U32.pack(total_bits), _U32.pack(kept.size) + np.packbits(kept).tobytes()]
            )

        return cut

    def _packet_fields(self, packet: bytes, skeleton: Skeleton):
        """(packet header bytes, parts, levels, segment budget, bits) of a stream packet."""
        if len(packet) < _PACKET.size:
            raise CorruptStreamError(f"spiht packet of {len(packet)} bytes is shorter than its header")
        parts = split_parts(packet, None, "spiht packet", start=_PACKET.size)
        if len(parts) not in (4, 5):
            raise CorruptStreamError(f"spiht packet: {len(parts)} parts, expected 4 or 5")
        levels = decode_ints(parts[-3])
        total = _packet_total(parts[-2])
        if len(parts[-1]) < _U32.size:
            raise CorruptStreamError(
                f"spiht packet: its bit stream part is {len(parts[-1])} bytes, shorter than its 4-byte length"
            )
        (n_bits,) = _U32.unpack_from(parts[-1])
        bits = np.unpackbits(np.frombuffer(parts[-1], dtype=np.uint8, offset=4))[:n_bits]
        if (
            levels.size != skeleton.num_channels
            or bits.size != n_bits
            or levels.min(initial=0) < 0
            or levels.max(initial=0) >= F_LEVELS
        ):
            raise CorruptStreamError("spiht packet: levels or bits do not fit the skeleton")
        return packet[: _PACKET.size], parts, levels, int(total), bits

    def _smaller(self, bits_per_second: float) -> SpihtCodec:
        if bits_per_second > self.config["bits_per_second"]:
            raise CodecError(
                f"cannot truncate to {bits_per_second:g} bit/s, above the coded {self.config['bits_per_second']:g}"
            )
        return SpihtCodec(**{**self.config, "bits_per_second": bits_per_second})


_PACKET = struct.Struct("<BI")  # flags (1: carries the start anchors, 2: last segment), frames


def _packet_total(part: bytes) -> int:
    """A stream packet's segment budget B_T (a plain u32, so a relay rewrites it cheaply)."""
    if len(part) != _U32.size:
        raise CorruptStreamError(f"spiht packet: a {len(part)}-byte segment budget, expected {_U32.size}")
    return _U32.unpack(part)[0]


def _line(start: np.ndarray, end: np.ndarray, frames: int, span: int) -> np.ndarray:
    t = np.arange(frames)[:, None] / max(span, 1)
    return start + (end - start) * t


class _StreamEncoder(StreamEncoder):
    """Frames in, one packet per segment out, W + 1 frames behind (the batch coder's anchors,
    lines and budgets, so the frames decode exactly as the whole clip would)."""

    def __init__(self, codec: SpihtCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.window = codec.config["window"]
        self.anchor_q = ANCHOR_QUANTUM * channel_scale(skeleton)
        self.buffer = np.zeros((0, skeleton.num_channels))
        self.previous: np.ndarray | None = None  # last continuous frame seen
        self.start: np.ndarray | None = None  # the current segment's start anchor (ints)
        self.out = HeldFrames(max(codec.seam_frames, seams.CONTEXT) if codec.seam_frames else 0)

    def code(self, frames: np.ndarray) -> list[Coded]:
        cont = continuous_frames("spiht", self.skeleton, self.fps, frames, self.previous)
        if not len(cont):
            return []
        self.previous = cont[-1]
        self.buffer = np.vstack((self.buffer, cont))
        packets = []
        while len(self.buffer) > self.window:
            packets.append(self._coded(self.buffer[: self.window + 1], last=False))
            self.buffer = self.buffer[self.window :]
        return packets

    def finish(self) -> list[Coded]:
        if not len(self.buffer):
            return []
        packet = self._coded(self.buffer, last=True)
        self.buffer = self.buffer[:0]
        return [packet]

    def _coded(self, values: np.ndarray, last: bool) -> Coded:
        """A packet, the frames the decoder gives out for it (it holds the seam's context back)
        and its cut table (each channel stream's length: :meth:`SpihtCodec.packet_cuts`)."""
        packet = self._packet(values, last)
        frames = self.out.out(len(values) if last else self.window, last)
        return Coded(packet, frames, tuple(self.codec.packet_cuts(packet, self.skeleton).tolist()))

    def _packet(self, values: np.ndarray, last: bool) -> bytes:
        n = len(values) if last else self.window
        first = self.start is None
        start = np.round(values[0] / self.anchor_q).astype(np.int64) if self.start is None else self.start
        self.start = start
        end = np.round(values[-1] / self.anchor_q).astype(np.int64)
        residual = values[:n] - _line(start * self.anchor_q, end * self.anchor_q, n, n - 1 if last else n)
        total = int(np.floor(self.codec.config["bits_per_second"] * n / self.fps))
        levels, streams = self.codec._code_segment(self.skeleton, values[:n], residual, total)
        bits = np.concatenate(streams) if streams else np.zeros(0, dtype=np.uint8)
        parts = ([encode_ints(start)] if first else []) + [
            encode_ints(end - start),
            encode_ints(levels),
            _U32.pack(total),
            _U32.pack(bits.size) + np.packbits(bits).tobytes(),
        ]
        self.start = end
        return _PACKET.pack(int(first) | 2 * int(last), n) + join_parts(parts)


class _StreamDecoder(StreamDecoder):
    """Packets in, frames out, exactly as the whole clip decodes; a damaged or out-of-order
    packet raises CorruptStreamError and leaves the decoder as it was."""

    def __init__(self, codec: SpihtCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.anchor_q = ANCHOR_QUANTUM * channel_scale(skeleton)
        self.start: np.ndarray | None = None
        self.held = np.zeros((0, skeleton.num_channels))  # last frames, until their seam is smoothed
        self.held_uncertainty = np.zeros(skeleton.num_channels)

    def push(self, packet: bytes) -> np.ndarray:
        """The frames this packet completes: the previous segment's held tail and this
        segment but its own last frames, which wait for the next seam (all of it for the last
        segment)."""
        try:
            frames, last, uncertainty = self._push(packet)
        except CorruptStreamError:
            raise
        except Exception as e:  # noqa: BLE001 - a packet that does not parse
            raise CorruptStreamError(f"spiht packet does not decode ({type(e).__name__}: {e})") from None
        joined = np.vstack((self.held, frames))
        if len(self.held):
            limits = SEAM_LIMIT * (self.held_uncertainty + uncertainty)[None, :]
            joined = seams.smooth_seams(joined, [len(self.held)], self.codec.seam_frames, limits)
        self.held_uncertainty = uncertainty
        hold = max(self.codec.seam_frames, seams.CONTEXT) if self.codec.seam_frames else 0
        keep = 0 if last else min(hold, len(joined))
        self.held = joined[len(joined) - keep :]
        return joined[: len(joined) - keep]

    def _push(self, packet: bytes) -> tuple[np.ndarray, bool, np.ndarray]:
        flags, n = _PACKET.unpack_from(packet)
        n_ch = self.skeleton.num_channels
        if not 0 < n <= self.codec.config["window"]:
            raise CorruptStreamError(f"spiht packet: {n} frames in a segment of {self.codec.config['window']}")
        parts = split_parts(packet, None, "spiht packet", start=_PACKET.size)
        start = self.start
        if flags & 1:
            start = decode_ints(parts.pop(0))
        if start is None or len(parts) != 4 or start.size != n_ch:
            raise CorruptStreamError("spiht packet: no start anchors (a packet is missing) or wrong layout")
        end = start + decode_ints(parts[0])
        levels = decode_ints(parts[1])
        total = _packet_total(parts[2])
        (n_bits,) = _U32.unpack_from(parts[3])
        bits = np.unpackbits(np.frombuffer(parts[3], dtype=np.uint8, offset=4))[:n_bits]
        if (
            end.size != n_ch
            or levels.size != n_ch
            or bits.size != n_bits
            or n_bits > total
            or levels.min(initial=0) < 0
            or levels.max(initial=0) >= F_LEVELS
        ):
            raise CorruptStreamError("spiht packet: anchors, levels or bits do not fit the skeleton")
        coeffs = np.zeros((n_ch, self.codec.config["window"]))
        uncertainty = self.codec._uncertainty(levels, self.skeleton)
        scale = channel_scale(self.skeleton)
        cursor = 0
        for c, first, used, values, plane in self.codec._segment_streams(levels, total, bits, 0, "the packet"):
            coeffs[c] = values
            uncertainty[c] = 2.0 ** (plane + 1) * QUANTUM * scale[c]
            cursor = first + used
        if cursor != n_bits:
            raise CorruptStreamError(f"spiht packet: {n_bits - cursor} bits left over")
        out = _line(start * self.anchor_q, end * self.anchor_q, n, n - 1 if flags & 2 else n)
        out += self.codec._residual(coeffs, self.skeleton, n)
        self.start = end
        return out, bool(flags & 2), uncertainty
