"""``spiht`` as a stream: one packet per segment, W + 1 frames behind, that decodes exactly as
the whole clip would (seams smoothed as each next segment arrives)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mocodec.codecs.base import (
    Coded,
    HeldFrames,
    StreamDecoder,
    StreamEncoder,
    continuous_frames,
)
from mocodec.codecs.perceptual.spihtlayout import (
    ANCHOR_QUANTUM,
    F_LEVELS,
    PACKET,
    QUANTUM,
    SEAM_LIMIT,
    U32,
    channel_scale,
    line,
    packet_total,
)
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.coding.transforms import seams
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton

if TYPE_CHECKING:
    from mocodec.codecs.perceptual.spiht import SpihtCodec


class SpihtStreamEncoder(StreamEncoder):
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
        residual = values[:n] - line(start * self.anchor_q, end * self.anchor_q, n, n - 1 if last else n)
        total = int(np.floor(self.codec.config["bits_per_second"] * n / self.fps))
        levels, streams = self.codec.code_segment(self.skeleton, values[:n], residual, total)
        bits = np.concatenate(streams) if streams else np.zeros(0, dtype=np.uint8)
        parts = ([encode_ints(start)] if first else []) + [
            encode_ints(end - start),
            encode_ints(levels),
            U32.pack(total),
            U32.pack(bits.size) + np.packbits(bits).tobytes(),
        ]
        self.start = end
        return PACKET.pack(int(first) | 2 * int(last), n) + join_parts(parts)


class SpihtStreamDecoder(StreamDecoder):
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
        flags, n = PACKET.unpack_from(packet)
        n_ch = self.skeleton.num_channels
        if not 0 < n <= self.codec.config["window"]:
            raise CorruptStreamError(f"spiht packet: {n} frames in a segment of {self.codec.config['window']}")
        parts = split_parts(packet, None, "spiht packet", start=PACKET.size)
        start = self.start
        if flags & 1:
            start = decode_ints(parts.pop(0))
        if start is None or len(parts) != 4 or start.size != n_ch:
            raise CorruptStreamError("spiht packet: no start anchors (a packet is missing) or wrong layout")
        end = start + decode_ints(parts[0])
        levels = decode_ints(parts[1])
        total = packet_total(parts[2])
        (n_bits,) = U32.unpack_from(parts[3])
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
        uncertainty = self.codec.uncertainty(levels, self.skeleton)
        scale = channel_scale(self.skeleton)
        cursor = 0
        for c, first, used, values, plane in self.codec.segment_streams(levels, total, bits, 0, "the packet"):
            coeffs[c] = values
            uncertainty[c] = 2.0 ** (plane + 1) * QUANTUM * scale[c]
            cursor = first + used
        if cursor != n_bits:
            raise CorruptStreamError(f"spiht packet: {n_bits - cursor} bits left over")
        out = line(start * self.anchor_q, end * self.anchor_q, n, n - 1 if flags & 2 else n)
        out += self.codec.residual(coeffs, self.skeleton, n)
        self.start = end
        return out, bool(flags & 2), uncertainty
