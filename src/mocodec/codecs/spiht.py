"""``spiht``: 1-D SPIHT with perceptual bit allocation, 001 ch. 6.

Per segment of W frames (a power of two, 128 by default) and per channel:

1. Anchors. The channel's value at every segment start (and at the last frame) is sent at 0.1
   degree or 0.1 cm, delta coded; the segment's residual is taken from the straight line
   between its anchors. This is how the root (and every other channel) cannot drift: the
   figure is pinned to the anchors to 0.05 cm, whatever the budget, and a segment's residual
   starts and ends near zero, so the periodised wavelet sees no jump where a walk ends away
   from where it began.
2. The residual, zero-padded to W, goes through a periodised multi-level wavelet (CDF 9/7 by
   default, D4 available; ``levels`` deep, coarsest band of W / 2^levels), is quantised to a
   fine quantum (1/256 degree or cm) and coded by 1-D SPIHT (:mod:`mocodec.coding.spiht`).
3. Bit allocation (6.1): B_c = F_c B_T / sum F_i, with B_T = bits_per_second x W / fps and F_c
   the importance of :mod:`mocodec.perception` (``perceptual``: body part, depth, energy, bone
   length; ``energy``; ``uniform``). F_c is sent as a half-octave level (4 bits before entropy
   coding, as changes from the channel's previous segment) so the decoder derives the same
   budgets. A channel the anchor line already gives to within the anchors' precision gets
   F = 0: the encoder knows it, and the budget goes where it is used. Each channel's stream
   stops exactly at its budget, so the SPIHT part of a segment is exactly B_T bits (less only
   when a channel is coded to the quantum before its budget ends).

Every channel stream is embedded: cutting each to a smaller budget (``truncate``) gives a
valid, coarser file without re-encoding. Angles are made continuous first
(:meth:`Motion.continuous`).
"""

from __future__ import annotations

import struct

import numpy as np

from mocodec import perception
from mocodec.codecs.base import Codec, Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.coding import spiht, wavelets
from mocodec.coding.rangecoder import decode_ints, encode_ints
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.skeleton import Skeleton

QUANTUM = 1.0 / 256          # degrees, or cm for translations: the finest SPIHT plane
ANCHOR_QUANTUM = 0.1         # degrees, or cm: the root is pinned to within 0.05 cm
N0_BITS = 6                  # each channel stream starts with its top plane + 1 (0: all zero)
F_LEVELS = 16                # importance sent as half-octave levels 1..15 below the segment's top; 0 = none
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
    description = "001 ch. 6: wavelet + 1-D SPIHT per channel, perceptual bit allocation, embedded streams"
    knobs = (
        Knob("bits_per_second", float, 8000.0, "SPIHT bits per second for the whole figure", low=1.0, high=1e8),
        Knob("window", int, 128, "frames per segment W (a power of two)", low=4, high=1 << 14),
        Knob("wavelet", str, "cdf97", "wavelet", choices=("cdf97", "d4")),
        Knob("levels", int, 0, "decomposition levels (0: log2(W) - 2)", low=0, high=14),
        Knob("allocation", str, "perceptual", "bit allocation (6.1)", choices=perception.ALLOCATIONS),
        Knob("leg_score", float, 1.0, "body-part score of the legs", low=0.0, high=1.0),
        Knob("upper_score", float, 0.5, "body-part score of arms, torso and head", low=0.0, high=1.0),
    )
    quality = QualityKnob("bits_per_second", higher_is_better=True, log_scale=True)

    def __init__(self, **knobs):
        super().__init__(**knobs)
        w = self.config["window"]
        if w & (w - 1):
            raise CodecError(f"codec spiht: window must be a power of two, got {w}")
        levels = self.config["levels"] or max(int(np.log2(w)) - 2, 0)
        if levels > int(np.log2(w)):
            raise CodecError(f"codec spiht: {levels} levels need a window of at least {1 << levels}")
        self.n_levels = levels

    @property
    def delay_frames(self) -> int:
        return self.config["window"]

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
        return np.array([int(np.floor(self.config["bits_per_second"] * (b - a) / fps))
                         for a, b in self._segments(frames)], dtype=np.int64)

    def _encode(self, motion) -> bytes:
        return self.encode_body(motion, self.segment_budgets(motion.num_frames, motion.fps))

    def encode_with_budgets(self, motion, segment_bits: np.ndarray) -> bytes:
        """A payload whose segments get the given SPIHT budgets B_T (crowd allocation, 6.5),
        instead of the codec's constant bit rate."""
        segment_bits = np.asarray(segment_bits, dtype=np.int64)
        if segment_bits.shape != (len(self._segments(motion.num_frames)),) or segment_bits.min(initial=0) < 0:
            raise CodecError(f"need {len(self._segments(motion.num_frames))} non-negative segment budgets")
        return self.wrap(self.encode_body(motion, segment_bits), motion.num_frames, motion.fps)

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
        w, approx = cfg["window"], cfg["window"] >> self.n_levels
        levels_f, streams = [], []
        for (a, b), total in zip(self._segments(frames), segment_bits):
            seg = np.zeros((w, ch.shape[1]))
            seg[:b - a] = residual[a:b]
            coeffs = np.round(wavelets.forward(seg.T, cfg["wavelet"], self.n_levels) / (QUANTUM * scale[:, None]))
            f = perception.channel_importance(sk, ch[a:b], cfg["allocation"], self._scores())
            # a channel the anchors already give to within their precision gets no budget
            f[np.abs(seg[:b - a]).max(axis=0) <= 0.5 * anchor_q + 1e-12] = 0.0
            lv = importance_levels(f)
            budgets = perception.allocate(level_weights(lv), int(total))
            levels_f.append(lv)
            for c in range(ch.shape[1]):
                if budgets[c] <= N0_BITS:
                    continue
                bits, n0 = spiht.encode(coeffs[c].astype(np.int64), approx, int(budgets[c]) - N0_BITS)
                head = np.array([(n0 + 1) >> k & 1 for k in range(N0_BITS - 1, -1, -1)], dtype=np.uint8)
                streams += [head, bits]
        bits = np.concatenate(streams) if streams else np.zeros(0, dtype=np.uint8)
        levels = np.stack(levels_f)                          # (segments, channels), sent per channel as changes
        parts = [encode_ints(np.diff(a_int, axis=0, prepend=0).T), encode_ints(np.diff(levels, axis=0, prepend=0).T),
                 encode_ints(np.diff(segment_bits, prepend=0)), _U32.pack(bits.size) + np.packbits(bits).tobytes()]
        return b"".join(_U32.pack(len(p)) + p for p in parts)

    def _parse(self, body: bytes, skeleton: Skeleton, frames: int):
        """(parts, anchor deltas, importance levels, segment budgets, bits) of a body, checked
        against the frames."""
        n_ch = skeleton.num_channels
        parts, pos = [], 0
        for _ in range(4):
            (size,) = _U32.unpack_from(body, pos)
            if pos + 4 + size > len(body):
                raise CorruptStreamError(f"spiht payload: a {size}-byte part at byte {pos} overruns the end")
            parts.append(body[pos + 4:pos + 4 + size])
            pos += 4 + size
        deltas = decode_ints(parts[0])
        level_changes = decode_ints(parts[1])
        n_seg = len(self._segments(frames))
        if deltas.size != anchor_frames(frames, self.config["window"]).size * n_ch or level_changes.size != n_seg * n_ch:
            raise CorruptStreamError("spiht payload: anchor or allocation streams do not match the frames")
        levels_f = np.cumsum(level_changes.reshape(n_ch, n_seg).T, axis=0).ravel()
        if levels_f.size != n_seg * n_ch \
                or levels_f.min(initial=0) < 0 or levels_f.max(initial=0) >= F_LEVELS:
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
        """Decode every channel stream: yields (segment, channel, start bit, bits used, coeffs)."""
        w, approx = self.config["window"], self.config["window"] >> self.n_levels
        cursor = 0
        for k, total in enumerate(totals):
            budgets = perception.allocate(level_weights(levels_f[k * n_ch:(k + 1) * n_ch]), int(total))
            for c in range(n_ch):
                if budgets[c] <= N0_BITS:
                    continue
                if cursor + N0_BITS > bits.size:
                    raise CorruptStreamError(f"spiht payload: bits end in segment {k}, channel {c}")
                n0 = int(np.dot(bits[cursor:cursor + N0_BITS], 1 << np.arange(N0_BITS - 1, -1, -1))) - 1
                coeffs, used = spiht.decode(bits, cursor + N0_BITS, int(budgets[c]) - N0_BITS, w, approx, n0)
                yield k, c, cursor, N0_BITS + used, coeffs
                cursor += N0_BITS + used
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
        w = cfg["window"]
        segments = self._segments(frames)
        coeffs = np.zeros((len(segments), n_ch, w))
        for k, c, _, _, values in self._walk(levels_f, totals, bits, n_ch):
            coeffs[k, c] = values
        for k, (a, b) in enumerate(segments):
            seg = wavelets.inverse(coeffs[k] * (QUANTUM * scale[:, None]), w, cfg["wavelet"], self.n_levels)
            out[a:b] += seg.T[:b - a]
        return out

    def truncate(self, payload: bytes, skeleton: Skeleton, bits_per_second: float) -> tuple["SpihtCodec", bytes]:
        """The payload cut to a lower rate without re-encoding: every segment budget shrinks by
        bits_per_second / the codec's rate, and every channel stream keeps the prefix its new
        budget allows. Returns the codec for the new rate and its payload."""
        from mocodec.codecs.base import read_envelope

        if bits_per_second > self.config["bits_per_second"]:
            raise CodecError(f"cannot truncate to {bits_per_second:g} bit/s, above the coded "
                             f"{self.config['bits_per_second']:g}")
        frames, fps, body = read_envelope(payload)
        smaller = self.with_knob("bits_per_second", bits_per_second)
        if frames == 0:
            return smaller, payload
        parts, _, levels_f, totals, bits = self._parse(body, skeleton, frames)
        if np.array_equal(totals, self.segment_budgets(frames, fps)):
            new_totals = smaller.segment_budgets(frames, fps)         # as if encoded at the new rate
        else:                                                          # explicit (crowd) budgets scale
            new_totals = np.floor(totals * (bits_per_second / self.config["bits_per_second"])).astype(np.int64)
        n_ch = skeleton.num_channels
        budgets = [perception.allocate(level_weights(levels_f[k * n_ch:(k + 1) * n_ch]), int(t))
                   for k, t in enumerate(new_totals)]
        keep = [bits[start:start + min(used, int(budgets[k][c]))]
                for k, c, start, used, _ in self._walk(levels_f, totals, bits, n_ch) if budgets[k][c] > N0_BITS]
        new_bits = np.concatenate(keep) if keep else np.zeros(0, dtype=np.uint8)
        new_parts = [parts[0], parts[1], encode_ints(np.diff(new_totals, prepend=0)),
                     _U32.pack(new_bits.size) + np.packbits(new_bits).tobytes()]
        new_body = b"".join(_U32.pack(len(p)) + p for p in new_parts)
        return smaller, smaller.wrap(new_body, frames, fps)
